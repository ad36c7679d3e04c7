//! `canmotion scan`: which nodes are on the bus, what they are, and their NMT state.
//!
//! 1. Every node id 1–127 gets an SDO upload of 0x1000 (device type), a bounded number in flight
//!    at once, each with a short timeout; a node that answers at all (even with an abort) is
//!    there.
//! 2. Each node found is asked for its identity 0x1018:1–4, its name 0x1008 and its heartbeat
//!    producer time 0x1017 (whatever it does not have stays empty).
//! 3. Heartbeats are listened to the whole time; for a node whose 0x1017 is set but whose
//!    heartbeat has not come yet, the scan waits up to 1.5 × that period (bounded by
//!    [`ScanOptions::max_heartbeat_wait`]). A node heard only by its heartbeat (a stopped node
//!    does not answer SDO) is listed too.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::Semaphore;
use tokio::task::JoinSet;

use super::sdo::upload_bytes;
use super::{ToolError, runtime};
use crate::bus::Bus;
use crate::canopen::NmtState;
use crate::canopen::index;
use crate::gateway::GatewayError;
use crate::gateway::io::NodeIo;

/// How the scan probes.
#[derive(Debug, Clone)]
pub struct ScanOptions {
    /// How long a node has to answer one SDO request.
    pub timeout: Duration,
    /// SDO requests in flight at once.
    pub concurrency: usize,
    /// The longest wait for the heartbeat of a node whose 0x1017 is set.
    pub max_heartbeat_wait: Duration,
}

impl Default for ScanOptions {
    /// 100 ms per request, 32 in flight, heartbeats awaited up to 2 s.
    fn default() -> Self {
        ScanOptions {
            timeout: Duration::from_millis(100),
            concurrency: 32,
            max_heartbeat_wait: Duration::from_secs(2),
        }
    }
}

/// What the scan learnt of one node.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NodeInfo {
    /// Node id.
    pub node: u8,
    /// NMT state from its heartbeat (a boot-up counts as pre-operational), if one was heard.
    pub state: Option<NmtState>,
    /// Heartbeat producer time 0x1017 in ms, if readable.
    pub heartbeat_ms: Option<u16>,
    /// Whether it answered SDO (a stopped node does not).
    pub answered_sdo: bool,
    /// Device type 0x1000.
    pub device_type: Option<u32>,
    /// Vendor-ID 0x1018:1.
    pub vendor_id: Option<u32>,
    /// Product code 0x1018:2.
    pub product_code: Option<u32>,
    /// Revision number 0x1018:3.
    pub revision: Option<u32>,
    /// Serial number 0x1018:4.
    pub serial: Option<u32>,
    /// Manufacturer device name 0x1008.
    pub name: Option<String>,
}

fn u32_of(b: &[u8]) -> Option<u32> {
    <[u8; 4]>::try_from(b).ok().map(u32::from_le_bytes)
}

/// Whether an SDO outcome means the node is there (it answered, whatever it said), is absent
/// (no answer), or the bus failed.
fn answered(r: &Result<Vec<u8>, GatewayError>) -> Option<bool> {
    match r {
        Ok(_)
        | Err(
            GatewayError::SdoAbort { .. }
            | GatewayError::SdoProtocol { .. }
            | GatewayError::SdoClient { .. }
            | GatewayError::SdoLength { .. },
        ) => Some(true),
        Err(GatewayError::SdoTimeout { .. }) => Some(false),
        Err(_) => None,
    }
}

/// Scan `bus` for CANopen nodes; the nodes found, by node id.
pub fn scan(bus: &Bus, opts: &ScanOptions) -> Result<Vec<NodeInfo>, ToolError> {
    runtime()?.block_on(scan_async(bus, opts))
}

async fn read_with(
    io: &NodeIo,
    node: u8,
    index: u16,
    sub: u8,
    timeout: Duration,
) -> Result<Vec<u8>, GatewayError> {
    match tokio::time::timeout(timeout, upload_bytes(io, node, index, sub)).await {
        Ok(r) => r,
        Err(_) => Err(GatewayError::SdoTimeout { node, index, sub }),
    }
}

async fn details(io: &NodeIo, node: u8, timeout: Duration) -> Result<NodeInfo, GatewayError> {
    let mut info = NodeInfo {
        node,
        answered_sdo: true,
        ..NodeInfo::default()
    };
    let get = async |index: u16, sub: u8| -> Result<Option<Vec<u8>>, GatewayError> {
        let r = read_with(io, node, index, sub, timeout).await;
        match answered(&r) {
            None => r.map(Some),
            Some(_) => Ok(r.ok()),
        }
    };
    info.device_type = get(index::DEVICE_TYPE, 0)
        .await?
        .as_deref()
        .and_then(u32_of);
    info.vendor_id = get(index::IDENTITY, 1).await?.as_deref().and_then(u32_of);
    info.product_code = get(index::IDENTITY, 2).await?.as_deref().and_then(u32_of);
    info.revision = get(index::IDENTITY, 3).await?.as_deref().and_then(u32_of);
    info.serial = get(index::IDENTITY, 4).await?.as_deref().and_then(u32_of);
    info.name = get(index::DEVICE_NAME, 0).await?.map(|b| {
        String::from_utf8_lossy(&b)
            .trim_end_matches('\0')
            .to_string()
    });
    info.heartbeat_ms = get(index::PRODUCER_HEARTBEAT_TIME, 0).await?.and_then(|b| {
        <[u8; 2]>::try_from(b.as_slice())
            .ok()
            .map(u16::from_le_bytes)
    });
    Ok(info)
}

