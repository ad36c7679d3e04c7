//! Checklist tests of the simulated drive, sans-I/O (`/work/shared/docs/canopen-checklist.md`).
//!
//! No bus: time is a [`Duration`] advanced by hand, frames go in through [`SimDrive::handle`]
//! and come out in a log stamped with the time they were sent. The SDO client side is
//! canopen-rs's [`SdoClient`], an independent implementation of the other end.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use canopen_rs::sdo::{SdoClient, SdoEvent};
use canopen_rs::{Address, ByteString, DataType, NodeId, Value};

use super::{EMCY_PARAMETER, FaultCause, SimDrive};
use crate::bus::Frame;
use crate::canopen::dictionary::{DriveDictionary, int_value, value_as_i128};
use crate::canopen::emcy::{Emcy, code as emcy};
use crate::canopen::{AbortCode, NmtState, cob, nmt};
use crate::cia402::{State, statusword as sw};
use crate::config::machine::DEMO_DRIVE;

/// The node under test.
const NODE: u8 = 5;
/// The SYNC COB-ID (0x1005 default).
const SYNC: u16 = 0x080;
/// The SYNC period the cyclic tests use (0x1006, µs): equal to the default 0x60C2 (1 ms).
const PERIOD_US: i64 = 1000;

fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

fn us(n: u64) -> Duration {
    Duration::from_micros(n)
}

fn dict_from(text: &str) -> Arc<DriveDictionary> {
    Arc::new(DriveDictionary::parse(Path::new("cia402-servo.toml"), text).expect("dictionary"))
}

fn dict() -> Arc<DriveDictionary> {
    dict_from(DEMO_DRIVE)
}

/// RPDO1 of the default mapping: controlword (u16), then 0x60C1:1 (i32).
fn cw_and_i32(cw: u16, x: i32) -> [u8; 6] {
    let mut d = [0u8; 6];
    d[..2].copy_from_slice(&cw.to_le_bytes());
    d[2..].copy_from_slice(&x.to_le_bytes());
    d
}

/// A drive on a bench: the clock, the frames it sent (with when), and the master's helpers.
struct Bench {
    drive: SimDrive,
    now: Duration,
    log: Vec<(Duration, Frame)>,
}

impl Bench {
    /// A booted drive at t = 0 (its boot-up message is in the log).
    fn new() -> Bench {
        Bench::with(SimDrive::new(dict(), NODE))
    }

    fn with(mut drive: SimDrive) -> Bench {
        let mut out = Vec::new();
        drive.boot(Duration::ZERO, &mut out);
        Bench {
            drive,
            now: Duration::ZERO,
            log: out.into_iter().map(|f| (Duration::ZERO, f)).collect(),
        }
    }

    // ---- time and frames -------------------------------------------------------------------

    /// Feed one frame at the current time.
    fn feed(&mut self, f: Frame) {
        let mut out = Vec::new();
        self.drive.handle(self.now, &f, &mut out);
        self.log.extend(out.into_iter().map(|f| (self.now, f)));
    }

    fn send(&mut self, id: u16, data: &[u8]) {
        self.feed(Frame::new(id, data).expect("frame"));
    }

    /// Advance the clock to `end`, polling the drive whenever it asks to be ([`SimDrive::poll_at`]).
    fn run_until(&mut self, end: Duration) {
        while self.now < end {
            let next = self.drive.poll_at(self.now).max(self.now + us(1)).min(end);
            self.now = next;
            let mut out = Vec::new();
            self.drive.poll(self.now, &mut out);
            self.log.extend(out.into_iter().map(|f| (self.now, f)));
        }
    }

    fn advance(&mut self, d: Duration) {
        self.run_until(self.now + d);
    }

    /// Forget the frames sent so far.
    fn clear(&mut self) {
        self.log.clear();
    }

    /// The frames sent on `id`, with when.
    fn sent(&self, id: u16) -> Vec<(Duration, Vec<u8>)> {
        self.log
            .iter()
            .filter(|(_, f)| f.id() == id)
            .map(|(t, f)| (*t, f.data().to_vec()))
            .collect()
    }

    /// The EMCY codes sent, with when.
    fn emcys(&self) -> Vec<(Duration, u16)> {
        self.log
            .iter()
            .filter(|(_, f)| f.id() == cob::EMCY + u16::from(NODE))
            .map(|(t, f)| (*t, Emcy::from_frame(f).expect("EMCY frame").code))
            .collect()
    }

    fn emcy_count(&self, code: u16) -> usize {
        self.emcys().iter().filter(|(_, c)| *c == code).count()
    }

    // ---- NMT, SYNC, PDO --------------------------------------------------------------------

    fn nmt(&mut self, cs: u8, node: u8) {
        self.send(cob::NMT, &[cs, node]);
    }

    fn sync(&mut self) {
        self.send(SYNC, &[]);
    }

    /// RPDO `n` (1-based) on its default COB-ID.
    fn rpdo(&mut self, n: usize, data: &[u8]) {
        self.send(cob::RPDO[n - 1] + u16::from(NODE), data);
    }

    fn tpdos(&self, n: usize) -> Vec<(Duration, Vec<u8>)> {
        self.sent(cob::TPDO[n - 1] + u16::from(NODE))
    }

    fn heartbeats(&self) -> Vec<(Duration, u8)> {
        self.sent(cob::HEARTBEAT + u16::from(NODE))
            .into_iter()
            .map(|(t, d)| {
                assert_eq!(d.len(), 1, "heartbeat DLC");
                (t, d[0])
            })
            .collect()
    }

    // ---- SDO -------------------------------------------------------------------------------

    /// One SDO request on 0x600 + id; the response taken off 0x580 + id (other frames the
    /// request caused stay in the log).
    fn sdo_exchange(&mut self, req: [u8; 8]) -> [u8; 8] {
        let start = self.log.len();
        self.send(cob::SDO_RX + u16::from(NODE), &req);
        let at = (start..self.log.len())
            .find(|&i| self.log[i].1.id() == cob::SDO_TX + u16::from(NODE))
            .unwrap_or_else(|| panic!("no SDO response to {req:02X?}"));
        let (_, f) = self.log.remove(at);
        f.data().try_into().expect("SDO responses are 8 bytes")
    }

    /// Run a canopen-rs client transaction to its end.
    fn sdo_run(&mut self, client: &mut SdoClient, mut req: [u8; 8]) -> SdoEvent {
        for _ in 0..100 {
            let resp = self.sdo_exchange(req);
            match client.on_response(&resp) {
                SdoEvent::Send(next) => req = next,
                done => return done,
            }
        }
        panic!("SDO transfer did not finish");
    }

    fn client() -> SdoClient {
        SdoClient::new(NodeId::new(NODE).expect("node id"))
    }

    fn read(&mut self, index: u16, sub: u8, t: DataType) -> Result<Value, u32> {
        let mut c = Bench::client();
        let req = c.read(Address::new(index, sub), t);
        match self.sdo_run(&mut c, req) {
            SdoEvent::Complete(Some(v)) => Ok(v),
            SdoEvent::Aborted(code) => Err(code),
            other => panic!("read {index:04X}:{sub}: {other:?}"),
        }
    }

    fn write(&mut self, index: u16, sub: u8, v: Value) -> Result<(), u32> {
        let mut c = Bench::client();
        let req = c.write(Address::new(index, sub), v);
        match self.sdo_run(&mut c, req) {
            SdoEvent::Complete(None) => Ok(()),
            SdoEvent::Aborted(code) => Err(code),
            other => panic!("write {index:04X}:{sub}: {other:?}"),
        }
    }

    fn data_type(&self, index: u16, sub: u8) -> DataType {
        self.drive
            .od()
            .def(index, sub)
            .unwrap_or_else(|| panic!("no {index:04X}:{sub}"))
            .data_type
    }

    /// Write an integer with the entry's own type; the abort code if refused.
    fn try_set(&mut self, index: u16, sub: u8, x: i64) -> Result<(), u32> {
        let v = int_value(self.data_type(index, sub), i128::from(x)).expect("fits the type");
        self.write(index, sub, v)
    }

    /// Write an integer with the entry's own type; it must succeed.
    fn set(&mut self, index: u16, sub: u8, x: i64) {
        if let Err(code) = self.try_set(index, sub, x) {
            panic!(
                "write {index:04X}:{sub} = {x:#X}: abort {}",
                AbortCode(code)
            );
        }
    }

    /// Read an integer entry by SDO.
    fn get(&mut self, index: u16, sub: u8) -> i64 {
        let t = self.data_type(index, sub);
        match self.read(index, sub, t) {
            Ok(v) => value_as_i128(&v).expect("integer") as i64,
            Err(code) => panic!("read {index:04X}:{sub}: abort {}", AbortCode(code)),
        }
    }

    /// The abort code of a write that must fail.
    fn refused(&mut self, index: u16, sub: u8, v: Value) -> u32 {
        match self.write(index, sub, v) {
            Ok(()) => panic!("write {index:04X}:{sub} = {v:?} was accepted"),
            Err(code) => code,
        }
    }

    // ---- CiA 402 ---------------------------------------------------------------------------

    fn sw(&self) -> u16 {
        self.drive.statusword()
    }

    fn state(&self) -> State {
        let s = self.drive.state();
        assert_eq!(
            State::from_statusword(self.sw()),
            Some(s),
            "statusword coding"
        );
        s
    }

    /// Controlword by SDO.
    fn cw(&mut self, cw: u16) {
        self.set(0x6040, 0, i64::from(cw));
    }

