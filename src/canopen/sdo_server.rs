//! The SDO server protocol (CiA 301 §7.2.4): expedited, segmented and block transfers,
//! download and upload, of any length up to [`super::MAX_OBJECT_BYTES`].
//!
//! The protocol lives here; what an address means, and whether a write is allowed, is the
//! [`SdoTarget`]'s, which works on bytes (what they mean is the target's business). canopen-rs's
//! `SdoServer` is not used: it answers a missing sub-index with "object does not exist", a
//! length mismatch with 0x06070012 only, has no range or device-state aborts, and keeps at most
//! 32 bytes (see `tests/canopen_rs_gaps.rs`).
//!
//! A request may need several frames back (a block upload's sub-block): [`SdoServer::handle`]
//! pushes them to `out`.

use super::abort::AbortCode;
use super::sdo_client::{block_end_frame, crc16, push_sub_block as sub_block};

/// What the server serves.
pub trait SdoTarget {
    /// The bytes of an address (little-endian for numbers), or why not.
    fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, AbortCode>;
    /// Whether a download of `size` bytes (when indicated) to the address may start.
    fn sdo_check_write(
        &mut self,
        index: u16,
        sub: u8,
        size: Option<usize>,
    ) -> Result<(), AbortCode>;
    /// Apply a completed download.
    fn sdo_write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode>;
}

const MAX_LEN: usize = super::MAX_OBJECT_BYTES;

/// Segments per block this server asks for in a block download (CiA 301: 1 to 127).
pub const BLOCK_SIZE: u8 = 127;

/// "Invalid block size" (CiA 301 Table 22).
const INVALID_BLOCK_SIZE: AbortCode = AbortCode(0x0504_0002);
/// "CRC error".
const CRC_ERROR: AbortCode = AbortCode(0x0504_0004);

#[derive(Debug, Default)]
enum Transfer {
    #[default]
    Idle,
    Download {
        index: u16,
        sub: u8,
        size: Option<usize>,
        buf: Vec<u8>,
        toggle: bool,
    },
    Upload {
        data: Vec<u8>,
        pos: usize,
        toggle: bool,
    },
    /// Block download: receiving sub-blocks; `next` is the sequence number expected.
    BlockDownload {
        index: u16,
        sub: u8,
        size: Option<usize>,
        crc: bool,
        buf: Vec<u8>,
        next: u8,
        /// The last segment came in sequence: the end request is next.
        complete: bool,
    },
    /// Block upload: initiated, waiting for the start request.
    BlockUploadReady {
        index: u16,
        sub: u8,
        data: Vec<u8>,
        blksize: u8,
        crc: bool,
    },
    /// Block upload: a sub-block of `count` segments from `start` was sent.
    BlockUpload {
        index: u16,
        sub: u8,
        data: Vec<u8>,
        start: usize,
        count: u8,
        crc: bool,
    },
    /// Block upload: the end was sent; waiting for its confirmation.
    BlockUploadEnd,
}

/// A sans-I/O SDO server: one request in, the answers out.
#[derive(Debug, Default)]
pub struct SdoServer {
    transfer: Transfer,
}

fn abort(index: u16, sub: u8, code: AbortCode) -> [u8; 8] {
    let mut r = [0u8; 8];
    r[0] = 0x80;
    r[1..3].copy_from_slice(&index.to_le_bytes());
    r[3] = sub;
    r[4..].copy_from_slice(&code.0.to_le_bytes());
    r
}

fn addressed(cs: u8, index: u16, sub: u8) -> [u8; 8] {
    let mut r = [0u8; 8];
    r[0] = cs;
    r[1..3].copy_from_slice(&index.to_le_bytes());
    r[3] = sub;
    r
}

/// Whether a segmented or block download of `size` bytes (when indicated) may start.
fn may_start_download(
    target: &mut impl SdoTarget,
    index: u16,
    sub: u8,
    size: Option<usize>,
) -> Result<(), AbortCode> {
    if size.is_some_and(|n| n > MAX_LEN) {
        return Err(AbortCode::LENGTH_TOO_HIGH);
    }
    target.sdo_check_write(index, sub, size)
}

impl SdoServer {
    /// A server with no transfer in progress.
    pub fn new() -> SdoServer {
        SdoServer::default()
    }

    /// Abandon any transfer (reset communication).
    pub fn reset(&mut self) {
        self.transfer = Transfer::Idle;
    }

