//! `canmotion reset IFACE NODE|all`: a CiA 402 fault reset that checks the fault really
//! cleared.
//!
//! For each node, over SDO (so in Pre-operational as in Operational):
//!
//! 1. read the statusword 0x6041 and the error code 0x603F;
//! 2. a node not in Fault is left alone (a node in Fault reaction active is waited for);
//! 3. controlword 0x6040 = 0x0000, then 0x0080: bit 7's rising edge is the fault reset
//!    (transition 15; the frame with bit 7 low first, as the checklist asks);
//! 4. the statusword must leave Fault (bit 3 clear) within [`ResetOptions::deadline`];
//! 5. and stay clear for [`ResetOptions::observe`]: a fault whose cause persists may let the
//!    drive out of Fault only to come back. A fault comes back when the statusword's fault bit
//!    (bit 3) does; an EMCY in the window whose node's statusword has no fault bit is not a
//!    returned fault (a warning, or the heartbeat loss a drive reports after the gateway's
//!    heartbeat stopped, EMCY 0x8130): it is reported as information
//!    ([`ResetReport::info_emcys`]);
//! 6. bit 7 goes low again (0x0000: the drive stays in Switch on disabled), and 0x603F is read
//!    again.
//!
//! A node whose fault did not clear, or came back, is an error naming the node, its statusword
//! and state, and 0x603F with its meaning.

use std::fmt;
use std::time::{Duration, Instant};

use canopen_rs::{DataType, Value};

use super::{ToolError, runtime};
use crate::bus::Bus;
use crate::canopen::emcy;
use crate::canopen::index;
use crate::cia402::{State, statusword as swb};
use crate::gateway::GatewayError;
use crate::gateway::io::NodeIo;

/// How long the reset may take and how long it is watched.
#[derive(Debug, Clone)]
pub struct ResetOptions {
    /// The statusword must leave Fault within this after the reset edge.
    pub deadline: Duration,
    /// Then stay out of Fault this long.
    pub observe: Duration,
    /// Statusword polling period.
    pub poll: Duration,
}

impl Default for ResetOptions {
    /// 1 s to clear, 500 ms watched, polled every 10 ms.
    fn default() -> Self {
        ResetOptions {
            deadline: Duration::from_secs(1),
            observe: Duration::from_millis(500),
            poll: Duration::from_millis(10),
        }
    }
}

/// How a node's reset went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResetOutcome {
    /// The node was not in Fault: nothing was sent.
    NotFaulted,
    /// Out of Fault after this long, and stayed out for the observation window.
    Cleared {
        /// From the reset edge to the first statusword without bit 3.
        after: Duration,
    },
    /// Still in Fault at the deadline.
    NotCleared,
    /// Out of Fault, then back in (statusword bit 3) within the observation window.
    CameBack {
        /// From the reset edge to the return.
        after: Duration,
        /// The EMCY code that came with it (the first one the node sent in the window), if one
        /// did.
        emcy: Option<u16>,
    },
}

/// What the reset of one node found and did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ResetReport {
    /// Node id.
    pub node: u8,
    /// Statusword before.
    pub statusword_before: u16,
    /// 0x603F before.
    pub error_before: u16,
    /// Statusword at the end.
    pub statusword_after: u16,
    /// 0x603F at the end.
    pub error_after: u16,
    /// The outcome.
    pub outcome: ResetOutcome,
    /// EMCYs the node sent after the fault cleared while its statusword showed no fault (bit 3
    /// clear): information, not a returned fault. Code, and the statusword read after it.
    pub info_emcys: Vec<(u16, u16)>,
}

impl ResetReport {
    /// Whether the node ended without a fault.
    pub fn ok(&self) -> bool {
        matches!(
            self.outcome,
            ResetOutcome::NotFaulted | ResetOutcome::Cleared { .. }
        )
    }
}

fn state_name(sw: u16) -> &'static str {
    State::from_statusword(sw).map_or("an undefined state", |s| s.name())
}

fn code(c: u16) -> String {
    if c == 0 {
        "0x0000 (no error)".to_string()
    } else {
        format!("0x{c:04X} ({})", emcy::meaning(c))
    }
}

impl fmt::Display for ResetReport {
    /// One line: `node 2: Fault (statusword 0x0208, 0x603F = 0x8611 (following error)) → fault
    /// cleared after 12 ms, ...`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.node;
        let (sw0, sw1) = (self.statusword_before, self.statusword_after);
        let before = format!(
            "{} (statusword 0x{sw0:04X}), 0x603F = {}",
            state_name(sw0),
            code(self.error_before)
        );
        let after = format!(
            "{} (statusword 0x{sw1:04X}), 0x603F = {}",
            state_name(sw1),
            code(self.error_after)
        );
        let info = |f: &mut fmt::Formatter<'_>| -> fmt::Result {
            for &(c, sw) in &self.info_emcys {
                write!(
                    f,
                    "\nnode {n}: EMCY {} after the fault cleared, with no fault in the statusword (0x{sw:04X}, {}): information, not a returned fault",
                    code(c),
                    state_name(sw)
                )?;
            }
            Ok(())
        };
        match self.outcome {
            ResetOutcome::NotFaulted => {
                write!(f, "node {n}: not in Fault, nothing to reset: {before}")
            }
            ResetOutcome::Cleared { after: t } => {
                write!(
                    f,
                    "node {n}: fault cleared {:.1} ms after the reset and still clear; was {before}; now {after}",
                    t.as_secs_f64() * 1e3
                )?;
                info(f)
            }
            ResetOutcome::NotCleared => write!(
                f,
                "node {n}: fault NOT cleared: still {after} after the reset (was 0x603F = {}); its cause persists",
                code(self.error_before)
            ),
            ResetOutcome::CameBack { after: t, emcy } => {
                let e = emcy.map_or(String::new(), |c| format!(" with EMCY {}", code(c)));
                write!(
                    f,
                    "node {n}: fault came back {:.1} ms after the reset{e}: now {after} (was 0x603F = {}); its cause persists",
                    t.as_secs_f64() * 1e3,
                    code(self.error_before)
                )?;
                info(f)
            }
        }
    }
}

