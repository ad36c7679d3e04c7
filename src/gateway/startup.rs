//! Start-up over SDO and NMT, in the order CiA 301/402 ask for (see the checklist):
//! reset communication, boot-ups, identity, position actual (every axis inside its travel, and
//! the caller's check of the motion from there), heartbeats, the machine file's writes, limits,
//! PDO remap with read-back, SYNC, mode (confirmed by 0x6061), IP period, NMT start.
//!
//! Nothing is written to a drive before every axis is known to stand inside its travel: the
//! software position limits (0x607D) written to a drive outside them make it pull towards them
//! as soon as it is enabled, uncommanded.

use std::time::Duration;

use canopen_rs::{DataType, Value};

use super::GatewayError;
use super::io::NodeIo;
use crate::bus::Bus;
use crate::canopen::index;
use crate::canopen::nmt;
use crate::config::machine::ip_time_period;
use crate::config::{AxisConfig, Machine, PdoConfig};

/// The entry of the drives' consumer heartbeat time (0x1016) that start-up writes with the
/// gateway's heartbeat, and the orderly end switches off ([`stop_consuming_heartbeat`]).
pub const HEARTBEAT_CONSUMER_SUB: u8 = 1;

/// How long the drives have to boot after reset communication.
pub const BOOT_TIMEOUT: Duration = Duration::from_secs(3);

async fn write(io: &NodeIo, node: u8, index: u16, sub: u8, v: Value) -> Result<(), GatewayError> {
    io.write(node, index, sub, v).await
}

async fn write_checked(
    io: &NodeIo,
    node: u8,
    index: u16,
    sub: u8,
    v: Value,
) -> Result<(), GatewayError> {
    io.write(node, index, sub, v).await?;
    let back = io.read(node, index, sub, v.data_type()).await?;
    if back != v {
        return Err(GatewayError::ReadBack {
            node,
            index,
            sub,
            written: format!("{v:?}"),
            found: format!("{back:?}"),
        });
    }
    Ok(())
}

/// CiA 301 §7.5.2.35–38: COB-ID invalid, mapping count 0, entries, count, COB-ID valid; then
/// read everything back.
async fn remap(
    io: &NodeIo,
    node: u8,
    comm: u16,
    map: u16,
    pdo: &PdoConfig,
) -> Result<(), GatewayError> {
    let cob = u32::from(pdo.cob_id);
    write(io, node, comm, 1, Value::Unsigned32(cob | 0x8000_0000)).await?;
    write(io, node, map, 0, Value::Unsigned8(0)).await?;
    for (i, e) in pdo.mapping.iter().enumerate() {
        write(io, node, map, i as u8 + 1, Value::Unsigned32(e.to_u32())).await?;
    }
    write(io, node, map, 0, Value::Unsigned8(pdo.mapping.len() as u8)).await?;
    write(io, node, comm, 2, Value::Unsigned8(pdo.transmission)).await?;
    write(io, node, comm, 1, Value::Unsigned32(cob)).await?;
    // Read back.
    let checks = [
        (comm, 1u8, Value::Unsigned32(cob)),
        (comm, 2, Value::Unsigned8(pdo.transmission)),
        (map, 0, Value::Unsigned8(pdo.mapping.len() as u8)),
    ];
    for (idx, sub, want) in checks.into_iter().chain(
        pdo.mapping
            .iter()
            .enumerate()
            .map(|(i, e)| (map, i as u8 + 1, Value::Unsigned32(e.to_u32()))),
    ) {
        let got = io.read(node, idx, sub, want.data_type()).await?;
        if got != want {
            return Err(GatewayError::ReadBack {
                node,
                index: idx,
                sub,
                written: format!("{want:?}"),
                found: format!("{got:?}"),
            });
        }
    }
    Ok(())
}

/// Disable a PDO we do not use (bit 31 of its COB-ID), so only configured process data runs.
async fn disable_pdo(io: &NodeIo, node: u8, comm: u16) -> Result<(), GatewayError> {
    let cob = io.read_u32(node, comm, 1).await?;
    if cob & 0x8000_0000 == 0 {
        write(io, node, comm, 1, Value::Unsigned32(cob | 0x8000_0000)).await?;
    }
    Ok(())
}

