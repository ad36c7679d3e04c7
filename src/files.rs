//! Files the command line reads and writes, with their bounds.
//!
//! Inputs (machine files, drive dictionaries, tool tables, resume files, EDS files, programs
//! to optimise, candump logs) must be regular files: a FIFO would block forever, `/dev/zero`
//! would grow memory without end, a directory is a mistake. [`open_input`] refuses them
//! before reading a byte, naming the path and what it is. Whole-file reads are bounded
//! ([`MAX_CONFIG_BYTES`]); files read line by line are bounded per line instead
//! ([`read_bounded_line`]), so any length of log or program streams in bounded memory.
//!
//! Outputs ([`Output`]) are written as `FILE.partial` and renamed over `FILE` when complete, so
//! a failed run never leaves a truncated file that looks whole; but only when `FILE` is absent
//! or a regular file. A device (`/dev/null`), a FIFO or a symlink is written in place (a symlink
//! through to its target, which stays a link): renaming over them would replace the node. A
//! directory is refused.

use std::fs::{File, OpenOptions};
use std::io::{BufRead, Read, Write};
use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

/// Largest configuration file read whole (machine file, drive dictionary, tool table, resume
/// file, EDS file, program given to `optimize`): 16 MiB, far beyond any real one.
pub const MAX_CONFIG_BYTES: u64 = 16 * 1024 * 1024;

/// Longest line of a file read line by line (a candump log, a G-code program: G-code's
/// `MAX_LINE_BYTES` is this one), terminator excluded: 64 KiB.
pub const MAX_LINE_BYTES: usize = 64 * 1024;

/// What a path that is not a regular file is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    /// A directory.
    Directory,
    /// A FIFO (named pipe).
    Fifo,
    /// A character device, e.g. `/dev/zero`.
    CharDevice,
    /// A block device.
    BlockDevice,
    /// A Unix socket.
    Socket,
    /// Anything else that is not a regular file.
    Other,
}

impl FileKind {
    fn of(t: std::fs::FileType) -> Option<FileKind> {
        Some(if t.is_file() {
            return None;
        } else if t.is_dir() {
            FileKind::Directory
        } else if t.is_fifo() {
            FileKind::Fifo
        } else if t.is_char_device() {
            FileKind::CharDevice
        } else if t.is_block_device() {
            FileKind::BlockDevice
        } else if t.is_socket() {
            FileKind::Socket
        } else {
            FileKind::Other
        })
    }
}

impl std::fmt::Display for FileKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FileKind::Directory => "a directory",
            FileKind::Fifo => "a FIFO (named pipe)",
            FileKind::CharDevice => "a character device",
            FileKind::BlockDevice => "a block device",
            FileKind::Socket => "a socket",
            FileKind::Other => "not a regular file",
        })
    }
}

/// Text from a file, shown with its control characters escaped (`\u{1b}`, `\r`, ...): an ANSI
/// escape sequence, a carriage return or a bidirectional override in a resume file's reason or
/// a machine's name must not redraw or fake what the operator reads.
#[derive(Debug, Clone, Copy)]
pub struct Escaped<'a>(pub &'a str);

impl std::fmt::Display for Escaped<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use std::fmt::Write as _;
        for c in self.0.chars() {
            // C0, DEL, C1, and the bidirectional embeddings, overrides and isolates.
            let bidi = matches!(c, '\u{200E}' | '\u{200F}' | '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}');
            if c.is_control() || bidi {
                write!(f, "{}", c.escape_default())?;
            } else {
                f.write_char(c)?;
            }
        }
        Ok(())
    }
}

