//! The client against a byte-level SDO server written here from CiA 301 (segmented and block,
//! both ways, of any length, with lost segments and a bad CRC on demand), against our own
//! [`crate::canopen::sdo_server::SdoServer`], and byte-exact frames.

use std::collections::{HashMap, VecDeque};
use std::time::Duration;

use super::*;

const T0: Duration = Duration::ZERO;

/// A test server over a byte store.
#[derive(Default)]
struct Server {
    store: HashMap<(u16, u8), Vec<u8>>,
    state: Srv,
    /// Block transfers: a sequence number lost once (not sent in an upload, not taken in a
    /// download).
    lose: Option<u8>,
    /// Block size the server asks for in a block download.
    blksize: u8,
    /// Send a wrong CRC at the end of a block upload.
    bad_crc: bool,
    /// Answer nothing at all.
    mute: bool,
}

#[derive(Default)]
enum Srv {
    #[default]
    Idle,
    DlSeg {
        key: (u16, u8),
        buf: Vec<u8>,
        toggle: bool,
    },
    UlSeg {
        data: Vec<u8>,
        pos: usize,
        toggle: bool,
    },
    BlkDl {
        key: (u16, u8),
        buf: Vec<u8>,
        next: u8,
        last_seen: bool,
    },
    BlkUl {
        data: Vec<u8>,
        acked: usize,
        blksize: u8,
    },
    BlkUlEnd,
}

fn frame(cmd: u8, key: (u16, u8)) -> [u8; 8] {
    let mut f = [0u8; 8];
    f[0] = cmd;
    f[1..3].copy_from_slice(&key.0.to_le_bytes());
    f[3] = key.1;
    f
}

impl Server {
    fn with(key: (u16, u8), data: Vec<u8>) -> Server {
        let mut s = Server {
            blksize: 127,
            ..Server::default()
        };
        s.store.insert(key, data);
        s
    }

    fn sub_block(&mut self, data: &[u8], acked: usize, blksize: u8, out: &mut Vec<[u8; 8]>) {
        let mut pos = acked;
        for seq in 1..=blksize {
            let len = (data.len() - pos).min(7);
            let last = pos + len >= data.len();
            let mut f = [0u8; 8];
            f[0] = seq | if last { 0x80 } else { 0 };
            f[1..1 + len].copy_from_slice(&data[pos..pos + len]);
            if self.lose == Some(seq) {
                self.lose = None;
            } else {
                out.push(f);
            }
            pos += len;
            if last {
                break;
            }
        }
    }

