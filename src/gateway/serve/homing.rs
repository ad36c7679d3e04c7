//! `home AXIS|all`: CiA 402 homing (mode 6) with each axis's `[axis.homing]` table, group by
//! group in the table's `order` (lower first; axes of the same order home together, so Z can
//! go first).
//!
//! For each group of drive-homed axes (a method number, or `"current"`, which is method 37:
//! the current position becomes the home offset):
//! 1. the cyclic master releases the axes: controlword bit 4 cleared, the setpoint tracks
//!    position actual, and the drive's IP mode goes inactive (statusword bit 12 clear);
//! 2. SDO: 0x6098 method, 0x6099:1/2 speeds, 0x609A acceleration, 0x607C home offset, then
//!    0x6060 = 6, confirmed in 0x6061;
//! 3. controlword bit 4 rises (homing operation start); the drive homes by itself, the setpoint
//!    following its position actual, until statusword bits 12 (homing attained) and 10 (target
//!    reached), or bit 13 (homing error), or the axis's `timeout_ms`, or `abort`;
//! 4. bit 4 cleared; 0x6060 back to the axis's mode (7 or 8), confirmed; the master re-arms the
//!    axes from position actual (bit 4, then statusword bit 12): bumpless. This step runs after
//!    an error too, so the machine stays enabled and holding.
//!
//! Axes with `method = "absolute"` (an absolute encoder) are homed at once, without motion; an
//! axis without an `[axis.homing]` table is homed where it stands.

use std::time::Duration;

use canopen_rs::{DataType, Value};

use super::Controller;
use super::protocol::ServeError;
use super::thread::Request;
use crate::canopen::index;

use crate::gateway::GatewayError;
use crate::master::cyclic::{AxisControl, DriveOpStatus, Phase};

/// CiA 402 mode 6, homing.
pub const HOMING_MODE: i8 = 6;
/// How long a drive may take to show a new mode in 0x6061.
const MODE_TIMEOUT: Duration = Duration::from_secs(1);

/// Why homing failed.
#[derive(Debug, thiserror::Error)]
pub enum HomingError {
    /// The drive reported a homing error (statusword bit 13).
    #[error(
        "axis {axis} (node {node}): homing error reported by the drive (statusword bit 13, 0x{statusword:04X}): {cause}"
    )]
    Drive {
        /// Axis.
        axis: String,
        /// Node.
        node: u8,
        /// The statusword.
        statusword: u16,
        /// What the method's failure means.
        cause: String,
    },
    /// Homing did not complete in time.
    #[error("axis {axis} (node {node}): homing did not complete within {timeout_ms} ms")]
    TimedOut {
        /// Axis.
        axis: String,
        /// Node.
        node: u8,
        /// The axis's `timeout_ms`.
        timeout_ms: u32,
    },
    /// The drive did not take a mode of operation.
    #[error(
        "axis {axis} (node {node}): 0x6061 shows mode {found}, not {mode}, after 0x6060 = {mode}"
    )]
    Mode {
        /// Axis.
        axis: String,
        /// Node.
        node: u8,
        /// Written.
        mode: i8,
        /// Read back.
        found: i8,
    },
    /// An SDO transfer failed.
    #[error("axis {axis}: {source}")]
    Sdo {
        /// Axis.
        axis: String,
        /// The transfer's error (node, object, abort code or our time-out).
        source: Box<GatewayError>,
    },
    /// `abort` (or a stop signal) during homing.
    #[error("homing interrupted by abort")]
    Aborted,
    /// An alarm stopped the machine during homing.
    #[error("homing stopped by an alarm: {alarm}")]
    Alarm {
        /// The alarm.
        alarm: String,
    },
    /// Homing failed, and so did the return to the cyclic mode after it.
    #[error("{error}; then the return to the cyclic mode failed: {restore}")]
    NotRestored {
        /// The homing's error.
        error: Box<HomingError>,
        /// The return's.
        restore: Box<HomingError>,
    },
    /// The cyclic master refused a step, or did not reach it in time.
    #[error("homing: {0}")]
    Master(Box<ServeError>),
}

