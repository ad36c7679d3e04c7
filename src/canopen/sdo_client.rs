//! The SDO client protocol (CiA 301 §7.2.4.3), sans-I/O: expedited, segmented and block
//! transfers, upload and download, of any length.
//!
//! canopen-rs's client keeps a transfer in a 32-byte buffer and reports anything longer as an
//! abort from the node, which it is not (`tests/canopen_rs_gaps.rs`). This one works on bytes:
//! what the bytes mean (a `UNSIGNED32`, a `VISIBLE_STRING`) is the caller's business.
//!
//! One transfer per [`SdoClient`], in the style of [`crate::sim::SimDrive::poll`]: time is an
//! argument (`now`, a [`Duration`] since any fixed instant), frames to send are pushed to `out`
//! (the data of `0x600 + node` frames), and every call returns a [`Step`]:
//!
//! ```text
//! let mut c = SdoClient::upload(node, 0x1008, 0, Mode::Segmented, now, &mut out);
//! loop {
//!     send(out.drain(..));
//!     match wait_for(0x580 + node, c.poll_at()) {          // the driver's I/O
//!         Some(frame) => step = c.on_response(&frame, now, &mut out),
//!         None => step = c.poll(now, &mut out),            // the deadline passed
//!     }
//!     if let Step::Done(r) = step { break r }
//! }
//! ```
//!
//! Failures are typed ([`SdoError`]) and tell the node's abort ([`SdoError::Aborted`]) apart
//! from the client's own ([`SdoError::TimedOut`], [`SdoError::Protocol`], for which this client
//! sends the abort frame itself).
//!
//! Frames, by command specifier in the first byte's top three bits (CiA 301 Tables 14–38):
//! download initiate `ccs = 1` / `scs = 3`, download segment `ccs = 0` / `scs = 1`, upload
//! initiate `ccs = 2` / `scs = 2`, upload segment `ccs = 3` / `scs = 0`, abort `4`, block upload
//! `ccs = 5` / `scs = 6`, block download `ccs = 6` / `scs = 5`.

use std::time::Duration;

use super::abort::AbortCode;

/// How long a server may take to answer one request, unless the caller says otherwise.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(500);

/// The largest upload this client accepts unless told otherwise (a server announcing more is
/// aborted with "out of memory" rather than allowed to fill the gateway's memory).
pub const DEFAULT_MAX_LEN: usize = 1 << 20;

/// Segments per block this client asks for in a block upload (CiA 301: 1 to 127).
pub const BLOCK_SIZE: u8 = 127;

/// How the transfer runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Expedited where the data fits in 4 bytes, segmented (7 bytes a frame, each confirmed)
    /// otherwise. Every server supports it.
    Segmented,
    /// Block transfer (CiA 301 §7.2.4.3.9–16): up to 127 segments per confirmation, with a
    /// CRC. A server without it aborts with 0x05040001 (command specifier).
    Block,
}

/// What a finished transfer gives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// The bytes of the object.
    Uploaded(Vec<u8>),
    /// The server confirmed the download.
    Downloaded,
}

/// Why a transfer failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SdoError {
    /// The server aborted the transfer (its abort frame).
    #[error("aborted by the node with 0x{:08X} ({})", code.0, code.meaning())]
    Aborted {
        /// The server's abort code.
        code: AbortCode,
    },
    /// No answer within the time-out: this client sent the abort (0x05040000).
    #[error("no answer within {} ms", timeout.as_millis())]
    TimedOut {
        /// The time-out that passed.
        timeout: Duration,
    },
    /// The server's frame broke the protocol: this client aborted with `code`.
    #[error("the node's answer broke the SDO protocol ({what}); the gateway aborted the transfer with 0x{:08X}", code.0)]
    Protocol {
        /// What was wrong.
        what: &'static str,
        /// The abort code this client sent.
        code: AbortCode,
    },
}