    /// Shutdown, switch on, enable operation.
    fn enable(&mut self) {
        self.cw(0x06);
        assert_eq!(self.state(), State::ReadyToSwitchOn);
        self.cw(0x07);
        assert_eq!(self.state(), State::SwitchedOn);
        self.cw(0x0F);
        assert_eq!(self.state(), State::OperationEnabled);
    }

    /// Operational, SYNC period 1 ms, mode 7, Operation enabled, IP started the CiA 402 way.
    fn ip_running(position: i32) -> Bench {
        let mut b = Bench::with(SimDrive::new(dict(), NODE).with_position(position));
        b.set(0x1006, 0, PERIOD_US);
        b.set(0x6060, 0, 7);
        b.nmt(nmt::START, NODE);
        b.enable();
        let actual = b.get(0x6064, 0);
        b.set(0x60C1, 1, actual);
        b.cw(0x1F);
        assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0, "IP active");
        b
    }

    /// One IP cycle: 1 ms later, RPDO1 (controlword, setpoint), then SYNC.
    fn ip_cycle(&mut self, cw: u16, setpoint: i32) {
        self.advance(ms(1));
        self.rpdo(1, &cw_and_i32(cw, setpoint));
        self.sync();
    }

    /// One CSP cycle: 1 ms later, RPDO2 (controlword, 0x607A, event-driven), then SYNC.
    fn csp_cycle(&mut self, cw: u16, target: i32) {
        self.advance(ms(1));
        self.rpdo(2, &cw_and_i32(cw, target));
        self.sync();
    }

    /// The CiA 301 remap procedure on a PDO (communication index `comm`), then read back.
    fn remap(&mut self, comm: u16, entries: &[u32]) {
        let map = comm + 0x200;
        let cob_id = self.get(comm, 1) as u32;
        self.set(comm, 1, i64::from(cob_id | 0x8000_0000));
        self.set(map, 0, 0);
        for (i, e) in entries.iter().enumerate() {
            self.set(map, i as u8 + 1, i64::from(*e));
        }
        self.set(map, 0, entries.len() as i64);
        self.set(comm, 1, i64::from(cob_id & 0x7FFF_FFFF));
        assert_eq!(self.get(map, 0), entries.len() as i64);
        for (i, e) in entries.iter().enumerate() {
            assert_eq!(self.get(map, i as u8 + 1) as u32, *e);
        }
        assert_eq!(self.get(comm, 1) as u32, cob_id & 0x7FFF_FFFF);
    }
}

// ============================================================================================
// NMT
// ============================================================================================

#[test]
fn boot_up_is_0x700_plus_id_with_0x00_then_pre_operational() {
    let mut drive = SimDrive::new(dict(), NODE);
    let mut out = Vec::new();
    // Before boot the node is silent and deaf.
    drive.handle(
        ms(0),
        &Frame::new(cob::NMT, &[nmt::START, 0]).unwrap(),
        &mut out,
    );
    drive.poll(ms(5), &mut out);
    assert!(out.is_empty());
    drive.boot(ms(10), &mut out);
    assert_eq!(out, vec![Frame::new(0x705, &[0x00]).unwrap()]);
    assert_eq!(drive.nmt_state(), NmtState::PreOperational);
    assert_eq!(drive.state(), State::SwitchOnDisabled);
    // Device type low word = profile 402, identity as configured.
    let mut b = Bench::new();
    assert_eq!(b.get(0x1000, 0) & 0xFFFF, 0x0192);
    assert_eq!(b.get(0x1018, 1), 0x0CA7);
    assert_eq!(b.get(0x1018, 2), 0x0402);
}

#[test]
fn heartbeat_producer_sends_nmt_state_byte_every_0x1017_ms() {
    let mut b = Bench::new();
    b.clear();
    // Disabled by default.
    b.advance(ms(500));
    assert!(b.heartbeats().is_empty());
    b.set(0x1017, 0, 100);
    let t0 = b.now;
    b.run_until(t0 + ms(350));
    assert_eq!(
        b.heartbeats(),
        vec![
            (t0 + ms(100), 0x7F),
            (t0 + ms(200), 0x7F),
            (t0 + ms(300), 0x7F)
        ]
    );
    for (cs, byte) in [
        (nmt::START, 0x05),
        (nmt::STOP, 0x04),
        (nmt::PRE_OPERATIONAL, 0x7F),
    ] {
        b.clear();
        b.nmt(cs, NODE);
        b.advance(ms(100));
        let hb = b.heartbeats();
        assert_eq!(hb.len(), 1, "{hb:?}");
        assert_eq!(hb[0].1, byte, "after NMT {cs:#04X}");
    }
}

#[test]
fn nmt_addressed_to_another_node_is_ignored_and_node_0_means_all() {
    let mut b = Bench::new();
    b.clear();
    b.nmt(nmt::START, NODE + 1);
    assert_eq!(b.drive.nmt_state(), NmtState::PreOperational);
    b.nmt(nmt::RESET_NODE, NODE + 1);
    b.nmt(nmt::RESET_COMMUNICATION, NODE + 1);
    assert!(
        b.heartbeats().is_empty(),
        "no boot-up for another node's reset"
    );
    b.nmt(nmt::START, 0);
    assert_eq!(b.drive.nmt_state(), NmtState::Operational);
    b.nmt(nmt::STOP, 0);
    assert_eq!(b.drive.nmt_state(), NmtState::Stopped);
    b.nmt(nmt::PRE_OPERATIONAL, 0);
    assert_eq!(b.drive.nmt_state(), NmtState::PreOperational);
    b.nmt(nmt::START, NODE);
    assert_eq!(b.drive.nmt_state(), NmtState::Operational);
}

#[test]
fn reset_communication_restores_0x1000_to_0x1fff_and_sends_a_new_boot_up() {
    let mut b = Bench::new();
    b.set(0x1017, 0, 100);
    b.set(0x1800, 2, 5);
    b.set(0x1006, 0, PERIOD_US);
    b.set(0x6065, 0, 500); // application object: kept
    b.nmt(nmt::START, NODE);
    b.clear();
    b.nmt(nmt::RESET_COMMUNICATION, NODE);
    assert_eq!(b.heartbeats(), vec![(b.now, 0x00)]);
    assert_eq!(b.drive.nmt_state(), NmtState::PreOperational);
    assert_eq!(b.get(0x1017, 0), 0);
    assert_eq!(b.get(0x1800, 2), 1);
    assert_eq!(b.get(0x1006, 0), 0);
    assert_eq!(b.get(0x6065, 0), 500);
    // The heartbeat producer is off again (0x1017 = 0).
    b.advance(ms(500));
    assert_eq!(b.heartbeats().len(), 1);
}

#[test]
fn reset_node_restores_application_objects_too() {
    let mut b = Bench::new();
    b.set(0x1017, 0, 100);
    b.set(0x6065, 0, 500);
    b.set(0x607D, 2, 4000);
    b.enable();
    b.nmt(nmt::START, NODE);
    b.clear();
    b.nmt(nmt::RESET_NODE, NODE);
    assert_eq!(b.heartbeats(), vec![(b.now, 0x00)]);
    assert_eq!(b.drive.nmt_state(), NmtState::PreOperational);
    assert_eq!(b.state(), State::SwitchOnDisabled);
    assert_eq!(b.get(0x1017, 0), 0);
    assert_eq!(b.get(0x6065, 0), 10000);
    assert_eq!(b.get(0x607D, 2), 1_000_000_000);
    assert_eq!(b.get(0x6040, 0), 0);
}

#[test]
fn pdos_run_only_in_operational() {
    let mut b = Bench::new();
    b.clear();
    // Pre-operational: no synchronous TPDO on SYNC, no event TPDO, RPDOs ignored.
    b.sync();
    b.rpdo(2, &cw_and_i32(0x06, 0));
    b.advance(ms(50));
    assert!(b.tpdos(1).is_empty());
    assert!(b.tpdos(2).is_empty());
    assert_eq!(b.state(), State::SwitchOnDisabled);
    // Stopped: the same.
    b.nmt(nmt::STOP, NODE);
    b.sync();
    b.rpdo(2, &cw_and_i32(0x06, 0));
    b.advance(ms(50));
    assert!(b.tpdos(1).is_empty() && b.tpdos(2).is_empty());
    assert_eq!(b.state(), State::SwitchOnDisabled);
    // Operational: they run.
    b.nmt(nmt::START, NODE);
    b.sync();
    assert_eq!(b.tpdos(1).len(), 1);
    b.rpdo(2, &cw_and_i32(0x06, 0));
    assert_eq!(b.state(), State::ReadyToSwitchOn);
    b.advance(ms(10));
    assert!(!b.tpdos(2).is_empty());
}

// ============================================================================================
// SDO
// ============================================================================================

#[test]
fn sdo_expedited_command_bytes() {
    let mut b = Bench::new();
    // Upload of a u16: request 0x40, response 0x4B (2 bytes).
    let r = b.sdo_exchange([0x40, 0x41, 0x60, 0x00, 0, 0, 0, 0]);
    assert_eq!(r[..4], [0x4B, 0x41, 0x60, 0x00]);
    assert_eq!(u16::from_le_bytes([r[4], r[5]]), b.sw());
    // Download of 4/2/1 bytes: 0x23/0x2B/0x2F, acknowledged with 0x60.
    let r = b.sdo_exchange([0x23, 0x7A, 0x60, 0x00, 0x10, 0x27, 0, 0]);
    assert_eq!(r, [0x60, 0x7A, 0x60, 0x00, 0, 0, 0, 0]);
    assert_eq!(b.drive.od().int(0x607A, 0), 10000);
    let r = b.sdo_exchange([0x2B, 0x17, 0x10, 0x00, 0xE8, 0x03, 0, 0]);
    assert_eq!(r, [0x60, 0x17, 0x10, 0x00, 0, 0, 0, 0]);
    let r = b.sdo_exchange([0x2F, 0x60, 0x60, 0x00, 0x07, 0, 0, 0]);
    assert_eq!(r, [0x60, 0x60, 0x60, 0x00, 0, 0, 0, 0]);
    // An abort is 0x80, the address, then the code.
    let r = b.sdo_exchange([0x40, 0x00, 0x20, 0x00, 0, 0, 0, 0]);
    assert_eq!(r, [0x80, 0x00, 0x20, 0x00, 0x00, 0x00, 0x02, 0x06]);
}