    fn handle(&mut self, req: [u8; 8]) -> Vec<[u8; 8]> {
        let mut out = Vec::new();
        if self.mute {
            return out;
        }
        let key = (u16::from_le_bytes([req[1], req[2]]), req[3]);
        match std::mem::take(&mut self.state) {
            Srv::BlkDl {
                key: k,
                mut buf,
                mut next,
                mut last_seen,
            } => {
                // A segment of a block download (or the end request after the last one).
                if last_seen && req[0] & 0xE3 == 0xC1 {
                    let n = usize::from((req[0] >> 2) & 7);
                    buf.truncate(buf.len() - n);
                    assert_eq!(u16::from_le_bytes([req[1], req[2]]), crc16(&buf), "CRC");
                    self.store.insert(k, buf);
                    out.push([0xA1, 0, 0, 0, 0, 0, 0, 0]);
                    return out;
                }
                let (seq, last) = (req[0] & 0x7F, req[0] & 0x80 != 0);
                if self.lose == Some(seq) {
                    self.lose = None;
                } else if seq == next {
                    buf.extend_from_slice(&req[1..8]);
                    next += 1;
                    last_seen = last;
                }
                if last || seq == self.blksize {
                    out.push([0xA2, next - 1, self.blksize, 0, 0, 0, 0, 0]);
                    next = 1;
                }
                self.state = Srv::BlkDl {
                    key: k,
                    buf,
                    next,
                    last_seen,
                };
                return out;
            }
            Srv::BlkUl {
                data,
                acked,
                blksize,
            } if req[0] == 0xA3 || req[0] & 0xE3 == 0xA2 => {
                let acked = if req[0] == 0xA3 {
                    acked
                } else {
                    acked + 7 * usize::from(req[1])
                };
                let blksize = if req[0] == 0xA3 { blksize } else { req[2] };
                if req[0] != 0xA3 && acked >= data.len() {
                    let n = (7 - (data.len() % 7)) % 7;
                    let n = if data.is_empty() { 7 } else { n };
                    let crc = crc16(&data) ^ u16::from(self.bad_crc);
                    let mut e = [0u8; 8];
                    e[0] = 0xC1 | ((n as u8) << 2);
                    e[1..3].copy_from_slice(&crc.to_le_bytes());
                    out.push(e);
                    self.state = Srv::BlkUlEnd;
                    return out;
                }
                self.sub_block(&data, acked, blksize, &mut out);
                self.state = Srv::BlkUl {
                    data,
                    acked,
                    blksize,
                };
                return out;
            }
            Srv::BlkUlEnd if req[0] == 0xA1 => return out,
            Srv::DlSeg {
                key: k,
                mut buf,
                toggle,
            } if req[0] & 0xE0 == 0 => {
                assert_eq!(req[0] & 0x10 != 0, toggle, "client toggle");
                let n = 7 - usize::from((req[0] >> 1) & 7);
                buf.extend_from_slice(&req[1..1 + n]);
                out.push([0x20 | if toggle { 0x10 } else { 0 }, 0, 0, 0, 0, 0, 0, 0]);
                if req[0] & 1 != 0 {
                    self.store.insert(k, buf);
                } else {
                    self.state = Srv::DlSeg {
                        key: k,
                        buf,
                        toggle: !toggle,
                    };
                }
                return out;
            }
            Srv::UlSeg { data, pos, toggle } if req[0] & 0xE0 == 0x60 => {
                assert_eq!(req[0] & 0x10 != 0, toggle, "client toggle");
                let n = (data.len() - pos).min(7);
                let last = pos + n == data.len();
                let mut f = [0u8; 8];
                f[0] = (if toggle { 0x10 } else { 0 }) | (((7 - n) as u8) << 1) | u8::from(last);
                f[1..1 + n].copy_from_slice(&data[pos..pos + n]);
                out.push(f);
                if !last {
                    self.state = Srv::UlSeg {
                        data,
                        pos: pos + n,
                        toggle: !toggle,
                    };
                }
                return out;
            }
            _ => {}
        }
        match req[0] {
            0x80 => {}
            c if c & 0xE0 == 0x20 => {
                if c & 0x02 != 0 {
                    let n = 4 - usize::from((c >> 2) & 3);
                    self.store.insert(key, req[4..4 + n].to_vec());
                } else {
                    self.state = Srv::DlSeg {
                        key,
                        buf: Vec::new(),
                        toggle: false,
                    };
                }
                out.push(frame(0x60, key));
            }
            0x40 => {
                let data = self.store.get(&key).cloned().unwrap_or_default();
                if (1..=4).contains(&data.len()) {
                    let mut f = frame(0x43 | (((4 - data.len()) as u8) << 2), key);
                    f[4..4 + data.len()].copy_from_slice(&data);
                    out.push(f);
                } else {
                    let mut f = frame(0x41, key);
                    f[4..].copy_from_slice(&(data.len() as u32).to_le_bytes());
                    out.push(f);
                    self.state = Srv::UlSeg {
                        data,
                        pos: 0,
                        toggle: false,
                    };
                }
            }
            c if c & 0xE3 == 0xA0 => {
                let data = self.store.get(&key).cloned().unwrap_or_default();
                let mut f = frame(0xC6, key);
                f[4..].copy_from_slice(&(data.len() as u32).to_le_bytes());
                out.push(f);
                self.state = Srv::BlkUl {
                    data,
                    acked: 0,
                    blksize: req[4],
                };
            }
            c if c & 0xE1 == 0xC0 => {
                let mut f = frame(0xA4, key);
                f[4] = self.blksize;
                out.push(f);
                self.state = Srv::BlkDl {
                    key,
                    buf: Vec::new(),
                    next: 1,
                    last_seen: false,
                };
            }
            _ => out.push(frame(0x80, key)),
        }
        out
    }
}

