//! Machine files: the bus, SYNC and heartbeat settings, and the axes with their drives.
//!
//! See `dictionaries/machines/demo-xyz.toml` for a commented example. Paths of drive
//! dictionaries are relative to the machine file.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use canopen_rs::Value;
use serde::Deserialize;

use super::{ConfigError, parse_toml};
use crate::canopen::dictionary::{DriveDictionary, int_value, type_name, value_as_i128};
use crate::canopen::index;
use crate::interpolator::filter::{AxisFilter, FilterKind, FilterSpec};
use crate::planner::{AXIS_FILTER_RANGE_S, MAX_LIMIT};

use super::operation::{AxisLimits, RawHoming, RawOperation, RawSim};
pub use super::operation::{
    DEFAULT_CONTROL_SOCKET, DEFAULT_HOMING_TIMEOUT_MS, DEFAULT_JOG_TIMEOUT_MS,
    DEFAULT_UNHOMED_JOG_FRACTION, HOMING_TIMEOUT_MS, HomingConfig, HomingMethod, JOG_TIMEOUT_MS,
    OperationConfig, SimOptions,
};

/// The most axes a machine may have.
pub const MAX_AXES: usize = 8;

/// Axis letters a machine file may use (RS274: linear X Y Z, rotary A B C, secondary linear U V W).
pub const AXIS_LETTERS: [&str; 9] = ["X", "Y", "Z", "A", "B", "C", "U", "V", "W"];

/// The demo machine file, embedded so that `canmotion run` works with no files at all.
pub const DEMO_MACHINE: &str = include_str!("../../dictionaries/machines/demo-xyz.toml");
/// The drive dictionary the demo machine names.
pub const DEMO_DRIVE: &str = include_str!("../../dictionaries/drives/cia402-servo.toml");
/// The demo machine's tool table.
pub const DEMO_TOOLS: &str = include_str!("../../dictionaries/tools/demo-tools.toml");
/// Where the embedded demo tool table lives in the source tree (for messages).
pub const DEMO_TOOLS_PATH: &str = "dictionaries/tools/demo-tools.toml";
/// Where the embedded demo machine file lives in the source tree (for messages).
pub const DEMO_MACHINE_PATH: &str = "dictionaries/machines/demo-xyz.toml";

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMachine {
    machine: RawMeta,
    bus: RawBus,
    sync: RawSync,
    heartbeat: RawHeartbeat,
    axis: Vec<RawAxis>,
    #[serde(default)]
    program: RawProgram,
    #[serde(default)]
    planner: RawPlanner,
    #[serde(default)]
    operation: RawOperation,
}

/// `[planner]`: how the look-ahead joins elements and shapes speed (all keys optional).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlanner {
    profile: Option<crate::planner::ProfileKind>,
    corner_acc_mm_s2: Option<f64>,
    path_acc_share: Option<f64>,
    path_acc_mm_s2: Option<f64>,
    chord_tol_mm: Option<f64>,
    default_tolerance_mm: Option<f64>,
    lookahead: Option<usize>,
    #[serde(default)]
    integer_periods: bool,
    axis_filter_ms: Option<f64>,
}

/// `[program]`: how programs are interpreted on this machine (all keys optional).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProgram {
    tool_table: Option<String>,
    #[serde(default)]
    loaded_tool: u32,
    g28_mm: Option<Vec<f64>>,
    g30_mm: Option<Vec<f64>>,
    #[serde(default)]
    work_offsets_mm: std::collections::BTreeMap<String, Vec<f64>>,
    #[serde(default)]
    outside_corners: crate::compensation::OutsideCorners,
    #[serde(default)]
    subroutine_path: Vec<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMeta {
    name: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBus {
    interface: String,
    bitrate: u32,
    cycle_us: u32,
    #[serde(default = "default_max_load")]
    max_load_percent: f64,
}

fn default_max_load() -> f64 {
    70.0
}

/// Worst-case length in bits of a classic CAN data frame with an 11-bit identifier and `n` data
/// bytes, stuff bits and the 3-bit intermission included (Davis et al. 2007):
/// `C(n) = 8n + 47 + ⌊(34 + 8n − 1)/4⌋`, so C(0) = 55, C(6) = 115, C(8) = 135.
pub fn frame_bits(n: usize) -> u32 {
    let n = n as u32;
    8 * n + 47 + (34 + 8 * n - 1) / 4
}

/// The bus time one cycle's process data needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BusLoad {
    /// SYNC frame, bits.
    pub sync_bits: u32,
    /// Every axis's RPDO and TPDO, bits.
    pub pdo_bits: u32,
    /// Bits available in one cycle (bit rate × period).
    pub cycle_bits: f64,
    /// `(sync_bits + pdo_bits) / cycle_bits`, percent.
    pub percent: f64,
    /// Time to carry SYNC and all PDOs, µs: the shortest synchronous window (0x1007) that holds them.
    pub carry_us: f64,
}