#[test]
fn sdo_abort_no_object_0x06020000() {
    let mut b = Bench::new();
    assert_eq!(
        b.read(0x2000, 0, DataType::Unsigned32),
        Err(AbortCode::NO_OBJECT.0)
    );
    assert_eq!(
        b.refused(0x2000, 0, Value::Unsigned32(1)),
        AbortCode::NO_OBJECT.0
    );
}

#[test]
fn sdo_abort_no_sub_index_0x06090011() {
    let mut b = Bench::new();
    assert_eq!(
        b.read(0x1018, 5, DataType::Unsigned32),
        Err(AbortCode::NO_SUB.0)
    );
    assert_eq!(
        b.refused(0x607D, 3, Value::Integer32(0)),
        AbortCode::NO_SUB.0
    );
    // A VAR has only sub-index 0.
    assert_eq!(
        b.read(0x6041, 1, DataType::Unsigned16),
        Err(AbortCode::NO_SUB.0)
    );
}

#[test]
fn sdo_abort_read_only_0x06010002() {
    let mut b = Bench::new();
    // const
    assert_eq!(
        b.refused(0x1000, 0, Value::Unsigned32(0x0192)),
        AbortCode::READ_ONLY.0
    );
    // ro
    assert_eq!(
        b.refused(0x6041, 0, Value::Unsigned16(0x27)),
        AbortCode::READ_ONLY.0
    );
    assert_eq!(
        b.refused(0x6064, 0, Value::Integer32(5)),
        AbortCode::READ_ONLY.0
    );
    assert_eq!(b.get(0x6064, 0), 0);
}

#[test]
fn sdo_abort_write_only_0x06010001() {
    let mut b = Bench::new();
    assert_eq!(
        b.read(0x60C4, 6, DataType::Unsigned8),
        Err(AbortCode::WRITE_ONLY.0)
    );
    // ... but it can be written (buffer clear).
    b.set(0x60C4, 6, 0);
}

#[test]
fn sdo_abort_length_mismatch_0x06070010() {
    let mut b = Bench::new();
    // 4 bytes, then 1 byte, to the u16 controlword.
    assert_eq!(
        b.refused(0x6040, 0, Value::Unsigned32(0x0F)),
        AbortCode::LENGTH_MISMATCH.0
    );
    assert_eq!(
        b.refused(0x6040, 0, Value::Unsigned8(0x0F)),
        AbortCode::LENGTH_MISMATCH.0
    );
    // 2 bytes to a u32.
    assert_eq!(
        b.refused(0x6065, 0, Value::Unsigned16(100)),
        AbortCode::LENGTH_MISMATCH.0
    );
    assert_eq!(b.get(0x6040, 0), 0);
    assert_eq!(b.get(0x6065, 0), 10000);
    assert_eq!(b.state(), State::SwitchOnDisabled);
}

#[test]
fn sdo_abort_value_too_high_0x06090031_and_too_low_0x06090032() {
    let mut b = Bench::new();
    // 0x6060: 0..=10.
    assert_eq!(
        b.refused(0x6060, 0, Value::Integer8(11)),
        AbortCode::VALUE_TOO_HIGH.0
    );
    // 0x60C2:2 (interpolation time index): -6..=0.
    assert_eq!(
        b.refused(0x60C2, 2, Value::Integer8(1)),
        AbortCode::VALUE_TOO_HIGH.0
    );
    assert_eq!(
        b.refused(0x60C2, 2, Value::Integer8(-7)),
        AbortCode::VALUE_TOO_LOW.0
    );
    // 0x6007: 0..=3.
    assert_eq!(
        b.refused(0x6007, 0, Value::Integer16(-1)),
        AbortCode::VALUE_TOO_LOW.0
    );
    assert_eq!(b.get(0x6060, 0), 0);
    assert_eq!(b.get(0x60C2, 2), -3);
    assert_eq!(b.get(0x6007, 0), 1);
    // The limits themselves are accepted.
    b.set(0x60C2, 2, -6);
    b.set(0x60C2, 2, 0);
}

#[test]
fn sdo_sync_counter_0x1019_is_writable_only_while_0x1006_is_0() {
    let mut b = Bench::new();
    b.set(0x1006, 0, PERIOD_US);
    assert_eq!(
        b.refused(0x1019, 0, Value::Unsigned8(5)),
        AbortCode::DEVICE_STATE.0
    );
    assert_eq!(b.get(0x1019, 0), 0);
    b.set(0x1006, 0, 0);
    b.set(0x1019, 0, 5);
    assert_eq!(b.get(0x1019, 0), 5);
    // 1 is reserved.
    assert_eq!(
        b.refused(0x1019, 0, Value::Unsigned8(1)),
        AbortCode::INVALID_VALUE.0
    );
}

#[test]
fn sdo_segmented_upload_of_the_device_name_0x1008() {
    let mut b = Bench::new();
    // Initiate: 0x41, size indicated = 19 bytes.
    let r = b.sdo_exchange([0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0]);
    assert_eq!(r[..4], [0x41, 0x08, 0x10, 0x00]);
    assert_eq!(u32::from_le_bytes([r[4], r[5], r[6], r[7]]), 19);
    // The whole transfer, with canopen-rs's client.
    assert_eq!(
        b.read(0x1008, 0, DataType::VisibleString),
        Ok(Value::VisibleString(
            ByteString::from_str("canmotion sim servo").unwrap()
        ))
    );
    // const: not writable.
    assert_eq!(
        b.refused(
            0x1008,
            0,
            Value::VisibleString(ByteString::from_str("another name").unwrap())
        ),
        AbortCode::READ_ONLY.0
    );
}

#[test]
fn sdo_segmented_download_is_reassembled() {
    // The demo dictionary has no writable object longer than 4 bytes: add one.
    let text = format!(
        "{DEMO_DRIVE}\n[[object]]\nindex = 0x2000\nname = \"User label\"\ntype = \"string\"\n\
         access = \"rw\"\ndefault = \"\"\n"
    );
    let mut b = Bench::with(SimDrive::new(dict_from(&text), NODE));
    let label = ByteString::from_str("axis X, left gantry motor").unwrap();
    assert_eq!(b.write(0x2000, 0, Value::VisibleString(label)), Ok(()));
    assert_eq!(
        b.read(0x2000, 0, DataType::VisibleString),
        Ok(Value::VisibleString(label))
    );

    // A segmented download of a 4-byte value is legal too (byte by byte on the wire).
    let r = b.sdo_exchange([0x21, 0x65, 0x60, 0x00, 4, 0, 0, 0]);
    assert_eq!(r, [0x60, 0x65, 0x60, 0x00, 0, 0, 0, 0]);
    // One segment, toggle 0, 4 bytes (n = 3 unused), last.
    let seg = [(3 << 1) | 0x01, 0x34, 0x12, 0, 0, 0, 0, 0];
    let r = b.sdo_exchange(seg);
    assert_eq!(r[0], 0x20);
    assert_eq!(b.get(0x6065, 0), 0x1234);
}

// ============================================================================================
// PDO remapping (CiA 301 §7.5.2.35/36, CANopenNode CO_PDO.c rules)
// ============================================================================================

#[test]
fn pdo_mapping_written_while_the_pdo_is_valid_is_refused_0x06010000() {
    let mut b = Bench::new();
    assert_eq!(
        b.refused(0x1A00, 1, Value::Unsigned32(0x6064_0020)),
        AbortCode::UNSUPPORTED_ACCESS.0
    );
    assert_eq!(
        b.refused(0x1A00, 0, Value::Unsigned8(1)),
        AbortCode::UNSUPPORTED_ACCESS.0
    );
    assert_eq!(
        b.refused(0x1600, 0, Value::Unsigned8(0)),
        AbortCode::UNSUPPORTED_ACCESS.0
    );
    assert_eq!(b.get(0x1A00, 0), 2);
    assert_eq!(b.get(0x1A00, 1), 0x6041_0010);
}

#[test]
fn pdo_mapping_entry_written_while_sub0_is_not_0_is_refused_0x06010000() {
    let mut b = Bench::new();
    b.set(0x1800, 1, 0x8000_0185);
    assert_eq!(
        b.refused(0x1A00, 1, Value::Unsigned32(0x6064_0020)),
        AbortCode::UNSUPPORTED_ACCESS.0
    );
    b.set(0x1A00, 0, 0);
    b.set(0x1A00, 1, 0x6064_0020);
}

#[test]
fn pdo_mapping_longer_than_64_bits_is_refused_0x06040042() {
    let mut b = Bench::new();
    b.set(0x1800, 1, 0x8000_0185);
    b.set(0x1A00, 0, 0);
    b.set(0x1A00, 1, 0x6064_0020);
    b.set(0x1A00, 2, 0x6062_0020);
    b.set(0x1A00, 3, 0x6041_0010);
    assert_eq!(
        b.refused(0x1A00, 0, Value::Unsigned8(3)),
        AbortCode::PDO_TOO_LONG.0
    );
    assert_eq!(b.get(0x1A00, 0), 0);
    // Exactly 64 bits is fine.
    b.set(0x1A00, 0, 2);
}