/// Runs a transfer to its end; the frames the client sent, in order.
fn exchange(
    server: &mut Server,
    mut client: SdoClient,
    mut out: Vec<[u8; 8]>,
) -> (Result<Outcome, SdoError>, Vec<[u8; 8]>) {
    let mut sent = Vec::new();
    let mut queue: VecDeque<[u8; 8]> = out.drain(..).collect();
    let mut now = T0;
    loop {
        while let Some(req) = queue.pop_front() {
            sent.push(req);
            for resp in server.handle(req) {
                now += Duration::from_millis(1);
                let step = client.on_response(&resp, now, &mut out);
                queue.extend(out.drain(..));
                if let Step::Done(r) = step {
                    sent.extend(queue.drain(..));
                    return (r, sent);
                }
            }
        }
        // Nothing more to send and no answer: the deadline passes.
        assert_eq!(
            client.poll(client.poll_at() - Duration::from_nanos(1), &mut out),
            Step::Pending
        );
        now = client.poll_at();
        if let Step::Done(r) = client.poll(now, &mut out) {
            sent.append(&mut out);
            return (r, sent);
        }
    }
}

fn bytes(n: usize) -> Vec<u8> {
    (0..n).map(|i| (i * 7 + 3) as u8).collect()
}

const KEY: (u16, u8) = (0x2000, 1);

fn upload(server: &mut Server, mode: Mode) -> Result<Outcome, SdoError> {
    let mut out = Vec::new();
    let c = SdoClient::upload(KEY.0, KEY.1, mode, T0, &mut out);
    exchange(server, c, out).0
}

fn download(server: &mut Server, data: Vec<u8>, mode: Mode) -> Result<Outcome, SdoError> {
    let mut out = Vec::new();
    let c = SdoClient::download(KEY.0, KEY.1, data, mode, T0, &mut out);
    exchange(server, c, out).0
}

#[test]
fn uploads_and_downloads_of_any_length_both_modes() {
    for n in [
        0,
        1,
        3,
        4,
        5,
        7,
        8,
        13,
        14,
        32,
        33,
        34,
        127 * 7,
        127 * 7 + 1,
        1000,
        5000,
    ] {
        for mode in [Mode::Segmented, Mode::Block] {
            let data = bytes(n);
            let mut s = Server::with(KEY, data.clone());
            assert_eq!(
                upload(&mut s, mode),
                Ok(Outcome::Uploaded(data.clone())),
                "upload {n} bytes {mode:?}"
            );
            let mut s = Server::with(KEY, Vec::new());
            assert_eq!(
                download(&mut s, data.clone(), mode),
                Ok(Outcome::Downloaded)
            );
            assert_eq!(s.store[&KEY], data, "download {n} bytes {mode:?}");
        }
    }
}

#[test]
fn a_block_lost_segment_is_sent_again() {
    // Not the sub-block's final segment: its loss leaves the client waiting (a time-out, as
    // CiA 301 has it), which `silence_times_out_with_the_clients_abort` covers.
    for lose in [1u8, 2, 50, 99, 126] {
        let data = bytes(2000);
        let mut s = Server::with(KEY, data.clone());
        s.lose = Some(lose);
        assert_eq!(
            upload(&mut s, Mode::Block),
            Ok(Outcome::Uploaded(data.clone()))
        );
        let mut s = Server::with(KEY, Vec::new());
        s.lose = Some(lose);
        s.blksize = 100;
        assert_eq!(
            download(&mut s, data.clone(), Mode::Block),
            Ok(Outcome::Downloaded)
        );
        assert_eq!(s.store[&KEY], data, "lost {lose}");
    }
}

#[test]
fn a_bad_crc_is_the_clients_abort_not_the_nodes() {
    let mut s = Server::with(KEY, bytes(100));
    s.bad_crc = true;
    let mut out = Vec::new();
    let c = SdoClient::upload(KEY.0, KEY.1, Mode::Block, T0, &mut out);
    let (r, sent) = exchange(&mut s, c, out);
    let code = AbortCode(0x0504_0004);
    assert_eq!(
        r,
        Err(SdoError::Protocol {
            what: "CRC error",
            code
        })
    );
    let last = sent.last().unwrap();
    assert_eq!(last[0], 0x80);
    assert_eq!(
        u32::from_le_bytes([last[4], last[5], last[6], last[7]]),
        code.0
    );
}

