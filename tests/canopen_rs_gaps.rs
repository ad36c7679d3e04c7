//! Pins the gaps of canopen-rs 0.6 (`canopen_rs::sdo::SdoServer` over its `ObjectDictionary`,
//! and its `SdoClient`) that made us write our own SDO server (`src/canopen/sdo_server.rs`) and
//! client (`src/canopen/sdo_client.rs`).
//!
//! Each test asserts canopen-rs's CURRENT behaviour, next to what CiA 301 requires and what our
//! own dictionary answers. When one of them fails, upstream has changed: reconsider whether our
//! server is still needed (and update `src/canopen/sdo_server.rs`'s doc).
//!
//! Checked against the source of canopen-rs 0.6.1 (`src/sdo/server.rs`,
//! `src/object_dictionary.rs`, `src/sdo/mod.rs`).

use std::path::Path;
use std::sync::Arc;

use canmotion::canopen::{AbortCode, Od};
use canmotion::config::DriveDictionary;
use canmotion::config::machine::DEMO_DRIVE;
use canopen_rs::sdo::SdoServer;
use canopen_rs::{Address, Entry, NodeId, ObjectDictionary, Value};

/// A small canopen-rs dictionary: identity object 0x1018 (subs 0–1), heartbeat time 0x1017
/// (u16 rw) and modes of operation 0x6060 (i8 rw).
fn their_od() -> ObjectDictionary<8> {
    let mut od = ObjectDictionary::new();
    od.insert(
        Address::new(0x1018, 0),
        Entry::constant(Value::Unsigned8(1)),
    )
    .unwrap();
    od.insert(
        Address::new(0x1018, 1),
        Entry::ro(Value::Unsigned32(0x0000_0CA7)),
    )
    .unwrap();
    od.insert(Address::new(0x1017, 0), Entry::rw(Value::Unsigned16(0)))
        .unwrap();
    od.insert(Address::new(0x6060, 0), Entry::rw(Value::Integer8(0)))
        .unwrap();
    od
}

fn their_server() -> SdoServer {
    SdoServer::new(NodeId::new(1).unwrap())
}

/// Our run-time dictionary for the demo drive.
fn our_od() -> Od {
    let dict = DriveDictionary::parse(Path::new("cia402-servo.toml"), DEMO_DRIVE).unwrap();
    Od::new(Arc::new(dict), 1)
}

/// The abort code of an SDO response, if it is an abort.
fn abort_code(resp: &[u8; 8]) -> Option<u32> {
    (resp[0] == 0x80).then(|| u32::from_le_bytes([resp[4], resp[5], resp[6], resp[7]]))
}

fn request(cs: u8, index: u16, sub: u8, data: [u8; 4]) -> [u8; 8] {
    let i = index.to_le_bytes();
    [cs, i[0], i[1], sub, data[0], data[1], data[2], data[3]]
}

/// (a) CiA 301 §7.2.4.3.17: an existing object without the requested sub-index answers
/// 0x06090011 "sub-index does not exist". canopen-rs's dictionary is flat (entries keyed by
/// index *and* sub-index, no notion of an object), so its server answers 0x06020000 "object does
/// not exist" for a read and a write alike. (Its `SdoAbortCode::SubIndexDoesNotExist` exists
/// but is never used.)
#[test]
fn gap_a_missing_sub_index_answers_no_object_instead_of_no_sub_index() {
    let mut od = their_od();
    let mut s = their_server();
    // Upload 0x1018:5 (0x1018 exists, sub-index 5 does not).
    let r = s
        .handle(&mut od, &request(0x40, 0x1018, 5, [0; 4]))
        .unwrap();
    assert_eq!(abort_code(&r), Some(AbortCode::NO_OBJECT.0)); // CiA 301: NO_SUB
    // Download 0x1018:5.
    let r = s
        .handle(&mut od, &request(0x23, 0x1018, 5, [1, 0, 0, 0]))
        .unwrap();
    assert_eq!(abort_code(&r), Some(AbortCode::NO_OBJECT.0)); // CiA 301: NO_SUB
    // A truly missing object is answered right.
    let r = s
        .handle(&mut od, &request(0x40, 0x2000, 0, [0; 4]))
        .unwrap();
    assert_eq!(abort_code(&r), Some(AbortCode::NO_OBJECT.0));

    // Ours tells the two apart.
    let ours = our_od();
    assert_eq!(ours.sdo_read(0x1018, 5), Err(AbortCode::NO_SUB));
    assert_eq!(ours.sdo_read(0x2000, 0), Err(AbortCode::NO_OBJECT));
}

