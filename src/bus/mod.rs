//! The bus: one narrow interface over CAN frames, with two implementations.
//!
//! - [`socketcan`]: a Linux SocketCAN interface (`vcan0`, `can0`) through the
//!   `socketcan` crate, blocking for the cyclic thread and tokio-driven for the non-cyclic traffic.
//! - [`inproc`]: an in-process bus with vcan semantics: every port sees every frame sent by every
//!   *other* port, in send order. It carries the embedded default (simulated drives in the same
//!   process) and fast tests.
//!
//! A [`Bus`] is a description that opens [`Port`]s (a socket each). Every port may carry a set of
//! [`Filter`]s, applied by the kernel on SocketCAN and in software in-process, so the cyclic thread
//! only ever wakes for its own process data.
//!
//! Besides frames, a port can receive the controller's error frames ([`error`]: bus-off,
//! error-passive, protocol errors…) through [`Port::recv_any`], and the cyclic thread sends with
//! [`Port::try_send`], which never waits, so that it alone decides how long a full transmit queue
//! may hold up a cycle. [`sync_tap`] timestamps SYNC frames in the kernel.

pub mod error;
mod frame;
pub mod inproc;
pub mod socketcan;
pub mod sync_tap;

use std::time::Duration;

pub use error::ErrorFrame;
pub use frame::Frame;

/// What a port receives: a frame, or an error frame from the controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Received {
    /// A data or remote frame.
    Frame(Frame),
    /// An error frame (see [`error`]).
    Error(ErrorFrame),
}

/// The outcome of one attempt to queue a frame without waiting ([`Port::try_send`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrySend {
    /// The frame is in the transmit queue.
    Queued,
    /// The transmit queue has no room (ENOBUFS): nothing was queued.
    QueueFull,
}

/// A receive filter: a frame passes when `frame.id & mask == id & mask`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Filter {
    /// Identifier bits to match.
    pub id: u16,
    /// Which identifier bits matter.
    pub mask: u16,
}

impl Filter {
    /// Exactly one identifier.
    pub fn exact(id: u16) -> Filter {
        Filter { id, mask: 0x7FF }
    }

    /// Whether `id` passes this filter.
    pub fn matches(&self, id: u16) -> bool {
        id & self.mask == self.id & self.mask
    }
}

/// Whether `id` passes `filters` (an empty set passes everything).
pub fn passes(filters: &[Filter], id: u16) -> bool {
    filters.is_empty() || filters.iter().any(|f| f.matches(id))
}

/// Errors of the bus layer. Each says what to do about it.
#[derive(Debug, thiserror::Error)]
pub enum BusError {
    /// The kernel has no SocketCAN support at all.
    #[error(
        "this kernel has no SocketCAN support (socket(AF_CAN) failed: {0}); load the CAN modules \
         (`modprobe can can-raw vcan`), or run inside User-Mode Linux with tools/in-vcan.sh, \
         or use `--bus sim` for the in-process bus"
    )]
    NoSocketCan(std::io::Error),
    /// The named interface does not exist.
    #[error(
        "CAN interface '{iface}' does not exist; create it: for a virtual bus `modprobe vcan && \
         ip link add dev {iface} type vcan && ip link set up {iface}`, for a real adapter \
         `ip link set {iface} up type can bitrate 1000000`"
    )]
    NoSuchInterface {
        /// Interface name.
        iface: String,
    },
    /// The interface exists but is down (ENETDOWN).
    #[error("CAN interface '{iface}' is down; bring it up: `ip link set up {iface}`")]
    InterfaceDown {
        /// Interface name.
        iface: String,
    },
    /// The transmit queue stayed full (ENOBUFS) for longer than the send deadline: the frame was
    /// not sent. On a real bus this means no other node acknowledges frames, or the bus is
    /// overloaded.
    #[error(
        "CAN interface '{iface}': transmit queue full (ENOBUFS) for {waited_us} µs, frame {frame} \
         not sent; is any other node connected and acknowledging, and is the bitrate right?"
    )]
    TxQueueFull {
        /// Interface name.
        iface: String,
        /// The frame that could not be sent.
        frame: Frame,
        /// How long the send waited for room.
        waited_us: u64,
    },
    /// The controller reported bus-off (error frame).
    #[error("CAN interface '{iface}': controller is bus-off")]
    BusOff {
        /// Interface name.
        iface: String,
    },
    /// The in-process bus was shut down.
    #[error("the in-process bus is closed")]
    Closed,
    /// The port cannot do this (e.g. send an error frame on a bus without them).
    #[error("{0}")]
    Unsupported(&'static str),
    /// Any other I/O error from the socket.
    #[error("CAN interface '{iface}': {source}")]
    Io {
        /// Interface name.
        iface: String,
        /// The underlying error.
        source: std::io::Error,
    },
}

impl BusError {
    /// Whether the bus is gone for this port (bus-off, interface down or removed): nothing sent
    /// on it reaches anyone any more.
    pub fn is_bus_lost(&self) -> bool {
        matches!(
            self,
            BusError::BusOff { .. }
                | BusError::InterfaceDown { .. }
                | BusError::NoSuchInterface { .. }
                | BusError::Closed
        )
    }
}

/// One connection to a bus (a socket): blocking, used by threads.
///
/// A port receives error frames of the classes in its error mask, bus-off only unless
/// [`Port::set_error_mask`] says otherwise; [`Port::recv_timeout`] reports a bus-off as
/// [`BusError::BusOff`] and skips the others, [`Port::recv_any`] returns them all.
pub trait Port: Send {
    /// Send a frame. Never blocks for longer than a short transmit deadline
    /// ([`socketcan::SEND_DEADLINE`]).
    fn send(&mut self, frame: &Frame) -> Result<(), BusError>;
    /// Wait up to `timeout` for a frame; `Ok(None)` on timeout. A zero timeout polls.
    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<Frame>, BusError>;
    /// Replace the receive filters (an empty set receives everything).
    fn set_filters(&mut self, filters: &[Filter]) -> Result<(), BusError>;