async fn statusword(io: &NodeIo, node: u8) -> Result<u16, GatewayError> {
    match io
        .read(node, index::STATUSWORD, 0, DataType::Unsigned16)
        .await?
    {
        Value::Unsigned16(v) => Ok(v),
        _ => Err(GatewayError::SdoProtocol {
            node,
            index: index::STATUSWORD,
            sub: 0,
        }),
    }
}

async fn error_code(io: &NodeIo, node: u8) -> Result<u16, GatewayError> {
    match io
        .read(node, index::ERROR_CODE, 0, DataType::Unsigned16)
        .await?
    {
        Value::Unsigned16(v) => Ok(v),
        _ => Err(GatewayError::SdoProtocol {
            node,
            index: index::ERROR_CODE,
            sub: 0,
        }),
    }
}

fn faulted(sw: u16) -> bool {
    sw & swb::FAULT != 0
}

/// Reset one node (see the module documentation).
pub async fn reset_node(
    io: &NodeIo,
    node: u8,
    opts: &ResetOptions,
) -> Result<ResetReport, GatewayError> {
    let mut sw = statusword(io, node).await?;
    // Fault reaction active ends in Fault by itself (transition 14): wait for it.
    let deadline = Instant::now() + opts.deadline;
    while State::from_statusword(sw) == Some(State::FaultReactionActive)
        && Instant::now() < deadline
    {
        tokio::time::sleep(opts.poll).await;
        sw = statusword(io, node).await?;
    }
    let error_before = error_code(io, node).await?;
    let mut report = ResetReport {
        node,
        statusword_before: sw,
        error_before,
        statusword_after: sw,
        error_after: error_before,
        outcome: ResetOutcome::NotFaulted,
        info_emcys: Vec::new(),
    };
    if !faulted(sw) {
        return Ok(report);
    }
    let emcys_before = io
        .health()
        .lock()
        .unwrap()
        .get(&node)
        .map_or(0, |h| h.emcys.len());
    io.write(node, index::CONTROLWORD, 0, Value::Unsigned16(0x0000))
        .await?;
    io.write(node, index::CONTROLWORD, 0, Value::Unsigned16(0x0080))
        .await?;
    let edge = Instant::now();
    // 4. Out of Fault within the deadline.
    let cleared = loop {
        sw = statusword(io, node).await?;
        if !faulted(sw) {
            break Some(edge.elapsed());
        }
        if edge.elapsed() > opts.deadline {
            break None;
        }
        tokio::time::sleep(opts.poll).await;
    };
    report.outcome =
        match cleared {
            None => ResetOutcome::NotCleared,
            Some(after) => {
                // 5. And staying out: the fault bit decides, not an EMCY (a warning or a
                // heartbeat loss without a fault is information).
                let watch_end = Instant::now() + opts.observe;
                let mut outcome = ResetOutcome::Cleared { after };
                let mut seen = emcys_before;
                let mut pending: Vec<u16> = Vec::new();
                loop {
                    pending.extend(io.health().lock().unwrap().get(&node).map_or(
                        Vec::new(),
                        |h| {
                            let new = h.emcys.get(seen..).unwrap_or(&[]);
                            seen = h.emcys.len();
                            new.iter().map(|e| e.code).collect()
                        },
                    ));
                    sw = statusword(io, node).await?;
                    if faulted(sw) {
                        outcome = ResetOutcome::CameBack {
                            after: edge.elapsed(),
                            emcy: pending.first().copied(),
                        };
                        break;
                    }
                    // Read after the EMCY and without the fault bit: not a returned fault.
                    report.info_emcys.extend(pending.drain(..).map(|c| (c, sw)));
                    if Instant::now() >= watch_end {
                        break;
                    }
                    tokio::time::sleep(opts.poll).await;
                }
                outcome
            }
        };
    // 6. Bit 7 low again: the next reset is an edge too.
    io.write(node, index::CONTROLWORD, 0, Value::Unsigned16(0x0000))
        .await?;
    report.statusword_after = statusword(io, node).await?;
    report.error_after = error_code(io, node).await?;
    Ok(report)
}

/// Reset `nodes` on `bus`, one after the other; a report per node.
pub fn reset(bus: &Bus, nodes: &[u8], opts: &ResetOptions) -> Result<Vec<ResetReport>, ToolError> {
    let rt = runtime()?;
    rt.block_on(async {
        let io = NodeIo::start(bus, nodes)?;
        let mut out = Vec::new();
        for &n in nodes {
            out.push(reset_node(&io, n, opts).await?);
        }
        Ok(out)
    })
}

/// The CiA 402 drives on `bus` (device type 0x1000 with profile 0x0192), found by a scan.
pub fn drives_on(bus: &Bus) -> Result<Vec<u8>, ToolError> {
    let nodes = super::scan::scan(bus, &super::scan::ScanOptions::default())?;
    Ok(nodes
        .iter()
        .filter(|n| n.device_type.is_some_and(|t| t & 0xFFFF == 0x0192))
        .map(|n| n.node)
        .collect())
}