#[test]
fn pdo_mapping_of_a_non_mappable_object_is_refused_0x06040041() {
    let mut b = Bench::new();
    b.set(0x1800, 1, 0x8000_0185);
    b.set(0x1A00, 0, 0);
    // 0x6065 is not PDO-mappable.
    assert_eq!(
        b.refused(0x1A00, 1, Value::Unsigned32(0x6065_0020)),
        AbortCode::NOT_MAPPABLE.0
    );
    // Wrong length for a u16.
    assert_eq!(
        b.refused(0x1A00, 1, Value::Unsigned32(0x6041_0020)),
        AbortCode::NOT_MAPPABLE.0
    );
    // A read-only object cannot be received.
    b.set(0x1400, 1, 0x8000_0205);
    b.set(0x1600, 0, 0);
    assert_eq!(
        b.refused(0x1600, 1, Value::Unsigned32(0x6041_0010)),
        AbortCode::NOT_MAPPABLE.0
    );
    // A missing object or sub-index is named as such.
    assert_eq!(
        b.refused(0x1600, 1, Value::Unsigned32(0x2000_0020)),
        AbortCode::NO_OBJECT.0
    );
    assert_eq!(
        b.refused(0x1600, 1, Value::Unsigned32(0x60C1_0220)),
        AbortCode::NO_SUB.0
    );
}

#[test]
fn pdo_enable_with_an_empty_mapping_is_refused_0x06090030() {
    let mut b = Bench::new();
    b.set(0x1800, 1, 0x8000_0185);
    b.set(0x1A00, 0, 0);
    assert_eq!(
        b.refused(0x1800, 1, Value::Unsigned32(0x185)),
        AbortCode::INVALID_VALUE.0
    );
    assert_eq!(b.get(0x1800, 1) as u32, 0x8000_0185);
}

#[test]
fn pdo_reserved_transmission_type_is_refused_0x06090030() {
    let mut b = Bench::new();
    for tt in [241u8, 245, 251] {
        assert_eq!(
            b.refused(0x1800, 2, Value::Unsigned8(tt)),
            AbortCode::INVALID_VALUE.0
        );
        assert_eq!(
            b.refused(0x1400, 2, Value::Unsigned8(tt)),
            AbortCode::INVALID_VALUE.0
        );
    }
    assert_eq!(b.get(0x1800, 2), 1);
    for tt in [1, 240, 254, 255] {
        b.set(0x1800, 2, tt);
        b.set(0x1400, 2, tt);
    }
}

#[test]
fn pdo_cob_id_of_a_valid_pdo_cannot_change_0x06090030() {
    let mut b = Bench::new();
    assert_eq!(
        b.refused(0x1800, 1, Value::Unsigned32(0x186)),
        AbortCode::INVALID_VALUE.0
    );
    // Rewriting the same COB-ID is fine; invalidate first to change it.
    b.set(0x1800, 1, 0x185);
    b.set(0x1800, 1, 0x8000_0186);
    b.set(0x1800, 1, 0x186);
    b.nmt(nmt::START, NODE);
    b.clear();
    b.sync();
    assert_eq!(b.sent(0x186).len(), 1);
    assert!(b.tpdos(1).is_empty());
}

#[test]
fn pdo_full_remap_sequence_is_used_by_the_next_tpdo_and_rpdo() {
    let mut b = Bench::with(SimDrive::new(dict(), NODE).with_position(-1234));
    // TPDO1: position actual first, then the statusword.
    b.remap(0x1800, &[0x6064_0020, 0x6041_0010]);
    // RPDO1: target position, then the controlword.
    b.remap(0x1400, &[0x607A_0020, 0x6040_0010]);
    b.nmt(nmt::START, NODE);
    b.clear();
    b.sync();
    let t = b.tpdos(1);
    assert_eq!(t.len(), 1);
    let mut want = (-1234i32).to_le_bytes().to_vec();
    want.extend_from_slice(&b.sw().to_le_bytes());
    assert_eq!(t[0].1, want);

    let mut d = 4321i32.to_le_bytes().to_vec();
    d.extend_from_slice(&0x0006u16.to_le_bytes());
    b.rpdo(1, &d);
    b.sync();
    assert_eq!(b.get(0x607A, 0), 4321);
    assert_eq!(b.get(0x6040, 0), 6);
    assert_eq!(b.state(), State::ReadyToSwitchOn);
}

// ============================================================================================
// SYNC
// ============================================================================================

#[test]
fn sync_rpdo_takes_effect_at_the_next_sync_not_before() {
    let mut b = Bench::new();
    b.nmt(nmt::START, NODE);
    b.rpdo(1, &cw_and_i32(0x06, 0));
    b.advance(ms(20));
    assert_eq!(b.state(), State::SwitchOnDisabled);
    assert_eq!(b.drive.od().int(0x6040, 0), 0);
    b.sync();
    assert_eq!(b.state(), State::ReadyToSwitchOn);
    // The TPDO sent on that SYNC already reports the new state.
    let t = b.tpdos(1);
    assert_eq!(
        State::from_statusword(u16::from_le_bytes([t[0].1[0], t[0].1[1]])),
        Some(State::ReadyToSwitchOn)
    );
    // The last RPDO before a SYNC wins.
    b.rpdo(1, &cw_and_i32(0x00, 0));
    b.rpdo(1, &cw_and_i32(0x07, 0));
    b.advance(ms(5));
    assert_eq!(b.state(), State::ReadyToSwitchOn);
    b.sync();
    assert_eq!(b.state(), State::SwitchedOn);
}

#[test]
fn sync_tpdo_is_sent_on_every_nth_sync_for_transmission_type_n() {
    let mut b = Bench::new();
    b.set(0x1800, 2, 3);
    b.nmt(nmt::START, NODE);
    b.clear();
    let mut syncs = Vec::new();
    for _ in 0..9 {
        b.advance(ms(1));
        b.sync();
        syncs.push(b.now);
    }
    let at: Vec<Duration> = b.tpdos(1).iter().map(|(t, _)| *t).collect();
    assert_eq!(at, vec![syncs[2], syncs[5], syncs[8]]);
}

#[test]
fn sync_missing_for_more_than_1_5_periods_raises_emcy_0x8100_once() {
    let mut b = Bench::new();
    b.set(0x1006, 0, PERIOD_US);
    b.nmt(nmt::START, NODE);
    b.advance(ms(10));
    b.sync();
    let t0 = b.now;
    b.clear();
    b.run_until(t0 + us(1500));
    assert_eq!(b.emcy_count(emcy::COMMUNICATION), 0, "not at 1.5 T");
    b.run_until(t0 + ms(100));
    let e: Vec<_> = b
        .emcys()
        .into_iter()
        .filter(|(_, c)| *c == emcy::COMMUNICATION)
        .collect();
    assert_eq!(e.len(), 1, "once: {e:?}");
    assert!(e[0].0 > t0 + us(1500) && e[0].0 <= t0 + us(1501), "{e:?}");
    // SYNCs on time raise nothing.
    b.clear();
    for _ in 0..20 {
        b.advance(ms(1));
        b.sync();
    }
    assert_eq!(b.emcy_count(emcy::COMMUNICATION), 0);
}

#[test]
fn sync_with_wrong_dlc_raises_emcy_0x8240() {
    let mut b = Bench::new();
    b.nmt(nmt::START, NODE);
    b.clear();
    b.sync();
    assert!(b.emcys().is_empty());
    // 0x1019 = 0: DLC must be 0.
    b.send(SYNC, &[1]);
    assert_eq!(b.emcy_count(emcy::SYNC_LENGTH), 1);
    // 0x1019 = 5: DLC must be 1 (the counter).
    b.set(0x1019, 0, 5);
    b.clear();
    b.send(SYNC, &[1]);
    assert!(b.emcys().is_empty());
    b.sync();
    assert_eq!(b.emcy_count(emcy::SYNC_LENGTH), 1);
}

#[test]
fn short_rpdo_raises_emcy_0x8210_and_is_not_applied() {
    let mut b = Bench::new();
    b.nmt(nmt::START, NODE);
    b.clear();
    b.rpdo(1, &[0x06, 0x00]);
    assert_eq!(b.emcy_count(emcy::PDO_LENGTH), 1);
    b.sync();
    assert_eq!(b.state(), State::SwitchOnDisabled);
    // Event-driven RPDO2 too.
    b.rpdo(2, &[0x06, 0x00, 0x00]);
    assert_eq!(b.emcy_count(emcy::PDO_LENGTH), 2);
    assert_eq!(b.state(), State::SwitchOnDisabled);
}

#[test]
fn long_rpdo_raises_emcy_0x8220() {
    let mut b = Bench::new();
    b.nmt(nmt::START, NODE);
    b.clear();
    b.rpdo(1, &[0x06, 0x00, 0, 0, 0, 0, 0xAA, 0xBB]);
    assert_eq!(b.emcy_count(emcy::PDO_TOO_LONG), 1);
}

// ============================================================================================
// Heartbeat consumer (0x1016) and error behaviour
// ============================================================================================

/// Consuming node 3 with `ms` consumer time, Operational, Operation enabled.
fn consumer_bench(time_ms: u16) -> Bench {
    let mut b = Bench::new();
    b.set(0x1016, 1, (3 << 16) | i64::from(time_ms));
    b.nmt(nmt::START, NODE);
    b.enable();
    b.clear();
    b
}