/// How many axes fit in a cycle at `load_percent`, each with an RPDO and a TPDO of `pdo_bytes`:
/// `N = ⌊(U·R·T − C_sync)/(C_rpdo + C_tpdo)⌋`.
pub fn max_axes(bitrate: u32, cycle_us: u32, pdo_bytes: usize, load_percent: f64) -> u32 {
    let avail = load_percent / 100.0 * f64::from(bitrate) * f64::from(cycle_us) * 1e-6;
    let n = (avail - f64::from(frame_bits(0))) / f64::from(2 * frame_bits(pdo_bytes));
    n.max(0.0).floor() as u32
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSync {
    cob_id: u16,
    window_us: u32,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHeartbeat {
    gateway_node: u8,
    gateway_producer_ms: u16,
    drive_consumer_ms: u16,
    drive_producer_ms: u16,
    gateway_consumer_ms: u16,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAxis {
    name: String,
    node: u8,
    dictionary: PathBuf,
    mode: AxisMode,
    #[serde(default)]
    kind: AxisKind,
    /// Read as `counts_per_mm` (linear) or `counts_per_deg` (rotary); filled in by
    /// [`resolve_kind`].
    #[serde(skip)]
    counts_per_mm: f64,
    #[serde(rename = "counts_per_mm")]
    counts_per_mm_key: Option<f64>,
    counts_per_deg: Option<f64>,
    #[serde(default)]
    wrap: RawWrap,
    /// Read from `wrap` by [`resolve_kind`].
    #[serde(skip)]
    wrapped: bool,
    #[serde(skip)]
    wrap_shortest: bool,
    min_mm: f64,
    max_mm: f64,
    max_vel_mm_s: f64,
    max_acc_mm_s2: f64,
    max_jerk_mm_s3: f64,
    following_error_mm: f64,
    following_error_timeout_ms: u16,
    #[serde(default = "default_enable_timeout_ms")]
    enable_timeout_ms: u32,
    setpoint_pdo: RawPdo,
    feedback_pdo: RawPdo,
    #[serde(default)]
    sdo: Vec<RawSdo>,
    #[serde(default)]
    filter: Option<RawFilter>,
    #[serde(default)]
    homing: Option<RawHoming>,
    #[serde(default)]
    sim: RawSim,
}

/// `filter = { kind = "linear", time_ms = 8 }`: the axis's post-interpolation filter.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFilter {
    kind: FilterKind,
    time_ms: f64,
}

fn default_enable_timeout_ms() -> u32 {
    DEFAULT_ENABLE_TIMEOUT_MS
}

/// `[axis] enable_timeout_ms` when the file gives none: how long the drive has to reach
/// Operation enabled, and then to set statusword bit 12 (IP active / following).
pub const DEFAULT_ENABLE_TIMEOUT_MS: u32 = 2000;
/// The bounds of `enable_timeout_ms`. CiA 402 sets no limit; drives with a brake to release or a
/// commutation to find take seconds, and a minute is beyond any of them.
pub const ENABLE_TIMEOUT_MS: std::ops::RangeInclusive<u32> = 1..=60_000;

/// The longest post-interpolation filter a machine file may ask for.
pub const MAX_FILTER_MS: f64 = 1000.0;

/// The fewest counts an axis's travel may span: an encoder that cannot tell this many positions
/// apart over the whole travel cannot position the axis (`counts_per_mm = 0.001` turned a
/// 100 mm move into no motion at all, and the run still ended well).
pub const MIN_TRAVEL_COUNTS: f64 = 1000.0;
/// The narrowest following-error window, counts (0x6065): setpoint and position actual are
/// each rounded to a count, so a window of a few counts trips on rounding alone, and one that
/// rounds to 0 trips at once.
pub const MIN_FOLLOWING_ERROR_COUNTS: f64 = 10.0;
/// The bound on the following-error window, counts, which a window must stay below: the largest
/// value the gateway writes to 0x6065 (an INTEGER32 position difference); a wider window would
/// be clamped to it, and a window that wide supervises nothing.
pub const MAX_FOLLOWING_ERROR_COUNTS: f64 = i32::MAX as f64;
/// The smallest axis limit (`max_vel_mm_s`, `max_acc_mm_s2`, `max_jerk_mm_s3`) and path
/// acceleration a machine file may give. The planner honours limits within
/// [`crate::planner::profile::MIN_LIMIT`]`..=`[`crate::planner::MAX_LIMIT`] after scaling by
/// `path_acc_share` (at least [`MIN_PATH_ACC_SHARE`]); below, it would clamp them silently.
pub const MIN_AXIS_LIMIT: f64 = 1.0e-3;
/// The smallest `path_acc_share`.
pub const MIN_PATH_ACC_SHARE: f64 = 1.0e-3;
const _: () = assert!(MIN_AXIS_LIMIT * MIN_PATH_ACC_SHARE >= crate::planner::profile::MIN_LIMIT);
/// Head-room of the drive's own velocity limit (0x607F) over `max_vel_mm_s`, for its position
/// loop to catch up.
pub const DRIVE_VELOCITY_HEADROOM: f64 = 1.5;

/// Objects the gateway writes itself (at start-up or every cycle), or that decide how a drive
/// reacts to a lost gateway: a machine file's `sdo` entry may not write them, since the value
/// would override the machine file's own keys or switch off supervision. (first index, last
/// index, what it is, why the gateway owns it).
pub const GATEWAY_OWNED: &[(u16, u16, &str, &str)] = &[
    (
        index::COB_ID_SYNC,
        index::SYNC_WINDOW_LENGTH,
        "SYNC COB-ID, period and window",
        "written from [sync] and [bus] cycle_us",
    ),
    (
        index::COB_ID_EMCY,
        index::INHIBIT_TIME_EMCY,
        "EMCY COB-ID and inhibit time",
        "the gateway listens to EMCYs at 0x80 + node, undelayed",
    ),
    (
        index::CONSUMER_HEARTBEAT_TIME,
        index::CONSUMER_HEARTBEAT_TIME,
        "heartbeat consumer",
        "written from [heartbeat] gateway_node and drive_consumer_ms",
    ),
    (
        index::PRODUCER_HEARTBEAT_TIME,
        index::PRODUCER_HEARTBEAT_TIME,
        "heartbeat producer",
        "written from [heartbeat] drive_producer_ms",
    ),
    (
        index::SYNC_COUNTER_OVERFLOW,
        index::SYNC_COUNTER_OVERFLOW,
        "SYNC counter overflow",
        "the gateway's SYNC carries no counter",
    ),
    (
        index::ERROR_BEHAVIOUR,
        index::ERROR_BEHAVIOUR,
        "error behaviour",
        "decides the drive's reaction to a lost gateway",
    ),
    (
        index::RPDO_COMMUNICATION,
        index::PDO_PARAMETERS_LAST,
        "PDO communication and mapping",
        "written from setpoint_pdo and feedback_pdo",
    ),
    (
        index::ABORT_CONNECTION_OPTION,
        index::ABORT_CONNECTION_OPTION,
        "abort connection option",
        "decides the drive's reaction to a lost gateway",
    ),
    (
        index::CONTROLWORD,
        index::CONTROLWORD,
        "controlword",
        "written every cycle",
    ),
    (
        index::MODES_OF_OPERATION,
        index::MODES_OF_OPERATION,
        "modes of operation",
        "written from mode",
    ),
    (
        index::FOLLOWING_ERROR_WINDOW,
        index::FOLLOWING_ERROR_TIMEOUT,
        "following error window and time-out",
        "written from following_error_mm and following_error_timeout_ms",
    ),
    (
        index::TARGET_POSITION,
        index::TARGET_POSITION,
        "target position",
        "written every cycle",
    ),
    (
        index::HOME_OFFSET,
        index::HOME_OFFSET,
        "home offset",
        "written from [axis.homing] offset_mm",
    ),
    (
        index::SOFTWARE_POSITION_LIMIT,
        index::SOFTWARE_POSITION_LIMIT,
        "software position limits",
        "written from min_mm and max_mm",
    ),
    (
        index::HOMING_METHOD,
        index::HOMING_ACCELERATION,
        "homing method, speeds and acceleration",
        "written from [axis.homing]",
    ),
    (
        index::MAX_PROFILE_VELOCITY,
        index::MAX_PROFILE_VELOCITY,
        "max profile velocity",
        "written from max_vel_mm_s",
    ),
    (
        index::IP_SUBMODE,
        index::IP_TIME_PERIOD,
        "interpolation sub-mode, data and period",
        "written from mode and [bus] cycle_us, and every cycle",
    ),
];

/// CAN-IDs CiA 301 (§7.3.5, restricted CAN-IDs) reserves: no configurable object, SYNC
/// included, may use them. They hold NMT, every node's default SDO channels and heartbeats.
pub const RESTRICTED_CAN_IDS: &[(u16, u16, &str)] = &[
    (0x000, 0x000, "NMT"),
    (0x001, 0x07F, "reserved"),
    (0x101, 0x180, "reserved"),
    (0x581, 0x5FF, "default SDO (server to client)"),
    (0x601, 0x67F, "default SDO (client to server)"),
    (0x6E0, 0x6FF, "reserved"),
    (0x701, 0x77F, "NMT error control (heartbeat, boot-up)"),
    (0x780, 0x7FF, "reserved"),
];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPdo {
    number: u8,
    transmission: u8,
    mapping: Vec<u32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSdo {
    index: u16,
    #[serde(default)]
    sub: u8,
    value: toml::Value,
}

/// What an axis moves: a slide (mm) or a rotary table or head (degrees).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AxisKind {
    /// Millimetres: `counts_per_mm`, and the `_mm` keys in mm.
    #[default]
    Linear,
    /// Degrees (A, B, C only): `counts_per_deg`, and the `_mm` keys read in degrees
    /// (`min_mm`/`max_mm` deg, `max_vel_mm_s` deg/s, `max_acc_mm_s2` deg/s², `max_jerk_mm_s3`
    /// deg/s³, `following_error_mm` deg).
    Rotary,
}

/// `wrap`: `false` (the default), `true` (LinuxCNC's WRAPPED_ROTARY: a G90 word's sign gives
/// the direction) or `"shortest"` (a G90 position the shortest way round).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(untagged)]
enum RawWrap {
    #[default]
    #[serde(skip)]
    Unset,
    Flag(bool),
    Rule(String),
}

/// Checks `kind`, the counts key that goes with it and `wrap`, and fills in the axis's counts
/// per unit (mm or degree).
fn resolve_kind(ctx: &Ctx, table: &str, a: &mut RawAxis) -> Result<(), ConfigError> {
    let rotary_letter = matches!(a.name.as_str(), "A" | "B" | "C");
    let counts = match a.kind {
        AxisKind::Rotary if !rotary_letter => {
            return Err(ctx.err(
                table,
                "kind",
                format!(
                    "\"rotary\" is for the A, B and C axes; {} is linear",
                    a.name
                ),
            ));
        }
        AxisKind::Rotary => {
            if a.counts_per_mm_key.is_some() {
                return Err(ctx.err(
                    table,
                    "counts_per_mm",
                    "a rotary axis gives counts_per_deg (counts per degree), not counts_per_mm",
                ));
            }
            a.counts_per_deg.ok_or_else(|| {
                ctx.err(
                    table,
                    "counts_per_deg",
                    "a rotary axis needs counts_per_deg",
                )
            })?
        }
        AxisKind::Linear => {
            if a.counts_per_deg.is_some() {
                return Err(ctx.err(
                    table,
                    "counts_per_deg",
                    "a linear axis gives counts_per_mm, not counts_per_deg (set kind = \"rotary\" for a rotary A, B or C axis)",
                ));
            }
            a.counts_per_mm_key.ok_or_else(|| {
                ctx.err(table, "counts_per_mm", "a linear axis needs counts_per_mm")
            })?
        }
    };
    (a.wrapped, a.wrap_shortest) = match &a.wrap {
        RawWrap::Unset | RawWrap::Flag(false) => (false, false),
        RawWrap::Flag(true) => (true, false),
        RawWrap::Rule(r) if r == "shortest" => (true, true),
        RawWrap::Rule(r) => {
            return Err(ctx.err(
                table,
                "wrap",
                format!(
                    "{r:?} is no wrap rule: true (LinuxCNC's: the sign of a G90 word gives the direction), \"shortest\" or false"
                ),
            ));
        }
    };
    if a.wrapped && a.kind != AxisKind::Rotary {
        return Err(ctx.err(
            table,
            "wrap",
            "only a rotary axis (kind = \"rotary\") wraps",
        ));
    }
    a.counts_per_mm = counts;
    Ok(())
}

/// The position mode an axis's drive runs in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AxisMode {
    /// Interpolated position (CiA 402 mode 7), linear sub-mode 0, setpoint in 0x60C1:01.
    Ip,
    /// Cyclic synchronous position (mode 8), setpoint in 0x607A.
    Csp,
}

impl AxisMode {
    /// The CiA 402 mode number (0x6060).
    pub fn number(self) -> i8 {
        match self {
            AxisMode::Ip => 7,
            AxisMode::Csp => 8,
        }
    }
    /// The object that carries the position setpoint in this mode.
    pub fn setpoint_object(self) -> (u16, u8) {
        match self {
            AxisMode::Ip => (index::IP_DATA_RECORD, 1),
            AxisMode::Csp => (index::TARGET_POSITION, 0),
        }
    }
}

/// One PDO mapping entry: index, sub-index and length in bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MapEntry {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Length in bits.
    pub bits: u8,
}

impl MapEntry {
    /// Decode `idx<<16 | sub<<8 | bits`.
    pub fn from_u32(v: u32) -> MapEntry {
        MapEntry {
            index: (v >> 16) as u16,
            sub: (v >> 8) as u8,
            bits: v as u8,
        }
    }
    /// Encode as `idx<<16 | sub<<8 | bits`.
    pub fn to_u32(self) -> u32 {
        (u32::from(self.index) << 16) | (u32::from(self.sub) << 8) | u32::from(self.bits)
    }
}

/// A PDO as the gateway configures it on a drive.
#[derive(Debug, Clone)]
pub struct PdoConfig {
    /// PDO number 1–4.
    pub number: u8,
    /// COB-ID from the predefined connection set.
    pub cob_id: u16,
    /// Transmission type (1–240: every n-th SYNC).
    pub transmission: u8,
    /// Mapped objects in frame order.
    pub mapping: Vec<MapEntry>,
}

impl PdoConfig {
    /// Byte offset and entry of `(index, sub)` in the frame.
    pub fn offset_of(&self, index: u16, sub: u8) -> Option<(usize, MapEntry)> {
        let mut off = 0usize;
        for e in &self.mapping {
            if e.index == index && e.sub == sub {
                return Some((off, *e));
            }
            off += usize::from(e.bits / 8);
        }
        None
    }
    /// Frame length in bytes.
    pub fn len_bytes(&self) -> usize {
        self.mapping.iter().map(|e| usize::from(e.bits / 8)).sum()
    }
}

/// An extra SDO write at start-up, typed from the dictionary.
#[derive(Debug, Clone)]
pub struct SdoWrite {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Value, typed as the dictionary says.
    pub value: Value,
}

/// One axis and its drive.
#[derive(Debug, Clone)]
pub struct AxisConfig {
    /// Axis letter (X, Y, Z).
    pub name: String,
    /// CANopen node id of its drive.
    pub node: u8,
    /// The drive's dictionary.
    pub dictionary: Arc<DriveDictionary>,
    /// Position mode.
    pub mode: AxisMode,
    /// Linear (mm) or rotary (degrees: every `_mm` field of the axis is then in degrees).
    pub kind: AxisKind,
    /// A rotary axis whose position wraps at 360° (LinuxCNC's WRAPPED_ROTARY): a G90 word's
    /// magnitude is the position modulo a turn and its sign the direction (LinuxCNC's
    /// `unwrap_rotary`), and its travel limits do not apply.
    pub wrap: bool,
    /// A wrapped axis whose G90 moves take the shortest way instead (`wrap = "shortest"`).
    pub wrap_shortest: bool,
    /// Encoder counts per millimetre (per degree for a rotary axis).
    pub counts_per_mm: f64,
    /// Lower travel limit.
    pub min_mm: f64,
    /// Upper travel limit.
    pub max_mm: f64,
    /// Maximum velocity.
    pub max_vel_mm_s: f64,
    /// Maximum acceleration.
    pub max_acc_mm_s2: f64,
    /// Maximum jerk.
    pub max_jerk_mm_s3: f64,
    /// Following error window (written to 0x6065 in counts).
    pub following_error_mm: f64,
    /// Following error time-out (0x6066).
    pub following_error_timeout_ms: u16,
    /// How long the drive has to reach Operation enabled, and then again to set statusword bit
    /// 12 (IP active / following), ms.
    pub enable_timeout_ms: u32,
    /// The RPDO that carries controlword and setpoint.
    pub setpoint_pdo: PdoConfig,
    /// The TPDO that carries statusword and position actual.
    pub feedback_pdo: PdoConfig,
    /// Extra SDO writes at start-up, in order.
    pub sdo: Vec<SdoWrite>,
    /// The post-interpolation filter on the axis's setpoints (`filter`), if any.
    pub filter: Option<FilterSpec>,
    /// How the axis homes (`[axis.homing]`); `None`: it has no homing, and counts as homed
    /// only where homing is not required (`[operation] require_homing = false`).
    pub homing: Option<HomingConfig>,
    /// Options of the simulated drive (`[axis.sim]`): its start position and switches.
    pub sim: SimOptions,
}