#[test]
fn silence_times_out_with_the_clients_abort() {
    let mut s = Server::with(KEY, bytes(10));
    s.mute = true;
    let mut out = Vec::new();
    let c = SdoClient::upload(KEY.0, KEY.1, Mode::Segmented, T0, &mut out)
        .with_timeout(Duration::from_millis(300), T0);
    assert_eq!(c.poll_at(), Duration::from_millis(300));
    let (r, sent) = exchange(&mut s, c, out);
    assert_eq!(
        r,
        Err(SdoError::TimedOut {
            timeout: Duration::from_millis(300)
        })
    );
    assert_eq!(
        sent.last().unwrap(),
        &[0x80, 0x00, 0x20, 0x01, 0x00, 0x00, 0x04, 0x05]
    );
}

#[test]
fn the_nodes_abort_is_reported_as_the_nodes() {
    let mut s = Server::with(KEY, bytes(10));
    let mut out = Vec::new();
    let mut c = SdoClient::upload(0x1008, 0, Mode::Segmented, T0, &mut out);
    let abort = [0x80, 0x08, 0x10, 0x00, 0x00, 0x00, 0x02, 0x06];
    assert_eq!(
        c.on_response(&abort, T0, &mut out),
        Step::Done(Err(SdoError::Aborted {
            code: AbortCode::NO_OBJECT
        }))
    );
    let _ = &mut s;
}

#[test]
fn an_upload_longer_than_allowed_is_refused_locally() {
    let mut s = Server::with(KEY, bytes(2000));
    let mut out = Vec::new();
    let c = SdoClient::upload(KEY.0, KEY.1, Mode::Segmented, T0, &mut out).with_max_len(1000);
    let (r, _) = exchange(&mut s, c, out);
    assert!(
        matches!(r, Err(SdoError::Protocol { code, .. }) if code == AbortCode::OUT_OF_MEMORY),
        "{r:?}"
    );
}

#[test]
fn toggle_errors_and_wrong_addresses_are_protocol_errors() {
    let mut out = Vec::new();
    let mut c = SdoClient::upload(0x1008, 0, Mode::Segmented, T0, &mut out);
    // Initiate response for another object.
    let r = c.on_response(&[0x41, 0x09, 0x10, 0, 10, 0, 0, 0], T0, &mut out);
    assert!(
        matches!(r, Step::Done(Err(SdoError::Protocol { code, .. })) if code == AbortCode::COMMAND)
    );
    let mut out = Vec::new();
    let mut c = SdoClient::upload(0x1008, 0, Mode::Segmented, T0, &mut out);
    assert_eq!(
        c.on_response(&[0x41, 0x08, 0x10, 0, 10, 0, 0, 0], T0, &mut out),
        Step::Pending
    );
    // First segment with the toggle set.
    let r = c.on_response(&[0x10, 1, 2, 3, 4, 5, 6, 7], T0, &mut out);
    assert!(
        matches!(r, Step::Done(Err(SdoError::Protocol { code, .. })) if code == AbortCode::TOGGLE)
    );
    // Short frames are ignored.
    let mut c = SdoClient::upload(0x1008, 0, Mode::Segmented, T0, &mut out);
    assert_eq!(c.on_response(&[0x41, 0x08], T0, &mut out), Step::Pending);
}

#[test]
fn byte_exact_frames_of_a_segmented_upload() {
    // CiA 301's example shape: initiate 0x40, response 0x41 with size, segments 0x60/0x70.
    let mut s = Server::with((0x1008, 0), b"canmotion simulated CiA 402 drive!".to_vec());
    let mut out = Vec::new();
    let c = SdoClient::upload(0x1008, 0, Mode::Segmented, T0, &mut out);
    let (r, sent) = exchange(&mut s, c, out);
    assert_eq!(
        r,
        Ok(Outcome::Uploaded(
            b"canmotion simulated CiA 402 drive!".to_vec()
        ))
    );
    assert_eq!(sent[0], [0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0]);
    let cmds: Vec<u8> = sent[1..].iter().map(|f| f[0]).collect();
    assert_eq!(cmds, [0x60, 0x70, 0x60, 0x70, 0x60], "34 bytes: 5 segments");
}