/// What a call leaves.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    /// The transfer goes on: send what was pushed, then wait for an answer or
    /// [`SdoClient::poll_at`].
    Pending,
    /// The transfer ended.
    Done(Result<Outcome, SdoError>),
}

#[derive(Debug)]
enum State {
    /// Download: waiting for the initiate response (`then_segments`: a segmented download).
    DownloadInitiate,
    /// Segmented download: waiting for the confirmation of the segment sent from `pos`.
    DownloadSegment {
        pos: usize,
        len: usize,
        toggle: bool,
    },
    /// Upload: waiting for the initiate response.
    UploadInitiate,
    /// Segmented upload: waiting for a segment with `toggle`.
    UploadSegment { size: Option<usize>, toggle: bool },
    /// Block download: waiting for the initiate response.
    BlockDownloadInitiate,
    /// Block download: a sub-block of `count` segments from `start` was sent; waiting for its
    /// confirmation.
    BlockDownloadSub { start: usize, count: u8 },
    /// Block download: the end request was sent; waiting for its confirmation.
    BlockDownloadEnd,
    /// Block upload: waiting for the initiate response.
    BlockUploadInitiate,
    /// Block upload: receiving segments; `next` is the sequence number expected, `sub_start`
    /// the length of `buf` when this sub-block began.
    BlockUploadSub {
        size: Option<usize>,
        crc: bool,
        next: u8,
        sub_start: usize,
    },
    /// Block upload: the last segment came; waiting for the end frame with the CRC.
    BlockUploadEnd { size: Option<usize>, crc: bool },
    /// Finished.
    Done,
}

/// One SDO transfer with one node (see the module documentation).
#[derive(Debug)]
pub struct SdoClient {
    index: u16,
    sub: u8,
    state: State,
    /// Download: the bytes to send. Upload: the bytes received.
    buf: Vec<u8>,
    timeout: Duration,
    deadline: Duration,
    max_len: usize,
}

fn addressed(cmd: u8, index: u16, sub: u8) -> [u8; 8] {
    let mut f = [0u8; 8];
    f[0] = cmd;
    f[1..3].copy_from_slice(&index.to_le_bytes());
    f[3] = sub;
    f
}

/// Pushes one sub-block of a block transfer: the segments of `data` from `start`, at most
/// `blksize`, numbered from 1, the last one of the data flagged (bit 7); the number pushed.
pub(super) fn push_sub_block(data: &[u8], start: usize, blksize: u8, out: &mut Vec<[u8; 8]>) -> u8 {
    let mut pos = start;
    let mut count = 0u8;
    loop {
        count += 1;
        let len = (data.len() - pos).min(7);
        let last = pos + len >= data.len();
        let mut f = [0u8; 8];
        f[0] = count | if last { 0x80 } else { 0 };
        f[1..1 + len].copy_from_slice(&data[pos..pos + len]);
        out.push(f);
        pos += len;
        if last || count == blksize {
            return count;
        }
    }
}

/// The end frame of a block transfer of `data` (client download end, `ccs = 6`, and server
/// upload end, `scs = 6`, share it): `n`, the bytes of the last segment that held no data, and
/// the CRC when both sides use one.
pub(super) fn block_end_frame(data: &[u8], crc: bool) -> [u8; 8] {
    let used = data.len() - 7 * (data.len().saturating_sub(1) / 7);
    let n = if data.is_empty() { 7 } else { 7 - used };
    let mut e = [0u8; 8];
    e[0] = 0xC1 | ((n as u8) << 2);
    if crc {
        e[1..3].copy_from_slice(&crc16(data).to_le_bytes());
    }
    e
}

/// CRC-16/XMODEM (polynomial 0x1021, start 0), the block transfer's CRC (CiA 301 §7.2.4.3.16).
pub fn crc16(data: &[u8]) -> u16 {
    /// The CRC-16-CCITT generator x^16 + x^12 + x^5 + 1.
    const POLYNOMIAL: u16 = 0x1021; // not an object index: a CRC polynomial
    let mut crc: u16 = 0;
    for &b in data {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ POLYNOMIAL
            } else {
                crc << 1
            };
        }
    }
    crc
}

