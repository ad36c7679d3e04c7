//! The SDO server protocol (CiA 301 §7.2.4): expedited and segmented download and upload.
//!
//! The protocol lives here; what an address means, and whether a write is allowed, is the
//! [`SdoTarget`]'s. canopen-rs's `SdoServer` is not used: it answers a missing sub-index with
//! "object does not exist", a length mismatch with 0x06070012 only, and has no range or
//! device-state aborts (see `tests/canopen_rs_gaps.rs`).

use canopen_rs::Value;

use super::abort::AbortCode;

/// What the server serves.
pub trait SdoTarget {
    /// The value of an address, or why not.
    fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Value, AbortCode>;
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

const MAX_LEN: usize = canopen_rs::MAX_STRING_LEN;

#[derive(Debug)]
enum Transfer {
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
}

/// A sans-I/O SDO server: one request in, at most one response out.
#[derive(Debug)]
pub struct SdoServer {
    transfer: Transfer,
}

impl Default for SdoServer {
    fn default() -> Self {
        SdoServer {
            transfer: Transfer::Idle,
        }
    }
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

impl SdoServer {
    /// A server with no transfer in progress.
    pub fn new() -> SdoServer {
        SdoServer::default()
    }

    /// Abandon any transfer (reset communication).
    pub fn reset(&mut self) {
        self.transfer = Transfer::Idle;
    }

    /// Handle one request (the data of a 0x600 + node frame). `None` when no answer is due
    /// (a client abort, or a frame that is not 8 bytes long, which CiA 301 says to ignore).
    pub fn handle(&mut self, target: &mut impl SdoTarget, req: &[u8]) -> Option<[u8; 8]> {
        if req.len() != 8 {
            return None;
        }
        let index = u16::from_le_bytes([req[1], req[2]]);
        let sub = req[3];
        match req[0] >> 5 {
            // initiate download
            1 => {
                self.transfer = Transfer::Idle;
                let e = req[0] & 0x02 != 0;
                let s = req[0] & 0x01 != 0;
                if e {
                    let n = if s {
                        4 - usize::from((req[0] >> 2) & 3)
                    } else {
                        4
                    };
                    let data = &req[4..4 + n];
                    let r = target
                        .sdo_check_write(index, sub, s.then_some(n))
                        .and_then(|()| target.sdo_write(index, sub, data));
                    Some(match r {
                        Ok(()) => addressed(0x60, index, sub),
                        Err(code) => abort(index, sub, code),
                    })
                } else {
                    let size =
                        s.then(|| u32::from_le_bytes([req[4], req[5], req[6], req[7]]) as usize);
                    if size.is_some_and(|n| n > MAX_LEN) {
                        return Some(abort(index, sub, AbortCode::LENGTH_TOO_HIGH));
                    }
                    if let Err(code) = target.sdo_check_write(index, sub, size) {
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
            }
            // download segment
            0 => {
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
                match target.sdo_write(index, sub, &data) {
                    Ok(()) => Some([ack, 0, 0, 0, 0, 0, 0, 0]),
                    Err(code) => Some(abort(index, sub, code)),
                }
            }
            // initiate upload
            2 => {
                self.transfer = Transfer::Idle;
                let v = match target.sdo_read(index, sub) {
                    Ok(v) => v,
                    Err(code) => return Some(abort(index, sub, code)),
                };
                let mut data = [0u8; MAX_LEN];
                let n = v.encode_le(&mut data).unwrap_or(0);
                if (1..=4).contains(&n) {
                    let mut r = addressed(0x43 | (((4 - n) as u8) << 2), index, sub);
                    r[4..4 + n].copy_from_slice(&data[..n]);
                    Some(r)
                } else {
                    let mut r = addressed(0x41, index, sub);
                    r[4..].copy_from_slice(&(n as u32).to_le_bytes());
                    self.transfer = Transfer::Upload {
                        data: data[..n].to_vec(),
                        pos: 0,
                        toggle: false,
                    };
                    Some(r)
                }
            }
            // upload segment
            3 => {
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
            // abort from the client: no answer
            4 => {
                self.transfer = Transfer::Idle;
                None
            }
            _ => {
                self.transfer = Transfer::Idle;
                Some(abort(index, sub, AbortCode::COMMAND))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use canopen_rs::sdo::{SdoClient, SdoEvent};
    use canopen_rs::{Address, ByteString, DataType, NodeId};
    use std::collections::BTreeMap;

    /// A target with a few typed entries, no device rules.
    struct Table(BTreeMap<(u16, u8), Value>);

    impl SdoTarget for Table {
        fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Value, AbortCode> {
            self.0
                .get(&(index, sub))
                .copied()
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
            let resp = server.handle(t, &frame).expect("a response");
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
            s.handle(&mut t, &[0x40, 0x64, 0x60, 0, 0, 0, 0, 0]),
            Some([0x43, 0x64, 0x60, 0, 0xFB, 0xFF, 0xFF, 0xFF])
        );
        // download 2 bytes to 0x1017 → 0x60
        assert_eq!(
            s.handle(&mut t, &[0x2B, 0x17, 0x10, 0, 0xE8, 0x03, 0, 0]),
            Some([0x60, 0x17, 0x10, 0, 0, 0, 0, 0])
        );
        // 4 bytes to a u16: length mismatch abort 0x06070010
        assert_eq!(
            s.handle(&mut t, &[0x23, 0x17, 0x10, 0, 1, 0, 0, 0]),
            Some([0x80, 0x17, 0x10, 0, 0x10, 0x00, 0x07, 0x06])
        );
    }

    #[test]
    fn toggle_errors_abort_and_short_frames_are_ignored() {
        let mut s = SdoServer::new();
        let mut t = table();
        assert!(s.handle(&mut t, &[0x40, 0x08, 0x10, 0]).is_none());
        let r = s
            .handle(&mut t, &[0x40, 0x08, 0x10, 0, 0, 0, 0, 0])
            .unwrap();
        assert_eq!(r[0], 0x41);
        // first segment request must have toggle 0
        let r = s.handle(&mut t, &[0x70, 0, 0, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(r[0], 0x80);
        assert_eq!(
            u32::from_le_bytes([r[4], r[5], r[6], r[7]]),
            AbortCode::TOGGLE.0
        );
        // a segment with no transfer in progress
        let r = s.handle(&mut t, &[0x60, 0, 0, 0, 0, 0, 0, 0]).unwrap();
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
                let _ = s.handle(&mut t, &f);
            }
        }
    }
}
