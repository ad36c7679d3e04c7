//! SocketCAN ports (`vcan0`, `can0`) through the `socketcan` crate.
//!
//! Filters are installed in the kernel, so a port only wakes for the frames it asked for. Error
//! frames come through for the classes of the port's error mask (bus-off by default, see
//! [`Port::set_error_mask`]). A full transmit queue (ENOBUFS, the usual answer of a real
//! controller nobody acknowledges) is retried by [`Port::send`] and [`AsyncSocketCanPort::send`]
//! for up to [`SEND_DEADLINE`] and then reported, never silently dropped; [`Port::try_send`]
//! never waits, for the cyclic thread, which has its own deadline.

use std::io;
use std::time::{Duration, Instant};

use socketcan::{
    CanErrorFrame, CanFilter, CanFrame, EmbeddedFrame, Frame as _, Socket, SocketOptions,
    StandardId,
};

use super::error::{self, ErrorFrame};
use super::{BusError, Filter, Frame, Port, Received, TrySend, frames_only};

/// How long a send waits for room in a full transmit queue before it reports the frame unsent.
pub const SEND_DEADLINE: Duration = Duration::from_millis(2);

/// How long to wait between two attempts at a full transmit queue.
const SEND_RETRY_PAUSE: Duration = Duration::from_micros(50);

pub(super) fn open_error(iface: &str, e: io::Error) -> BusError {
    match e.raw_os_error() {
        Some(libc::EAFNOSUPPORT) | Some(libc::EPROTONOSUPPORT) => BusError::NoSocketCan(e),
        Some(libc::ENODEV) | Some(libc::ENXIO) => missing_interface(iface, af_can_unavailable()),
        Some(libc::ENETDOWN) => BusError::InterfaceDown {
            iface: iface.to_string(),
        },
        _ if e.kind() == io::ErrorKind::NotFound => missing_interface(iface, af_can_unavailable()),
        _ => BusError::Io {
            iface: iface.to_string(),
            source: e,
        },
    }
}

pub(super) fn io_error(iface: &str, e: io::Error) -> BusError {
    match e.raw_os_error() {
        Some(libc::ENETDOWN) => BusError::InterfaceDown {
            iface: iface.to_string(),
        },
        Some(libc::ENODEV) => BusError::NoSuchInterface {
            iface: iface.to_string(),
        },
        _ => BusError::Io {
            iface: iface.to_string(),
            source: e,
        },
    }
}

/// Check that the interface exists and is up before opening a socket on it: binding a CAN
/// socket to a down interface succeeds, and the first send fails much later.
pub(super) fn check_interface(iface: &str) -> Result<(), BusError> {
    let flags_path = format!("/sys/class/net/{iface}/flags");
    match std::fs::read_to_string(&flags_path) {
        Ok(s) => {
            let flags = u32::from_str_radix(s.trim().trim_start_matches("0x"), 16).unwrap_or(1);
            if flags & libc::IFF_UP as u32 == 0 {
                return Err(BusError::InterfaceDown {
                    iface: iface.to_string(),
                });
            }
            Ok(())
        }
        Err(_) if std::path::Path::new("/sys/class/net").exists() => {
            Err(missing_interface(iface, af_can_unavailable()))
        }
        Err(_) => Ok(()),
    }
}

/// Why `iface` cannot be found: on a kernel without SocketCAN no CAN interface can exist, and
/// advice to create one (`ip link add ... type vcan`) cannot work, so that is said instead.
/// `af_can` is [`af_can_unavailable`]'s answer.
fn missing_interface(iface: &str, af_can: Option<io::Error>) -> BusError {
    match af_can {
        Some(e) => BusError::NoSocketCan(e),
        None => BusError::NoSuchInterface {
            iface: iface.to_string(),
        },
    }
}

/// The error of `socket(AF_CAN, SOCK_RAW, CAN_RAW)` when this kernel has no SocketCAN (errno 97,
/// EAFNOSUPPORT, or EPROTONOSUPPORT without `can-raw`); `None` when a CAN socket can be made.
/// The socket crate looks the interface up by name before it makes its socket, so a missing
/// SocketCAN shows first as a missing interface; this tells the two apart.
fn af_can_unavailable() -> Option<io::Error> {
    // SAFETY: socket(2) with constant arguments; a descriptor it returns is ours and is closed
    // at once.
    let fd = unsafe { libc::socket(libc::AF_CAN, libc::SOCK_RAW, libc::CAN_RAW) };
    if fd >= 0 {
        // SAFETY: `fd` is the descriptor just opened, closed once.
        unsafe { libc::close(fd) };
        return None;
    }
    let e = io::Error::last_os_error();
    matches!(
        e.raw_os_error(),
        Some(libc::EAFNOSUPPORT) | Some(libc::EPROTONOSUPPORT)
    )
    .then_some(e)
}