impl AxisConfig {
    /// Index of the axis in the X, Y, Z position vector the motion front end produces; `None`
    /// for the other letters, which hold their position until the front end commands them.
    pub fn xyz(&self) -> Option<usize> {
        match self.name.as_str() {
            "X" => Some(0),
            "Y" => Some(1),
            "Z" => Some(2),
            _ => None,
        }
    }

    /// Index of the axis among the auxiliary axes A B C U V W ([`crate::gcode::AUX_LETTERS`]);
    /// `None` for X, Y and Z.
    pub fn aux(&self) -> Option<usize> {
        crate::gcode::AUX_LETTERS
            .iter()
            .position(|l| self.name.len() == 1 && self.name.starts_with(*l))
    }

    /// Whether the travel limits apply (not on a wrapped rotary axis).
    pub fn has_travel(&self) -> bool {
        !self.wrap
    }

    /// Millimetres to counts (rounded to the nearest count).
    pub fn mm_to_counts(&self, mm: f64) -> i32 {
        (mm * self.counts_per_mm)
            .round()
            .clamp(i32::MIN as f64, i32::MAX as f64) as i32
    }
    /// Counts to millimetres.
    pub fn counts_to_mm(&self, counts: i32) -> f64 {
        f64::from(counts) / self.counts_per_mm
    }
}

/// Heartbeat settings.
#[derive(Debug, Clone, Copy)]
pub struct Heartbeat {
    /// The gateway's own node id (its heartbeat is 0x700 + this).
    pub gateway_node: u8,
    /// How often the gateway sends its heartbeat.
    pub gateway_producer_ms: u16,
    /// The drives' consumer time for the gateway's heartbeat (0x1016:1).
    pub drive_consumer_ms: u16,
    /// The drives' producer time (0x1017).
    pub drive_producer_ms: u16,
    /// How long the gateway waits for a drive's heartbeat before declaring it lost.
    pub gateway_consumer_ms: u16,
}

/// A loaded, validated machine.
#[derive(Debug, Clone)]
pub struct Machine {
    /// The file it came from.
    pub file: PathBuf,
    /// Its name.
    pub name: String,
    /// Default bus interface (`sim` for the in-process bus with simulated drives).
    pub interface: String,
    /// Bit rate (bit/s), for documentation and bus-load figures.
    pub bitrate: u32,
    /// The cycle (SYNC and interpolation) period.
    pub cycle_us: u32,
    /// COB-ID of SYNC (0x1005).
    pub sync_cob_id: u16,
    /// Synchronous window (0x1007), µs.
    pub sync_window_us: u32,
    /// Heartbeat settings.
    pub heartbeat: Heartbeat,
    /// Axes in machine order.
    pub axes: Vec<AxisConfig>,
    /// The bus load limit the machine was admitted under.
    pub max_load_percent: f64,
    /// How programs are interpreted on this machine (`[program]`).
    pub program: ProgramSetup,
    /// How the look-ahead plans (`[planner]`; the period and the jerk limits come from the
    /// bus and the axes).
    pub planner: crate::planner::PlannerConfig,
    /// What `canmotion serve` requires and allows (`[operation]`).
    pub operation: OperationConfig,
}

/// Work offset names in the order of [`crate::gcode::Setup::work_offsets_mm`].
pub const WORK_OFFSETS: [&str; 9] = [
    "G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3",
];

/// The machine's `[program]` table: what the interpreter starts with.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgramSetup {
    /// The tool table file as written (relative to the machine file), if any.
    pub tool_table_file: Option<PathBuf>,
    /// The tool table (empty without `tool_table`); filled by [`Machine::load`] and
    /// [`Machine::demo`], left empty by [`Machine::parse`].
    pub tools: crate::gcode::ToolTable,
    /// Tool in the spindle at the start (0 = none).
    pub loaded_tool: u32,
    /// G28 and G30 positions, machine mm (X, Y, Z).
    pub g28_mm: nalgebra::Vector3<f64>,
    /// See `g28_mm`.
    pub g30_mm: nalgebra::Vector3<f64>,
    /// Origins of G54 … G59.3 in machine mm (see [`WORK_OFFSETS`]).
    pub work_offsets_mm: [nalgebra::Vector3<f64>; 9],
    /// How cutter radius compensation (G41/G42) joins outside corners.
    pub compensation: crate::compensation::CompOptions,
    /// Folders searched in order for subroutine files (`o<name> call` → `name.ngc`), as
    /// written in `subroutine_path`, relative to the machine file's folder.
    pub subroutine_path: Vec<PathBuf>,
    /// The machine file's folder, which `subroutine_path` is relative to.
    pub base_dir: PathBuf,
}

impl Machine {
    /// The interpreter's setup on this machine, starting at `start_mm`.
    pub fn setup(&self, start_mm: nalgebra::Vector3<f64>) -> crate::gcode::Setup {
        let mut setup = crate::gcode::Setup::new(start_mm);
        setup.tools = self.program.tools.clone();
        setup.loaded_tool = self.program.loaded_tool;
        setup.g28_mm = self.program.g28_mm;
        setup.g30_mm = self.program.g30_mm;
        setup.work_offsets_mm = self.program.work_offsets_mm;
        for a in &self.axes {
            if let Some(i) = a.aux() {
                setup.aux_axes[i] = true;
                setup.aux_wrapped[i] = a.wrap;
                setup.aux_shortest[i] = a.wrap_shortest;
            }
        }
        // G5/G5.1 are sampled within the planner's chord tolerance (0 there: no limit on
        // arcs, and the interpreter's default for splines).
        if self.planner.chord_tol_mm >= crate::gcode::MIN_SPLINE_TOL_MM {
            setup.spline_tol_mm = self.planner.chord_tol_mm;
        }
        setup.subroutine_path = self
            .program
            .subroutine_path
            .iter()
            .map(|dir| self.program.base_dir.join(dir))
            .collect();
        setup
    }
}

fn program_setup(ctx: &Ctx, raw: &RawProgram) -> Result<ProgramSetup, ConfigError> {
    let point = |key: &str, v: &[f64]| -> Result<nalgebra::Vector3<f64>, ConfigError> {
        match v {
            [x, y, z] if v.iter().all(|c| c.is_finite() && c.abs() <= 1e9) => {
                Ok(nalgebra::Vector3::new(*x, *y, *z))
            }
            _ => Err(ctx.err(
                "program",
                key,
                format!("{v:?} must be [x, y, z] in mm, finite and at most 1e9 in magnitude"),
            )),
        }
    };
    let mut work_offsets_mm = [nalgebra::Vector3::zeros(); 9];
    for (name, v) in &raw.work_offsets_mm {
        let i = WORK_OFFSETS.iter().position(|w| w == name).ok_or_else(|| {
            ctx.err(
                "program.work_offsets_mm",
                name,
                format!("no such work offset; one of {}", WORK_OFFSETS.join(" ")),
            )
        })?;
        work_offsets_mm[i] = point(&format!("work_offsets_mm.{name}"), v)?;
    }
    if raw.loaded_tool > crate::gcode::MAX_TOOL_NUMBER {
        return Err(ctx.err(
            "program",
            "loaded_tool",
            format!(
                "{} above the largest tool number {}",
                raw.loaded_tool,
                crate::gcode::MAX_TOOL_NUMBER
            ),
        ));
    }
    if raw.loaded_tool != 0 && raw.tool_table.is_none() {
        return Err(ctx.err("program", "loaded_tool", "a loaded tool needs a tool_table"));
    }
    Ok(ProgramSetup {
        tool_table_file: raw.tool_table.as_ref().map(PathBuf::from),
        tools: crate::gcode::ToolTable::new(),
        loaded_tool: raw.loaded_tool,
        g28_mm: raw
            .g28_mm
            .as_deref()
            .map_or(Ok(nalgebra::Vector3::zeros()), |v| point("g28_mm", v))?,
        g30_mm: raw
            .g30_mm
            .as_deref()
            .map_or(Ok(nalgebra::Vector3::zeros()), |v| point("g30_mm", v))?,
        work_offsets_mm,
        compensation: crate::compensation::CompOptions {
            outside_corners: raw.outside_corners,
        },
        subroutine_path: raw
            .subroutine_path
            .iter()
            .map(|dir| {
                if dir.trim().is_empty() {
                    Err(ctx.err(
                        "program",
                        "subroutine_path",
                        "an empty folder name: give folders relative to the machine file, e.g. [\"subs\"]",
                    ))
                } else {
                    Ok(PathBuf::from(dir))
                }
            })
            .collect::<Result<_, _>>()?,
        base_dir: ctx
            .file
            .parent()
            .unwrap_or(Path::new(""))
            .to_path_buf(),
    })
}

/// Default share of each axis's acceleration and jerk the speed profiles may use.
pub const DEFAULT_PATH_ACC_SHARE: f64 = 0.75;
/// Default chord (bow-height) error on arcs, mm (1 µm, as in `shared/seeds` 001).
pub const DEFAULT_CHORD_TOL_MM: f64 = 0.001;
/// Default look-ahead window, elements: 2000 since session 34 (was 1000), so that on chorded
/// curves of 30 µm the window holds the braking distance from near the curve's cap, where it
/// leaves little tangential acceleration (see `src/planner/curve.rs`).
pub const DEFAULT_LOOKAHEAD: usize = 2000;