impl From<ServeError> for HomingError {
    fn from(e: ServeError) -> HomingError {
        match e {
            ServeError::Alarm { alarm } => HomingError::Alarm { alarm },
            e => HomingError::Master(Box::new(e)),
        }
    }
}

/// What a failed homing method means, for the operator.
fn cause_of(method: i8) -> String {
    match method {
        17 | 18 => format!("method {method}: the limit switch was not found"),
        19..=30 => format!("method {method}: the home switch was not found"),
        m => format!("method {m} failed"),
    }
}

/// Homes `axes` (indices, machine order), group by group in their `order`.
pub(super) async fn home(ctl: &mut Controller<'_>, axes: &[usize]) -> Result<(), ServeError> {
    let m = ctl.m;
    let mut orders: Vec<u32> = axes
        .iter()
        .map(|i| m.axes[*i].homing.as_ref().map_or(0, |h| h.order))
        .collect();
    orders.sort_unstable();
    orders.dedup();
    for order in orders {
        let group: Vec<usize> = axes
            .iter()
            .copied()
            .filter(|i| m.axes[*i].homing.as_ref().map_or(0, |h| h.order) == order)
            .collect();
        let mut drive = Vec::new();
        for &i in &group {
            match m.axes[i].homing.as_ref().and_then(|h| h.drive_method()) {
                Some(method) => drive.push((i, method)),
                // An absolute encoder, or no homing table: homed where it stands.
                None => ctl.homed[i] = true,
            }
        }
        if drive.is_empty() {
            continue;
        }
        for &(i, _) in &drive {
            ctl.homed[i] = false;
        }
        let mask = drive.iter().fold(0u32, |m, (i, _)| m | 1 << i);
        let result = home_group(ctl, &drive, mask).await;
        // Whatever happened: back to the cyclic mode, holding, enabled.
        let back = back_to_cyclic(ctl, &drive, mask).await;
        match (result, back) {
            (Ok(()), Ok(())) => {}
            (Err(e), Ok(())) | (Ok(()), Err(e)) => return Err(e.into()),
            (Err(e), Err(back)) => {
                return Err(HomingError::NotRestored {
                    error: Box::new(e),
                    restore: Box::new(back),
                }
                .into());
            }
        }
        for &(i, _) in &drive {
            ctl.homed[i] = true;
        }
        ctl.publish();
    }
    Ok(())
}

