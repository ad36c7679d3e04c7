//! A listening socket that receives only the SYNC frames on an interface, each with the time the
//! kernel received it (`SO_TIMESTAMPNS`, read with `recvmsg`), for the SYNC period statistics.
//!
//! The gateway's own SYNC reaches this socket through SocketCAN's local loopback. On `vcan0` the
//! kernel stamps it when the sending socket hands it to the driver, so the figures are the
//! sending times as the kernel saw them (the cyclic thread's wake-up jitter plus its work before
//! the send); on a controller with echo (`IFF_ECHO`, most real adapters) the loopback copy comes
//! back when the frame has been transmitted, so they include the wait for the bus. The
//! timestamps are CLOCK_REALTIME: only their differences are used.

use std::io;
use std::time::UNIX_EPOCH;

use socketcan::{CanFilter, Socket, SocketOptions};

use super::BusError;
use super::socketcan::{check_interface, io_error, open_error};

/// SYNC frames with their kernel receive timestamps.
pub struct SyncTap {
    iface: String,
    sock: socketcan::CanSocket,
}

impl SyncTap {
    /// Open a socket on `iface` that receives the frames with identifier `cob_id` (11 bits) and
    /// no error frames, timestamped.
    pub fn open(iface: &str, cob_id: u16) -> Result<SyncTap, BusError> {
        let sock = socketcan::CanSocket::open(iface).map_err(|e| open_error(iface, e))?;
        check_interface(iface)?;
        let e = |e| io_error(iface, e);
        sock.set_filters(&[CanFilter::new(u32::from(cob_id & 0x7FF), 0x7FF)])
            .map_err(e)?;
        sock.set_error_filter_drop_all().map_err(e)?;
        sock.set_recv_timestamp(true).map_err(e)?;
        sock.set_nonblocking(true).map_err(e)?;
        Ok(SyncTap {
            iface: iface.to_string(),
            sock,
        })
    }

    /// Let the socket hold about `bytes` of received frames (SO_RCVBUFFORCE where permitted,
    /// else SO_RCVBUF up to the system's limit): a reader that drains it rarely (a test counting
    /// SYNCs over a whole run) loses none.
    pub fn set_receive_buffer(&mut self, bytes: usize) -> Result<(), BusError> {
        let fd = std::os::fd::AsRawFd::as_raw_fd(&self.sock);
        let v = libc::c_int::try_from(bytes).unwrap_or(libc::c_int::MAX);
        let set = |opt| {
            // SAFETY: a plain setsockopt with an int we own, on the fd we own.
            unsafe {
                libc::setsockopt(
                    fd,
                    libc::SOL_SOCKET,
                    opt,
                    (&v as *const libc::c_int).cast(),
                    std::mem::size_of::<libc::c_int>() as libc::socklen_t,
                )
            }
        };
        if set(libc::SO_RCVBUFFORCE) != 0 && set(libc::SO_RCVBUF) != 0 {
            return Err(io_error(&self.iface, io::Error::last_os_error()));
        }
        Ok(())
    }

    /// Hand every SYNC received since the last call to `on`, oldest first, as its kernel receive
    /// time in ns (CLOCK_REALTIME). Never waits. Returns how many there were.
    pub fn drain(&mut self, mut on: impl FnMut(u64)) -> Result<usize, BusError> {
        let mut n = 0;
        loop {
            match self.sock.read_frame_with_timestamp() {
                Ok((_, at)) => {
                    let ns = at
                        .duration_since(UNIX_EPOCH)
                        .map_or(0, |d| d.as_nanos() as u64);
                    on(ns);
                    n += 1;
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => return Ok(n),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(io_error(&self.iface, e)),
            }
        }
    }
}

impl std::fmt::Debug for SyncTap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "SyncTap({})", self.iface)
    }
}