impl SdoClient {
    fn new(index: u16, sub: u8, state: State, buf: Vec<u8>, now: Duration) -> SdoClient {
        SdoClient {
            index,
            sub,
            state,
            buf,
            timeout: DEFAULT_TIMEOUT,
            deadline: now + DEFAULT_TIMEOUT,
            max_len: DEFAULT_MAX_LEN,
        }
    }

    /// Starts an upload of `index:sub`; the first request is pushed to `out`.
    pub fn upload(
        index: u16,
        sub: u8,
        mode: Mode,
        now: Duration,
        out: &mut Vec<[u8; 8]>,
    ) -> SdoClient {
        match mode {
            Mode::Segmented => {
                out.push(addressed(0x40, index, sub));
                SdoClient::new(index, sub, State::UploadInitiate, Vec::new(), now)
            }
            Mode::Block => {
                // ccs 5, cc (CRC supported), cs 0 (initiate); blksize; pst 0 (no switch).
                let mut f = addressed(0xA4, index, sub);
                f[4] = BLOCK_SIZE;
                out.push(f);
                SdoClient::new(index, sub, State::BlockUploadInitiate, Vec::new(), now)
            }
        }
    }

    /// Starts a download of `data` to `index:sub`; the first request is pushed to `out`.
    pub fn download(
        index: u16,
        sub: u8,
        data: Vec<u8>,
        mode: Mode,
        now: Duration,
        out: &mut Vec<[u8; 8]>,
    ) -> SdoClient {
        let len = data.len();
        match mode {
            Mode::Segmented if (1..=4).contains(&len) => {
                // Expedited, size indicated: n = 4 − len unused bytes.
                let mut f = addressed(0x23 | (((4 - len) as u8) << 2), index, sub);
                f[4..4 + len].copy_from_slice(&data);
                out.push(f);
                SdoClient::new(index, sub, State::DownloadInitiate, data, now)
            }
            Mode::Segmented => {
                let mut f = addressed(0x21, index, sub);
                f[4..].copy_from_slice(&(len as u32).to_le_bytes());
                out.push(f);
                SdoClient::new(index, sub, State::DownloadInitiate, data, now)
            }
            Mode::Block => {
                // ccs 6, cc (CRC supported), s (size indicated), cs 0 (initiate).
                let mut f = addressed(0xC6, index, sub);
                f[4..].copy_from_slice(&(len as u32).to_le_bytes());
                out.push(f);
                SdoClient::new(index, sub, State::BlockDownloadInitiate, data, now)
            }
        }
    }

    /// The time-out per answer (default [`DEFAULT_TIMEOUT`]), from now on.
    pub fn with_timeout(mut self, timeout: Duration, now: Duration) -> SdoClient {
        self.timeout = timeout;
        self.deadline = now + timeout;
        self
    }

    /// The largest upload accepted (default [`DEFAULT_MAX_LEN`]).
    pub fn with_max_len(mut self, max_len: usize) -> SdoClient {
        self.max_len = max_len;
        self
    }

    /// When [`SdoClient::poll`] must be called if no answer comes.
    pub fn poll_at(&self) -> Duration {
        self.deadline
    }

    /// The address of the transfer.
    pub fn address(&self) -> (u16, u8) {
        (self.index, self.sub)
    }

    /// No answer came: past the deadline the transfer is aborted (the abort is pushed to
    /// `out`) and ends with [`SdoError::TimedOut`].
    pub fn poll(&mut self, now: Duration, out: &mut Vec<[u8; 8]>) -> Step {
        if matches!(self.state, State::Done) || now < self.deadline {
            return Step::Pending;
        }
        self.abort_frame(AbortCode::TIMEOUT, out);
        self.state = State::Done;
        Step::Done(Err(SdoError::TimedOut {
            timeout: self.timeout,
        }))
    }