/// (b) CiA 301: a download whose length does not match the object's data type answers
/// 0x06070010 "data type does not match, length of service parameter does not match" (what the
/// project checklist decodes). canopen-rs has no such code (its `SdoAbortCode` lacks it) and
/// answers every expedited length error with 0x06070012 "length too high", even when the data
/// is too SHORT (1 byte to a u16).
#[test]
fn gap_b_expedited_length_error_answers_0x06070012_never_0x06070010() {
    let mut od = their_od();
    let mut s = their_server();
    // 0x23: 4 bytes to the u16 0x1017 (too long).
    let r = s
        .handle(&mut od, &request(0x23, 0x1017, 0, [0xE8, 0x03, 0, 0]))
        .unwrap();
    assert_eq!(abort_code(&r), Some(AbortCode::LENGTH_TOO_HIGH.0)); // CiA 301: LENGTH_MISMATCH
    // 0x2F: 1 byte to the u16 0x1017 (too short, still "too high").
    let r = s
        .handle(&mut od, &request(0x2F, 0x1017, 0, [0x64, 0, 0, 0]))
        .unwrap();
    assert_eq!(abort_code(&r), Some(AbortCode::LENGTH_TOO_HIGH.0)); // CiA 301: LENGTH_MISMATCH
    // 0x2B: 2 bytes to the i8 0x6060.
    let r = s
        .handle(&mut od, &request(0x2B, 0x6060, 0, [7, 0, 0, 0]))
        .unwrap();
    assert_eq!(abort_code(&r), Some(AbortCode::LENGTH_TOO_HIGH.0)); // CiA 301: LENGTH_MISMATCH
    // Nothing was written.
    assert_eq!(
        od.read(Address::new(0x1017, 0)).unwrap(),
        Value::Unsigned16(0)
    );
    assert_eq!(
        od.read(Address::new(0x6060, 0)).unwrap(),
        Value::Integer8(0)
    );

    // Ours answers 0x06070010.
    let ours = our_od();
    assert_eq!(
        ours.sdo_check_write(0x1017, 0, Some(4)),
        Err(AbortCode::LENGTH_MISMATCH)
    );
    assert_eq!(
        ours.sdo_check_write(0x1017, 0, Some(1)),
        Err(AbortCode::LENGTH_MISMATCH)
    );
}

/// (c) CiA 301 §7.2.4.3.17: a value outside the object's range answers 0x06090031 "value too
/// high" / 0x06090032 "value too low" (0x06090030 when invalid). canopen-rs's `Entry` is a
/// value and an access type only, no range: its server stores any value of the right type.
#[test]
fn gap_c_no_value_range_check() {
    let mut od = their_od();
    let mut s = their_server();
    // Modes of operation = 11 (our dictionary: 0..=10).
    let r = s
        .handle(&mut od, &request(0x2F, 0x6060, 0, [11, 0, 0, 0]))
        .unwrap();
    assert_eq!(r[0], 0x60, "accepted"); // CiA 301: abort VALUE_TOO_HIGH
    assert_eq!(
        od.read(Address::new(0x6060, 0)).unwrap(),
        Value::Integer8(11)
    );
    // -1 too.
    let r = s
        .handle(&mut od, &request(0x2F, 0x6060, 0, [0xFF, 0, 0, 0]))
        .unwrap();
    assert_eq!(r[0], 0x60, "accepted"); // CiA 301: abort VALUE_TOO_LOW
    assert_eq!(
        od.read(Address::new(0x6060, 0)).unwrap(),
        Value::Integer8(-1)
    );

    // Ours refuses both.
    let ours = our_od();
    assert_eq!(
        ours.sdo_decode_write(0x6060, 0, &[11]),
        Err(AbortCode::VALUE_TOO_HIGH)
    );
    assert_eq!(
        ours.sdo_decode_write(0x6060, 0, &[0xFF]),
        Err(AbortCode::VALUE_TOO_LOW)
    );
}

/// (d) CiA 301 §7.2.4.3: segmented and block transfers have no length limit. canopen-rs's
/// client keeps a transfer in a buffer of `MAX_STRING_LEN` (32) bytes: an upload of a longer
/// object (a 34-byte device name) ends in `SdoEvent::Aborted(0x08000000)`, its own failure
/// reported as if the node had aborted. Ours (`canmotion::canopen::sdo_client`) uploads it
/// whole, from our server too.
#[test]
fn gap_d_the_client_stops_at_32_bytes_and_calls_it_the_nodes_abort() {
    use canmotion::canopen::sdo_client::{Mode, Outcome, SdoClient, Step};
    use canmotion::canopen::{SdoServer as OurServer, SdoTarget};
    use canopen_rs::sdo::{SdoClient as TheirClient, SdoEvent};
    struct Name(Vec<u8>);
    impl SdoTarget for Name {
        fn sdo_read(&mut self, _: u16, _: u8) -> Result<Vec<u8>, AbortCode> {
            Ok(self.0.clone())
        }
        fn sdo_check_write(&mut self, _: u16, _: u8, _: Option<usize>) -> Result<(), AbortCode> {
            Ok(())
        }
        fn sdo_write(&mut self, _: u16, _: u8, _: &[u8]) -> Result<(), AbortCode> {
            Ok(())
        }
    }
    let name = b"canmotion simulated servo, 34 byte".to_vec();
    let mut target = Name(name.clone());
    // Theirs, against our server (which answers correctly: 34 bytes, 5 segments).
    let mut server = OurServer::new();
    let mut client = TheirClient::new(NodeId::new(1).unwrap());
    let mut req = client.read(Address::new(0x1008, 0), canopen_rs::DataType::VisibleString);
    let event = loop {
        let mut out = Vec::new();
        server.handle(&mut target, &req, &mut out);
        match client.on_response(&out[0]) {
            SdoEvent::Send(next) => req = next,
            done => break done,
        }
    };
    assert_eq!(event, SdoEvent::Aborted(0x0800_0000)); // CiA 301: the 34 bytes
    // Ours.
    let mut server = OurServer::new();
    let mut out = Vec::new();
    let mut c = SdoClient::upload(0x1008, 0, Mode::Segmented, Default::default(), &mut out);
    let result = loop {
        let mut answers = Vec::new();
        server.handle(&mut target, &out.remove(0), &mut answers);
        if let Step::Done(r) = c.on_response(&answers[0], Default::default(), &mut out) {
            break r;
        }
    };
    assert_eq!(result, Ok(Outcome::Uploaded(name)));
}