#[test]
fn heartbeat_consumer_timeout_raises_emcy_0x8130_and_stops_the_motor_in_fault() {
    // The drive consumes node 3 (the master) with 100 ms, and is moving in IP.
    let mut b = Bench::ip_running(0);
    b.set(0x1016, 1, (3 << 16) | 100);
    b.clear();
    let mut sp = 0;
    let mut last = b.now;
    // Beats every 50 ms keep it alive.
    for k in 0..200 {
        sp += 20;
        b.ip_cycle(0x1F, sp);
        if k % 50 == 0 {
            b.send(0x703, &[0x05]);
            last = b.now;
        }
    }
    assert!(b.emcys().is_empty());
    // Silence from node 3 while the setpoints keep coming: nothing up to the consumer time.
    while b.now + ms(1) <= last + ms(100) {
        sp += 20;
        b.ip_cycle(0x1F, sp);
    }
    assert_eq!(b.now, last + ms(100));
    assert!(b.emcys().is_empty(), "not before the consumer time");
    assert_eq!(b.state(), State::OperationEnabled);
    assert!(b.get(0x606C, 0) > 10_000, "moving");
    // Just past it: EMCY 0x8130, and 0x6007 = 1 takes the drive to Fault.
    b.run_until(last + ms(100) + us(1));
    assert_eq!(b.emcys(), vec![(last + ms(100) + us(1), emcy::HEARTBEAT)]);
    assert_ne!(b.state(), State::OperationEnabled);
    b.advance(ms(50));
    assert_eq!(b.state(), State::Fault);
    assert_eq!(b.drive.fault_cause(), Some(FaultCause::HeartbeatLost));
    assert_eq!(b.get(0x603F, 0), i64::from(emcy::HEARTBEAT));
    assert_eq!(b.get(0x606C, 0), 0, "stopped");
    let p = b.drive.position_counts();
    b.advance(ms(20));
    assert_eq!(b.drive.position_counts(), p);
    assert_eq!(b.emcy_count(emcy::HEARTBEAT), 1, "reported once");
}

#[test]
fn heartbeat_consumer_is_armed_by_the_first_heartbeat_only() {
    let mut b = consumer_bench(100);
    b.advance(ms(1000));
    assert!(b.emcys().is_empty());
    assert_eq!(b.state(), State::OperationEnabled);
    // Another node's heartbeat does not arm it either.
    b.send(0x704, &[0x05]);
    b.advance(ms(1000));
    assert!(b.emcys().is_empty());
    b.send(0x703, &[0x05]);
    b.advance(ms(101));
    assert_eq!(b.emcy_count(emcy::HEARTBEAT), 1);
}

#[test]
fn heartbeat_loss_applies_0x1029_communication_error_behaviour() {
    // Default 0x1029:1 = 0: Operational → Pre-operational.
    let mut b = consumer_bench(100);
    b.send(0x703, &[0x05]);
    b.advance(ms(150));
    assert_eq!(b.drive.nmt_state(), NmtState::PreOperational);
    // 2: Stopped.
    let mut b = Bench::new();
    b.set(0x1029, 1, 2);
    b.set(0x1016, 1, (3 << 16) | 100);
    b.nmt(nmt::START, NODE);
    b.send(0x703, &[0x05]);
    b.advance(ms(150));
    assert_eq!(b.drive.nmt_state(), NmtState::Stopped);
    // 1: no change; 0x6007 = 0: no drive reaction.
    let mut b = Bench::new();
    b.set(0x1029, 1, 1);
    b.set(0x6007, 0, 0);
    b.set(0x1016, 1, (3 << 16) | 100);
    b.nmt(nmt::START, NODE);
    b.enable();
    b.send(0x703, &[0x05]);
    b.advance(ms(150));
    assert_eq!(b.drive.nmt_state(), NmtState::Operational);
    assert_eq!(b.state(), State::OperationEnabled);
    assert_eq!(b.emcy_count(emcy::HEARTBEAT), 1);
}

// ============================================================================================
// CiA 402
// ============================================================================================

#[test]
fn cia402_walks_to_operation_enabled_with_06_07_0f() {
    let mut b = Bench::new();
    assert_eq!(b.get(0x6041, 0) as u16 & 0x4F, 0x40, "Switch on disabled");
    b.cw(0x06);
    assert_eq!(b.get(0x6041, 0) as u16 & 0x6F, 0x21, "Ready to switch on");
    b.cw(0x07);
    assert_eq!(b.get(0x6041, 0) as u16 & 0x6F, 0x23, "Switched on");
    b.cw(0x0F);
    assert_eq!(b.get(0x6041, 0) as u16 & 0x6F, 0x27, "Operation enabled");
    assert_eq!(b.state(), State::OperationEnabled);
    assert_ne!(b.sw() & sw::VOLTAGE_ENABLED, 0);
    // Disable voltage goes back.
    b.cw(0x00);
    assert_eq!(b.state(), State::SwitchOnDisabled);
}

#[test]
fn mode_7_is_confirmed_in_0x6061() {
    let mut b = Bench::new();
    assert_eq!(b.get(0x6061, 0), 0);
    b.set(0x6060, 0, 7);
    assert_eq!(b.get(0x6061, 0), 7);
    // A mode the drive does not support (0x6502 bit 2 clear: PV) is refused.
    assert_eq!(
        b.refused(0x6060, 0, Value::Integer8(3)),
        AbortCode::INVALID_VALUE.0
    );
    assert_eq!(b.get(0x6061, 0), 7);
}

#[test]
fn ip_starts_after_preload_with_cw_0x1f_and_sets_statusword_bit_12() {
    let mut b = Bench::with(SimDrive::new(dict(), NODE).with_position(1234));
    b.set(0x1006, 0, PERIOD_US);
    b.set(0x6060, 0, 7);
    b.nmt(nmt::START, NODE);
    b.enable();
    assert_eq!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0, "not before bit 4");
    let actual = b.get(0x6064, 0);
    assert_eq!(actual, 1234);
    b.set(0x60C1, 1, actual);
    b.cw(0x1F);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
    // Bumpless: streaming the preloaded setpoint holds the motor.
    for _ in 0..20 {
        b.ip_cycle(0x1F, 1234);
    }
    assert_eq!(b.drive.position_counts(), 1234);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
}

#[test]
fn clearing_cw_bit_4_stops_ip_and_clears_bit_12() {
    let mut b = Bench::ip_running(0);
    b.ip_cycle(0x1F, 0);
    b.cw(0x0F);
    assert_eq!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
    assert_eq!(b.state(), State::OperationEnabled);
    // Setpoints are no longer followed.
    for _ in 0..20 {
        b.ip_cycle(0x0F, 500);
    }
    assert_eq!(b.drive.position_counts(), 0);
    // And a new rising edge starts it again.
    b.set(0x60C1, 1, 0);
    b.ip_cycle(0x1F, 0);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
}

#[test]
fn ip_is_refused_when_0x60c2_differs_from_the_sync_period() {
    let mut b = Bench::new();
    b.set(0x1006, 0, 2 * PERIOD_US); // 2 ms, 0x60C2 still 1 ms
    b.set(0x6060, 0, 7);
    b.nmt(nmt::START, NODE);
    b.enable();
    b.set(0x60C1, 1, 0);
    b.clear();
    b.cw(0x1F);
    assert_eq!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
    assert_eq!(b.emcy_count(EMCY_PARAMETER), 1);
    // Setpoints are not followed.
    for _ in 0..10 {
        b.advance(ms(2));
        b.rpdo(1, &cw_and_i32(0x1F, 500));
        b.sync();
    }
    assert_eq!(b.drive.position_counts(), 0);
    assert_eq!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
    // With 0x60C2 = 2 × 10^-3 s it starts.
    b.set(0x60C2, 1, 2);
    b.cw(0x0F);
    b.cw(0x1F);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
}

#[test]
fn ip_follows_setpoints_latched_each_sync_with_lag() {
    let mut b = Bench::ip_running(0);
    b.clear();
    // A ramp of 20 counts per 1 ms cycle (20000 counts/s), 300 cycles.
    let mut worst = 0i32;
    for k in 1..=300 {
        let sp = 20 * k;
        b.ip_cycle(0x1F, sp);
        let lag = sp - b.drive.position_counts();
        if k > 20 {
            assert!(lag > 0, "lags behind the setpoint: cycle {k}, lag {lag}");
        }
        worst = worst.max(lag);
    }
    assert!(worst < 100, "lag {worst} counts");
    // Then it holds: it settles within a few counts.
    for _ in 0..100 {
        b.ip_cycle(0x1F, 6000);
    }
    assert!((b.drive.position_counts() - 6000).abs() <= 2);
    assert_eq!(b.get(0x6062, 0), 6000);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
    assert!(b.emcys().is_empty());
}

/// IP running, then a setpoint jump far beyond 0x6065, held until the drive reports the
/// following error (the fault reaction is then under way).
fn following_error(b: &mut Bench) {
    b.ip_cycle(0x1F, 100_000);
    let jump = b.now;
    while b.emcy_count(emcy::FOLLOWING_ERROR) == 0 {
        assert!(b.now < jump + ms(50), "no following error");
        b.ip_cycle(0x1F, 100_000);
    }
    assert_eq!(b.state(), State::FaultReactionActive);
}

