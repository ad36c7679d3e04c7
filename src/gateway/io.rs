//! The non-cyclic side of the master on tokio: one receive task dispatches SDO responses,
//! boot-ups, heartbeats and EMCYs; SDO transfers are driven by the sans-I/O
//! [`crate::canopen::sdo_client::SdoClient`] (expedited, segmented or block, of any length); the
//! gateway's own heartbeat is a task of its own.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use canopen_rs::{DataType, Value};
use tokio::sync::mpsc;

use super::GatewayError;
use crate::bus::{AsyncPort, Bus, Filter, Frame};
use crate::canopen::sdo_client::{Mode, Outcome, SdoClient, Step};
use crate::canopen::{Emcy, NmtState, cob};

/// How long an SDO server may take to answer one request.
pub const SDO_TIMEOUT: Duration = crate::master::startup::SDO_TIMEOUT;

/// What the monitor knows of one node.
#[derive(Debug, Clone, Default)]
pub struct NodeHealth {
    /// Last heartbeat (or boot-up) and when.
    pub last_heartbeat: Option<(NmtState, Instant)>,
    /// Boot-ups seen since [`NodeIo::clear_bootups`].
    pub bootups: u32,
    /// EMCYs with a non-zero code, oldest first.
    pub emcys: Vec<Emcy>,
}

/// Shared view of the nodes, written by the receive task, read by everyone.
pub type Health = Arc<Mutex<HashMap<u8, NodeHealth>>>;

/// The non-cyclic connection to the drives.
pub struct NodeIo {
    tx: Arc<AsyncPort>,
    sdo_rx: HashMap<u8, tokio::sync::Mutex<mpsc::UnboundedReceiver<[u8; 8]>>>,
    health: Health,
    bootup_notify: Arc<tokio::sync::Notify>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
    /// The gateway's heartbeat producer, once started.
    heartbeat: Option<tokio::task::JoinHandle<()>>,
}

impl NodeIo {
    /// Open the ports and start the receive task for `nodes`. Must run inside tokio.
    pub fn start(bus: &Bus, nodes: &[u8]) -> Result<NodeIo, GatewayError> {
        let mut filters = Vec::new();
        for &n in nodes {
            let n = u16::from(n);
            filters.push(Filter::exact(cob::SDO_TX + n));
            filters.push(Filter::exact(cob::EMCY + n));
            filters.push(Filter::exact(cob::HEARTBEAT + n));
        }
        let mut rx = bus.open_async(&filters)?;
        // The sending port listens to nothing useful (only NMT frames of other masters, which
        // it never reads).
        let tx = Arc::new(bus.open_async(&[Filter::exact(cob::NMT)])?);
        let health: Health = Arc::new(Mutex::new(HashMap::new()));
        let bootup_notify = Arc::new(tokio::sync::Notify::new());
        let mut sdo_tx = HashMap::new();
        let mut sdo_rx = HashMap::new();
        for &n in nodes {
            let (t, r) = mpsc::unbounded_channel();
            sdo_tx.insert(n, t);
            sdo_rx.insert(n, tokio::sync::Mutex::new(r));
            health.lock().unwrap().insert(n, NodeHealth::default());
        }
        let h = health.clone();
        let notify = bootup_notify.clone();
        let task = tokio::spawn(async move {
            while let Ok(f) = rx.recv().await {
                let id = f.id();
                if (cob::SDO_TX + 1..=cob::SDO_TX + 127).contains(&id) {
                    let node = (id - cob::SDO_TX) as u8;
                    if let (Some(t), Ok(d)) = (sdo_tx.get(&node), <[u8; 8]>::try_from(f.data())) {
                        let _ = t.send(d);
                    }
                } else if (cob::HEARTBEAT + 1..=cob::HEARTBEAT + 127).contains(&id)
                    && f.data().len() == 1
                {
                    let node = (id - cob::HEARTBEAT) as u8;
                    if let Some(state) = NmtState::from_byte(f.data()[0]) {
                        let mut g = h.lock().unwrap();
                        let e = g.entry(node).or_default();
                        e.last_heartbeat = Some((state, Instant::now()));
                        if state == NmtState::BootUp {
                            e.bootups += 1;
                            drop(g);
                            notify.notify_waiters();
                        }
                    }
                } else if let Some(e) = Emcy::from_frame(&f)
                    && e.code != 0
                {
                    tracing::info!("{e}");
                    h.lock().unwrap().entry(e.node).or_default().emcys.push(e);
                }
            }
        });
        Ok(NodeIo {
            tx,
            sdo_rx,
            health,
            bootup_notify,
            tasks: vec![task],
            heartbeat: None,
        })
    }

    /// The shared health view.
    pub fn health(&self) -> Health {
        self.health.clone()
    }

    /// Send a frame.
    pub async fn send(&self, f: &Frame) -> Result<(), GatewayError> {
        Ok(self.tx.send(f).await?)
    }

    /// Send an NMT command to `node` (0 = all).
    pub async fn nmt(&self, cs: u8, node: u8) -> Result<(), GatewayError> {
        self.send(&Frame::new(cob::NMT, &[cs, node]).expect("NMT"))
            .await
    }

    /// Forget boot-ups seen so far.
    pub fn clear_bootups(&self) {
        for h in self.health.lock().unwrap().values_mut() {
            h.bootups = 0;
        }
    }