    /// Try once to queue `frame`, without waiting: [`TrySend::QueueFull`] when the transmit
    /// queue has no room. The default waits like [`Port::send`].
    fn try_send(&mut self, frame: &Frame) -> Result<TrySend, BusError> {
        self.send(frame).map(|()| TrySend::Queued)
    }
    /// Receive error frames of these classes ([`error::class`] bits; 0 for none). Ports that
    /// never see error frames accept any mask.
    fn set_error_mask(&mut self, classes: u32) -> Result<(), BusError> {
        let _ = classes;
        Ok(())
    }
    /// Wait up to `timeout` for a frame or an error frame; `Ok(None)` on timeout.
    fn recv_any(&mut self, timeout: Duration) -> Result<Option<Received>, BusError> {
        Ok(self.recv_timeout(timeout)?.map(Received::Frame))
    }
    /// Send an error frame, as a controller's driver would report it to every other socket
    /// (fault injection: vcan has no controller).
    fn send_error(&mut self, error: &ErrorFrame) -> Result<(), BusError> {
        let _ = error;
        Err(BusError::Unsupported("this port cannot send error frames"))
    }
}

/// [`Port::recv_timeout`] in terms of [`Port::recv_any`]: a bus-off is an error, other error
/// frames are skipped. The clock is read only after a skipped error frame (rare), so the wait
/// is then bounded by twice `timeout`.
pub(crate) fn frames_only(
    port: &mut dyn Port,
    iface: &str,
    timeout: Duration,
) -> Result<Option<Frame>, BusError> {
    let mut deadline: Option<std::time::Instant> = None;
    let mut left = timeout;
    loop {
        match port.recv_any(left)? {
            Some(Received::Frame(f)) => return Ok(Some(f)),
            Some(Received::Error(e)) if e.is_bus_off() => {
                return Err(BusError::BusOff {
                    iface: iface.to_string(),
                });
            }
            Some(Received::Error(_)) => {
                let now = std::time::Instant::now();
                left = deadline
                    .get_or_insert(now + timeout)
                    .saturating_duration_since(now);
            }
            None => return Ok(None),
        }
    }
}

/// Which bus to open ports on.
#[derive(Clone, Debug)]
pub enum Bus {
    /// The in-process bus.
    InProc(inproc::InProcBus),
    /// A SocketCAN interface by name.
    SocketCan(String),
}

impl Bus {
    /// Parse a `--bus` argument: `sim` is a new in-process bus, anything else an interface name.
    pub fn from_arg(arg: &str) -> Bus {
        if arg == "sim" {
            Bus::InProc(inproc::InProcBus::new())
        } else {
            Bus::SocketCan(arg.to_string())
        }
    }

    /// A short name for messages.
    pub fn name(&self) -> &str {
        match self {
            Bus::InProc(_) => "sim (in-process)",
            Bus::SocketCan(name) => name,
        }
    }

    /// Open a blocking port that receives the frames passing `filters` (all when empty).
    pub fn open(&self, filters: &[Filter]) -> Result<Box<dyn Port>, BusError> {
        match self {
            Bus::InProc(bus) => Ok(Box::new(bus.port(filters))),
            Bus::SocketCan(iface) => Ok(Box::new(socketcan::SocketCanPort::open(iface, filters)?)),
        }
    }

    /// A socket that receives only SYNC frames (`cob_id`) with their kernel receive timestamps,
    /// for the SYNC period statistics; `None` on the in-process bus, which has no kernel (the
    /// gateway then times SYNC on its own clock as it sends).
    pub fn sync_tap(&self, cob_id: u16) -> Result<Option<sync_tap::SyncTap>, BusError> {
        match self {
            Bus::InProc(_) => Ok(None),
            Bus::SocketCan(iface) => Ok(Some(sync_tap::SyncTap::open(iface, cob_id)?)),
        }
    }

    /// Open a port for tokio tasks. Must be called inside a tokio runtime.
    pub fn open_async(&self, filters: &[Filter]) -> Result<AsyncPort, BusError> {
        match self {
            Bus::InProc(bus) => Ok(AsyncPort::InProc(bus.async_port(filters))),
            Bus::SocketCan(iface) => Ok(AsyncPort::SocketCan(socketcan::AsyncSocketCanPort::open(
                iface, filters,
            )?)),
        }
    }
}

/// A port for tokio tasks: frames are awaited, sends never block the runtime.
pub enum AsyncPort {
    /// In-process.
    InProc(inproc::AsyncInProcPort),
    /// SocketCAN through tokio's reactor.
    SocketCan(socketcan::AsyncSocketCanPort),
}

impl AsyncPort {
    /// Wait for the next frame passing this port's filters.
    pub async fn recv(&mut self) -> Result<Frame, BusError> {
        match self {
            AsyncPort::InProc(p) => p.recv().await,
            AsyncPort::SocketCan(p) => p.recv().await,
        }
    }

    /// Send a frame.
    pub async fn send(&self, frame: &Frame) -> Result<(), BusError> {
        match self {
            AsyncPort::InProc(p) => p.send(frame),
            AsyncPort::SocketCan(p) => p.send(frame).await,
        }
    }
}

impl std::fmt::Debug for AsyncPort {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AsyncPort::InProc(_) => f.write_str("AsyncPort(in-process)"),
            AsyncPort::SocketCan(p) => write!(f, "AsyncPort({})", p.iface()),
        }
    }
}