/// An input or output that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The input is not a regular file.
    #[error("{path}: is {kind}; give a regular file")]
    NotRegular {
        /// The path.
        path: PathBuf,
        /// What it is.
        kind: FileKind,
    },
    /// The input is larger than its bound.
    #[error("{path}: larger than {max_bytes} bytes, the bound for this file")]
    TooLarge {
        /// The path.
        path: PathBuf,
        /// The bound.
        max_bytes: u64,
    },
    /// A line of the input is longer than its bound.
    #[error("{path}:{line}: line longer than {max_bytes} bytes")]
    LineTooLong {
        /// The path.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// The bound.
        max_bytes: usize,
    },
    /// The input is not UTF-8 text.
    #[error("{path}:{line}: not UTF-8 text")]
    NotText {
        /// The path.
        path: PathBuf,
        /// 1-based line of the first bad byte.
        line: usize,
    },
    /// The input could not be opened or read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The path.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The output is a directory.
    #[error("{path}: is a directory; give a file name for the output")]
    OutputIsDirectory {
        /// The path.
        path: PathBuf,
    },
    /// The output could not be created or written.
    #[error("{path}: cannot write: {source}")]
    Write {
        /// The path.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// Opens `path` for reading if it is a regular file (after symlinks), refusing anything else
/// before a byte is read; a FIFO is opened non-blocking so that the check itself cannot hang.
pub fn open_input(path: &Path) -> Result<File, FileError> {
    let read_err = |source| FileError::Read {
        path: path.to_path_buf(),
        source,
    };
    let not_regular = |kind| FileError::NotRegular {
        path: path.to_path_buf(),
        kind,
    };
    let meta = std::fs::metadata(path).map_err(read_err)?;
    if let Some(kind) = FileKind::of(meta.file_type()) {
        return Err(not_regular(kind));
    }
    // The path may have changed since: check what was opened.
    let file = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(read_err)?;
    let meta = file.metadata().map_err(read_err)?;
    if let Some(kind) = FileKind::of(meta.file_type()) {
        return Err(not_regular(kind));
    }
    Ok(file)
}

/// The bytes of the regular file `path`, at most `max_bytes` of them.
pub fn read_bounded(path: &Path, max_bytes: u64) -> Result<Vec<u8>, FileError> {
    read_to_end_bounded(open_input(path)?, path, max_bytes)
}

/// The bytes of `reader` (standard input where `-` is allowed; `path` names it in errors), at
/// most `max_bytes` of them.
pub fn read_to_end_bounded(
    reader: impl Read,
    path: &Path,
    max_bytes: u64,
) -> Result<Vec<u8>, FileError> {
    let mut bytes = Vec::new();
    reader
        .take(max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(|source| FileError::Read {
            path: path.to_path_buf(),
            source,
        })?;
    if bytes.len() as u64 > max_bytes {
        return Err(FileError::TooLarge {
            path: path.to_path_buf(),
            max_bytes,
        });
    }
    Ok(bytes)
}

/// The text of the regular file `path` (UTF-8, at most `max_bytes`): a configuration file.
pub fn read_text(path: &Path, max_bytes: u64) -> Result<String, FileError> {
    let bytes = read_bounded(path, max_bytes)?;
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let line = 1 + e.as_bytes()[..at].iter().filter(|b| **b == b'\n').count();
        FileError::NotText {
            path: path.to_path_buf(),
            line,
        }
    })
}

/// Reads one line of `reader` into `buf` (cleared; terminator `\n` or `\r\n` stripped), reading
/// no more than `max_bytes` + 2 bytes of it. `Ok(false)` at the end of the input; a longer line
/// is [`FileError::LineTooLong`] at `line` (the 1-based number of the line being read).
pub fn read_bounded_line<R: BufRead>(
    reader: &mut R,
    buf: &mut Vec<u8>,
    max_bytes: usize,
    path: &Path,
    line: usize,
) -> Result<bool, FileError> {
    buf.clear();
    let n = reader
        .by_ref()
        .take(max_bytes as u64 + 2)
        .read_until(b'\n', buf)
        .map_err(|source| FileError::Read {
            path: path.to_path_buf(),
            source,
        })?;
    if n == 0 {
        return Ok(false);
    }
    if buf.last() == Some(&b'\n') {
        buf.pop();
        if buf.last() == Some(&b'\r') {
            buf.pop();
        }
    }
    if buf.len() > max_bytes {
        return Err(FileError::LineTooLong {
            path: path.to_path_buf(),
            line,
            max_bytes,
        });
    }
    Ok(true)
}

/// An output file, buffered. Written atomically (`FILE.partial`, renamed on [`Output::finish`],
/// removed if dropped unfinished) when the target is absent or a regular file; otherwise (a
/// device, a FIFO, a symlink) written in place. A directory is refused.
pub struct Output {
    path: PathBuf,
    /// The partial file to rename over `path` when finished (atomic writes only).
    partial: Option<PathBuf>,
    w: Option<std::io::BufWriter<File>>,
}

impl std::fmt::Debug for Output {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Output")
            .field("path", &self.path)
            .field("partial", &self.partial)
            .finish()
    }
}

/// Whether an output at `path` is written through a partial file and a rename (absent or a
/// regular file, not through a symlink); `Err` for a directory.
pub fn check_output(path: &Path) -> Result<bool, FileError> {
    let write_err = |source| FileError::Write {
        path: path.to_path_buf(),
        source,
    };
    match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(true),
        Err(e) => Err(write_err(e)),
        Ok(meta) => {
            let t = meta.file_type();
            let target_is_dir = if t.is_symlink() {
                std::fs::metadata(path).is_ok_and(|m| m.is_dir())
            } else {
                t.is_dir()
            };
            if target_is_dir {
                return Err(FileError::OutputIsDirectory {
                    path: path.to_path_buf(),
                });
            }
            Ok(t.is_file())
        }
    }
}

impl Output {
    /// Creates the output `path` (see [`Output`] for how).
    pub fn create(path: &Path) -> Result<Output, FileError> {
        let partial = if check_output(path)? {
            let mut p = path.as_os_str().to_owned();
            p.push(".partial");
            Some(PathBuf::from(p))
        } else {
            None
        };
        let target = partial.as_deref().unwrap_or(path);
        let f = File::create(target).map_err(|source| FileError::Write {
            path: target.to_path_buf(),
            source,
        })?;
        Ok(Output {
            path: path.to_path_buf(),
            partial,
            w: Some(std::io::BufWriter::with_capacity(1 << 16, f)),
        })
    }