#[test]
fn expedited_download_frames_are_byte_exact() {
    let mut out = Vec::new();
    let _ = SdoClient::download(0x6040, 0, vec![0x0F, 0x00], Mode::Segmented, T0, &mut out);
    assert_eq!(out, [[0x2B, 0x40, 0x60, 0x00, 0x0F, 0x00, 0x00, 0x00]]);
    out.clear();
    let _ = SdoClient::download(
        0x1017,
        0,
        500u16.to_le_bytes().to_vec(),
        Mode::Block,
        T0,
        &mut out,
    );
    assert_eq!(out, [[0xC6, 0x17, 0x10, 0x00, 2, 0, 0, 0]]);
}

/// Runs a transfer against our own server (`crate::canopen::sdo_server`) over a byte table.
fn against_our_server(
    table: &mut ByteTable,
    mut client: SdoClient,
    mut out: Vec<[u8; 8]>,
) -> Result<Outcome, SdoError> {
    use crate::canopen::sdo_server::SdoServer;
    let mut server = SdoServer::new();
    let mut queue: VecDeque<[u8; 8]> = out.drain(..).collect();
    while let Some(req) = queue.pop_front() {
        let mut answers = Vec::new();
        server.handle(table, &req, &mut answers);
        for a in answers {
            if let Step::Done(r) = client.on_response(&a, T0, &mut out) {
                return r;
            }
            queue.extend(out.drain(..));
        }
    }
    panic!("the transfer stalled");
}

/// A byte store served by our server.
struct ByteTable(HashMap<(u16, u8), Vec<u8>>);

impl crate::canopen::sdo_server::SdoTarget for ByteTable {
    fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, AbortCode> {
        self.0
            .get(&(index, sub))
            .cloned()
            .ok_or(AbortCode::NO_OBJECT)
    }
    fn sdo_check_write(&mut self, _: u16, _: u8, _: Option<usize>) -> Result<(), AbortCode> {
        Ok(())
    }
    fn sdo_write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        self.0.insert((index, sub), data.to_vec());
        Ok(())
    }
}

#[test]
fn against_our_sdo_server_any_length_both_modes() {
    for n in [0, 1, 4, 5, 7, 8, 20, 32, 33, 34, 127 * 7, 1000, 5000] {
        for mode in [Mode::Segmented, Mode::Block] {
            let data = bytes(n);
            let mut table = ByteTable(HashMap::from([(KEY, data.clone())]));
            let mut out = Vec::new();
            let c = SdoClient::upload(KEY.0, KEY.1, mode, T0, &mut out);
            assert_eq!(
                against_our_server(&mut table, c, out),
                Ok(Outcome::Uploaded(data.clone())),
                "upload {n} {mode:?}"
            );
            let mut out = Vec::new();
            let c = SdoClient::download(0x2001, 0, data.clone(), mode, T0, &mut out);
            assert_eq!(
                against_our_server(&mut table, c, out),
                Ok(Outcome::Downloaded)
            );
            assert_eq!(table.0[&(0x2001, 0)], data, "download {n} {mode:?}");
        }
    }
    // A missing object: the node's abort, in both modes.
    for mode in [Mode::Segmented, Mode::Block] {
        let mut out = Vec::new();
        let c = SdoClient::upload(0x3000, 0, mode, T0, &mut out);
        assert_eq!(
            against_our_server(&mut ByteTable(HashMap::new()), c, out),
            Err(SdoError::Aborted {
                code: AbortCode::NO_OBJECT
            })
        );
    }
}

#[test]
fn crc16_is_the_xmodem_crc() {
    // The CRC-16/XMODEM check value (reveng's catalogue): "123456789" → 0x31C3.
    assert_eq!(crc16(b"123456789"), 0x31C3);
    assert_eq!(crc16(b""), 0);
}

proptest::proptest! {
    #[test]
    fn never_panics_on_any_answers(
        block in proptest::prelude::any::<bool>(),
        up in proptest::prelude::any::<bool>(),
        answers in proptest::collection::vec(proptest::collection::vec(proptest::prelude::any::<u8>(), 0..=8), 0..40)
    ) {
        let mode = if block { Mode::Block } else { Mode::Segmented };
        let mut out = Vec::new();
        let mut c = if up {
            SdoClient::upload(KEY.0, KEY.1, mode, T0, &mut out).with_max_len(4096)
        } else {
            SdoClient::download(KEY.0, KEY.1, bytes(100), mode, T0, &mut out)
        };
        for a in &answers {
            if let Step::Done(_) = c.on_response(a, T0, &mut out) {
                break;
            }
        }
    }
}