    /// Wait until every node in `nodes` has sent a boot-up, or `timeout`; the missing ones.
    pub async fn wait_bootups(&self, nodes: &[u8], timeout: Duration) -> Vec<u8> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let notified = self.bootup_notify.notified();
            let missing: Vec<u8> = {
                let g = self.health.lock().unwrap();
                nodes
                    .iter()
                    .copied()
                    .filter(|n| g.get(n).is_none_or(|h| h.bootups == 0))
                    .collect()
            };
            if missing.is_empty() {
                return missing;
            }
            if tokio::time::timeout_at(deadline, notified).await.is_err() {
                return missing;
            }
        }
    }

    /// Start the gateway's own heartbeat: `0x700 + node` with state Operational, every `period`.
    pub fn start_heartbeat(&mut self, node: u8, period: Duration) {
        let tx = self.tx.clone();
        let f = Frame::new(
            cob::HEARTBEAT + u16::from(node),
            &[NmtState::Operational.byte()],
        )
        .expect("id");
        self.stop_heartbeat();
        self.heartbeat = Some(tokio::spawn(async move {
            let mut tick = tokio::time::interval(period);
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            loop {
                tick.tick().await;
                if tx.send(&f).await.is_err() {
                    return;
                }
            }
        }));
    }

    /// Stop the gateway's own heartbeat (it also stops when the `NodeIo` is dropped).
    pub fn stop_heartbeat(&mut self) {
        if let Some(t) = self.heartbeat.take() {
            t.abort();
        }
    }

    /// Runs one SDO transfer with `node` to its end: `start` makes the client and pushes its
    /// first request.
    async fn transfer(
        &self,
        node: u8,
        start: impl FnOnce(Duration, &mut Vec<[u8; 8]>) -> SdoClient,
    ) -> Result<Outcome, GatewayError> {
        let rx = self
            .sdo_rx
            .get(&node)
            .ok_or(GatewayError::UnknownNode { node })?;
        let mut rx = rx.lock().await;
        while rx.try_recv().is_ok() {} // stale responses
        let req = cob::SDO_RX + u16::from(node);
        let epoch = tokio::time::Instant::now();
        let mut out = Vec::new();
        let mut client = start(Duration::ZERO, &mut out).with_timeout(SDO_TIMEOUT, Duration::ZERO);
        let (index, sub) = client.address();
        loop {
            for f in out.drain(..) {
                self.send(&Frame::new(req, &f).expect("id")).await?;
            }
            let step = match tokio::time::timeout_at(epoch + client.poll_at(), rx.recv()).await {
                Ok(Some(r)) => client.on_response(&r, epoch.elapsed(), &mut out),
                Ok(None) => return Err(GatewayError::Bus(crate::bus::BusError::Closed)),
                Err(_) => client.poll(epoch.elapsed().max(client.poll_at()), &mut out),
            };
            if let Step::Done(result) = step {
                // The client's own abort, if it sent one, goes out before the error.
                for f in out.drain(..) {
                    let _ = self.send(&Frame::new(req, &f).expect("id")).await;
                }
                return result.map_err(|e| GatewayError::from_sdo(node, index, sub, e));
            }
        }
    }

    /// SDO upload of `index:sub`: its bytes, of any length (segmented, or expedited where the
    /// node answers so).
    pub async fn upload(&self, node: u8, index: u16, sub: u8) -> Result<Vec<u8>, GatewayError> {
        self.upload_with(node, index, sub, Mode::Segmented).await
    }

    /// [`NodeIo::upload`] in a given transfer mode (block transfers for long objects).
    pub async fn upload_with(
        &self,
        node: u8,
        index: u16,
        sub: u8,
        mode: Mode,
    ) -> Result<Vec<u8>, GatewayError> {
        match self
            .transfer(node, |now, out| {
                SdoClient::upload(index, sub, mode, now, out)
            })
            .await?
        {
            Outcome::Uploaded(bytes) => Ok(bytes),
            Outcome::Downloaded => Err(GatewayError::SdoProtocol { node, index, sub }),
        }
    }

    /// SDO download of `data` to `index:sub`, of any length.
    pub async fn download(
        &self,
        node: u8,
        index: u16,
        sub: u8,
        data: &[u8],
        mode: Mode,
    ) -> Result<(), GatewayError> {
        let data = data.to_vec();
        self.transfer(node, move |now, out| {
            SdoClient::download(index, sub, data, mode, now, out)
        })
        .await
        .map(|_| ())
    }

    /// SDO upload of `index:sub` decoded as `data_type`. A length that does not fit the type
    /// is [`GatewayError::SdoLength`] (the node answered; the answer is not that type).
    pub async fn read(
        &self,
        node: u8,
        index: u16,
        sub: u8,
        data_type: DataType,
    ) -> Result<Value, GatewayError> {
        let bytes = self.upload(node, index, sub).await?;
        Value::decode_le(data_type, &bytes).map_err(|_| GatewayError::SdoLength {
            node,
            index,
            sub,
            data_type,
            len: bytes.len(),
        })
    }

    /// SDO download of `value` to `index:sub`.
    pub async fn write(
        &self,
        node: u8,
        index: u16,
        sub: u8,
        value: Value,
    ) -> Result<(), GatewayError> {
        let mut buf = [0u8; canopen_rs::MAX_STRING_LEN];
        let n = value
            .encode_le(&mut buf)
            .map_err(|_| GatewayError::SdoProtocol { node, index, sub })?;
        self.download(node, index, sub, &buf[..n], Mode::Segmented)
            .await
    }

    /// Read an integer entry.
    pub async fn read_u32(&self, node: u8, index: u16, sub: u8) -> Result<u32, GatewayError> {
        match self.read(node, index, sub, DataType::Unsigned32).await? {
            Value::Unsigned32(v) => Ok(v),
            _ => Err(GatewayError::SdoProtocol { node, index, sub }),
        }
    }
}

impl Drop for NodeIo {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
        self.stop_heartbeat();
    }
}