async fn check_identity(io: &NodeIo, a: &AxisConfig) -> Result<(), GatewayError> {
    let id = a.dictionary.identity;
    for (index, sub, object, expected) in [
        (0x1000u16, 0u8, "device type 0x1000", id.device_type),
        (index::IDENTITY, 1, "vendor-ID 0x1018:1", id.vendor_id),
        (index::IDENTITY, 2, "product code 0x1018:2", id.product_code),
        (index::IDENTITY, 3, "revision 0x1018:3", id.revision),
    ] {
        let found = io.read_u32(a.node, index, sub).await?;
        if found != expected {
            return Err(GatewayError::WrongIdentity {
                axis: a.name.clone(),
                node: a.node,
                object,
                expected,
                found,
                dictionary: a.dictionary.file.display().to_string(),
            });
        }
    }
    Ok(())
}

async fn configure_axis(io: &NodeIo, m: &Machine, a: &AxisConfig) -> Result<(), GatewayError> {
    let n = a.node;
    // Heartbeats: the drive produces, and consumes the gateway's.
    let hb = &m.heartbeat;
    write_checked(
        io,
        n,
        index::PRODUCER_HEARTBEAT_TIME,
        0,
        Value::Unsigned16(hb.drive_producer_ms),
    )
    .await?;
    // Written at every start-up, before NMT start: the orderly end of the last run switched it
    // off ([`stop_consuming_heartbeat`]), and a drive must watch the gateway before it moves.
    let consumer = (u32::from(hb.gateway_node) << 16) | u32::from(hb.drive_consumer_ms);
    write_checked(
        io,
        n,
        index::CONSUMER_HEARTBEAT_TIME,
        HEARTBEAT_CONSUMER_SUB,
        Value::Unsigned32(consumer),
    )
    .await?;
    // The machine file's own writes.
    for w in &a.sdo {
        write_checked(io, n, w.index, w.sub, w.value).await?;
    }
    // Limits in the drive's units.
    let counts = |mm: f64| a.mm_to_counts(mm);
    write_checked(
        io,
        n,
        index::FOLLOWING_ERROR_WINDOW,
        0,
        Value::Unsigned32(counts(a.following_error_mm).unsigned_abs()),
    )
    .await?;
    write_checked(
        io,
        n,
        index::FOLLOWING_ERROR_TIMEOUT,
        0,
        Value::Unsigned16(a.following_error_timeout_ms),
    )
    .await?;
    write_checked(
        io,
        n,
        index::SOFTWARE_POSITION_LIMIT,
        1,
        Value::Integer32(counts(a.min_mm)),
    )
    .await?;
    write_checked(
        io,
        n,
        index::SOFTWARE_POSITION_LIMIT,
        2,
        Value::Integer32(counts(a.max_mm)),
    )
    .await?;
    // The drive's own velocity limit, with head-room for its position loop to catch up.
    // (The machine file's validation keeps it within UNSIGNED32.)
    let vmax = (a.max_vel_mm_s * a.counts_per_mm * crate::config::machine::DRIVE_VELOCITY_HEADROOM)
        .ceil() as u32;
    write_checked(
        io,
        n,
        index::MAX_PROFILE_VELOCITY,
        0,
        Value::Unsigned32(vmax),
    )
    .await?;
    // Process data: our two PDOs, every other one off.
    let rx = a.setpoint_pdo.number;
    let tx = a.feedback_pdo.number;
    for k in 1..=4u8 {
        if k != rx {
            disable_pdo(io, n, index::RPDO_COMMUNICATION + u16::from(k - 1)).await?;
        }
        if k != tx {
            disable_pdo(io, n, index::TPDO_COMMUNICATION + u16::from(k - 1)).await?;
        }
    }
    remap(
        io,
        n,
        index::RPDO_COMMUNICATION + u16::from(rx - 1),
        index::RPDO_MAPPING + u16::from(rx - 1),
        &a.setpoint_pdo,
    )
    .await?;
    remap(
        io,
        n,
        index::TPDO_COMMUNICATION + u16::from(tx - 1),
        index::TPDO_MAPPING + u16::from(tx - 1),
        &a.feedback_pdo,
    )
    .await?;
    // SYNC consumer settings (the gateway produces SYNC).
    write_checked(
        io,
        n,
        index::COB_ID_SYNC,
        0,
        Value::Unsigned32(u32::from(m.sync_cob_id)),
    )
    .await?;
    write_checked(
        io,
        n,
        index::COMMUNICATION_CYCLE_PERIOD,
        0,
        Value::Unsigned32(m.cycle_us),
    )
    .await?;
    write_checked(
        io,
        n,
        index::SYNC_WINDOW_LENGTH,
        0,
        Value::Unsigned32(m.sync_window_us),
    )
    .await?;
    // Interpolation: linear sub-mode, period = SYNC period.
    let (v, idx) = ip_time_period(m.cycle_us).expect("validated");
    write_checked(io, n, index::IP_SUBMODE, 0, Value::Integer16(0)).await?;
    write_checked(io, n, index::IP_TIME_PERIOD, 1, Value::Unsigned8(v)).await?;
    write_checked(io, n, index::IP_TIME_PERIOD, 2, Value::Integer8(idx)).await?;
    // Mode, confirmed by 0x6061.
    let mode = a.mode.number();
    write(io, n, index::MODES_OF_OPERATION, 0, Value::Integer8(mode)).await?;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(1);
    loop {
        let found = match io
            .read(n, index::MODES_DISPLAY, 0, DataType::Integer8)
            .await?
        {
            Value::Integer8(v) => v,
            _ => -1,
        };
        if found == mode {
            break;
        }
        if tokio::time::Instant::now() > deadline {
            return Err(GatewayError::ModeNotConfirmed {
                axis: a.name.clone(),
                node: n,
                mode,
                found,
            });
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    Ok(())
}

/// Refuses a start with an axis outside its travel (`counts`: position actual per axis, machine
/// order).
pub fn check_in_travel(m: &Machine, counts: &[i32]) -> Result<(), GatewayError> {
    for (a, &c) in m.axes.iter().zip(counts) {
        let position_mm = a.counts_to_mm(c);
        if !(a.min_mm..=a.max_mm).contains(&position_mm) {
            return Err(GatewayError::StartOutsideTravel {
                axis: a.name.clone(),
                node: a.node,
                position_mm,
                min_mm: a.min_mm,
                max_mm: a.max_mm,
            });
        }
    }
    Ok(())
}

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
    let nodes: Vec<u8> = m.axes.iter().map(|a| a.node).collect();
    io.clear_bootups();
    for &n in &nodes {
        io.nmt(nmt::RESET_COMMUNICATION, n).await?;
    }
    let missing = io.wait_bootups(&nodes, BOOT_TIMEOUT).await;
    if !missing.is_empty() {
        return Err(GatewayError::MissingNodes {
            missing: m
                .axes
                .iter()
                .filter(|a| missing.contains(&a.node))
                .map(|a| format!("axis {} (node {})", a.name, a.node))
                .collect(),
            timeout_ms: BOOT_TIMEOUT.as_millis() as u64,
            bus: bus.name().to_string(),
        });
    }
    io.clear_bootups();
    // The gateway's heartbeat runs before the drives start consuming it.
    io.start_heartbeat(
        m.heartbeat.gateway_node,
        Duration::from_millis(u64::from(m.heartbeat.gateway_producer_ms)),
    );
    let mut pos = Vec::new();
    for a in &m.axes {
        check_identity(io, a).await?;
        pos.push(
            match io
                .read(a.node, index::POSITION_ACTUAL, 0, DataType::Integer32)
                .await?
            {
                Value::Integer32(v) => v,
                _ => 0,
            },
        );
    }
    if let Err(e) = check_in_travel(m, &pos).and_then(|()| check(&pos)) {
        for &n in &nodes {
            let _ = io.nmt(nmt::PRE_OPERATIONAL, n).await;
        }
        return Err(e);
    }
    for a in &m.axes {
        configure_axis(io, m, a).await?;
    }
    for &n in &nodes {
        io.nmt(nmt::START, n).await?;
    }
    Ok(pos)
}

/// The orderly end, once every drive is disabled and before the gateway's heartbeat stops: every
/// drive stops consuming it (0x1016:[`HEARTBEAT_CONSUMER_SUB`] = 0, read back). Heartbeat
/// consumption goes on in Pre-operational (CiA 301 §7.2.8.3.2.2), so without this every drive
/// would report a heartbeat loss (EMCY 0x8130, and Fault with 0x6007 = 1) some 0.5 s after a
/// clean run. Not after a fault stop: the drives keep watching, so that a drive still stops by
/// itself should the gateway die next. The next start-up writes the entry again.
pub async fn stop_consuming_heartbeat(m: &Machine, io: &NodeIo) -> Result<(), GatewayError> {
    for a in &m.axes {
        write_checked(
            io,
            a.node,
            index::CONSUMER_HEARTBEAT_TIME,
            HEARTBEAT_CONSUMER_SUB,
            Value::Unsigned32(0),
        )
        .await
        .map_err(|source| GatewayError::HeartbeatStillConsumed {
            axis: a.name.clone(),
            node: a.node,
            source: Box::new(source),
        })?;
    }
    Ok(())
}