    /// Handle one request (the data of a 0x600 + node frame); the answers (0x580 + node) go to
    /// `out`. None is due for a client abort, for a segment of a block download that does not
    /// end a sub-block, or for a frame that is not 8 bytes long (CiA 301 says to ignore it).
    pub fn handle(&mut self, target: &mut impl SdoTarget, req: &[u8], out: &mut Vec<[u8; 8]>) {
        let Ok(req) = <[u8; 8]>::try_from(req) else {
            return;
        };
        // Inside a block download every frame is a segment (its first byte a sequence
        // number), except an abort and, once the last segment came, the end request.
        if let Transfer::BlockDownload { complete, .. } = self.transfer
            && req[0] != 0x80
            && !(complete && req[0] & 0xE3 == 0xC1)
        {
            self.block_download_segment(&req, out);
            return;
        }
        let index = u16::from_le_bytes([req[1], req[2]]);
        let sub = req[3];
        if let Some(r) = match req[0] >> 5 {
            1 => self.initiate_download(target, &req, index, sub),
            0 => self.download_segment(target, &req, index, sub),
            2 => self.initiate_upload(target, index, sub),
            3 => self.upload_segment(&req, index, sub),
            4 => {
                self.transfer = Transfer::Idle;
                None
            }
            5 => self.block_upload(target, &req, index, sub, out),
            6 => self.block_download(target, &req, index, sub),
            _ => {
                self.transfer = Transfer::Idle;
                Some(abort(index, sub, AbortCode::COMMAND))
            }
        } {
            out.push(r);
        }
    }

    fn initiate_download(
        &mut self,
        target: &mut impl SdoTarget,
        req: &[u8; 8],
        index: u16,
        sub: u8,
    ) -> Option<[u8; 8]> {
        self.transfer = Transfer::Idle;
        let e = req[0] & 0x02 != 0;
        let s = req[0] & 0x01 != 0;
        if e {
            let n = if s {
                4 - usize::from((req[0] >> 2) & 3)
            } else {
                4
            };
            let r = target
                .sdo_check_write(index, sub, s.then_some(n))
                .and_then(|()| target.sdo_write(index, sub, &req[4..4 + n]));
            return Some(match r {
                Ok(()) => addressed(0x60, index, sub),
                Err(code) => abort(index, sub, code),
            });
        }
        let size = s.then(|| u32::from_le_bytes([req[4], req[5], req[6], req[7]]) as usize);
        if let Err(code) = may_start_download(target, index, sub, size) {
            return Some(abort(index, sub, code));
        }
        self.transfer = Transfer::Download {
            index,
            sub,
            size,
            buf: Vec::new(),
            toggle: false,
        };
        Some(addressed(0x60, index, sub))
    }

    fn download_segment(
        &mut self,
        target: &mut impl SdoTarget,
        req: &[u8; 8],
        index: u16,
        sub: u8,
    ) -> Option<[u8; 8]> {
        let Transfer::Download {
            index,
            sub,
            size,
            buf,
            toggle,
        } = &mut self.transfer
        else {
            return Some(abort(index, sub, AbortCode::COMMAND));
        };
        let (index, sub) = (*index, *sub);
        let t = req[0] & 0x10 != 0;
        if t != *toggle {
            self.transfer = Transfer::Idle;
            return Some(abort(index, sub, AbortCode::TOGGLE));
        }
        let n = 7 - usize::from((req[0] >> 1) & 7);
        let last = req[0] & 0x01 != 0;
        buf.extend_from_slice(&req[1..1 + n]);
        if buf.len() > MAX_LEN || size.is_some_and(|s| buf.len() > s) {
            self.transfer = Transfer::Idle;
            return Some(abort(index, sub, AbortCode::LENGTH_TOO_HIGH));
        }
        *toggle = !*toggle;
        let ack = 0x20 | if t { 0x10 } else { 0 };
        if !last {
            return Some([ack, 0, 0, 0, 0, 0, 0, 0]);
        }
        let data = std::mem::take(buf);
        let size = *size;
        self.transfer = Transfer::Idle;
        if size.is_some_and(|s| s != data.len()) {
            return Some(abort(index, sub, AbortCode::LENGTH_TOO_LOW));
        }
        Some(match target.sdo_write(index, sub, &data) {
            Ok(()) => [ack, 0, 0, 0, 0, 0, 0, 0],
            Err(code) => abort(index, sub, code),
        })
    }