    fn abort_frame(&self, code: AbortCode, out: &mut Vec<[u8; 8]>) {
        let mut f = addressed(0x80, self.index, self.sub);
        f[4..].copy_from_slice(&code.0.to_le_bytes());
        out.push(f);
    }

    fn fail(&mut self, what: &'static str, code: AbortCode, out: &mut Vec<[u8; 8]>) -> Step {
        self.abort_frame(code, out);
        self.state = State::Done;
        Step::Done(Err(SdoError::Protocol { what, code }))
    }

    fn done(&mut self, outcome: Outcome) -> Step {
        self.state = State::Done;
        Step::Done(Ok(outcome))
    }

    /// Whether an initiate response names this transfer's address.
    fn echoes_address(&self, f: &[u8; 8]) -> bool {
        u16::from_le_bytes([f[1], f[2]]) == self.index && f[3] == self.sub
    }

    /// One frame from the server (the data of a `0x580 + node` frame). Frames that are not
    /// 8 bytes long are ignored, as CiA 301 asks.
    pub fn on_response(&mut self, data: &[u8], now: Duration, out: &mut Vec<[u8; 8]>) -> Step {
        let Ok(f) = <[u8; 8]>::try_from(data) else {
            return Step::Pending;
        };
        if matches!(self.state, State::Done) {
            return Step::Pending;
        }
        // An abort from the server ends any transfer (in a block upload's data phase the first
        // byte is a sequence number, and 0x80 is then "last segment, sequence 0", never valid).
        if f[0] == 0x80 {
            self.state = State::Done;
            let code = AbortCode(u32::from_le_bytes([f[4], f[5], f[6], f[7]]));
            return Step::Done(Err(SdoError::Aborted { code }));
        }
        self.deadline = now + self.timeout;
        match std::mem::replace(&mut self.state, State::Done) {
            State::Done => Step::Pending,
            State::DownloadInitiate => {
                if f[0] != 0x60 || !self.echoes_address(&f) {
                    return self.fail(
                        "not a download initiate response for this object",
                        AbortCode::COMMAND,
                        out,
                    );
                }
                if (1..=4).contains(&self.buf.len()) {
                    return self.done(Outcome::Downloaded);
                }
                self.send_download_segment(0, false, out)
            }
            State::DownloadSegment { pos, len, toggle } => {
                if f[0] & 0xE0 != 0x20 {
                    return self.fail("not a download segment response", AbortCode::COMMAND, out);
                }
                if (f[0] & 0x10 != 0) != toggle {
                    return self.fail("toggle bit not alternated", AbortCode::TOGGLE, out);
                }
                let pos = pos + len;
                if pos >= self.buf.len() {
                    return self.done(Outcome::Downloaded);
                }
                self.send_download_segment(pos, !toggle, out)
            }
            State::UploadInitiate => {
                if f[0] & 0xE0 != 0x40 || !self.echoes_address(&f) {
                    return self.fail(
                        "not an upload initiate response for this object",
                        AbortCode::COMMAND,
                        out,
                    );
                }
                let (e, s) = (f[0] & 0x02 != 0, f[0] & 0x01 != 0);
                if e {
                    let n = if s {
                        4 - usize::from((f[0] >> 2) & 3)
                    } else {
                        4
                    };
                    return self.done(Outcome::Uploaded(f[4..4 + n].to_vec()));
                }
                let size = s.then(|| u32::from_le_bytes([f[4], f[5], f[6], f[7]]) as usize);
                if let Err(step) = self.expect_size(size, out) {
                    return step;
                }
                out.push([0x60, 0, 0, 0, 0, 0, 0, 0]);
                self.state = State::UploadSegment {
                    size,
                    toggle: false,
                };
                Step::Pending
            }
            State::UploadSegment { size, toggle } => {
                if f[0] & 0xE0 != 0x00 {
                    return self.fail("not an upload segment", AbortCode::COMMAND, out);
                }
                if (f[0] & 0x10 != 0) != toggle {
                    return self.fail("toggle bit not alternated", AbortCode::TOGGLE, out);
                }
                let n = 7 - usize::from((f[0] >> 1) & 7);
                let last = f[0] & 0x01 != 0;
                self.buf.extend_from_slice(&f[1..1 + n]);
                if self.buf.len() > size.unwrap_or(self.max_len).min(self.max_len) {
                    return self.fail(
                        "more data than the size the node indicated",
                        AbortCode::LENGTH_TOO_HIGH,
                        out,
                    );
                }
                if last {
                    if size.is_some_and(|s| s != self.buf.len()) {
                        return self.fail(
                            "less data than the size the node indicated",
                            AbortCode::LENGTH_TOO_LOW,
                            out,
                        );
                    }
                    let data = std::mem::take(&mut self.buf);
                    return self.done(Outcome::Uploaded(data));
                }
                out.push([0x60 | if toggle { 0 } else { 0x10 }, 0, 0, 0, 0, 0, 0, 0]);
                self.state = State::UploadSegment {
                    size,
                    toggle: !toggle,
                };
                Step::Pending
            }
            State::BlockDownloadInitiate => {
                if f[0] & 0xE3 != 0xA0 || !self.echoes_address(&f) {
                    return self.fail(
                        "not a block download initiate response for this object",
                        AbortCode::COMMAND,
                        out,
                    );
                }
                self.send_sub_block(0, f[4], out)
            }
            State::BlockDownloadSub { start, count } => {
                if f[0] & 0xE3 != 0xA2 {
                    return self.fail("not a block download confirmation", AbortCode::COMMAND, out);
                }
                let (ackseq, blksize) = (f[1], f[2]);
                if ackseq > count {
                    return self.fail(
                        "confirmed a segment that was not sent",
                        AbortCode(0x0504_0003),
                        out,
                    );
                }
                let pos = (start + 7 * usize::from(ackseq)).min(self.buf.len());
                let all_sent = start + 7 * usize::from(count) >= self.buf.len();
                if all_sent && ackseq == count {
                    out.push(block_end_frame(&self.buf, true));
                    self.state = State::BlockDownloadEnd;
                    return Step::Pending;
                }
                self.send_sub_block(pos, blksize, out)
            }
            State::BlockDownloadEnd => {
                if f[0] & 0xE3 != 0xA1 {
                    return self.fail("not a block download end response", AbortCode::COMMAND, out);
                }
                self.done(Outcome::Downloaded)
            }
            State::BlockUploadInitiate => {
                if f[0] & 0xE0 == 0x40 {
                    // The server switched to a normal upload (a protocol switch it was not
                    // offered, but harmless): follow it.
                    self.state = State::UploadInitiate;
                    return self.on_response(&f, now, out);
                }
                if f[0] & 0xE1 != 0xC0 || !self.echoes_address(&f) {
                    return self.fail(
                        "not a block upload initiate response for this object",
                        AbortCode::COMMAND,
                        out,
                    );
                }
                let crc = f[0] & 0x04 != 0;
                let size = (f[0] & 0x02 != 0)
                    .then(|| u32::from_le_bytes([f[4], f[5], f[6], f[7]]) as usize);
                if let Err(step) = self.expect_size(size, out) {
                    return step;
                }
                out.push([0xA3, 0, 0, 0, 0, 0, 0, 0]);
                self.state = State::BlockUploadSub {
                    size,
                    crc,
                    next: 1,
                    sub_start: 0,
                };
                Step::Pending
            }
            State::BlockUploadSub {
                size,
                crc,
                next,
                sub_start,
            } => {
                let (seqno, last) = (f[0] & 0x7F, f[0] & 0x80 != 0);
                let mut next = next;
                if seqno == next {
                    self.buf.extend_from_slice(&f[1..8]);
                    next += 1;
                    if self.buf.len() > self.max_len.saturating_add(7) {
                        return self.fail(
                            "the object is longer than the gateway accepts",
                            AbortCode::OUT_OF_MEMORY,
                            out,
                        );
                    }
                }
                let good = next - 1;
                let in_sequence_last = last && seqno == good && seqno > 0;
                if last || seqno == BLOCK_SIZE {
                    // The sub-block's end: confirm it up to the last segment received in
                    // sequence; the server repeats the rest in the next sub-block.
                    out.push([0xA2, good, BLOCK_SIZE, 0, 0, 0, 0, 0]);
                    if in_sequence_last {
                        self.state = State::BlockUploadEnd { size, crc };
                    } else {
                        let sub_start = sub_start + 7 * usize::from(good);
                        self.buf.truncate(sub_start);
                        self.state = State::BlockUploadSub {
                            size,
                            crc,
                            next: 1,
                            sub_start,
                        };
                    }
                    return Step::Pending;
                }
                self.state = State::BlockUploadSub {
                    size,
                    crc,
                    next,
                    sub_start,
                };
                Step::Pending
            }
            State::BlockUploadEnd { size, crc } => {
                if f[0] & 0xE3 != 0xC1 {
                    return self.fail("not a block upload end", AbortCode::COMMAND, out);
                }
                let n = usize::from((f[0] >> 2) & 7);
                let len = self.buf.len().saturating_sub(n);
                self.buf.truncate(len);
                if size.is_some_and(|s| s != len) {
                    return self.fail(
                        "a length other than the size the node indicated",
                        AbortCode::LENGTH_MISMATCH,
                        out,
                    );
                }
                if crc && u16::from_le_bytes([f[1], f[2]]) != crc16(&self.buf) {
                    return self.fail("CRC error", AbortCode(0x0504_0004), out);
                }
                out.push([0xA1, 0, 0, 0, 0, 0, 0, 0]);
                let data = std::mem::take(&mut self.buf);
                self.done(Outcome::Uploaded(data))
            }
        }
    }