fn planner_config(
    ctx: &Ctx,
    raw: &RawPlanner,
    machine: &Machine,
) -> Result<crate::planner::PlannerConfig, ConfigError> {
    let mut jerk = nalgebra::Vector3::repeat(f64::INFINITY);
    let mut min_acc = f64::INFINITY;
    let mut aux = crate::planner::AuxLimits::NONE;
    for a in &machine.axes {
        if let Some(i) = a.xyz() {
            jerk[i] = a.max_jerk_mm_s3;
            min_acc = min_acc.min(a.max_acc_mm_s2);
        }
        if let Some(i) = a.aux() {
            aux.max_vel[i] = a.max_vel_mm_s;
            aux.max_acc[i] = a.max_acc_mm_s2;
            aux.max_jerk[i] = a.max_jerk_mm_s3;
        }
    }
    let number = |key: &str, v: Option<f64>, default: f64, ok: &dyn Fn(f64) -> bool, what: &str| {
        let v = v.unwrap_or(default);
        if ok(v) {
            Ok(v)
        } else {
            Err(ctx.err("planner", key, format!("{v} {what}")))
        }
    };
    let config = crate::planner::PlannerConfig {
        period_s: machine.cycle_s(),
        corner_acc_mm_s2: number(
            "corner_acc_mm_s2",
            raw.corner_acc_mm_s2,
            if min_acc.is_finite() { min_acc } else { 0.0 },
            &|v| (0.0..=MAX_LIMIT).contains(&v),
            "must be in 0..=1e9 (0: exact stop at every junction)",
        )?,
        path_acc_share: number(
            "path_acc_share",
            raw.path_acc_share,
            DEFAULT_PATH_ACC_SHARE,
            &|v| (MIN_PATH_ACC_SHARE..=1.0).contains(&v),
            &format!("must be in {MIN_PATH_ACC_SHARE}..=1, the range the planner honours"),
        )?,
        path_acc_mm_s2: number(
            "path_acc_mm_s2",
            raw.path_acc_mm_s2,
            f64::INFINITY,
            &|v| (MIN_AXIS_LIMIT..=MAX_LIMIT).contains(&v) || v == f64::INFINITY,
            &format!("must be in {MIN_AXIS_LIMIT}..={MAX_LIMIT:e}, the range the planner honours"),
        )?,
        max_jerk_mm_s3: jerk,
        profile: raw.profile.unwrap_or_default(),
        chord_tol_mm: number(
            "chord_tol_mm",
            raw.chord_tol_mm,
            DEFAULT_CHORD_TOL_MM,
            &|v| (0.0..=1.0).contains(&v),
            "must be in 0..=1 mm (0: no limit)",
        )?,
        default_tolerance_mm: number(
            "default_tolerance_mm",
            raw.default_tolerance_mm,
            crate::planner::DEFAULT_TOLERANCE_MM,
            &|v| v > 0.0 && v <= 1.0,
            "must be in (0, 1] mm: bare G64 never deviates without limit",
        )?,
        lookahead: match raw.lookahead.unwrap_or(DEFAULT_LOOKAHEAD) {
            n @ 2..=1_000_000 => n,
            n => {
                return Err(ctx.err(
                    "planner",
                    "lookahead",
                    format!("{n} elements must be in 2..=1000000"),
                ));
            }
        },
        integer_periods: raw.integer_periods,
        aux,
        axis_filter_s: match raw.axis_filter_ms {
            None => crate::planner::AXIS_FILTER_S,
            Some(ms) if AXIS_FILTER_RANGE_S.contains(&(ms / 1000.0)) => ms / 1000.0,
            Some(ms) => {
                return Err(ctx.err(
                    "planner",
                    "axis_filter_ms",
                    format!(
                        "{ms} ms must be in {}..={} ms, the filters the planner's vertex and \
                         corner rules are made for",
                        1000.0 * AXIS_FILTER_RANGE_S.start(),
                        1000.0 * AXIS_FILTER_RANGE_S.end()
                    ),
                ));
            }
        },
    };
    config
        .validate()
        .map_err(|e| ctx.err("planner", "profile", e.to_string()))?;
    Ok(config)
}

/// Checks that every folder of the subroutine path is a folder (when the machine file is read
/// from disk).
fn check_subroutine_path(path: &Path, program: &ProgramSetup) -> Result<(), ConfigError> {
    for dir in &program.subroutine_path {
        let full = program.base_dir.join(dir);
        if !full.is_dir() {
            return Err(ConfigError::Invalid {
                file: path.to_path_buf(),
                table: "program".into(),
                key: "subroutine_path".into(),
                message: format!(
                    "'{}' ({}) is not a folder: folders are relative to the machine file",
                    dir.display(),
                    full.display()
                ),
            });
        }
    }
    Ok(())
}

/// Checks that the loaded tool is in the table (once the table is read).
fn check_loaded_tool(path: &Path, program: &ProgramSetup) -> Result<(), ConfigError> {
    if program.loaded_tool != 0 && program.tools.get(program.loaded_tool).is_none() {
        return Err(ConfigError::Invalid {
            file: path.to_path_buf(),
            table: "program".into(),
            key: "loaded_tool".into(),
            message: format!(
                "tool {} is not in the tool table {}",
                program.loaded_tool,
                program
                    .tool_table_file
                    .as_ref()
                    .map_or(String::new(), |p| p.display().to_string())
            ),
        });
    }
    Ok(())
}

struct Ctx<'a> {
    file: &'a Path,
}

impl Ctx<'_> {
    fn err(&self, table: impl Into<String>, key: &str, message: impl Into<String>) -> ConfigError {
        ConfigError::Invalid {
            file: self.file.to_path_buf(),
            table: table.into(),
            key: key.to_string(),
            message: message.into(),
        }
    }
}

/// `0x60C2` encoding of a period: `value × 10^index` seconds, value ≤ 255.
pub fn ip_time_period(cycle_us: u32) -> Option<(u8, i8)> {
    if cycle_us == 0 {
        return None;
    }
    let mut v = u64::from(cycle_us);
    let mut idx: i8 = -6;
    while v % 10 == 0 && idx < 0 {
        v /= 10;
        idx += 1;
    }
    u8::try_from(v).ok().map(|v| (v, idx))
}

impl Machine {
    /// Load and validate a machine file; drive dictionaries are read relative to it.
    pub fn load(path: &Path) -> Result<Machine, ConfigError> {
        let text = crate::files::read_text(path, crate::files::MAX_CONFIG_BYTES)?;
        let base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        let mut machine =
            Machine::parse(path, &text, |rel| DriveDictionary::load(&base.join(rel)))?;
        if let Some(rel) = &machine.program.tool_table_file {
            machine.program.tools = crate::gcode::ToolTable::load(&base.join(rel))?;
        }
        check_loaded_tool(path, &machine.program)?;
        check_subroutine_path(path, &machine.program)?;
        Ok(machine)
    }

    /// The embedded demo machine (three simulated axes on the in-process bus).
    pub fn demo() -> Machine {
        let mut machine = Machine::parse(Path::new(DEMO_MACHINE_PATH), DEMO_MACHINE, |rel| {
            DriveDictionary::parse(&Path::new("dictionaries/machines").join(rel), DEMO_DRIVE)
        })
        .expect("the embedded demo machine is valid (a unit test checks it)");
        machine.program.tools =
            crate::gcode::ToolTable::parse(Path::new(DEMO_TOOLS_PATH), DEMO_TOOLS)
                .expect("the embedded demo tool table is valid (a unit test checks it)");
        machine
    }

