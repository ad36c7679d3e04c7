//! An in-process CAN bus with vcan semantics: a frame sent on one port is delivered, in order, to
//! every other port whose filters pass it (like SocketCAN's default loopback to other sockets,
//! without the sender's own copy). Error frames sent with [`Port::send_error`] reach the ports
//! whose error mask has one of their classes, as on SocketCAN.

use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::{BusError, ErrorFrame, Filter, Frame, Port, Received, error, frames_only, passes};

enum Sink {
    Blocking(mpsc::Sender<Received>),
    Async(tokio::sync::mpsc::UnboundedSender<Frame>),
}

struct Member {
    id: u64,
    filters: Vec<Filter>,
    /// Error classes this member receives (bus-off by default, as a SocketCAN port).
    error_mask: u32,
    sink: Sink,
}

#[derive(Default)]
struct Inner {
    next_id: u64,
    members: Vec<Member>,
}

/// The bus itself; cheap to clone (all clones are the same bus).
#[derive(Clone, Default)]
pub struct InProcBus {
    inner: Arc<Mutex<Inner>>,
}

impl std::fmt::Debug for InProcBus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("InProcBus")
    }
}

impl InProcBus {
    /// A new, empty bus.
    pub fn new() -> InProcBus {
        InProcBus::default()
    }

    fn join(&self, filters: &[Filter], sink: Sink) -> u64 {
        let mut inner = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        inner.next_id += 1;
        let id = inner.next_id;
        inner.members.push(Member {
            id,
            filters: filters.to_vec(),
            error_mask: error::class::BUS_OFF,
            sink,
        });
        id
    }

    /// Deliver `frame` to every member but `from`; drop members whose receiver is gone.
    fn deliver(&self, from: u64, frame: &Frame) {
        let mut inner = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        inner.members.retain(|m| {
            if m.id == from || !passes(&m.filters, frame.id()) {
                return true;
            }
            match &m.sink {
                Sink::Blocking(tx) => tx.send(Received::Frame(*frame)).is_ok(),
                Sink::Async(tx) => tx.send(*frame).is_ok(),
            }
        });
    }

    /// Deliver an error frame to every member but `from` whose error mask has one of its
    /// classes. Async ports (the non-cyclic side) get none: on SocketCAN they would only end on a
    /// bus-off, which the cyclic thread reports.
    fn deliver_error(&self, from: u64, e: &ErrorFrame) {
        let mut inner = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        inner.members.retain(|m| {
            if m.id == from || m.error_mask & e.class() == 0 {
                return true;
            }
            match &m.sink {
                Sink::Blocking(tx) => tx.send(Received::Error(*e)).is_ok(),
                Sink::Async(_) => true,
            }
        });
    }

    fn leave(&self, id: u64) {
        let mut inner = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        inner.members.retain(|m| m.id != id);
    }

    /// A blocking port.
    pub fn port(&self, filters: &[Filter]) -> InProcPort {
        let (tx, rx) = mpsc::channel();
        let id = self.join(filters, Sink::Blocking(tx));
        InProcPort {
            bus: self.clone(),
            id,
            rx,
        }
    }

    /// A port for tokio tasks.
    pub fn async_port(&self, filters: &[Filter]) -> AsyncInProcPort {
        let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
        let id = self.join(filters, Sink::Async(tx));
        AsyncInProcPort {
            bus: self.clone(),
            id,
            rx,
        }
    }
}

/// A blocking in-process port.
pub struct InProcPort {
    bus: InProcBus,
    id: u64,
    rx: mpsc::Receiver<Received>,
}