#[test]
fn following_error_beyond_0x6065_for_0x6066_sets_bit_13_emcy_0x8611_and_faults() {
    let mut b = Bench::ip_running(0);
    b.clear();
    b.ip_cycle(0x1F, 100_000);
    let jump = b.now;
    // 0x6066 = 10 ms: nothing for the first 9 ms.
    for _ in 0..9 {
        b.ip_cycle(0x1F, 100_000);
        assert_eq!(b.sw() & sw::OP_MODE_SPECIFIC_13, 0);
        assert_eq!(b.state(), State::OperationEnabled);
    }
    assert!(b.emcys().is_empty());
    for _ in 0..40 {
        b.ip_cycle(0x1F, 100_000);
    }
    let e: Vec<_> = b
        .emcys()
        .into_iter()
        .filter(|(_, c)| *c == emcy::FOLLOWING_ERROR)
        .collect();
    assert_eq!(e.len(), 1);
    assert!(
        e[0].0 > jump + ms(10) && e[0].0 <= jump + ms(12),
        "EMCY at {:?} after the jump",
        e[0].0 - jump
    );
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_13, 0);
    assert_eq!(b.get(0x603F, 0), 0x8611);
    assert_eq!(b.state(), State::Fault);
    assert_eq!(b.drive.fault_cause(), Some(FaultCause::FollowingError));
    assert_eq!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
}

#[test]
fn fault_reset_needs_the_rising_edge_of_cw_bit_7() {
    let mut b = Bench::ip_running(0);
    following_error(&mut b);
    // The master asserts the fault reset during the fault reaction...
    b.cw(0x80);
    b.advance(ms(100));
    assert_eq!(b.state(), State::Fault);
    b.clear();
    // ... holding it does nothing more.
    b.cw(0x80);
    b.advance(ms(10));
    b.cw(0x80);
    assert_eq!(b.state(), State::Fault);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_13, 0);
    assert_eq!(b.emcy_count(emcy::RESET), 0);
    // 0x00 then 0x80: reset to Switch on disabled.
    b.cw(0x00);
    assert_eq!(b.state(), State::Fault);
    b.cw(0x80);
    assert_eq!(b.state(), State::SwitchOnDisabled);
    assert_eq!(b.emcy_count(emcy::RESET), 1);
    let reset = b
        .sent(cob::EMCY + u16::from(NODE))
        .into_iter()
        .find(|(_, d)| d[..2] == [0, 0])
        .map(|(_, d)| d);
    assert_eq!(reset, Some(vec![0; 8]), "EMCY 0x0000, error register 0");
    assert_eq!(b.sw() & sw::OP_MODE_SPECIFIC_13, 0);
    assert_eq!(b.get(0x603F, 0), 0);
    assert_eq!(b.get(0x1001, 0), 0);
    assert_eq!(b.drive.fault_cause(), None);
}

#[test]
fn csp_follows_0x607a_with_bit_12_set_in_operation_enabled() {
    let mut b = Bench::new();
    b.set(0x1006, 0, PERIOD_US);
    b.set(0x6060, 0, 8);
    assert_eq!(b.get(0x6061, 0), 8);
    b.nmt(nmt::START, NODE);
    b.cw(0x06);
    b.cw(0x07);
    assert_eq!(
        b.sw() & sw::OP_MODE_SPECIFIC_12,
        0,
        "only in Operation enabled"
    );
    b.cw(0x0F);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
    b.clear();
    for k in 1..=200 {
        b.csp_cycle(0x0F, 10 * k);
        assert!((10 * k - b.drive.position_counts()).abs() < 50);
    }
    for _ in 0..100 {
        b.csp_cycle(0x0F, 2000);
    }
    assert!((b.drive.position_counts() - 2000).abs() <= 2);
    assert_eq!(b.get(0x6062, 0), 2000);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
    assert!(b.emcys().is_empty());
}

#[test]
fn software_position_limits_0x607d_clamp_the_demand_and_set_bit_11() {
    let mut b = Bench::new();
    b.set(0x607D, 2, 1500);
    b.set(0x1006, 0, PERIOD_US);
    b.set(0x6060, 0, 8);
    b.nmt(nmt::START, NODE);
    b.enable();
    b.clear();
    let mut max_pos = i32::MIN;
    for k in 1..=300 {
        let target = 10 * k;
        b.csp_cycle(0x0F, target);
        assert!(b.get(0x6062, 0) <= 1500, "demand clamped");
        max_pos = max_pos.max(b.drive.position_counts());
        if target > 1510 {
            assert_ne!(b.sw() & sw::INTERNAL_LIMIT, 0, "bit 11 at target {target}");
        } else if target < 1400 {
            assert_eq!(b.sw() & sw::INTERNAL_LIMIT, 0, "bit 11 at target {target}");
        }
    }
    for _ in 0..100 {
        b.csp_cycle(0x0F, 3000);
        max_pos = max_pos.max(b.drive.position_counts());
    }
    assert_ne!(b.sw() & sw::INTERNAL_LIMIT, 0);
    // CiA 402-2 (0x607D) bounds the position demand value *and* the position actual value:
    // the motor must not run past the limit while setpoints beyond it keep coming.
    assert!(
        max_pos <= 1502,
        "position actual reached {max_pos} with 0x607D:2 = 1500 (now {})",
        b.drive.position_counts()
    );
    assert!((b.drive.position_counts() - 1500).abs() <= 2);
    // Back inside: the flag clears.
    for _ in 0..50 {
        b.csp_cycle(0x0F, 1000);
    }
    assert_eq!(b.sw() & sw::INTERNAL_LIMIT, 0);
    assert!((b.drive.position_counts() - 1000).abs() <= 2);
}

#[test]
fn rewriting_0x6060_with_the_mode_in_force_does_not_stop_ip() {
    // python-canopen's BaseNode402 carries 0x6060 in its cyclic RPDO.
    let mut b = Bench::new();
    b.remap(0x1400, &[0x6040_0010, 0x6060_0008, 0x60C1_0120]);
    b.set(0x1006, 0, PERIOD_US);
    b.set(0x6060, 0, 7);
    b.nmt(nmt::START, NODE);
    b.enable();
    b.set(0x60C1, 1, 0);
    b.cw(0x1F);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
    // By SDO...
    b.set(0x6060, 0, 7);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0);
    // ... and every cycle in the RPDO.
    for k in 1..=100i32 {
        b.advance(ms(1));
        let mut d = 0x1Fu16.to_le_bytes().to_vec();
        d.push(7);
        d.extend_from_slice(&(10 * k).to_le_bytes());
        b.rpdo(1, &d);
        b.sync();
        assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0, "cycle {k}");
    }
    assert!((b.drive.position_counts() - 1000).abs() < 50);
    // A different mode while IP runs is refused.
    assert_eq!(
        b.refused(0x6060, 0, Value::Integer8(8)),
        AbortCode::DEVICE_STATE.0
    );
}

/// A drive following IP setpoints (TPDO1 on every SYNC, heartbeat every 100 ms), with `inject`
/// armed from its motion start.
fn injected(inject: crate::sim::Inject) -> Bench {
    let mut b = Bench::with(SimDrive::new(dict(), NODE).with_inject(inject));
    b.set(0x1017, 0, 100);
    b.set(0x1800, 2, 1);
    b.set(0x1006, 0, PERIOD_US);
    b.set(0x6060, 0, 7);
    b.nmt(nmt::START, NODE);
    b.enable();
    let actual = b.get(0x6064, 0);
    b.set(0x60C1, 1, actual);
    b.cw(0x1F);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0, "IP active");
    b
}

#[test]
fn no_heartbeat_stops_the_heartbeat_but_not_the_process_data() {
    let mut b = injected(crate::sim::Inject::NoHeartbeat { after: ms(300) });
    let t0 = b.now;
    for _ in 0..600 {
        b.advance(ms(1));
        b.sync();
    }
    let beats: Vec<Duration> = b
        .heartbeats()
        .iter()
        .map(|(t, _)| *t)
        .filter(|t| *t > t0)
        .collect();
    assert!(
        !beats.is_empty() && beats.iter().all(|t| *t <= t0 + ms(300)),
        "{beats:?}"
    );
    // TPDO1 still goes out on every SYNC after the heartbeat stopped.
    let late = b.tpdos(1).iter().filter(|(t, _)| *t > t0 + ms(400)).count();
    assert!(late >= 190, "{late} TPDOs");
    assert_eq!(b.state(), State::OperationEnabled);
    // A reset of the communication restarts it.
    b.nmt(nmt::RESET_COMMUNICATION, NODE);
    b.set(0x1017, 0, 100);
    b.clear();
    b.run_until(b.now + ms(350));
    assert!(b.heartbeats().len() >= 3, "{:?}", b.heartbeats());
}

#[test]
fn a_persistent_fault_survives_the_fault_reset() {
    let mut b = injected(crate::sim::Inject::PersistentFault { after: ms(50) });
    b.run_until(b.now + ms(200));
    assert_eq!(b.state(), State::Fault);
    assert_eq!(b.emcy_count(0x4310), 1);
    assert_eq!(b.get(0x603F, 0), 0x4310);
    b.cw(0x00);
    b.cw(0x80);
    b.run_until(b.now + ms(100));
    assert_eq!(b.state(), State::Fault);
    assert_eq!(b.get(0x603F, 0), 0x4310);
}

#[test]
fn a_recurring_fault_clears_on_reset_and_comes_back() {
    let mut b = injected(crate::sim::Inject::RecurringFault { after: ms(50) });
    b.run_until(b.now + ms(200));
    assert_eq!(b.state(), State::Fault);
    assert_eq!(b.get(0x603F, 0), 0x2310);
    b.cw(0x00);
    b.cw(0x80);
    assert_eq!(b.state(), State::SwitchOnDisabled);
    assert_eq!(b.get(0x603F, 0), 0);
    b.run_until(b.now + ms(30));
    assert_eq!(b.state(), State::SwitchOnDisabled);
    b.run_until(b.now + ms(40));
    assert_eq!(b.state(), State::Fault);
    assert_eq!(b.emcy_count(0x2310), 2);
}