fn configure<S: SocketOptions>(sock: &S, iface: &str, filters: &[Filter]) -> Result<(), BusError> {
    if !filters.is_empty() {
        let f: Vec<CanFilter> = filters
            .iter()
            .map(|f| CanFilter::new(u32::from(f.id), u32::from(f.mask)))
            .collect();
        sock.set_filters(&f).map_err(|e| io_error(iface, e))?;
    }
    Ok(())
}

fn to_socketcan(frame: &Frame) -> CanFrame {
    let id = StandardId::new(frame.id()).expect("Frame holds an 11-bit id");
    if frame.is_remote() {
        CanFrame::new_remote(id, frame.dlc() as usize).expect("dlc <= 8")
    } else {
        CanFrame::new(id, frame.data()).expect("data <= 8 bytes")
    }
}

/// Convert a received frame; extended-id frames are not CANopen's and are skipped (`None`).
fn from_socketcan(frame: CanFrame) -> Option<Received> {
    match frame {
        CanFrame::Error(e) => ErrorFrame::from_raw(e.error_bits() | error::CAN_ERR_FLAG, e.data())
            .map(Received::Error),
        f if f.is_extended() => None,
        CanFrame::Remote(_) => Frame::remote(f_id(&frame), frame.dlc() as u8).map(Received::Frame),
        CanFrame::Data(_) => Frame::new(f_id(&frame), frame.data()).map(Received::Frame),
    }
}

fn f_id(frame: &CanFrame) -> u16 {
    (frame.raw_id() & 0x7FF) as u16
}

/// What one attempt at writing a frame came to.
enum Attempt {
    Done,
    Full,
    Again,
    Failed(io::Error),
}

fn attempt(r: io::Result<()>) -> Attempt {
    match r {
        Ok(()) => Attempt::Done,
        Err(e)
            if e.raw_os_error() == Some(libc::ENOBUFS) || e.kind() == io::ErrorKind::WouldBlock =>
        {
            Attempt::Full
        }
        Err(e) if e.kind() == io::ErrorKind::Interrupted => Attempt::Again,
        Err(e) => Attempt::Failed(e),
    }
}

/// The send-retry policy of both ports: retry a full queue every [`SEND_RETRY_PAUSE`] until
/// [`SEND_DEADLINE`], then report the frame unsent. The callers only write and pause.
struct SendRetry {
    start: Instant,
}

enum Step {
    Finished(Result<(), BusError>),
    Pause(Duration),
    Retry,
}

impl SendRetry {
    fn new() -> SendRetry {
        SendRetry {
            start: Instant::now(),
        }
    }

    fn step(&self, r: io::Result<()>, iface: &str, frame: &Frame) -> Step {
        match attempt(r) {
            Attempt::Done => Step::Finished(Ok(())),
            Attempt::Again => Step::Retry,
            Attempt::Full => {
                let waited = self.start.elapsed();
                if waited >= SEND_DEADLINE {
                    Step::Finished(Err(BusError::TxQueueFull {
                        iface: iface.to_string(),
                        frame: *frame,
                        waited_us: waited.as_micros() as u64,
                    }))
                } else {
                    Step::Pause(SEND_RETRY_PAUSE)
                }
            }
            Attempt::Failed(e) => Step::Finished(Err(io_error(iface, e))),
        }
    }
}

/// A blocking SocketCAN port.
pub struct SocketCanPort {
    iface: String,
    sock: socketcan::CanSocket,
}

impl SocketCanPort {
    /// Open `iface` with kernel filters.
    pub fn open(iface: &str, filters: &[Filter]) -> Result<SocketCanPort, BusError> {
        let sock = socketcan::CanSocket::open(iface).map_err(|e| open_error(iface, e))?;
        check_interface(iface)?;
        configure(&sock, iface, filters)?;
        sock.set_error_filter(error::class::BUS_OFF)
            .map_err(|e| io_error(iface, e))?;
        sock.set_nonblocking(true).map_err(|e| io_error(iface, e))?;
        Ok(SocketCanPort {
            iface: iface.to_string(),
            sock,
        })
    }
}

impl Port for SocketCanPort {
    fn set_filters(&mut self, filters: &[Filter]) -> Result<(), BusError> {
        if filters.is_empty() {
            self.sock
                .set_filter_accept_all()
                .map_err(|e| io_error(&self.iface, e))
        } else {
            configure(&self.sock, &self.iface, filters)
        }
    }