impl Port for InProcPort {
    fn set_filters(&mut self, filters: &[Filter]) -> Result<(), BusError> {
        let mut inner = self.bus.inner.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(m) = inner.members.iter_mut().find(|m| m.id == self.id) {
            m.filters = filters.to_vec();
        }
        Ok(())
    }

    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        self.bus.deliver(self.id, frame);
        Ok(())
    }

    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<Frame>, BusError> {
        frames_only(self, "sim", timeout)
    }

    fn recv_any(&mut self, timeout: Duration) -> Result<Option<Received>, BusError> {
        let r = if timeout.is_zero() {
            self.rx.try_recv().map_err(|e| match e {
                mpsc::TryRecvError::Empty => None,
                mpsc::TryRecvError::Disconnected => Some(BusError::Closed),
            })
        } else {
            self.rx.recv_timeout(timeout).map_err(|e| match e {
                mpsc::RecvTimeoutError::Timeout => None,
                mpsc::RecvTimeoutError::Disconnected => Some(BusError::Closed),
            })
        };
        match r {
            Ok(f) => Ok(Some(f)),
            Err(None) => Ok(None),
            Err(Some(e)) => Err(e),
        }
    }

    fn set_error_mask(&mut self, classes: u32) -> Result<(), BusError> {
        let mut inner = self.bus.inner.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(m) = inner.members.iter_mut().find(|m| m.id == self.id) {
            m.error_mask = classes;
        }
        Ok(())
    }

    fn send_error(&mut self, e: &ErrorFrame) -> Result<(), BusError> {
        self.bus.deliver_error(self.id, e);
        Ok(())
    }
}

impl Drop for InProcPort {
    fn drop(&mut self) {
        self.bus.leave(self.id);
    }
}

/// An in-process port for tokio tasks.
pub struct AsyncInProcPort {
    bus: InProcBus,
    id: u64,
    rx: tokio::sync::mpsc::UnboundedReceiver<Frame>,
}

impl AsyncInProcPort {
    /// Wait for the next frame.
    pub async fn recv(&mut self) -> Result<Frame, BusError> {
        self.rx.recv().await.ok_or(BusError::Closed)
    }

    /// Send a frame to every other port.
    pub fn send(&self, frame: &Frame) -> Result<(), BusError> {
        self.bus.deliver(self.id, frame);
        Ok(())
    }
}

impl Drop for AsyncInProcPort {
    fn drop(&mut self) {
        self.bus.leave(self.id);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_other_port_sees_every_frame_in_order_but_not_its_own() {
        let bus = InProcBus::new();
        let mut a = bus.port(&[]);
        let mut b = bus.port(&[]);
        let mut c = bus.port(&[Filter::exact(0x181)]);
        for i in 0..5u8 {
            a.send(&Frame::new(0x180 + u16::from(i), &[i]).unwrap())
                .unwrap();
        }
        for i in 0..5u8 {
            let f = b.recv_timeout(Duration::ZERO).unwrap().unwrap();
            assert_eq!((f.id(), f.data()), (0x180 + u16::from(i), &[i][..]));
        }
        assert!(
            a.recv_timeout(Duration::ZERO).unwrap().is_none(),
            "sender got its own frame"
        );
        assert_eq!(c.recv_timeout(Duration::ZERO).unwrap().unwrap().id(), 0x181);
        assert!(
            c.recv_timeout(Duration::ZERO).unwrap().is_none(),
            "filter let through"
        );
    }

    #[test]
    fn error_frames_reach_the_ports_whose_mask_has_their_class() {
        let bus = InProcBus::new();
        let mut a = bus.port(&[]);
        let mut all = bus.port(&[Filter::exact(0x181)]);
        all.set_error_mask(error::class::ALL).unwrap();
        let mut none = bus.port(&[]);
        none.set_error_mask(0).unwrap();
        let mut default = bus.port(&[]);
        a.send_error(&ErrorFrame::error_passive(128, 0)).unwrap();
        a.send_error(&ErrorFrame::bus_off()).unwrap();
        let got = |p: &mut InProcPort| {
            std::iter::from_fn(|| p.recv_any(Duration::ZERO).unwrap()).collect::<Vec<_>>()
        };
        assert_eq!(
            got(&mut all),
            vec![
                Received::Error(ErrorFrame::error_passive(128, 0)),
                Received::Error(ErrorFrame::bus_off())
            ]
        );
        assert_eq!(got(&mut none), vec![]);
        // The default mask is bus-off only, and recv_timeout makes it an error.
        assert!(matches!(
            default.recv_timeout(Duration::ZERO),
            Err(BusError::BusOff { .. })
        ));
    }

    #[test]
    fn dropped_ports_leave_the_bus() {
        let bus = InProcBus::new();
        let mut a = bus.port(&[]);
        drop(bus.port(&[]));
        a.send(&Frame::new(1, &[]).unwrap()).unwrap();
        assert_eq!(bus.inner.lock().unwrap().members.len(), 1);
    }
}
