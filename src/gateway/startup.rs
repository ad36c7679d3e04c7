//! The driver of [`crate::master::startup`] on tokio: it feeds the sans-I/O [`Sequence`] the
//! boot-ups and SDO answers of the drives from a bus port of its own, wakes it at its deadlines,
//! sends what it pushes, starts the gateway's heartbeat when it asks, and maps its typed errors
//! to [`GatewayError`]. What is sent, in which order, and why, is the state machine's (see its
//! documentation); the tests of that run on a virtual clock (`tests/master_startup.rs`).

use std::time::Duration;

use super::GatewayError;
use super::io::NodeIo;
use crate::bus::{AsyncPort, Bus, Filter, Frame};
use crate::canopen::cob;
use crate::config::Machine;
use crate::master::startup::{Sequence, StartupError, Step};

pub use crate::master::startup::{BOOT_TIMEOUT, HEARTBEAT_CONSUMER_SUB};

/// Bring every axis's drive to Operational, configured. Returns position actual per axis.
///
/// Before anything is written to a drive, position actual (0x6064) of every axis is read: an
/// axis outside its travel refuses the start ([`GatewayError::StartOutsideTravel`]), and so does
/// `check` (the motion from there, given position actual per axis). On a refusal the drives are
/// left as their boot-up left them: Pre-operational, disabled, with their own settings.
pub async fn start(
    m: &Machine,
    bus: &Bus,
    io: &mut NodeIo,
    check: impl FnOnce(&[i32]) -> Result<(), GatewayError>,
) -> Result<Vec<i32>, GatewayError> {
    let mut seq = Sequence::start_up(m);
    drive(&mut seq, m, bus, io, Some(check)).await?;
    Ok(seq.positions().to_vec())
}

/// The orderly end, once every drive is disabled and before the gateway's heartbeat stops: every
/// drive stops consuming it ([`Sequence::orderly_end`], which says why). Not after a fault stop.
pub async fn stop_consuming_heartbeat(
    m: &Machine,
    bus: &Bus,
    io: &mut NodeIo,
) -> Result<(), GatewayError> {
    let mut seq = Sequence::orderly_end(m);
    drive(
        &mut seq,
        m,
        bus,
        io,
        None::<fn(&[i32]) -> Result<(), GatewayError>>,
    )
    .await
}

/// Runs `seq` to its end on `bus` (its time: a tokio instant taken now, plus the sequence's
/// `Duration`s).
async fn drive(
    seq: &mut Sequence<'_>,
    m: &Machine,
    bus: &Bus,
    io: &mut NodeIo,
    mut check: Option<impl FnOnce(&[i32]) -> Result<(), GatewayError>>,
) -> Result<(), GatewayError> {
    // The drives' boot-ups and SDO answers.
    let filters: Vec<Filter> = m
        .axes
        .iter()
        .flat_map(|a| {
            let n = u16::from(a.node);
            [
                Filter::exact(cob::SDO_TX + n),
                Filter::exact(cob::HEARTBEAT + n),
            ]
        })
        .collect();
    let mut port = bus.open_async(&filters)?;
    let epoch = tokio::time::Instant::now();
    let mut out: Vec<Frame> = Vec::new();
    let mut step = seq.poll(Duration::ZERO, &mut out);
    loop {
        if let Step::Done(result) = step {
            // What the sequence pushed last (NMT start; or, on its way out, an SDO abort, NMT
            // Pre-operational): a failure to send it matters only when all went well.
            let sent = send_all(&port, &mut out).await;
            return match result {
                Ok(()) => sent,
                Err(e) => Err(gateway_error(e, bus.name())),
            };
        }
        send_all(&port, &mut out).await?;
        step = match step {
            Step::Pending { poll_at } => {
                tokio::select! {
                    r = port.recv() => {
                        let f = r?;
                        seq.on_frame(epoch.elapsed(), &f, &mut out)
                    }
                    () = tokio::time::sleep_until(epoch + poll_at) => {
                        seq.poll(epoch.elapsed().max(poll_at), &mut out)
                    }
                }
            }
            Step::StartHeartbeat { node, period } => {
                io.start_heartbeat(node, period);
                seq.poll(epoch.elapsed(), &mut out)
            }
            Step::CheckPositions => match check.take().map_or(Ok(()), |c| c(seq.positions())) {
                Ok(()) => seq.proceed(epoch.elapsed(), &mut out),
                Err(e) => {
                    seq.refuse(&mut out);
                    let _ = send_all(&port, &mut out).await;
                    return Err(e);
                }
            },
            Step::Done(_) => unreachable!("returned above"),
        };
    }
}

async fn send_all(port: &AsyncPort, out: &mut Vec<Frame>) -> Result<(), GatewayError> {
    for f in out.drain(..) {
        port.send(&f).await?;
    }
    Ok(())
}

/// A start-up error as the run reports it (`bus`: the bus's name, for a missing node).
fn gateway_error(e: StartupError, bus: &str) -> GatewayError {
    match e {
        StartupError::MissingNodes { missing, timeout } => GatewayError::MissingNodes {
            missing: missing.iter().map(ToString::to_string).collect(),
            timeout_ms: timeout.as_millis() as u64,
            bus: bus.to_string(),
        },
        StartupError::WrongIdentity {
            axis,
            node,
            object,
            expected,
            found,
            dictionary,
        } => GatewayError::WrongIdentity {
            axis,
            node,
            object,
            expected,
            found,
            dictionary,
        },
        StartupError::Sdo {
            node,
            index,
            sub,
            error,
        } => GatewayError::from_sdo(node, index, sub, error),
        StartupError::SdoLength {
            node,
            index,
            sub,
            data_type,
            len,
        } => GatewayError::SdoLength {
            node,
            index,
            sub,
            data_type,
            len,
        },
        StartupError::ReadBack {
            node,
            index,
            sub,
            written,
            found,
        } => GatewayError::ReadBack {
            node,
            index,
            sub,
            written: format!("{written:?}"),
            found: format!("{found:?}"),
        },
        StartupError::ModeNotConfirmed {
            axis,
            node,
            mode,
            found,
        } => GatewayError::ModeNotConfirmed {
            axis,
            node,
            mode,
            found,
        },
        StartupError::OutsideTravel {
            axis,
            node,
            position_mm,
            min_mm,
            max_mm,
        } => GatewayError::StartOutsideTravel {
            axis,
            node,
            position_mm,
            min_mm,
            max_mm,
        },
        StartupError::HeartbeatStillConsumed { axis, node, source } => {
            GatewayError::HeartbeatStillConsumed {
                axis,
                node,
                source: Box::new(gateway_error(*source, bus)),
            }
        }
        // Only after the caller's refusal, which returns its own error.
        StartupError::Refused => GatewayError::Resume(e.to_string()),
    }
}