    /// Parse a machine file's text; `load_dict` resolves dictionary paths.
    pub fn parse(
        path: &Path,
        text: &str,
        mut load_dict: impl FnMut(&Path) -> Result<DriveDictionary, ConfigError>,
    ) -> Result<Machine, ConfigError> {
        let mut raw: RawMachine = parse_toml(path, text)?;
        let ctx = Ctx { file: path };
        if raw.bus.cycle_us < 250 || raw.bus.cycle_us > 100_000 {
            return Err(ctx.err(
                "bus",
                "cycle_us",
                format!("{} µs outside 250..=100000", raw.bus.cycle_us),
            ));
        }
        if ip_time_period(raw.bus.cycle_us).is_none() {
            return Err(ctx.err(
                "bus",
                "cycle_us",
                format!(
                    "{} µs cannot be written to 0x60C2 as value (≤ 255) × 10^index",
                    raw.bus.cycle_us
                ),
            ));
        }
        if !(10_000..=1_000_000).contains(&raw.bus.bitrate) {
            return Err(ctx.err(
                "bus",
                "bitrate",
                format!("{} outside 10000..=1000000", raw.bus.bitrate),
            ));
        }
        if raw.sync.cob_id == 0 || raw.sync.cob_id > 0x7FF {
            return Err(ctx.err(
                "sync",
                "cob_id",
                "must be an 11-bit identifier other than 0",
            ));
        }
        if raw.sync.window_us >= raw.bus.cycle_us {
            return Err(ctx.err(
                "sync",
                "window_us",
                format!(
                    "{} µs must be shorter than the cycle ({} µs)",
                    raw.sync.window_us, raw.bus.cycle_us
                ),
            ));
        }
        let hb = &raw.heartbeat;
        if hb.gateway_node == 0 || hb.gateway_node > 127 {
            return Err(ctx.err("heartbeat", "gateway_node", "must be 1..=127"));
        }
        for (key, v) in [
            ("gateway_producer_ms", hb.gateway_producer_ms),
            ("drive_producer_ms", hb.drive_producer_ms),
        ] {
            if v == 0 {
                return Err(ctx.err(
                    "heartbeat",
                    key,
                    "must be above 0 (heartbeats guard the motion)",
                ));
            }
        }
        // CiA 301 practice: a consumer waits 1.5–3× the producer time.
        if u32::from(hb.drive_consumer_ms) * 2 < u32::from(hb.gateway_producer_ms) * 3 {
            return Err(ctx.err(
                "heartbeat",
                "drive_consumer_ms",
                format!(
                    "{} ms is less than 1.5 × gateway_producer_ms ({} ms)",
                    hb.drive_consumer_ms, hb.gateway_producer_ms
                ),
            ));
        }
        if u32::from(hb.gateway_consumer_ms) * 2 < u32::from(hb.drive_producer_ms) * 3 {
            return Err(ctx.err(
                "heartbeat",
                "gateway_consumer_ms",
                format!(
                    "{} ms is less than 1.5 × drive_producer_ms ({} ms)",
                    hb.gateway_consumer_ms, hb.drive_producer_ms
                ),
            ));
        }
        if raw.axis.is_empty() || raw.axis.len() > MAX_AXES {
            return Err(ctx.err(
                "axis",
                "axis",
                format!("a machine has 1 to {MAX_AXES} [[axis]] tables"),
            ));
        }
        let mut names = BTreeSet::new();
        let mut nodes = BTreeSet::new();
        let mut axes = Vec::new();
        let mut dicts: Vec<(PathBuf, Arc<DriveDictionary>)> = Vec::new();
        for a in &mut raw.axis {
            let table = format!("axis {}", a.name);
            if !AXIS_LETTERS.contains(&a.name.as_str()) {
                return Err(ctx.err(
                    table,
                    "name",
                    format!(
                        "{:?}: the axis letter must be one of {}",
                        a.name,
                        AXIS_LETTERS.join(" ")
                    ),
                ));
            }
            if !ENABLE_TIMEOUT_MS.contains(&a.enable_timeout_ms) {
                return Err(ctx.err(
                    table,
                    "enable_timeout_ms",
                    format!(
                        "{} outside {}..={} ms",
                        a.enable_timeout_ms,
                        ENABLE_TIMEOUT_MS.start(),
                        ENABLE_TIMEOUT_MS.end()
                    ),
                ));
            }
            if !names.insert(a.name.clone()) {
                return Err(ctx.err(table, "name", "axis defined twice"));
            }
            resolve_kind(&ctx, &table, a)?;
            let a = &*a;
            if a.node == 0 || a.node > 127 {
                return Err(ctx.err(table, "node", format!("{} outside 1..=127", a.node)));
            }
            if a.node == hb.gateway_node {
                return Err(ctx.err(table, "node", "equals heartbeat.gateway_node"));
            }
            if !nodes.insert(a.node) {
                return Err(ctx.err(table, "node", format!("node {} used by two axes", a.node)));
            }
            for (key, v) in [
                ("counts_per_mm", a.counts_per_mm),
                ("following_error_mm", a.following_error_mm),
            ] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(ctx.err(table, key, format!("{v} must be a positive number")));
                }
            }
            for (key, v) in [
                ("max_vel_mm_s", a.max_vel_mm_s),
                ("max_acc_mm_s2", a.max_acc_mm_s2),
                ("max_jerk_mm_s3", a.max_jerk_mm_s3),
            ] {
                if !(MIN_AXIS_LIMIT..=MAX_LIMIT).contains(&v) {
                    return Err(ctx.err(table, key, format!("{v} outside {MIN_AXIS_LIMIT}..={MAX_LIMIT:e}, the range the planner honours")));
                }
            }
            if !(a.min_mm.is_finite() && a.max_mm.is_finite() && a.min_mm < a.max_mm) {
                return Err(ctx.err(
                    table,
                    "max_mm",
                    format!("min_mm {} must be below max_mm {}", a.min_mm, a.max_mm),
                ));
            }
            for (key, v) in [("min_mm", a.min_mm), ("max_mm", a.max_mm)] {
                if (v * a.counts_per_mm).abs() >= i32::MAX as f64 {
                    return Err(ctx.err(table, key, "beyond the INT32 range of position counts"));
                }
            }
            supervision(&ctx, &table, a)?;
            let filter = a
                .filter
                .as_ref()
                .map(|f| axis_filter(&ctx, &table, f, raw.bus.cycle_us))
                .transpose()?;
            let dict = match dicts.iter().find(|(p, _)| *p == a.dictionary) {
                Some((_, d)) => d.clone(),
                None => {
                    let d = Arc::new(load_dict(&a.dictionary).map_err(|e| {
                        ConfigError::Referenced {
                            file: path.to_path_buf(),
                            table: table.clone(),
                            key: "dictionary".into(),
                            source: Box::new(e),
                        }
                    })?);
                    dicts.push((a.dictionary.clone(), d.clone()));
                    d
                }
            };
            // The drive must support the mode (0x6502 bit mode−1).
            let supported = dict
                .sub(index::SUPPORTED_MODES, 0)
                .and_then(|s| match &s.default {
                    crate::canopen::dictionary::DefaultValue::Fixed(v) => value_as_i128(v),
                    _ => None,
                })
                .unwrap_or(0);
            let bit = 1i128 << (a.mode.number() - 1);
            if supported & bit == 0 {
                return Err(ctx.err(
                    table,
                    "mode",
                    format!(
                        "{:?} (mode {}) is not in the drive's supported modes 0x6502 = 0x{supported:08X} ({})",
                        a.mode,
                        a.mode.number(),
                        dict.file.display()
                    ),
                ));
            }
            let setpoint_pdo = pdo(
                &ctx,
                &table,
                "setpoint_pdo",
                &a.setpoint_pdo,
                &dict,
                a.node,
                true,
            )?;
            let feedback_pdo = pdo(
                &ctx,
                &table,
                "feedback_pdo",
                &a.feedback_pdo,
                &dict,
                a.node,
                false,
            )?;
            pdo_objects(&ctx, &table, &dict, &setpoint_pdo, &feedback_pdo)?;
            let (si, ss) = a.mode.setpoint_object();
            for (idx, sub, what) in [
                (index::CONTROLWORD, 0u8, "controlword 0x6040"),
                (si, ss, "the mode's setpoint"),
            ] {
                if setpoint_pdo.offset_of(idx, sub).is_none() {
                    return Err(ctx.err(
                        table.as_str(),
                        "setpoint_pdo.mapping",
                        format!(
                            "must map {what} (0x{idx:04X}:{sub:02X}) for mode {:?}",
                            a.mode
                        ),
                    ));
                }
            }
            for (idx, what) in [
                (index::STATUSWORD, "statusword 0x6041"),
                (index::POSITION_ACTUAL, "position actual 0x6064"),
            ] {
                if feedback_pdo.offset_of(idx, 0).is_none() {
                    return Err(ctx.err(
                        table.as_str(),
                        "feedback_pdo.mapping",
                        format!("must map {what}"),
                    ));
                }
            }
            let mut sdo = Vec::new();
            for (i, w) in a.sdo.iter().enumerate() {
                let key = format!("sdo[{i}]");
                if let Some((lo, hi, what, why)) = GATEWAY_OWNED
                    .iter()
                    .find(|(lo, hi, ..)| (*lo..=*hi).contains(&w.index))
                {
                    let range = if lo == hi {
                        format!("0x{lo:04X}")
                    } else {
                        format!("0x{lo:04X}–0x{hi:04X}")
                    };
                    return Err(ctx.err(
                        table.as_str(),
                        &key,
                        format!(
                            "0x{:04X}:{:02X}: the gateway owns {range} ({what}: {why}); an sdo entry may not override it",
                            w.index, w.sub
                        ),
                    ));
                }
                let def = dict.sub(w.index, w.sub).ok_or_else(|| {
                    ctx.err(
                        table.as_str(),
                        &key,
                        format!(
                            "0x{:04X}:{:02X} is not in {}",
                            w.index,
                            w.sub,
                            dict.file.display()
                        ),
                    )
                })?;
                if !def.access.writable() {
                    return Err(ctx.err(
                        table.as_str(),
                        &key,
                        format!(
                            "0x{:04X}:{:02X} ({}) is not writable",
                            w.index, w.sub, def.name
                        ),
                    ));
                }
                let value = match &w.value {
                    toml::Value::Integer(x) => int_value(def.data_type, i128::from(*x)),
                    toml::Value::Float(x) => match def.data_type {
                        canopen_rs::DataType::Real32 => Some(Value::Real32(*x as f32)),
                        canopen_rs::DataType::Real64 => Some(Value::Real64(*x)),
                        _ => None,
                    },
                    _ => None,
                }
                .ok_or_else(|| {
                    ctx.err(
                        table.as_str(),
                        &key,
                        format!(
                            "value {} does not fit {} ({})",
                            w.value,
                            type_name(def.data_type),
                            def.name
                        ),
                    )
                })?;
                if let Some(x) = crate::canopen::dictionary::value_as_f64(&value)
                    && (def.min.is_some_and(|lo| x < lo) || def.max.is_some_and(|hi| x > hi))
                {
                    return Err(ctx.err(
                        table.as_str(),
                        &key,
                        format!(
                            "value {x} outside the range [{:?}, {:?}] of {}",
                            def.min, def.max, def.name
                        ),
                    ));
                }
                sdo.push(SdoWrite {
                    index: w.index,
                    sub: w.sub,
                    value,
                });
            }
            let limits = AxisLimits {
                table: &table,
                counts_per_mm: a.counts_per_mm,
                min_mm: a.min_mm,
                max_mm: a.max_mm,
                max_vel_mm_s: a.max_vel_mm_s,
                max_acc_mm_s2: a.max_acc_mm_s2,
            };
            let table_err = |(t, k, m): (String, String, String)| ctx.err(t, &k, m);
            let homing = a
                .homing
                .as_ref()
                .map(|h| super::operation::homing(&limits, h, &dict))
                .transpose()
                .map_err(table_err)?;
            let sim = super::operation::sim(&limits, &a.sim).map_err(table_err)?;
            axes.push(AxisConfig {
                name: a.name.clone(),
                node: a.node,
                dictionary: dict,
                mode: a.mode,
                kind: a.kind,
                wrap: a.wrapped,
                wrap_shortest: a.wrap_shortest,
                counts_per_mm: a.counts_per_mm,
                min_mm: a.min_mm,
                max_mm: a.max_mm,
                max_vel_mm_s: a.max_vel_mm_s,
                max_acc_mm_s2: a.max_acc_mm_s2,
                max_jerk_mm_s3: a.max_jerk_mm_s3,
                following_error_mm: a.following_error_mm,
                following_error_timeout_ms: a.following_error_timeout_ms,
                enable_timeout_ms: a.enable_timeout_ms,
                setpoint_pdo,
                feedback_pdo,
                sdo,
                filter,
                homing,
                sim,
            });
        }
        if !axes.iter().any(|a| a.xyz().is_some()) {
            return Err(ctx.err(
                format!("axis {}", axes[0].name),
                "name",
                "a machine needs an X, Y or Z axis: programs are planned in X, Y and Z, and the other axes hold their position",
            ));
        }
        check_can_ids(&ctx, raw.sync.cob_id, &axes)?;
        let mut machine = Machine {
            file: path.to_path_buf(),
            name: raw.machine.name,
            interface: raw.bus.interface,
            bitrate: raw.bus.bitrate,
            cycle_us: raw.bus.cycle_us,
            sync_cob_id: raw.sync.cob_id,
            sync_window_us: raw.sync.window_us,
            heartbeat: Heartbeat {
                gateway_node: hb.gateway_node,
                gateway_producer_ms: hb.gateway_producer_ms,
                drive_consumer_ms: hb.drive_consumer_ms,
                drive_producer_ms: hb.drive_producer_ms,
                gateway_consumer_ms: hb.gateway_consumer_ms,
            },
            axes,
            max_load_percent: raw.bus.max_load_percent,
            program: program_setup(&ctx, &raw.program)?,
            planner: crate::planner::PlannerConfig::exact_stop(),
            operation: super::operation::operation(&raw.operation)
                .map_err(|(t, k, m)| ctx.err(t, &k, m))?,
        };
        machine.planner = planner_config(&ctx, &raw.planner, &machine)?;
        machine.admit(&ctx)?;
        Ok(machine)
    }

    /// Worst-case bus load of one cycle's process data (checklist, "Bus bandwidth").
    pub fn bus_load(&self) -> BusLoad {
        let sync_bits = frame_bits(0);
        let pdo_bits: u32 = self
            .axes
            .iter()
            .map(|a| {
                frame_bits(a.setpoint_pdo.len_bytes()) + frame_bits(a.feedback_pdo.len_bytes())
            })
            .sum();
        let cycle_bits = f64::from(self.bitrate) * f64::from(self.cycle_us) * 1e-6;
        let total = f64::from(sync_bits + pdo_bits);
        BusLoad {
            sync_bits,
            pdo_bits,
            cycle_bits,
            percent: 100.0 * total / cycle_bits,
            carry_us: total / f64::from(self.bitrate) * 1e6,
        }
    }

    /// Refuse what the bus cannot carry: a load above `max_load_percent`, or a synchronous window
    /// shorter than the time the cycle's frames take.
    fn admit(&self, ctx: &Ctx) -> Result<(), ConfigError> {
        let l = self.bus_load();
        let n = self.axes.len();
        let formula = format!(
            "SYNC {} bits + {} axes' PDOs {} bits = {} bits per {} µs cycle at {} bit/s, with C(n) = 8n + 47 + ⌊(34 + 8n − 1)/4⌋",
            l.sync_bits,
            n,
            l.pdo_bits,
            l.sync_bits + l.pdo_bits,
            self.cycle_us,
            self.bitrate
        );
        if !(1.0..=100.0).contains(&self.max_load_percent) {
            return Err(ctx.err(
                "bus",
                "max_load_percent",
                format!("{} outside 1..=100", self.max_load_percent),
            ));
        }
        if l.percent > self.max_load_percent {
            return Err(ctx.err(
                "bus",
                "cycle_us",
                format!(
                    "the process data needs {:.1} % of the bus, above max_load_percent = {} ({formula}); lengthen the cycle, raise the bit rate or drive fewer axes",
                    l.percent, self.max_load_percent
                ),
            ));
        }
        if self.sync_window_us != 0 && f64::from(self.sync_window_us) < l.carry_us {
            return Err(ctx.err(
                "sync",
                "window_us",
                format!(
                    "{} µs is shorter than the {:.0} µs the cycle's frames take on the bus ({formula})",
                    self.sync_window_us, l.carry_us
                ),
            ));
        }
        Ok(())
    }

    /// The cycle period in seconds.
    pub fn cycle_s(&self) -> f64 {
        f64::from(self.cycle_us) * 1e-6
    }

    /// The axis with letter `name`.
    pub fn axis(&self, name: &str) -> Option<&AxisConfig> {
        self.axes.iter().find(|a| a.name == name)
    }
}