    /// The path the output was asked for.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn err(&self, source: std::io::Error) -> FileError {
        FileError::Write {
            path: self.path.clone(),
            source,
        }
    }

    /// Writes `bytes`.
    pub fn write_all(&mut self, bytes: &[u8]) -> Result<(), FileError> {
        match self.w.as_mut() {
            Some(w) => w.write_all(bytes).map_err(|e| self.err(e)),
            None => Ok(()),
        }
    }

    /// Flushes the output and, for an atomic write, renames the partial file over the target.
    pub fn finish(mut self) -> Result<(), FileError> {
        if let Some(mut w) = self.w.take()
            && let Err(e) = w.flush()
        {
            if let Some(p) = &self.partial {
                let _ = std::fs::remove_file(p);
            }
            return Err(self.err(e));
        }
        match &self.partial {
            Some(p) => std::fs::rename(p, &self.path).map_err(|e| self.err(e)),
            None => Ok(()),
        }
    }
}

impl Drop for Output {
    fn drop(&mut self) {
        if self.w.take().is_some() {
            // Not finished: an error stopped the writer. A device or FIFO keeps what it got.
            if let Some(p) = &self.partial {
                let _ = std::fs::remove_file(p);
            }
        }
    }
}

/// Writes `bytes` to the output `path` whole (see [`Output`]).
pub fn write_output(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    let mut out = Output::create(path)?;
    out.write_all(bytes)?;
    out.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::FileTypeExt;

    fn mkfifo(path: &Path) {
        let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: `c` is a valid NUL-terminated path that outlives the call.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    }

    #[test]
    fn inputs_must_be_regular_files() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        mkfifo(&fifo);
        let cases = [
            (Path::new("/dev/zero"), FileKind::CharDevice),
            (fifo.as_path(), FileKind::Fifo),
            (dir.path(), FileKind::Directory),
        ];
        for (path, kind) in cases {
            let e = read_bounded(path, MAX_CONFIG_BYTES).unwrap_err();
            assert!(
                matches!(&e, FileError::NotRegular { path: p, kind: k } if p == path && *k == kind),
                "{e}"
            );
        }
        let big = dir.path().join("big");
        std::fs::write(&big, vec![b'#'; 101]).unwrap();
        assert!(matches!(
            read_bounded(&big, 100),
            Err(FileError::TooLarge { max_bytes: 100, .. })
        ));
        assert_eq!(read_bounded(&big, 101).unwrap().len(), 101);
    }

    #[test]
    fn lines_are_bounded() {
        let text = format!("short\r\n{}\nafter\n", "x".repeat(20));
        let mut r = std::io::BufReader::new(text.as_bytes());
        let mut buf = Vec::new();
        let p = Path::new("log");
        assert!(read_bounded_line(&mut r, &mut buf, 10, p, 1).unwrap());
        assert_eq!(buf, b"short");
        assert!(matches!(
            read_bounded_line(&mut r, &mut buf, 10, p, 2),
            Err(FileError::LineTooLong {
                line: 2,
                max_bytes: 10,
                ..
            })
        ));
        // /dev/zero has no line end: the read stops at the bound.
        let mut zero = std::io::BufReader::new(File::open("/dev/zero").unwrap());
        assert!(matches!(
            read_bounded_line(&mut zero, &mut buf, 1000, p, 1),
            Err(FileError::LineTooLong { line: 1, .. })
        ));
    }

    #[test]
    fn outputs_write_through_symlinks_and_devices_and_refuse_directories() {
        let dir = tempfile::tempdir().unwrap();
        // A regular file: replaced whole, no partial file left.
        let plain = dir.path().join("plain.csv");
        std::fs::write(&plain, "old\n").unwrap();
        write_output(&plain, b"new\n").unwrap();
        assert_eq!(std::fs::read(&plain).unwrap(), b"new\n");
        assert!(!dir.path().join("plain.csv.partial").exists());
        // A symlink: its target gets the text, the link stays a link.
        let target = dir.path().join("target.csv");
        std::fs::write(&target, "old\n").unwrap();
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        write_output(&link, b"through\n").unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().is_symlink());
        assert_eq!(std::fs::read(&target).unwrap(), b"through\n");
        // /dev/null: written, and still a character device.
        write_output(Path::new("/dev/null"), b"nothing\n").unwrap();
        let meta = std::fs::symlink_metadata("/dev/null").unwrap();
        assert!(meta.file_type().is_char_device());
        // A directory, directly or through a link: refused.
        let e = write_output(dir.path(), b"x").unwrap_err();
        assert!(matches!(e, FileError::OutputIsDirectory { .. }), "{e}");
        let dlink = dir.path().join("dlink");
        std::os::unix::fs::symlink(dir.path(), &dlink).unwrap();
        let e = write_output(&dlink, b"x").unwrap_err();
        assert!(matches!(e, FileError::OutputIsDirectory { .. }), "{e}");
        // Dropped unfinished: no partial file left, the old file intact.
        let mut out = Output::create(&plain).unwrap();
        out.write_all(b"half").unwrap();
        drop(out);
        assert_eq!(std::fs::read(&plain).unwrap(), b"new\n");
        assert!(!dir.path().join("plain.csv.partial").exists());
    }
}