async fn home_group(
    ctl: &mut Controller<'_>,
    drive: &[(usize, i8)],
    mask: u32,
) -> Result<(), HomingError> {
    let m = ctl.m;
    ctl.ask(Request::Release(mask)).await?;
    ctl.wait_for("release for homing", Duration::from_secs(2), false, |s| {
        drive.iter().all(|(i, _)| s.axes[*i].released)
    })
    .await?;
    for &(i, method) in drive {
        let a = &m.axes[i];
        let h = a.homing.as_ref().expect("drive-homed axes have a table");
        let node = a.node;
        let counts = |mm: f64| (mm * a.counts_per_mm).round();
        let writes = [
            (index::HOMING_METHOD, 0, Value::Integer8(method)),
            (
                index::HOMING_SPEEDS,
                1,
                Value::Unsigned32(counts(h.speed_search_mm_s).clamp(1.0, u32::MAX.into()) as u32),
            ),
            (
                index::HOMING_SPEEDS,
                2,
                Value::Unsigned32(counts(h.speed_zero_mm_s).clamp(1.0, u32::MAX.into()) as u32),
            ),
            (
                index::HOMING_ACCELERATION,
                0,
                Value::Unsigned32(counts(h.acc_mm_s2).clamp(1.0, u32::MAX.into()) as u32),
            ),
            (
                index::HOME_OFFSET,
                0,
                Value::Integer32(a.mm_to_counts(h.offset_mm)),
            ),
        ];
        for (index, sub, value) in writes {
            sdo(ctl, i, ctl.io.write(node, index, sub, value).await)?;
        }
        set_mode(ctl, i, HOMING_MODE).await?;
    }
    if ctl.homing_aborted() {
        return Err(HomingError::Aborted);
    }
    ctl.ask(Request::StartDriveOp(mask)).await?;
    let started = tokio::time::Instant::now();
    let mut done = vec![false; drive.len()];
    loop {
        let s = ctl.snapshot();
        if let Some(f) = &s.failure {
            return Err(HomingError::Alarm {
                alarm: f.to_string(),
            });
        }
        if ctl.homing_aborted() {
            return Err(HomingError::Aborted);
        }
        for (k, &(i, method)) in drive.iter().enumerate() {
            let a = &m.axes[i];
            match s.axes[i].drive_op {
                Some(DriveOpStatus::Attained) => done[k] = true,
                Some(DriveOpStatus::Error { statusword }) => {
                    return Err(HomingError::Drive {
                        axis: a.name.clone(),
                        node: a.node,
                        statusword,
                        cause: cause_of(method),
                    });
                }
                _ => {
                    let timeout_ms = a.homing.as_ref().map_or(30_000, |h| h.timeout_ms);
                    if started.elapsed() > Duration::from_millis(u64::from(timeout_ms)) {
                        return Err(HomingError::TimedOut {
                            axis: a.name.clone(),
                            node: a.node,
                            timeout_ms,
                        });
                    }
                }
            }
        }
        if done.iter().all(|d| *d) {
            return Ok(());
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
}

/// Bit 4 cleared, the drives back in their cyclic mode, the axes re-armed.
async fn back_to_cyclic(
    ctl: &mut Controller<'_>,
    drive: &[(usize, i8)],
    mask: u32,
) -> Result<(), HomingError> {
    let s = ctl.snapshot();
    if s.failure.is_some() || s.phase == Some(Phase::Disabled) {
        // The fault stop disabled the drives; enabling again re-arms every axis.
        return Ok(());
    }
    ctl.ask(Request::EndDriveOp(mask)).await?;
    // Bit 4 cleared stops the drive's homing motion; its mode changes once it stands still
    // (statusword bit 10, target reached, in homing mode: CiA 402-2's "interrupted" or
    // "error, velocity 0" rows).
    let since = ctl.snapshot().cycle;
    ctl.wait_for(
        "standstill after homing",
        Duration::from_secs(3),
        false,
        |s| {
            s.cycle > since + 1
                && drive.iter().all(|(i, _)| {
                    s.axes[*i]
                        .statusword
                        .is_some_and(|w| w & crate::cia402::statusword::TARGET_REACHED != 0)
                })
        },
    )
    .await?;
    for &(i, _) in drive {
        let mode = ctl.m.axes[i].mode.number();
        set_mode(ctl, i, mode).await?;
    }
    ctl.ask(Request::Rearm(mask)).await?;
    let timeout = drive
        .iter()
        .map(|(i, _)| ctl.m.axes[*i].enable_timeout_ms)
        .max()
        .unwrap_or(1000);
    ctl.wait_for(
        "re-arming after homing",
        Duration::from_millis(u64::from(timeout) + 500),
        false,
        |s| {
            drive
                .iter()
                .all(|(i, _)| s.axes[*i].control == Some(AxisControl::Cyclic))
        },
    )
    .await?;
    Ok(())
}

fn sdo<T>(ctl: &Controller<'_>, i: usize, r: Result<T, GatewayError>) -> Result<T, HomingError> {
    r.map_err(|source| HomingError::Sdo {
        axis: ctl.m.axes[i].name.clone(),
        source: Box::new(source),
    })
}

/// 0x6060 = `mode`, then 0x6061 read until it shows it.
async fn set_mode(ctl: &Controller<'_>, i: usize, mode: i8) -> Result<(), HomingError> {
    let a = &ctl.m.axes[i];
    sdo(
        ctl,
        i,
        ctl.io
            .write(a.node, index::MODES_OF_OPERATION, 0, Value::Integer8(mode))
            .await,
    )?;
    let deadline = tokio::time::Instant::now() + MODE_TIMEOUT;
    loop {
        let found = match sdo(
            ctl,
            i,
            ctl.io
                .read(a.node, index::MODES_DISPLAY, 0, DataType::Integer8)
                .await,
        )? {
            Value::Integer8(v) => v,
            _ => 0,
        };
        if found == mode {
            return Ok(());
        }
        if tokio::time::Instant::now() >= deadline {
            return Err(HomingError::Mode {
                axis: a.name.clone(),
                node: a.node,
                mode,
                found,
            });
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}