/// The largest following error (counts, read every ms) of an IP drive at 200 mm/s (1000
/// counts/mm, 4 ms SYNC) whose master stalls once for `hold_ms`: the demand stops at the last
/// setpoint, then the setpoints go on where they left off.
fn error_after_a_stalled_master(max_acc: i64, hold_ms: u64) -> i64 {
    let mut b = Bench::with(SimDrive::new(dict(), NODE).with_position(0));
    b.set(0x1006, 0, 4000);
    b.set(0x60C2, 1, 4);
    b.set(0x60C2, 2, -3);
    b.set(0x60C5, 0, max_acc);
    b.set(0x6060, 0, 7);
    b.set(0x6065, 0, 100_000_000); // no fault: measure
    b.nmt(nmt::START, NODE);
    b.enable();
    b.set(0x60C1, 1, 0);
    b.cw(0x1F);
    let step = 800; // counts per 4 ms
    let (mut sp, mut worst) = (0, 0);
    for c in 0..150 {
        sp += step * c.min(50) / 50; // 2 m/s² up to 200 mm/s, then steady
        let gap = if c == 100 { 4 + hold_ms } else { 4 };
        for _ in 0..gap {
            b.advance(ms(1));
            if c > 60 {
                worst = worst.max(b.get(0x60F4, 0).abs());
            }
        }
        b.rpdo(1, &cw_and_i32(0x1F, sp));
        b.sync();
    }
    worst
}

#[test]
fn a_stalled_master_stops_the_demand_and_0x60c5_bounds_the_motor_overshoot() {
    let steady = error_after_a_stalled_master(30_000_000, 0);
    // A 24 ms stall (six periods, as a virtual machine's host can cause): the demand holds, the
    // motor brakes at 0x60C5 (3 g) and overshoots well within a 2 mm window.
    let strong = error_after_a_stalled_master(30_000_000, 24);
    assert!(
        strong > 10 * steady && strong < 1000,
        "{strong} (steady {steady})"
    );
    // At 1 g the same stall costs more than 2 mm: 0x60C5 is the limit in force.
    let weak = error_after_a_stalled_master(10_000_000, 24);
    assert!(weak > 2000, "{weak}");
}

/// The simulated drives share the PC with the master; when their thread is descheduled, the
/// runner tells them ([`SimDrive::skip`]). The motor then resumes where it stopped, while the
/// heartbeat stays on its wall-clock grid: a freeze delays at most the beat that fell due in it.
#[test]
fn a_frozen_drive_skips_the_time_in_its_motor_but_not_in_its_heartbeat() {
    let mut b = Bench::with(SimDrive::new(dict(), NODE).with_position(0));
    b.set(0x1006, 0, 4000);
    b.set(0x60C2, 1, 4);
    b.set(0x60C2, 2, -3);
    b.set(0x1017, 0, 100);
    b.set(0x6060, 0, 7);
    b.nmt(nmt::START, NODE);
    b.enable();
    b.set(0x60C1, 1, 0);
    b.cw(0x1F);
    b.clear();
    let t0 = b.now;
    let step = 400; // counts per 4 ms: 100 mm/s at 1000 counts/mm
    let mut sp = 0;
    let mut before_freeze = None;
    for c in 0..150 {
        sp += step * c.min(25) / 25;
        if c == 80 {
            // The drives' thread is descheduled for 30 ms; the master's frames queue meanwhile
            // and are handled together at the wake-up, as the runner does.
            before_freeze = Some(b.get(0x6064, 0));
            b.now += ms(30);
            b.drive.skip(ms(30));
            assert_eq!(
                b.get(0x6064, 0),
                before_freeze.unwrap(),
                "the motor moved through frozen time"
            );
        } else {
            b.advance(ms(4));
        }
        b.rpdo(1, &cw_and_i32(0x1F, sp));
        b.sync();
    }
    assert!(before_freeze.is_some());
    assert_eq!(b.state(), State::OperationEnabled, "{:?}", b.emcys());
    // The heartbeat grid from before the freeze holds after it: every beat but the one that fell
    // due in the freeze is on t0 + k·100 ms.
    let hb = b.heartbeats();
    assert!(hb.len() >= 5, "{hb:?}");
    let off_grid: Vec<_> = hb
        .iter()
        .filter(|(t, _)| !(*t - t0).as_millis().is_multiple_of(100))
        .collect();
    assert!(off_grid.len() <= 1, "heartbeats off the grid: {off_grid:?}");
    let gaps = hb.windows(2).map(|w| w[1].0 - w[0].0).max().unwrap();
    assert!(gaps <= ms(130), "{gaps:?}");
}

// ============================================================================================
// Homing mode (6)

use super::homing::{self, Switch, Switches};
use super::{HomingStatus, SimSetup};

/// Homing speeds and acceleration of the homing tests: 20 mm/s search, 2 mm/s zero search,
/// 200 mm/s² at 1000 counts/mm.
const SEARCH: i64 = 20_000;
const ZERO: i64 = 2_000;
const HOMING_ACC: i64 = 200_000;

/// A drive on an axis with `setup`, in mode 6, Operation enabled, with `method` and `offset`.
fn homing_bench(setup: SimSetup, method: i64, offset: i64) -> Bench {
    let mut b = Bench::with(SimDrive::new(dict(), NODE).with_sim_setup(setup));
    b.set(0x6098, 0, method);
    b.set(0x607C, 0, offset);
    b.set(0x6099, 1, SEARCH);
    b.set(0x6099, 2, ZERO);
    b.set(0x609A, 0, HOMING_ACC);
    b.set(0x6060, 0, 6);
    assert_eq!(b.get(0x6061, 0), 6);
    b.enable();
    b
}

/// The homing bits of a statusword: (13, 12, 10).
fn homing_bits(s: u16) -> (bool, bool, bool) {
    (
        s & sw::HOMING_ERROR != 0,
        s & sw::HOMING_ATTAINED != 0,
        s & sw::TARGET_REACHED != 0,
    )
}

impl Bench {
    /// Advance 1 ms at a time until the drive no longer homes and stands still (bit 10), or
    /// `deadline` (virtual time) passes; every statusword seen on the way.
    fn run_homing(&mut self, deadline: Duration) -> Vec<u16> {
        let end = self.now + deadline;
        let mut seen = vec![self.sw()];
        while self.now < end {
            self.advance(ms(1));
            let s = self.sw();
            seen.push(s);
            if self.drive.homing_status() != HomingStatus::InProgress && s & sw::TARGET_REACHED != 0
            {
                return seen;
            }
        }
        panic!(
            "homing did not end within {deadline:?}: {:?}, statusword {:04X}",
            self.drive.homing_status(),
            self.sw()
        );
    }

    /// Where the motor physically is (the switches' frame), counts.
    fn physical(&self) -> f64 {
        self.drive.pos + self.drive.origin
    }
}

/// An axis from -5000 to 300000 counts (limit switches there), its home switch at 1000.
fn axis(start: i32, home_switch: Option<i32>) -> SimSetup {
    SimSetup {
        start_counts: start,
        home_switch_counts: home_switch,
        limit_switches_counts: Some([-5_000, 300_000]),
    }
}

#[test]
fn homing_objects_are_in_the_dictionary_and_mode_6_is_supported() {
    let mut b = Bench::new();
    assert_ne!(b.get(0x6502, 0) & (1 << 5), 0, "0x6502 bit 5: homing mode");
    for (index, sub, v) in [
        (0x6098, 0, 19),
        (0x6099, 1, 12_345),
        (0x6099, 2, 678),
        (0x609A, 0, 90_000),
        (0x607C, 0, -4321),
    ] {
        b.set(index, sub, v);
        assert_eq!(b.get(index, sub), v);
    }
    let n = b.get(0x60E3, 0);
    let listed: Vec<i64> = (1..=n as u8).map(|s| b.get(0x60E3, s)).collect();
    assert_eq!(listed, [17, 18, 19, 20, 21, 22, 35, 37]);
    // A method the drive does not run is refused (CiA 301: value range of parameter exceeded).
    assert_eq!(
        b.refused(0x6098, 0, Value::Integer8(1)),
        AbortCode::INVALID_VALUE.0
    );
    assert_eq!(b.get(0x6098, 0), 19);
}

#[test]
fn homing_methods_37_and_35_declare_the_current_position_home_without_motion() {
    for method in [37, 35] {
        let mut b = homing_bench(axis(12_345, None), method, 5_000);
        // Not started: bit 10 only.
        assert_eq!(homing_bits(b.sw()), (false, false, true), "method {method}");
        let before = b.physical();
        b.cw(0x1F);
        let seen = b.run_homing(ms(100));
        assert_eq!(b.drive.homing_status(), HomingStatus::Attained);
        assert_eq!(homing_bits(*seen.last().unwrap()), (false, true, true));
        assert_eq!(
            b.get(0x6064, 0),
            5_000,
            "method {method}: position actual = 0x607C"
        );
        assert!((b.physical() - before).abs() < 1.0, "no motion");
        assert_eq!(b.state(), State::OperationEnabled);
    }
}