    /// An upload announced `size` bytes (if it said): refused beyond the client's bound, else
    /// the buffer is made ready for them.
    fn expect_size(&mut self, size: Option<usize>, out: &mut Vec<[u8; 8]>) -> Result<(), Step> {
        if size.is_some_and(|n| n > self.max_len) {
            return Err(self.fail(
                "the object is longer than the gateway accepts",
                AbortCode::OUT_OF_MEMORY,
                out,
            ));
        }
        self.buf = Vec::with_capacity(size.unwrap_or(0).min(self.max_len));
        Ok(())
    }

    fn send_download_segment(&mut self, pos: usize, toggle: bool, out: &mut Vec<[u8; 8]>) -> Step {
        let len = (self.buf.len() - pos).min(7);
        let last = pos + len >= self.buf.len();
        let mut f = [0u8; 8];
        f[0] = (if toggle { 0x10 } else { 0 }) | (((7 - len) as u8) << 1) | u8::from(last);
        f[1..1 + len].copy_from_slice(&self.buf[pos..pos + len]);
        out.push(f);
        self.state = State::DownloadSegment { pos, len, toggle };
        Step::Pending
    }

    /// Sends the segments of one sub-block from `start`, at most `blksize` (1 to 127).
    fn send_sub_block(&mut self, start: usize, blksize: u8, out: &mut Vec<[u8; 8]>) -> Step {
        if !(1..=127).contains(&blksize) {
            return self.fail("invalid block size", AbortCode(0x0504_0002), out);
        }
        let count = push_sub_block(&self.buf, start, blksize, out);
        self.state = State::BlockDownloadSub { start, count };
        Step::Pending
    }
}

#[cfg(test)]
mod tests;