    fn set_error_mask(&mut self, classes: u32) -> Result<(), BusError> {
        self.sock
            .set_error_filter(classes & error::CAN_ERR_MASK)
            .map_err(|e| io_error(&self.iface, e))
    }

    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        let f = to_socketcan(frame);
        let retry = SendRetry::new();
        loop {
            match retry.step(self.sock.write_frame(&f), &self.iface, frame) {
                Step::Finished(r) => return r,
                Step::Pause(d) => std::thread::sleep(d),
                Step::Retry => {}
            }
        }
    }

    fn try_send(&mut self, frame: &Frame) -> Result<TrySend, BusError> {
        let f = to_socketcan(frame);
        loop {
            match attempt(self.sock.write_frame(&f)) {
                Attempt::Done => return Ok(TrySend::Queued),
                Attempt::Full => return Ok(TrySend::QueueFull),
                Attempt::Again => {}
                Attempt::Failed(e) => return Err(io_error(&self.iface, e)),
            }
        }
    }

    fn send_error(&mut self, e: &ErrorFrame) -> Result<(), BusError> {
        let f = CanFrame::Error(CanErrorFrame::new_error(e.class(), e.data()).expect("8 bytes"));
        let start = Instant::now();
        loop {
            match attempt(self.sock.write_frame(&f)) {
                Attempt::Done => return Ok(()),
                Attempt::Again => {}
                Attempt::Full if start.elapsed() < SEND_DEADLINE => {
                    std::thread::sleep(SEND_RETRY_PAUSE)
                }
                Attempt::Full => {
                    return Err(io_error(
                        &self.iface,
                        io::Error::from_raw_os_error(libc::ENOBUFS),
                    ));
                }
                Attempt::Failed(e) => return Err(io_error(&self.iface, e)),
            }
        }
    }

    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<Frame>, BusError> {
        let iface = self.iface.clone();
        frames_only(self, &iface, timeout)
    }

    fn recv_any(&mut self, timeout: Duration) -> Result<Option<Received>, BusError> {
        // The clock is read only when there is something to wait for: inside User-Mode Linux
        // every clock_gettime is a system call, and the cyclic thread polls with a zero timeout.
        let mut deadline = None;
        loop {
            // The socket is non-blocking: a queued frame costs one system call, an empty queue
            // one more, and only then do we sleep in ppoll (whose nanosecond timeout, unlike
            // poll's milliseconds, does not round a short wait to zero and spin).
            match self.sock.read_frame() {
                Ok(f) => {
                    if let Some(r) = from_socketcan(f) {
                        return Ok(Some(r));
                    }
                    continue;
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(io_error(&self.iface, e)),
            }
            if timeout.is_zero() {
                return Ok(None);
            }
            let now = Instant::now();
            let left = deadline
                .get_or_insert(now + timeout)
                .saturating_duration_since(now);
            if left.is_zero() {
                return Ok(None);
            }
            let ts = libc::timespec {
                tv_sec: left.as_secs() as libc::time_t,
                tv_nsec: left.subsec_nanos() as libc::c_long,
            };
            let mut pfd = libc::pollfd {
                fd: std::os::fd::AsRawFd::as_raw_fd(&self.sock),
                events: libc::POLLIN,
                revents: 0,
            };
            // SAFETY: one pollfd we own, a timespec we own, no signal mask.
            let r = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
            if r < 0 {
                let e = io::Error::last_os_error();
                if e.kind() == io::ErrorKind::Interrupted {
                    continue;
                }
                return Err(io_error(&self.iface, e));
            }
            if r == 0 {
                return Ok(None);
            }
        }
    }
}

/// A SocketCAN port driven by tokio's reactor.
pub struct AsyncSocketCanPort {
    iface: String,
    sock: socketcan::tokio::CanSocket,
}

impl AsyncSocketCanPort {
    /// Open `iface` with kernel filters. Must be called inside a tokio runtime.
    pub fn open(iface: &str, filters: &[Filter]) -> Result<AsyncSocketCanPort, BusError> {
        let sock = socketcan::tokio::CanSocket::open(iface).map_err(|e| open_error(iface, e))?;
        check_interface(iface)?;
        configure(&sock, iface, filters)?;
        sock.set_error_filter(error::class::BUS_OFF)
            .map_err(|e| io_error(iface, e))?;
        Ok(AsyncSocketCanPort {
            iface: iface.to_string(),
            sock,
        })
    }

    /// The interface name.
    pub fn iface(&self) -> &str {
        &self.iface
    }