#[test]
fn homing_legs_follow_the_cia_402_edge_and_direction_rules() {
    let sw = Switches {
        home: Some(1000.0),
        limits: [-5000.0, 300_000.0],
    };
    // (method, start, final direction, final switch, its state at the home, legs)
    for (method, x, dir, switch, until, n) in [
        (17, 50_000.0, 1.0, Switch::NegativeLimit, false, 2),
        (17, -6_000.0, 1.0, Switch::NegativeLimit, false, 1),
        (18, 50_000.0, -1.0, Switch::PositiveLimit, false, 2),
        // 19/20: the switch is active above 1000.
        (19, 0.0, -1.0, Switch::HomePositive, false, 2),
        (19, 50_000.0, -1.0, Switch::HomePositive, false, 1),
        (20, 0.0, 1.0, Switch::HomePositive, true, 3),
        (20, 50_000.0, 1.0, Switch::HomePositive, true, 2),
        // 21/22: the switch is active below 1000.
        (21, 50_000.0, 1.0, Switch::HomeNegative, false, 2),
        (21, 0.0, 1.0, Switch::HomeNegative, false, 1),
        (22, 50_000.0, -1.0, Switch::HomeNegative, true, 3),
        (22, 0.0, -1.0, Switch::HomeNegative, true, 2),
    ] {
        let legs = homing::legs(method, &sw, x).expect("a switch method");
        let last = legs.last().unwrap();
        assert_eq!(
            (legs.len(), last.dir, last.switch, last.until, last.fast),
            (n, dir, switch, until, false),
            "method {method} from {x}: {legs:?}"
        );
        // Each leg moves toward its switch's change of state.
        let mut at = x;
        for l in &legs {
            assert_ne!(
                sw.active(l.switch, at),
                l.until,
                "method {method}: {legs:?}"
            );
            at = sw.edge(l.switch).unwrap() + l.dir;
        }
    }
    assert!(homing::legs(1, &sw, 0.0).is_none());
}

#[test]
fn homing_on_the_home_switch_ends_at_its_edge_with_position_actual_the_home_offset() {
    // Every switch method, from either side of the switch, ends at the switch's edge (or
    // the limit switch's), standing, with 0x6064 = 0x607C; bit 13 is never seen and the
    // drive's following-error supervision never fires.
    for (method, start, edge) in [
        (19, -2_000, 1_000.0),
        (19, 40_000, 1_000.0),
        (20, -2_000, 1_000.0),
        (20, 40_000, 1_000.0),
        (21, -2_000, 1_000.0),
        (21, 40_000, 1_000.0),
        (22, -2_000, 1_000.0),
        (22, 40_000, 1_000.0),
        (17, 40_000, -5_000.0),
        (18, 250_000, 300_000.0),
    ] {
        let mut b = homing_bench(axis(start, Some(1000)), method, 7_000);
        b.cw(0x1F);
        let seen = b.run_homing(ms(30_000));
        let what = format!("method {method} from {start}");
        assert_eq!(b.drive.homing_status(), HomingStatus::Attained, "{what}");
        assert_eq!(b.get(0x6064, 0), 7_000, "{what}");
        assert!(
            (b.physical() - edge).abs() <= 1.0,
            "{what}: stopped at {}, the edge is at {edge}",
            b.physical()
        );
        assert_eq!(
            b.state(),
            State::OperationEnabled,
            "{what}: {:?}",
            b.emcys()
        );
        // The CiA 402 table, in order: in progress (0/0/0), then attained (0/1/x), ending 0/1/1.
        assert_eq!(homing_bits(seen[1]), (false, false, false), "{what}");
        assert!(seen.iter().all(|s| s & sw::HOMING_ERROR == 0), "{what}");
        let first_attained = seen.iter().position(|s| s & sw::HOMING_ATTAINED != 0);
        let first_attained = first_attained.expect("bit 12 seen");
        assert!(
            seen[..first_attained]
                .iter()
                .skip(1)
                .all(|s| homing_bits(*s) == (false, false, false)),
            "{what}"
        );
        assert_eq!(homing_bits(*seen.last().unwrap()), (false, true, true));
        // It took a search: the motor moved.
        assert!(seen.len() > 100, "{what}: {} ms", seen.len());
    }
}

#[test]
fn a_home_switch_never_found_is_a_homing_error_at_the_end_of_the_travel() {
    for method in [19, 20, 21, 22] {
        let mut b = homing_bench(axis(10_000, None), method, 0);
        b.cw(0x1F);
        let seen = b.run_homing(ms(60_000));
        let what = format!("method {method}");
        assert_eq!(b.drive.homing_status(), HomingStatus::Error, "{what}");
        // 1/0/0 while stopping, then 1/0/1 at standstill.
        assert!(seen.iter().any(|s| homing_bits(*s) == (true, false, false)));
        assert_eq!(
            homing_bits(*seen.last().unwrap()),
            (true, false, true),
            "{what}"
        );
        // Stopped past the limit switch it ran into by at most the braking distance.
        let braking = (SEARCH * SEARCH) as f64 / (2.0 * HOMING_ACC as f64);
        let x = b.physical();
        let past = if (19..=20).contains(&method) {
            x - 300_000.0
        } else {
            -5_000.0 - x
        };
        assert!(
            (0.0..=braking + SEARCH as f64 * 0.002).contains(&past),
            "{what}: at {x}"
        );
        // A homing error is no fault: the drive stays enabled and holds.
        assert_eq!(b.state(), State::OperationEnabled, "{what}");
        let held = b.get(0x6064, 0);
        b.advance(ms(50));
        assert_eq!(b.get(0x6064, 0), held);
    }
}

#[test]
fn clearing_bit_4_or_halt_interrupts_homing_with_the_homing_acceleration() {
    for cw in [0x0F, 0x11F] {
        let mut b = homing_bench(axis(100_000, Some(1000)), 21, 0);
        b.cw(0x1F);
        b.advance(ms(500));
        assert_eq!(b.drive.homing_status(), HomingStatus::InProgress);
        let v = b.drive.homing.v;
        assert!(
            (v + SEARCH as f64).abs() < 1.0,
            "searching at full speed: {v}"
        );
        let at = b.physical();
        b.cw(cw);
        assert_eq!(b.drive.homing_status(), HomingStatus::Interrupted);
        let seen = b.run_homing(ms(1_000));
        // Bit 10 waits for the stop; 12 and 13 stay clear.
        assert_eq!(homing_bits(seen[0]), (false, false, false), "cw {cw:#X}");
        assert_eq!(homing_bits(*seen.last().unwrap()), (false, false, true));
        let braking = (SEARCH * SEARCH) as f64 / (2.0 * HOMING_ACC as f64);
        let moved = at - b.physical();
        assert!(
            (braking * 0.9..=braking * 1.1 + 50.0).contains(&moved),
            "cw {cw:#X}: {moved} counts to stop, braking distance {braking}"
        );
        assert_eq!(b.state(), State::OperationEnabled);
        // A new rising edge of bit 4 starts over, and homes.
        b.cw(0x0F);
        b.cw(0x1F);
        b.run_homing(ms(30_000));
        assert_eq!(b.drive.homing_status(), HomingStatus::Attained);
        assert_eq!(b.get(0x6064, 0), 0);
    }
}

#[test]
fn a_mode_change_is_refused_while_homing_moves_and_disabling_interrupts_it() {
    let mut b = homing_bench(axis(100_000, Some(1000)), 21, 0);
    b.cw(0x1F);
    b.advance(ms(100));
    assert_eq!(
        b.refused(0x6060, 0, Value::Integer8(7)),
        AbortCode::DEVICE_STATE.0
    );
    assert_eq!(
        b.refused(0x6098, 0, Value::Integer8(37)),
        AbortCode::DEVICE_STATE.0
    );
    b.cw(0x07);
    assert_eq!(b.drive.homing_status(), HomingStatus::Interrupted);
    b.advance(ms(500));
    b.set(0x6060, 0, 7);
}

#[test]
fn leaving_homing_for_ip_or_csp_is_bumpless() {
    // IP: after homing, the set-point buffer holds position actual; streaming it holds still.
    let mut b = homing_bench(axis(30_000, Some(1000)), 19, 2_000);
    b.set(0x1006, 0, PERIOD_US);
    b.nmt(nmt::START, NODE);
    b.cw(0x1F);
    b.run_homing(ms(30_000));
    assert_eq!(b.get(0x6064, 0), 2_000);
    b.cw(0x0F);
    b.set(0x6060, 0, 7);
    assert_eq!(b.get(0x60C1, 1), 2_000, "IP buffer at position actual");
    b.cw(0x1F);
    assert_ne!(b.sw() & sw::OP_MODE_SPECIFIC_12, 0, "IP active");
    for _ in 0..50 {
        b.sync();
        b.advance(ms(1));
        assert!(
            (b.drive.pos - 2_000.0).abs() < 1.0,
            "moved to {}",
            b.drive.pos
        );
    }
    // Then a move from there, as the master streams it.
    for k in 1..=100 {
        b.ip_cycle(0x1F, 2_000 + 10 * k);
    }
    b.advance(ms(50));
    assert!((b.drive.pos - 3_000.0).abs() < 1.0, "at {}", b.drive.pos);

    // CSP: homing is entered from CSP while enabled, and left to CSP with 0x607A at the hold.
    let mut b = Bench::with(SimDrive::new(dict(), NODE).with_sim_setup(axis(30_000, Some(1000))));
    b.set(0x1006, 0, PERIOD_US);
    b.set(0x6060, 0, 8);
    b.nmt(nmt::START, NODE);
    b.enable();
    b.csp_cycle(0x0F, 30_000);
    b.set(0x6098, 0, 21);
    b.set(0x6060, 0, 6);
    b.cw(0x1F);
    b.run_homing(ms(30_000));
    assert_eq!(b.drive.homing_status(), HomingStatus::Attained);
    assert_eq!(b.get(0x6064, 0), 0);
    b.cw(0x0F);
    b.set(0x6060, 0, 8);
    assert_eq!(b.get(0x607A, 0), 0, "CSP target at the hold");
    for _ in 0..50 {
        b.sync();
        b.advance(ms(1));
        assert!(b.drive.pos.abs() < 1.0, "moved to {}", b.drive.pos);
    }
    b.csp_cycle(0x0F, 0);
    assert!(b.drive.pos.abs() < 1.0);
}