    fn initiate_upload(
        &mut self,
        target: &mut impl SdoTarget,
        index: u16,
        sub: u8,
    ) -> Option<[u8; 8]> {
        self.transfer = Transfer::Idle;
        let data = match target.sdo_read(index, sub) {
            Ok(d) => d,
            Err(code) => return Some(abort(index, sub, code)),
        };
        let n = data.len();
        if (1..=4).contains(&n) {
            let mut r = addressed(0x43 | (((4 - n) as u8) << 2), index, sub);
            r[4..4 + n].copy_from_slice(&data);
            return Some(r);
        }
        let mut r = addressed(0x41, index, sub);
        r[4..].copy_from_slice(&(n as u32).to_le_bytes());
        self.transfer = Transfer::Upload {
            data,
            pos: 0,
            toggle: false,
        };
        Some(r)
    }

    fn upload_segment(&mut self, req: &[u8; 8], index: u16, sub: u8) -> Option<[u8; 8]> {
        let Transfer::Upload { data, pos, toggle } = &mut self.transfer else {
            return Some(abort(index, sub, AbortCode::COMMAND));
        };
        let t = req[0] & 0x10 != 0;
        if t != *toggle {
            self.transfer = Transfer::Idle;
            return Some(abort(0, 0, AbortCode::TOGGLE));
        }
        let n = (data.len() - *pos).min(7);
        let last = *pos + n == data.len();
        let mut r = [0u8; 8];
        r[0] = (if t { 0x10 } else { 0 }) | (((7 - n) as u8) << 1) | u8::from(last);
        r[1..1 + n].copy_from_slice(&data[*pos..*pos + n]);
        *pos += n;
        *toggle = !*toggle;
        if last {
            self.transfer = Transfer::Idle;
        }
        Some(r)
    }

    /// Block upload (ccs 5): initiate, start, sub-block confirmations, end (CiA 301
    /// §7.2.4.3.12–15).
    fn block_upload(
        &mut self,
        target: &mut impl SdoTarget,
        req: &[u8; 8],
        index: u16,
        sub: u8,
        out: &mut Vec<[u8; 8]>,
    ) -> Option<[u8; 8]> {
        match (req[0] & 0x03, std::mem::take(&mut self.transfer)) {
            // Initiate.
            (0, _) => {
                let blksize = req[4];
                if !(1..=127).contains(&blksize) {
                    return Some(abort(index, sub, INVALID_BLOCK_SIZE));
                }
                let data = match target.sdo_read(index, sub) {
                    Ok(d) => d,
                    Err(code) => return Some(abort(index, sub, code)),
                };
                // Protocol switch threshold: at or below it, a normal upload serves better.
                let pst = usize::from(req[5]);
                if pst > 0 && data.len() <= pst {
                    return self.initiate_upload(target, index, sub);
                }
                let mut r = addressed(0xC6, index, sub);
                r[4..].copy_from_slice(&(data.len() as u32).to_le_bytes());
                self.transfer = Transfer::BlockUploadReady {
                    index,
                    sub,
                    data,
                    blksize,
                    crc: req[0] & 0x04 != 0,
                };
                Some(r)
            }
            // Start: the first sub-block.
            (
                3,
                Transfer::BlockUploadReady {
                    index,
                    sub,
                    data,
                    blksize,
                    crc,
                },
            ) => {
                let count = sub_block(&data, 0, blksize, out);
                self.transfer = Transfer::BlockUpload {
                    index,
                    sub,
                    data,
                    start: 0,
                    count,
                    crc,
                };
                None
            }
            // A sub-block's confirmation: the next one, a repeat, or the end.
            (
                2,
                Transfer::BlockUpload {
                    index,
                    sub,
                    data,
                    start,
                    count,
                    crc,
                },
            ) => {
                let (ackseq, blksize) = (req[1], req[2]);
                if ackseq > count || !(1..=127).contains(&blksize) {
                    let code = if ackseq > count {
                        AbortCode(0x0504_0003)
                    } else {
                        INVALID_BLOCK_SIZE
                    };
                    return Some(abort(index, sub, code));
                }
                let sent_all = start + 7 * usize::from(count) >= data.len();
                if sent_all && ackseq == count {
                    self.transfer = Transfer::BlockUploadEnd;
                    return Some(block_end_frame(&data, crc));
                }
                let start = start + 7 * usize::from(ackseq);
                let count = sub_block(&data, start, blksize, out);
                self.transfer = Transfer::BlockUpload {
                    index,
                    sub,
                    data,
                    start,
                    count,
                    crc,
                };
                None
            }
            // End confirmation: done, nothing to answer.
            (1, Transfer::BlockUploadEnd) => None,
            _ => Some(abort(index, sub, AbortCode::COMMAND)),
        }
    }