    /// Wait for the next frame; a bus-off is an error, other error frames are skipped.
    pub async fn recv(&mut self) -> Result<Frame, BusError> {
        loop {
            match self.sock.read_frame().await {
                Ok(f) => match from_socketcan(f) {
                    Some(Received::Frame(f)) => return Ok(f),
                    Some(Received::Error(e)) if e.is_bus_off() => {
                        return Err(BusError::BusOff {
                            iface: self.iface.clone(),
                        });
                    }
                    _ => {}
                },
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(io_error(&self.iface, e)),
            }
        }
    }

    /// Send a frame, waiting up to [`SEND_DEADLINE`] while the transmit queue is full.
    pub async fn send(&self, frame: &Frame) -> Result<(), BusError> {
        let f = to_socketcan(frame);
        let retry = SendRetry::new();
        loop {
            match retry.step(self.sock.try_write_frame(f), &self.iface, frame) {
                Step::Finished(r) => return r,
                Step::Pause(d) => tokio::time::sleep(d).await,
                Step::Retry => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_interface_says_how_to_create_it() {
        // On a kernel without SocketCAN this is NoSocketCan; with it, NoSuchInterface. Both must
        // tell the user what to do.
        let err = match SocketCanPort::open("canmotion-nope0", &[]) {
            Err(e) => e,
            Ok(_) => panic!("opened a nonexistent interface"),
        };
        let msg = err.to_string();
        assert!(
            msg.contains("ip link add dev canmotion-nope0 type vcan")
                || msg.contains("tools/in-vcan.sh"),
            "{msg}"
        );
    }

    #[test]
    fn a_missing_interface_on_a_kernel_without_socketcan_points_to_in_vcan() {
        // The advice to create the interface cannot work without AF_CAN: it must not be given.
        let no_af_can = io::Error::from_raw_os_error(libc::EAFNOSUPPORT);
        let err = missing_interface("vcan0", Some(no_af_can));
        assert!(matches!(err, BusError::NoSocketCan(_)), "{err:?}");
        let msg = err.to_string();
        assert!(msg.contains("tools/in-vcan.sh"), "{msg}");
        assert!(!msg.contains("ip link add"), "{msg}");
        let err = missing_interface("vcan0", None);
        assert!(matches!(err, BusError::NoSuchInterface { .. }), "{err:?}");
        // And on this machine, whichever it is, the classification follows the probe.
        let opened = SocketCanPort::open("canmotion-nope1", &[])
            .err()
            .expect("no such interface");
        match af_can_unavailable() {
            Some(_) => assert!(matches!(opened, BusError::NoSocketCan(_)), "{opened:?}"),
            None => assert!(
                matches!(opened, BusError::NoSuchInterface { .. }),
                "{opened:?}"
            ),
        }
    }

    #[test]
    fn error_frames_convert_with_their_class_and_data() {
        let e = ErrorFrame::error_passive(130, 4);
        let f = CanFrame::Error(CanErrorFrame::new_error(e.class(), e.data()).unwrap());
        assert_eq!(from_socketcan(f), Some(Received::Error(e)));
    }

    #[test]
    fn full_queues_are_retried_until_the_deadline_then_reported() {
        let f = Frame::new(0x201, &[1]).unwrap();
        let full = || Err(io::Error::from_raw_os_error(libc::ENOBUFS));
        let r = SendRetry::new();
        assert!(matches!(r.step(full(), "vcan0", &f), Step::Pause(_)));
        assert!(matches!(
            r.step(Err(io::ErrorKind::Interrupted.into()), "vcan0", &f),
            Step::Retry
        ));
        let late = SendRetry {
            start: Instant::now() - SEND_DEADLINE,
        };
        match late.step(full(), "vcan0", &f) {
            Step::Finished(Err(e)) => {
                let msg = e.to_string();
                assert!(msg.contains("ENOBUFS") && msg.contains("201#01"), "{msg}");
            }
            _ => panic!("a full queue past the deadline must be reported"),
        }
        match r.step(
            Err(io::Error::from_raw_os_error(libc::ENETDOWN)),
            "vcan0",
            &f,
        ) {
            Step::Finished(Err(BusError::InterfaceDown { .. })) => {}
            _ => panic!("ENETDOWN is the interface going down"),
        }
    }

    #[test]
    fn frames_convert_both_ways() {
        for f in [
            Frame::new(0x181, &[1, 2, 3]).unwrap(),
            Frame::new(0x000, &[]).unwrap(),
            Frame::remote(0x701, 1).unwrap(),
        ] {
            let back = from_socketcan(to_socketcan(&f)).unwrap();
            assert_eq!(back, Received::Frame(f));
        }
    }
}