fn heard(io: &NodeIo) -> BTreeMap<u8, NmtState> {
    io.health()
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .filter_map(|(&n, h)| {
            h.last_heartbeat.map(|(s, _)| {
                (
                    n,
                    if s == NmtState::BootUp {
                        NmtState::PreOperational
                    } else {
                        s
                    },
                )
            })
        })
        .collect()
}

async fn scan_async(bus: &Bus, opts: &ScanOptions) -> Result<Vec<NodeInfo>, ToolError> {
    let all: Vec<u8> = (1..=127).collect();
    let io = Arc::new(NodeIo::start(bus, &all)?);
    let permits = Arc::new(Semaphore::new(opts.concurrency.max(1)));

    // 1. Who answers 0x1000?
    let mut probes = JoinSet::new();
    for n in all {
        let (io, permits, t) = (io.clone(), permits.clone(), opts.timeout);
        probes.spawn(async move {
            let _p = permits.acquire_owned().await.expect("never closed");
            (n, read_with(&io, n, index::DEVICE_TYPE, 0, t).await)
        });
    }
    let mut present = Vec::new();
    while let Some(j) = probes.join_next().await {
        let (n, r) = j.expect("a probe task does not panic");
        match answered(&r) {
            Some(true) => present.push(n),
            Some(false) => {}
            None => return Err(r.expect_err("an error").into()),
        }
    }

    // 2. What are they?
    let mut found = BTreeMap::new();
    let mut reads = JoinSet::new();
    for n in present {
        let (io, permits, t) = (io.clone(), permits.clone(), opts.timeout);
        reads.spawn(async move {
            let _p = permits.acquire_owned().await.expect("never closed");
            details(&io, n, t).await
        });
    }
    while let Some(j) = reads.join_next().await {
        let info = j.expect("a scan task does not panic")?;
        found.insert(info.node, info);
    }

    // 3. Their heartbeats.
    let wait = found
        .values()
        .filter_map(|i| i.heartbeat_ms.filter(|&ms| ms > 0))
        .map(|ms| Duration::from_millis(u64::from(ms) * 3 / 2 + 10))
        .max()
        .unwrap_or_default()
        .min(opts.max_heartbeat_wait);
    let deadline = tokio::time::Instant::now() + wait;
    loop {
        let states = heard(&io);
        let waiting = found
            .values()
            .any(|i| i.heartbeat_ms.is_some_and(|ms| ms > 0) && !states.contains_key(&i.node));
        if !waiting || tokio::time::Instant::now() >= deadline {
            break;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    for (n, s) in heard(&io) {
        found
            .entry(n)
            .or_insert_with(|| NodeInfo {
                node: n,
                ..NodeInfo::default()
            })
            .state = Some(s);
    }
    Ok(found.into_values().collect())
}

fn hex32(v: Option<u32>) -> String {
    v.map_or_else(|| "-".into(), |v| format!("0x{v:08X}"))
}

/// The scan as a table, one node a line, under a header.
pub fn format_table(nodes: &[NodeInfo]) -> String {
    let mut s = format!(
        "{:>4}  {:<18} {:<11} {:<11} {:<11} {:<11} {:<11} {}\n",
        "node", "state", "device type", "vendor id", "product", "revision", "serial", "name"
    );
    for i in nodes {
        let state = match (i.state, i.heartbeat_ms) {
            (Some(st), _) => st.to_string(),
            (None, Some(0)) => "- (heartbeat off)".into(),
            (None, _) => "-".into(),
        };
        let name = match (&i.name, i.answered_sdo) {
            (Some(n), _) => n.clone(),
            (None, true) => "-".into(),
            (None, false) => "- (no SDO answer)".into(),
        };
        let _ = writeln!(
            s,
            "{:>4}  {:<18} {:<11} {:<11} {:<11} {:<11} {:<11} {}",
            i.node,
            state,
            hex32(i.device_type),
            hex32(i.vendor_id),
            hex32(i.product_code),
            hex32(i.revision),
            hex32(i.serial),
            name
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_shows_what_is_known() {
        let t = format_table(&[
            NodeInfo {
                node: 2,
                state: Some(NmtState::Operational),
                heartbeat_ms: Some(50),
                answered_sdo: true,
                device_type: Some(0x0002_0192),
                vendor_id: Some(0xCA7),
                product_code: Some(0x402),
                revision: Some(0x1_0000),
                serial: Some(0),
                name: Some("canmotion sim servo".into()),
            },
            NodeInfo {
                node: 9,
                state: Some(NmtState::Stopped),
                ..NodeInfo::default()
            },
        ]);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(
            lines[0],
            "node  state              device type vendor id   product     revision    serial      name"
        );
        assert_eq!(
            lines[1],
            "   2  operational        0x00020192  0x00000CA7  0x00000402  0x00010000  0x00000000  canmotion sim servo"
        );
        assert_eq!(
            lines[2],
            "   9  stopped            -           -           -           -           -           - (no SDO answer)"
        );
    }
}