    /// Block download (ccs 6): initiate and end here; the segments in between go to
    /// [`SdoServer::block_download_segment`] (CiA 301 §7.2.4.3.9–11).
    fn block_download(
        &mut self,
        target: &mut impl SdoTarget,
        req: &[u8; 8],
        index: u16,
        sub: u8,
    ) -> Option<[u8; 8]> {
        match (req[0] & 0x01, std::mem::take(&mut self.transfer)) {
            (0, _) => {
                let size = (req[0] & 0x02 != 0)
                    .then(|| u32::from_le_bytes([req[4], req[5], req[6], req[7]]) as usize);
                if let Err(code) = may_start_download(target, index, sub, size) {
                    return Some(abort(index, sub, code));
                }
                self.transfer = Transfer::BlockDownload {
                    index,
                    sub,
                    size,
                    crc: req[0] & 0x04 != 0,
                    buf: Vec::new(),
                    next: 1,
                    complete: false,
                };
                let mut r = addressed(0xA4, index, sub);
                r[4] = BLOCK_SIZE;
                Some(r)
            }
            (
                1,
                Transfer::BlockDownload {
                    index,
                    sub,
                    size,
                    crc,
                    mut buf,
                    complete: true,
                    ..
                },
            ) => {
                let n = usize::from((req[0] >> 2) & 7);
                let len = buf.len().saturating_sub(n);
                buf.truncate(len);
                if crc && u16::from_le_bytes([req[1], req[2]]) != crc16(&buf) {
                    return Some(abort(index, sub, CRC_ERROR));
                }
                if size.is_some_and(|s| s != buf.len()) {
                    return Some(abort(index, sub, AbortCode::LENGTH_MISMATCH));
                }
                Some(match target.sdo_write(index, sub, &buf) {
                    Ok(()) => [0xA1, 0, 0, 0, 0, 0, 0, 0],
                    Err(code) => abort(index, sub, code),
                })
            }
            _ => Some(abort(index, sub, AbortCode::COMMAND)),
        }
    }