/// Checks that the drive's dictionary has every object start-up reads or writes for the process
/// data: the COB-ID of each of the four RPDOs and TPDOs (those not used are switched off), and
/// the transmission type and mapping entries of the two the axis uses. Without this, a missing
/// object would end `run` on an SDO abort that `plan` never saw.
fn pdo_objects(
    ctx: &Ctx,
    table: &str,
    dict: &DriveDictionary,
    setpoint: &PdoConfig,
    feedback: &PdoConfig,
) -> Result<(), ConfigError> {
    let mut need: Vec<(u16, u8, &str)> = Vec::new();
    for k in 0..4u16 {
        need.push((index::RPDO_COMMUNICATION + k, 1, "dictionary"));
        need.push((index::TPDO_COMMUNICATION + k, 1, "dictionary"));
    }
    for (p, comm, map, key) in [
        (
            setpoint,
            index::RPDO_COMMUNICATION,
            index::RPDO_MAPPING,
            "setpoint_pdo.number",
        ),
        (
            feedback,
            index::TPDO_COMMUNICATION,
            index::TPDO_MAPPING,
            "feedback_pdo.number",
        ),
    ] {
        let k = u16::from(p.number - 1);
        need.push((comm + k, 2, key));
        need.push((map + k, 0, key));
        for i in 1..=p.mapping.len() {
            need.push((map + k, i as u8, key));
        }
    }
    for (index, sub, key) in need {
        if dict.sub(index, sub).is_none() {
            return Err(ctx.err(
                table,
                key,
                format!(
                    "start-up writes 0x{index:04X}:{sub:02X} for the process data, and it is not in {}",
                    dict.file.display()
                ),
            ));
        }
    }
    Ok(())
}

