//! SocketCAN ports (`vcan0`, `can0`) through the `socketcan` crate.
//!
//! Filters are installed in the kernel, so a port only wakes for the frames it asked for. Error
//! frames are enabled for bus-off only; a bus-off is reported as [`BusError::BusOff`]. A full
//! transmit queue (ENOBUFS, the usual answer of a real controller nobody acknowledges) is retried
//! for up to [`SEND_DEADLINE`] and then reported, never silently dropped.

use std::io;
use std::time::{Duration, Instant};

use socketcan::{
    CanFilter, CanFrame, EmbeddedFrame, Frame as _, Socket, SocketOptions, StandardId,
};

use super::{BusError, Filter, Frame, Port};

/// How long a send waits for room in a full transmit queue before it reports the frame unsent.
pub const SEND_DEADLINE: Duration = Duration::from_millis(2);

/// CAN_ERR_BUSOFF in the error class mask (linux/can/error.h).
const CAN_ERR_BUSOFF: u32 = 0x0000_0040;

fn open_error(iface: &str, e: io::Error) -> BusError {
    match e.raw_os_error() {
        Some(libc::EAFNOSUPPORT) | Some(libc::EPROTONOSUPPORT) => BusError::NoSocketCan(e),
        Some(libc::ENODEV) | Some(libc::ENXIO) => BusError::NoSuchInterface {
            iface: iface.to_string(),
        },
        Some(libc::ENETDOWN) => BusError::InterfaceDown {
            iface: iface.to_string(),
        },
        _ if e.kind() == io::ErrorKind::NotFound => BusError::NoSuchInterface {
            iface: iface.to_string(),
        },
        _ => BusError::Io {
            iface: iface.to_string(),
            source: e,
        },
    }
}

fn io_error(iface: &str, e: io::Error) -> BusError {
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
fn check_interface(iface: &str) -> Result<(), BusError> {
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
            Err(BusError::NoSuchInterface {
                iface: iface.to_string(),
            })
        }
        Err(_) => Ok(()),
    }
}

fn configure<S: SocketOptions>(sock: &S, iface: &str, filters: &[Filter]) -> Result<(), BusError> {
    if !filters.is_empty() {
        let f: Vec<CanFilter> = filters
            .iter()
            .map(|f| CanFilter::new(u32::from(f.id), u32::from(f.mask)))
            .collect();
        sock.set_filters(&f).map_err(|e| io_error(iface, e))?;
    }
    sock.set_error_filter(CAN_ERR_BUSOFF)
        .map_err(|e| io_error(iface, e))?;
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

/// Convert a received frame; extended-id frames are not CANopen's and are skipped (`Ok(None)`).
fn from_socketcan(iface: &str, frame: CanFrame) -> Result<Option<Frame>, BusError> {
    match frame {
        CanFrame::Error(e) => {
            if e.error_bits() & CAN_ERR_BUSOFF != 0 {
                Err(BusError::BusOff {
                    iface: iface.to_string(),
                })
            } else {
                Ok(None)
            }
        }
        f if f.is_extended() => Ok(None),
        CanFrame::Remote(_) => Ok(Frame::remote(f_id(&frame), frame.dlc() as u8)),
        CanFrame::Data(_) => Ok(Frame::new(f_id(&frame), frame.data())),
    }
}

fn f_id(frame: &CanFrame) -> u16 {
    (frame.raw_id() & 0x7FF) as u16
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

    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        let f = to_socketcan(frame);
        let start = Instant::now();
        loop {
            match self.sock.write_frame(&f) {
                Ok(()) => return Ok(()),
                Err(e)
                    if e.raw_os_error() == Some(libc::ENOBUFS)
                        || e.kind() == io::ErrorKind::WouldBlock =>
                {
                    let waited = start.elapsed();
                    if waited >= SEND_DEADLINE {
                        return Err(BusError::TxQueueFull {
                            iface: self.iface.clone(),
                            frame: *frame,
                            waited_us: waited.as_micros() as u64,
                        });
                    }
                    std::thread::sleep(Duration::from_micros(50));
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(io_error(&self.iface, e)),
            }
        }
    }

    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<Frame>, BusError> {
        let deadline = Instant::now() + timeout;
        loop {
            // The socket is non-blocking: a queued frame costs one system call, an empty queue
            // one more, and only then do we sleep in ppoll (whose nanosecond timeout, unlike
            // poll's milliseconds, does not round a short wait to zero and spin).
            match self.sock.read_frame() {
                Ok(f) => {
                    if let Some(f) = from_socketcan(&self.iface, f)? {
                        return Ok(Some(f));
                    }
                    continue;
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(io_error(&self.iface, e)),
            }
            let left = deadline.saturating_duration_since(Instant::now());
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
        Ok(AsyncSocketCanPort {
            iface: iface.to_string(),
            sock,
        })
    }

    /// The interface name.
    pub fn iface(&self) -> &str {
        &self.iface
    }

    /// Wait for the next frame.
    pub async fn recv(&mut self) -> Result<Frame, BusError> {
        loop {
            match self.sock.read_frame().await {
                Ok(f) => {
                    if let Some(f) = from_socketcan(&self.iface, f)? {
                        return Ok(f);
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(io_error(&self.iface, e)),
            }
        }
    }

    /// Send a frame, waiting up to [`SEND_DEADLINE`] while the transmit queue is full.
    pub async fn send(&self, frame: &Frame) -> Result<(), BusError> {
        let f = to_socketcan(frame);
        let start = Instant::now();
        loop {
            match self.sock.try_write_frame(f) {
                Ok(()) => return Ok(()),
                Err(e)
                    if e.raw_os_error() == Some(libc::ENOBUFS)
                        || e.kind() == io::ErrorKind::WouldBlock =>
                {
                    let waited = start.elapsed();
                    if waited >= SEND_DEADLINE {
                        return Err(BusError::TxQueueFull {
                            iface: self.iface.clone(),
                            frame: *frame,
                            waited_us: waited.as_micros() as u64,
                        });
                    }
                    tokio::time::sleep(Duration::from_micros(100)).await;
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(io_error(&self.iface, e)),
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
    fn frames_convert_both_ways() {
        for f in [
            Frame::new(0x181, &[1, 2, 3]).unwrap(),
            Frame::new(0x000, &[]).unwrap(),
            Frame::remote(0x701, 1).unwrap(),
        ] {
            let back = from_socketcan("x", to_socketcan(&f)).unwrap().unwrap();
            assert_eq!(back, f);
        }
    }
}