    fn block_download_segment(&mut self, req: &[u8; 8], out: &mut Vec<[u8; 8]>) {
        let Transfer::BlockDownload {
            index,
            sub,
            buf,
            next,
            complete,
            ..
        } = &mut self.transfer
        else {
            return;
        };
        let (seqno, last) = (req[0] & 0x7F, req[0] & 0x80 != 0);
        if seqno == *next && !*complete {
            buf.extend_from_slice(&req[1..8]);
            *next += 1;
            *complete = last;
            if buf.len() > MAX_LEN + 7 {
                let (index, sub) = (*index, *sub);
                self.transfer = Transfer::Idle;
                out.push(abort(index, sub, AbortCode::LENGTH_TOO_HIGH));
                return;
            }
        }
        if last || seqno == BLOCK_SIZE {
            out.push([0xA2, *next - 1, BLOCK_SIZE, 0, 0, 0, 0, 0]);
            *next = 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use canopen_rs::sdo::{SdoClient, SdoEvent};
    use canopen_rs::{Address, ByteString, DataType, NodeId, Value};
    use std::collections::BTreeMap;

    /// The one answer to a request (`None`: no answer).
    fn one(s: &mut SdoServer, t: &mut Table, req: &[u8]) -> Option<[u8; 8]> {
        let mut out = Vec::new();
        s.handle(t, req, &mut out);
        assert!(out.len() <= 1, "{out:?}");
        out.pop()
    }

    /// A target with a few typed entries, no device rules.
    struct Table(BTreeMap<(u16, u8), Value>);

    impl SdoTarget for Table {
        fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, AbortCode> {
            self.0
                .get(&(index, sub))
                .map(crate::canopen::value_bytes)
                .ok_or(AbortCode::NO_OBJECT)
        }
        fn sdo_check_write(
            &mut self,
            index: u16,
            sub: u8,
            size: Option<usize>,
        ) -> Result<(), AbortCode> {
            let v = self.0.get(&(index, sub)).ok_or(AbortCode::NO_OBJECT)?;
            match (v.data_type().fixed_size(), size) {
                (Some(f), Some(s)) if f != s => Err(AbortCode::LENGTH_MISMATCH),
                _ => Ok(()),
            }
        }
        fn sdo_write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
            let t = self.0[&(index, sub)].data_type();
            let v = Value::decode_le(t, data).map_err(|_| AbortCode::LENGTH_MISMATCH)?;
            self.0.insert((index, sub), v);
            Ok(())
        }
    }

    fn table() -> Table {
        let mut m = BTreeMap::new();
        m.insert((0x1017, 0), Value::Unsigned16(0));
        m.insert(
            (0x1008, 0),
            Value::VisibleString(ByteString::from_str("a rather long device name").unwrap()),
        );
        m.insert((0x6064, 0), Value::Integer32(-5));
        Table(m)
    }

    /// Drive canopen-rs's client against our server: an independent implementation of the
    /// other side.
    fn run(
        server: &mut SdoServer,
        t: &mut Table,
        mut frame: [u8; 8],
        client: &mut SdoClient,
    ) -> SdoEvent {
        for _ in 0..100 {
            let resp = one(server, t, &frame).expect("a response");
            match client.on_response(&resp) {
                SdoEvent::Send(next) => frame = next,
                done => return done,
            }
        }
        panic!("transfer did not finish");
    }

    #[test]
    fn expedited_and_segmented_both_ways_against_canopen_rs_client() {
        let mut s = SdoServer::new();
        let mut t = table();
        let mut c = SdoClient::new(NodeId::new(1).unwrap());
        let f = c.read(Address::new(0x6064, 0), DataType::Integer32);
        assert_eq!(
            run(&mut s, &mut t, f, &mut c),
            SdoEvent::Complete(Some(Value::Integer32(-5)))
        );
        let f = c.write(Address::new(0x1017, 0), Value::Unsigned16(100));
        assert_eq!(run(&mut s, &mut t, f, &mut c), SdoEvent::Complete(None));
        assert_eq!(t.0[&(0x1017, 0)], Value::Unsigned16(100));
        let name = ByteString::from_str("a new name longer than seven").unwrap();
        let f = c.write(Address::new(0x1008, 0), Value::VisibleString(name));
        assert_eq!(run(&mut s, &mut t, f, &mut c), SdoEvent::Complete(None));
        let f = c.read(Address::new(0x1008, 0), DataType::VisibleString);
        assert_eq!(
            run(&mut s, &mut t, f, &mut c),
            SdoEvent::Complete(Some(Value::VisibleString(name)))
        );
    }

    #[test]
    fn byte_exact_expedited_frames() {
        let mut s = SdoServer::new();
        let mut t = table();
        // upload 0x6064 → 0x43, value LE
        assert_eq!(
            one(&mut s, &mut t, &[0x40, 0x64, 0x60, 0, 0, 0, 0, 0]),
            Some([0x43, 0x64, 0x60, 0, 0xFB, 0xFF, 0xFF, 0xFF])
        );
        // download 2 bytes to 0x1017 → 0x60
        assert_eq!(
            one(&mut s, &mut t, &[0x2B, 0x17, 0x10, 0, 0xE8, 0x03, 0, 0]),
            Some([0x60, 0x17, 0x10, 0, 0, 0, 0, 0])
        );
        // 4 bytes to a u16: length mismatch abort 0x06070010
        assert_eq!(
            one(&mut s, &mut t, &[0x23, 0x17, 0x10, 0, 1, 0, 0, 0]),
            Some([0x80, 0x17, 0x10, 0, 0x10, 0x00, 0x07, 0x06])
        );
    }

    #[test]
    fn toggle_errors_abort_and_short_frames_are_ignored() {
        let mut s = SdoServer::new();
        let mut t = table();
        assert!(one(&mut s, &mut t, &[0x40, 0x08, 0x10, 0]).is_none());
        let r = one(&mut s, &mut t, &[0x40, 0x08, 0x10, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(r[0], 0x41);
        // first segment request must have toggle 0
        let r = one(&mut s, &mut t, &[0x70, 0, 0, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(r[0], 0x80);
        assert_eq!(
            u32::from_le_bytes([r[4], r[5], r[6], r[7]]),
            AbortCode::TOGGLE.0
        );
        // a segment with no transfer in progress
        let r = one(&mut s, &mut t, &[0x60, 0, 0, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(
            u32::from_le_bytes([r[4], r[5], r[6], r[7]]),
            AbortCode::COMMAND.0
        );
    }

    proptest::proptest! {
        #[test]
        fn never_panics(frames in proptest::collection::vec(proptest::collection::vec(proptest::prelude::any::<u8>(), 0..=8), 0..20)) {
            let mut s = SdoServer::new();
            let mut t = table();
            for f in frames {
                let _ = one(&mut s, &mut t, &f);
            }
        }
    }
}