/// Checks that SYNC takes a CAN-ID of its own: none CiA 301 restricts (NMT, every node's SDO
/// channels and heartbeats), and none of the machine's nodes' EMCYs or PDOs. A shared
/// identifier makes a drive take one object for the other.
fn check_can_ids(ctx: &Ctx, sync: u16, axes: &[AxisConfig]) -> Result<(), ConfigError> {
    if let Some((lo, hi, what)) = RESTRICTED_CAN_IDS
        .iter()
        .find(|(lo, hi, _)| (*lo..=*hi).contains(&sync))
    {
        return Err(ctx.err(
            "sync",
            "cob_id",
            format!(
                "0x{sync:03X} is a restricted CAN-ID of CiA 301 (0x{lo:03X}–0x{hi:03X}: {what})"
            ),
        ));
    }
    for a in axes {
        for (id, what) in [
            (crate::canopen::cob::EMCY + u16::from(a.node), "EMCY"),
            (a.setpoint_pdo.cob_id, "setpoint PDO"),
            (a.feedback_pdo.cob_id, "feedback PDO"),
        ] {
            if id == sync {
                return Err(ctx.err(
                    "sync",
                    "cob_id",
                    format!(
                        "0x{sync:03X} is the {what} of axis {} (node {})",
                        a.name, a.node
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Checks that the drive can supervise the axis as the file asks: a count fine enough to position
/// it, a following-error window (0x6065) that is neither tripped by rounding nor clamped nor as
/// long as the travel, and a velocity limit (0x607F) that fits the drive's UNSIGNED32.
fn supervision(ctx: &Ctx, table: &str, a: &RawAxis) -> Result<(), ConfigError> {
    let travel_mm = a.max_mm - a.min_mm;
    let travel_counts = travel_mm * a.counts_per_mm;
    if travel_counts < MIN_TRAVEL_COUNTS {
        return Err(ctx.err(
            table,
            "counts_per_mm",
            format!(
                "{}: the travel [{}, {}] mm spans {travel_counts} counts, fewer than {MIN_TRAVEL_COUNTS}: one count ({} mm) is too coarse to position the axis",
                a.counts_per_mm, a.min_mm, a.max_mm, 1.0 / a.counts_per_mm
            ),
        ));
    }
    let window_counts = a.following_error_mm * a.counts_per_mm;
    if window_counts.round() < MIN_FOLLOWING_ERROR_COUNTS {
        return Err(ctx.err(
            table,
            "following_error_mm",
            format!(
                "{} mm is {} counts in 0x6065 at counts_per_mm = {}, fewer than {MIN_FOLLOWING_ERROR_COUNTS}: setpoint and position actual are each rounded to a count, so the window would trip on rounding alone",
                a.following_error_mm,
                window_counts.round(),
                a.counts_per_mm
            ),
        ));
    }
    if window_counts.round() >= MAX_FOLLOWING_ERROR_COUNTS {
        return Err(ctx.err(
            table,
            "following_error_mm",
            format!(
                "{} mm is {window_counts:.0} counts at counts_per_mm = {}, not below the {MAX_FOLLOWING_ERROR_COUNTS} counts (2³¹ − 1) the gateway can write to 0x6065: it would be clamped there, and a jam never detected",
                a.following_error_mm, a.counts_per_mm
            ),
        ));
    }
    if a.following_error_mm >= travel_mm {
        return Err(ctx.err(
            table,
            "following_error_mm",
            format!(
                "{} mm is not shorter than the travel ({travel_mm} mm): a jam would never be detected",
                a.following_error_mm
            ),
        ));
    }
    let vmax_counts = a.max_vel_mm_s * a.counts_per_mm * DRIVE_VELOCITY_HEADROOM;
    if vmax_counts.ceil() > f64::from(u32::MAX) {
        return Err(ctx.err(
            table,
            "max_vel_mm_s",
            format!(
                "{} mm/s × counts_per_mm {} × {DRIVE_VELOCITY_HEADROOM} = {vmax_counts:.0} counts/s, above the {} the drive's velocity limit 0x607F (UNSIGNED32) can hold",
                a.max_vel_mm_s,
                a.counts_per_mm,
                u32::MAX
            ),
        ));
    }
    Ok(())
}

/// Checks an axis's `filter`: `time_ms` within 0..=[`MAX_FILTER_MS`] and, for a linear filter,
/// a whole number of cycles (its ramps last whole cycles; rather than round a time the file
/// states, the file is refused with the multiples on either side).
fn axis_filter(
    ctx: &Ctx,
    table: &str,
    raw: &RawFilter,
    cycle_us: u32,
) -> Result<FilterSpec, ConfigError> {
    let ms = raw.time_ms;
    if !(ms.is_finite() && (0.0..=MAX_FILTER_MS).contains(&ms)) {
        return Err(ctx.err(
            table,
            "filter.time_ms",
            format!("{ms} outside 0..={MAX_FILTER_MS} ms"),
        ));
    }
    let cycle_ms = f64::from(cycle_us) / 1000.0;
    let cycles = ms / cycle_ms;
    if raw.kind == FilterKind::Linear && (cycles - cycles.round()).abs() > 1e-9 {
        return Err(ctx.err(
            table,
            "filter.time_ms",
            format!(
                "{ms} ms is not a whole number of {cycle_ms} ms cycles (a linear filter's ramp lasts whole cycles): use {} or {} ms",
                cycles.floor() * cycle_ms,
                cycles.ceil() * cycle_ms
            ),
        ));
    }
    let spec = FilterSpec {
        kind: raw.kind,
        time_s: ms / 1000.0,
    };
    AxisFilter::new(spec, f64::from(cycle_us) * 1e-6)
        .map_err(|e| ctx.err(table, "filter.time_ms", e.to_string()))?;
    Ok(spec)
}

fn pdo(
    ctx: &Ctx,
    table: &str,
    key: &str,
    raw: &RawPdo,
    dict: &DriveDictionary,
    node: u8,
    receive: bool,
) -> Result<PdoConfig, ConfigError> {
    if !(1..=4).contains(&raw.number) {
        return Err(ctx.err(
            table,
            &format!("{key}.number"),
            format!("{} outside 1..=4", raw.number),
        ));
    }
    if !(1..=240).contains(&raw.transmission) {
        return Err(ctx.err(
            table,
            &format!("{key}.transmission"),
            format!(
                "{}: cyclic process data must be synchronous (1..=240)",
                raw.transmission
            ),
        ));
    }
    if !receive && raw.transmission != 1 {
        return Err(ctx.err(
            table,
            &format!("{key}.transmission"),
            format!(
                "{}: the gateway checks statusword and position actual on every SYNC, so the feedback must be sent on every SYNC (1)",
                raw.transmission
            ),
        ));
    }
    if raw.mapping.is_empty() || raw.mapping.len() > 8 {
        return Err(ctx.err(table, &format!("{key}.mapping"), "1 to 8 entries"));
    }
    let mut bits = 0u32;
    let mut mapping = Vec::new();
    for (i, &m) in raw.mapping.iter().enumerate() {
        let e = MapEntry::from_u32(m);
        let k = format!("{key}.mapping[{i}]");
        let def = dict.sub(e.index, e.sub).ok_or_else(|| {
            ctx.err(
                table,
                &k,
                format!(
                    "0x{m:08X}: object 0x{:04X}:{:02X} is not in {}",
                    e.index,
                    e.sub,
                    dict.file.display()
                ),
            )
        })?;
        if !def.pdo {
            return Err(ctx.err(
                table,
                &k,
                format!("0x{m:08X}: {} is not PDO-mappable", def.name),
            ));
        }
        if let Some(j) = mapping
            .iter()
            .position(|p: &MapEntry| p.index == e.index && p.sub == e.sub)
        {
            return Err(ctx.err(
                table,
                &k,
                format!(
                    "0x{m:08X}: {} is mapped twice (also {key}.mapping[{j}])",
                    def.name
                ),
            ));
        }
        let want = def.data_type.size() * 8;
        if usize::from(e.bits) != want {
            return Err(ctx.err(
                table,
                &k,
                format!("0x{m:08X}: {} is {want} bits, not {}", def.name, e.bits),
            ));
        }
        if receive && !def.access.writable() {
            return Err(ctx.err(
                table,
                &k,
                format!(
                    "0x{m:08X}: {} is read-only and cannot be received",
                    def.name
                ),
            ));
        }
        if !receive && !def.access.readable() {
            return Err(ctx.err(
                table,
                &k,
                format!("0x{m:08X}: {} is write-only and cannot be sent", def.name),
            ));
        }
        bits += u32::from(e.bits);
        mapping.push(e);
    }
    if bits > 64 {
        return Err(ctx.err(
            table,
            &format!("{key}.mapping"),
            format!("{bits} bits exceed the 64 of one frame"),
        ));
    }
    let base: u16 = match (receive, raw.number) {
        (true, n) => 0x100 + 0x100 * u16::from(n),
        (false, n) => 0x080 + 0x100 * u16::from(n),
    };
    Ok(PdoConfig {
        number: raw.number,
        cob_id: base + u16::from(node),
        transmission: raw.transmission,
        mapping,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_demo_machine_loads() {
        let m = Machine::demo();
        assert_eq!(m.axes.len(), 3);
        let names: Vec<_> = m.axes.iter().map(|a| (a.name.as_str(), a.node)).collect();
        assert_eq!(names, [("X", 1), ("Y", 2), ("Z", 3)]);
        assert_eq!(m.axes[0].setpoint_pdo.cob_id, 0x201);
        assert_eq!(m.axes[2].feedback_pdo.cob_id, 0x183);
    }

    #[test]
    fn the_demo_machine_file_on_disk_loads_too() {
        let m = Machine::load(Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/dictionaries/machines/demo-xyz.toml"
        )))
        .unwrap();
        assert_eq!(m.axes.len(), 3);
    }

    #[test]
    fn ip_period_encoding() {
        assert_eq!(ip_time_period(1000), Some((1, -3)));
        assert_eq!(ip_time_period(2000), Some((2, -3)));
        assert_eq!(ip_time_period(250), Some((25, -5)));
        assert_eq!(ip_time_period(1500), Some((15, -4)));
        assert_eq!(ip_time_period(1234), None);
    }

    fn demo_with(from: &str, to: &str) -> String {
        assert!(DEMO_MACHINE.contains(from), "demo file lacks {from:?}");
        let text = DEMO_MACHINE.replacen(from, to, 1);
        match Machine::parse(Path::new("m.toml"), &text, |rel| {
            DriveDictionary::parse(&Path::new("dictionaries/machines").join(rel), DEMO_DRIVE)
        }) {
            Ok(_) => panic!("accepted {to:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn errors_name_the_table_and_key() {
        assert_eq!(
            demo_with("node = 2", "node = 1"),
            "m.toml: [axis Y] node: node 1 used by two axes"
        );
        let e = demo_with(
            "mapping = [0x60400010, 0x60C10120]",
            "mapping = [0x60400010, 0x60410010]",
        );
        assert!(
            e.starts_with("m.toml: [axis X] setpoint_pdo.mapping[1]: 0x60410010"),
            "{e}"
        );
        let e = demo_with("cycle_us = 4000", "cycle_us = 1234");
        assert!(e.starts_with("m.toml: [bus] cycle_us: 1234"), "{e}");
        let e = demo_with("[machine]", "[machine]\nspeed = 3");
        assert!(e.contains("speed"), "{e}");
    }

    #[test]
    fn the_program_table_is_checked_and_reaches_the_interpreter_setup() {
        let e = demo_with("G54 = [0.0, 0.0, 0.0]", "G60 = [1.0, 2.0, 3.0]");
        assert!(
            e.starts_with("m.toml: [program.work_offsets_mm] G60: no such work offset"),
            "{e}"
        );
        let e = demo_with("g28_mm = [0.0, 0.0, 0.0]", "g28_mm = [1.0, 2.0]");
        assert!(e.starts_with("m.toml: [program] g28_mm: [1.0, 2.0]"), "{e}");
        let e = demo_with("loaded_tool = 1", "loaded_tool = 1\nspindle = 2");
        assert!(e.contains("spindle"), "{e}");

        let m = Machine::demo();
        assert_eq!(m.program.loaded_tool, 1);
        let t1 = m.program.tools.get(1).expect("tool 1 in the demo table");
        assert_eq!((t1.radius_mm, t1.length_mm), (2.0, 50.0));
        let text = DEMO_MACHINE.replacen(
            "G54 = [0.0, 0.0, 0.0]",
            "G54 = [10.0, 0.0, 0.0], \"G59.3\" = [1.0, 2.0, -3.5]",
            1,
        );
        let m = Machine::parse(Path::new("m.toml"), &text, |rel| {
            DriveDictionary::parse(&Path::new("dictionaries/machines").join(rel), DEMO_DRIVE)
        })
        .unwrap();
        let setup = m.setup(nalgebra::Vector3::new(1.0, 1.0, 1.0));
        assert_eq!(setup.start_mm, nalgebra::Vector3::new(1.0, 1.0, 1.0));
        assert_eq!(setup.work_offsets_mm[0].x, 10.0);
        assert_eq!(
            setup.work_offsets_mm[8],
            nalgebra::Vector3::new(1.0, 2.0, -3.5)
        );
    }

    #[test]
    fn a_loaded_tool_missing_from_the_table_is_refused_on_load() {
        let dir = tempfile::tempdir().unwrap();
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("dictionaries");
        let text = DEMO_MACHINE
            .replacen(
                "../drives/cia402-servo.toml",
                &root.join("drives/cia402-servo.toml").display().to_string(),
                3,
            )
            .replacen(
                "../tools/demo-tools.toml",
                &root.join("tools/demo-tools.toml").display().to_string(),
                1,
            );
        let ok = dir.path().join("ok.toml");
        std::fs::write(&ok, &text).unwrap();
        assert_eq!(
            Machine::load(&ok)
                .unwrap()
                .program
                .tools
                .get(2)
                .unwrap()
                .radius_mm,
            3.0
        );
        let bad = dir.path().join("bad.toml");
        std::fs::write(&bad, text.replacen("loaded_tool = 1", "loaded_tool = 9", 1)).unwrap();
        let e = Machine::load(&bad).unwrap_err().to_string();
        assert!(
            e.contains("[program] loaded_tool: tool 9 is not in the tool table"),
            "{e}"
        );
    }

    #[test]
    fn frame_lengths_and_the_checklist_table() {
        assert_eq!(
            (frame_bits(0), frame_bits(6), frame_bits(8)),
            (55, 115, 135)
        );
        // (bit rate, PDO bytes, [(1 ms, 2 ms, 4 ms) at 100 %], [same at 70 %]), checklist table.
        let table = [
            (1_000_000, 6, [4, 8, 17], [2, 5, 11]),
            (1_000_000, 8, [3, 7, 14], [2, 4, 10]),
            (500_000, 6, [1, 4, 8], [1, 2, 5]),
            (500_000, 8, [1, 3, 7], [1, 2, 4]),
        ];
        for (rate, bytes, full, seventy) in table {
            for (k, cycle_us) in [1000, 2000, 4000].into_iter().enumerate() {
                assert_eq!(
                    max_axes(rate, cycle_us, bytes, 100.0),
                    full[k],
                    "{rate} {bytes} B {cycle_us} µs 100 %"
                );
                assert_eq!(
                    max_axes(rate, cycle_us, bytes, 70.0),
                    seventy[k],
                    "{rate} {bytes} B {cycle_us} µs 70 %"
                );
            }
        }
    }

    /// The demo machine with three more axes (A, B, C on nodes 4, 5, 6) and `cycle_us`.
    fn six_axes(cycle_us: u32) -> String {
        let z = &DEMO_MACHINE[DEMO_MACHINE.rfind("[[axis]]").unwrap()..];
        let mut text =
            DEMO_MACHINE.replacen("cycle_us = 4000", &format!("cycle_us = {cycle_us}"), 1);
        text = text.replacen("window_us = 2000", "window_us = 0", 1);
        for (name, node) in [("A", 4), ("B", 5), ("C", 6)] {
            text.push('\n');
            text.push_str(
                &z.replacen("name = \"Z\"", &format!("name = \"{name}\""), 1)
                    .replacen("node = 3", &format!("node = {node}"), 1),
            );
        }
        text
    }

    fn parse(text: &str) -> Result<Machine, ConfigError> {
        Machine::parse(Path::new("six.toml"), text, |rel| {
            DriveDictionary::parse(&Path::new("dictionaries/machines").join(rel), DEMO_DRIVE)
        })
    }

    #[test]
    fn six_axes_at_1_mbit_are_refused_at_1_ms_and_accepted_at_4_ms() {
        let e = parse(&six_axes(1000)).unwrap_err().to_string();
        // SYNC 55 + 6 × (115 + 115) = 1435 bits in a 1000-bit cycle: 143.5 %.
        assert!(e.starts_with("six.toml: [bus] cycle_us: the process data needs 143.5 % of the bus, above max_load_percent = 70"), "{e}");
        assert!(e.contains("1435 bits per 1000 µs cycle"), "{e}");
        let m = parse(&six_axes(4000)).unwrap();
        assert_eq!(m.axes.len(), 6);
        assert!((m.bus_load().percent - 35.875).abs() < 1e-9);
        // 2 ms: 71.75 % — just above the default limit, accepted when the limit is raised.
        assert!(parse(&six_axes(2000)).is_err());
        let raised = six_axes(2000).replacen(
            "cycle_us = 2000",
            "cycle_us = 2000\nmax_load_percent = 75",
            1,
        );
        assert!(parse(&raised).is_ok());
    }

    #[test]
    fn an_axis_filter_is_optional_and_its_time_is_checked_by_name() {
        assert!(Machine::demo().axes.iter().all(|a| a.filter.is_none()));
        let x = "following_error_timeout_ms = 10  # 0x6066";
        let with = |f: &str| DEMO_MACHINE.replacen(x, &format!("{x}\nfilter = {f}"), 1);
        let m = parse(&with(r#"{ kind = "linear", time_ms = 8 }"#)).unwrap();
        assert_eq!(
            m.axes[0].filter,
            Some(FilterSpec {
                kind: FilterKind::Linear,
                time_s: 0.008
            })
        );
        assert_eq!(m.axes[1].filter, None);
        // An exponential filter's time constant need not be a whole number of cycles.
        let m = parse(&with(r#"{ kind = "exponential", time_ms = 4.5 }"#)).unwrap();
        assert_eq!(m.axes[0].filter.unwrap().time_s, 0.0045);

        let bad = |f: &str| parse(&with(f)).unwrap_err().to_string();
        assert_eq!(
            bad(r#"{ kind = "linear", time_ms = 10 }"#),
            "six.toml: [axis X] filter.time_ms: 10 ms is not a whole number of 4 ms cycles (a linear filter's ramp lasts whole cycles): use 8 or 12 ms"
        );
        assert_eq!(
            bad(r#"{ kind = "exponential", time_ms = -1 }"#),
            "six.toml: [axis X] filter.time_ms: -1 outside 0..=1000 ms"
        );
        assert_eq!(
            bad(r#"{ kind = "linear", time_ms = 1004 }"#),
            "six.toml: [axis X] filter.time_ms: 1004 outside 0..=1000 ms"
        );
        let e = bad(r#"{ kind = "cubic", time_ms = 8 }"#);
        assert!(e.contains("cubic") && e.contains("linear"), "{e}");
        let e = bad(r#"{ kind = "linear", time_ms = 8, order = 2 }"#);
        assert!(e.contains("order"), "{e}");
        let e = bad(r#"{ kind = "linear" }"#);
        assert!(e.contains("time_ms"), "{e}");
    }

    #[test]
    fn a_sync_window_too_short_for_the_frames_is_refused() {
        let text = DEMO_MACHINE.replacen("window_us = 2000", "window_us = 500", 1);
        let e = parse(&text).unwrap_err().to_string();
        // SYNC 55 + 3 × 230 = 745 bits = 745 µs at 1 Mbit/s.
        assert!(
            e.starts_with("six.toml: [sync] window_us: 500 µs is shorter than the 745 µs"),
            "{e}"
        );
    }

    #[test]
    fn schema_errors_name_the_table() {
        // An unknown key in the second [[axis]] entry: the entry by its axis name.
        let y = "name = \"Y\"\nnode = 2";
        let text = DEMO_MACHINE.replacen(y, &format!("{y}\ncolour = \"red\""), 1);
        let e = parse(&text).unwrap_err();
        match &e {
            ConfigError::Parse {
                table,
                line: Some(_),
                ..
            } => assert_eq!(table.as_deref(), Some("axis Y")),
            other => panic!("{other:?}"),
        }
        let msg = e.to_string();
        assert!(msg.starts_with("six.toml: line "), "{msg}");
        assert!(msg.contains(": [axis Y] unknown field `colour`"), "{msg}");
        // In [bus], after the axes' inline tables and multi-line arrays.
        let text = DEMO_MACHINE.replacen("bitrate = 1000000", "bitrate = 1000000\nspeed = 1", 1);
        let msg = parse(&text).unwrap_err().to_string();
        assert!(msg.contains(": [bus] unknown field `speed`"), "{msg}");
        // A wrong type inside an axis's inline table, and a missing key (the span is the header).
        let text = DEMO_MACHINE.replacen(
            "number = 1, transmission = 1",
            "number = \"one\", transmission = 1",
            1,
        );
        let msg = parse(&text).unwrap_err().to_string();
        assert!(msg.contains(": [axis X] invalid type"), "{msg}");
        let text = DEMO_MACHINE.replacen("gateway_producer_ms = 100", "", 1);
        let msg = parse(&text).unwrap_err().to_string();
        assert!(
            msg.contains(": [heartbeat] missing field `gateway_producer_ms`"),
            "{msg}"
        );
        // An unknown table is a key of the top level: no table named.
        let msg = parse(&format!("{DEMO_MACHINE}\n[spindle]\nrpm = 1\n"))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("column 2: unknown field `spindle`"), "{msg}");
    }

    /// The demo with `from` replaced by `to` (in the whole file, `n` times): the table and key of
    /// the `ConfigError::Invalid` it gives.
    fn invalid_with(from: &str, to: &str, n: usize) -> (String, String, String) {
        assert!(DEMO_MACHINE.contains(from), "demo file lacks {from:?}");
        let text = DEMO_MACHINE.replacen(from, to, n);
        match parse(&text) {
            Ok(_) => panic!("accepted {to:?}"),
            Err(ConfigError::Invalid {
                table,
                key,
                message,
                ..
            }) => (table, key, message),
            Err(e) => panic!("not an Invalid error: {e}"),
        }
    }

    fn parsed_with(from: &str, to: &str) -> Machine {
        assert!(DEMO_MACHINE.contains(from), "demo file lacks {from:?}");
        parse(&DEMO_MACHINE.replacen(from, to, 1)).expect("valid")
    }

    #[test]
    fn the_demo_homes_z_first_then_x_and_y_on_simulated_switches() {
        let m = Machine::demo();
        let h = |n: &str| m.axis(n).unwrap().homing.clone().expect("homing");
        let (x, y, z) = (h("X"), h("Y"), h("Z"));
        assert_eq!((z.order, x.order, y.order), (0, 1, 1));
        assert_eq!(x.method, HomingMethod::Drive(21));
        assert_eq!(x.drive_method(), Some(21));
        assert_eq!(z.method, HomingMethod::Drive(19));
        assert_eq!(x.timeout_ms, 30_000);
        assert_eq!((x.speed_search_mm_s, x.speed_zero_mm_s), (20.0, 2.0));
        assert_eq!((x.acc_mm_s2, x.offset_mm), (200.0, -2.0));
        assert_eq!(m.axis("Z").unwrap().sim.home_switch_mm, Some(2.0));
        let x_sim = m.axis("X").unwrap().sim;
        assert_eq!(x_sim.start_mm, 0.0, "runs on the demo start at 0");
        assert_eq!(x_sim.limit_switches_mm, None);
        assert_eq!(m.operation, OperationConfig::default());
        assert!(m.operation.require_homing);
        assert_eq!(m.operation.jog_timeout_ms, 500);
        assert_eq!(m.operation.unhomed_jog_fraction, 0.1);
        assert_eq!(
            m.operation.control_socket,
            PathBuf::from("/run/canmotion.sock")
        );
    }

    #[test]
    fn homing_methods_current_and_absolute_need_no_speeds() {
        let z = "method = 19              # Z homes first (order 0), up to a switch near the top, then off it downward\nspeed_search_mm_s = 10.0\nspeed_zero_mm_s = 1.0\nacc_mm_s2 = 200.0\n";
        for (method, want, drive) in [
            ("\"current\"", HomingMethod::Current, Some(37)),
            ("\"absolute\"", HomingMethod::Absolute, None),
            ("37", HomingMethod::Drive(37), Some(37)),
        ] {
            let m = parsed_with(z, &format!("method = {method}\n"));
            let h = m.axis("Z").unwrap().homing.clone().unwrap();
            assert_eq!(h.method, want);
            assert_eq!(h.drive_method(), drive);
            assert!(!h.moves());
            assert_eq!(h.speed_search_mm_s, 0.0);
        }
        // Without the table the axis has no homing.
        let start = DEMO_MACHINE.rfind("[axis.homing]").unwrap();
        let end = DEMO_MACHINE.rfind("[axis.sim]").unwrap();
        let text = format!("{}{}", &DEMO_MACHINE[..start], &DEMO_MACHINE[end..]);
        let m = parse(&text).expect("valid");
        assert!(m.axis("Z").unwrap().homing.is_none());
    }

    #[test]
    fn homing_tables_are_checked_against_the_axis_and_the_drive() {
        let x = "axis X.homing";
        for (from, to, key, says) in [
            (
                "speed_search_mm_s = 20.0",
                "speed_search_mm_s = 250.0",
                "speed_search_mm_s",
                "200",
            ),
            (
                "speed_search_mm_s = 20.0",
                "speed_search_mm_s = 0.0",
                "speed_search_mm_s",
                "(0, 200]",
            ),
            (
                "speed_zero_mm_s = 2.0",
                "speed_zero_mm_s = -1.0",
                "speed_zero_mm_s",
                "(0, 200]",
            ),
            (
                "acc_mm_s2 = 200.0",
                "acc_mm_s2 = 3000.0",
                "acc_mm_s2",
                "max_acc_mm_s2",
            ),
            (
                "offset_mm = -2.0",
                "offset_mm = -6.0",
                "offset_mm",
                "[-5, 300]",
            ),
            (
                "timeout_ms = 30000",
                "timeout_ms = 0",
                "timeout_ms",
                "100..=600000",
            ),
            ("method = 21 ", "method = 40 ", "method", "1..=37"),
            ("method = 21 ", "method = 1  ", "method", "0x60E3"),
            ("method = 21 ", "method = \"home\"", "method", "\"current\""),
            (
                "speed_search_mm_s = 20.0 #",
                "# speed_search_mm_s = 20.0 #",
                "speed_search_mm_s",
                "missing",
            ),
        ] {
            let (table, k, message) = invalid_with(from, to, 1);
            assert_eq!((table.as_str(), k.as_str()), (x, key), "{to}: {message}");
            assert!(message.contains(says), "{to}: {message}");
        }
        // A drive without homing mode: the dictionary's 0x6502 decides.
        let text = DEMO_MACHINE.to_string();
        let no_hm = DEMO_DRIVE.replace("default = 0x000000E1", "default = 0x000000C1");
        let e = Machine::parse(Path::new("m.toml"), &text, |rel| {
            DriveDictionary::parse(&Path::new("dictionaries/machines").join(rel), &no_hm)
        })
        .unwrap_err();
        assert!(
            matches!(&e, ConfigError::Invalid { table, key, message, .. }
                if table == "axis X.homing" && key == "method" && message.contains("0x6502")),
            "{e}"
        );
        // ... unless the axis homes without the drive.
        let text = DEMO_MACHINE
            .replace("method = 21 ", "method = \"absolute\"")
            .replace("method = 21\n", "method = \"absolute\"\n")
            .replace("method = 19 ", "method = \"absolute\"");
        Machine::parse(Path::new("m.toml"), &text, |rel| {
            DriveDictionary::parse(&Path::new("dictionaries/machines").join(rel), &no_hm)
        })
        .expect("absolute encoders need no homing mode");
    }

    #[test]
    fn sim_and_operation_tables_are_checked() {
        let (t, k, m) = invalid_with(
            "home_switch_mm = -2.0    #",
            "limit_switches_mm = [3.0, 1.0]\nhome_switch_mm = -2.0    #",
            1,
        );
        assert_eq!(
            (t.as_str(), k.as_str()),
            ("axis X.sim", "limit_switches_mm"),
            "{m}"
        );
        let (t, k, _) = invalid_with("home_switch_mm = -2.0    #", "start_mm = nan\n#", 1);
        assert_eq!((t.as_str(), k.as_str()), ("axis X.sim", "start_mm"));
        for (from, to, key) in [
            (
                "jog_timeout_ms = 500 ",
                "jog_timeout_ms = 10  ",
                "jog_timeout_ms",
            ),
            (
                "unhomed_jog_fraction = 0.1",
                "unhomed_jog_fraction = 1.5",
                "unhomed_jog_fraction",
            ),
            (
                "unhomed_jog_fraction = 0.1",
                "unhomed_jog_fraction = 0.0",
                "unhomed_jog_fraction",
            ),
            (
                "control_socket = \"/run/canmotion.sock\"",
                "control_socket = \"\"",
                "control_socket",
            ),
        ] {
            let (t, k, m) = invalid_with(from, to, 1);
            assert_eq!((t.as_str(), k.as_str()), ("operation", key), "{m}");
        }
        let m = parsed_with(
            "home_switch_mm = -2.0    #",
            "start_mm = 50.0\nlimit_switches_mm = [-4.0, 290.0]\nhome_switch_mm = -2.0    #",
        );
        let sim = m.axis("X").unwrap().sim;
        assert_eq!(sim.start_mm, 50.0);
        assert_eq!(sim.limit_switches_mm, Some([-4.0, 290.0]));
        let m = parsed_with("require_homing = true", "require_homing = false");
        assert!(!m.operation.require_homing);
        // The table is optional.
        let text = DEMO_MACHINE
            .lines()
            .filter(|l| {
                !l.starts_with("[operation]")
                    && !l.starts_with("require_homing")
                    && !l.starts_with("jog_timeout_ms")
                    && !l.starts_with("unhomed_jog_fraction")
                    && !l.starts_with("control_socket")
            })
            .collect::<Vec<_>>()
            .join("\n");
        assert_eq!(
            parse(&text).expect("valid").operation,
            OperationConfig::default()
        );
    }
}
