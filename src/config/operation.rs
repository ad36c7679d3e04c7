//! The machine file's tables for operating a machine: per axis `[axis.homing]` (how the axis
//! finds its home, CiA 402 homing mode 6) and `[axis.sim]` (the simulated drive's switches),
//! and the top-level `[operation]` (what `canmotion serve` requires and allows).

use std::path::PathBuf;

use serde::Deserialize;

use crate::canopen::dictionary::{DefaultValue, DriveDictionary, value_as_i128};
use crate::canopen::index;
use crate::cia402::ModeOfOperation;

/// `[axis.homing]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawHoming {
    method: toml::Value,
    speed_search_mm_s: Option<f64>,
    speed_zero_mm_s: Option<f64>,
    acc_mm_s2: Option<f64>,
    #[serde(default)]
    offset_mm: f64,
    #[serde(default)]
    order: u32,
    #[serde(default = "default_homing_timeout_ms")]
    timeout_ms: u32,
}

fn default_homing_timeout_ms() -> u32 {
    DEFAULT_HOMING_TIMEOUT_MS
}

/// `[axis.homing] timeout_ms` when the file gives none: the master's limit for the whole homing
/// of the axis.
pub const DEFAULT_HOMING_TIMEOUT_MS: u32 = 30_000;
/// The bounds of `[axis.homing] timeout_ms`: a search over a long axis at a low speed takes
/// minutes, and ten is beyond any.
pub const HOMING_TIMEOUT_MS: std::ops::RangeInclusive<u32> = 100..=600_000;

/// How an axis finds its home.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HomingMethod {
    /// The drive homes itself in CiA 402 homing mode (6) with this method (0x6098).
    Drive(i8),
    /// The encoder is absolute: nothing moves, the axis counts as homed.
    Absolute,
    /// The current position is declared home: the drive's method 37 (position actual becomes
    /// the home offset).
    Current,
}

/// `[axis.homing]`: an axis's homing (CiA 402 homing mode 6).
#[derive(Debug, Clone, PartialEq)]
pub struct HomingConfig {
    /// `method`: a CiA 402 method number (0x6098), `"absolute"` or `"current"`.
    pub method: HomingMethod,
    /// `speed_search_mm_s`: speed of the search for the switch (0x6099:1, in counts/s); 0 when
    /// not given, which only methods without motion (`"current"`, `"absolute"`, 35, 37) allow.
    pub speed_search_mm_s: f64,
    /// `speed_zero_mm_s`: speed of the search for zero, the final approach (0x6099:2); 0 when
    /// not given, as above.
    pub speed_zero_mm_s: f64,
    /// `acc_mm_s2`: the homing acceleration (0x609A, in counts/s²); 0 when not given, as above.
    pub acc_mm_s2: f64,
    /// `offset_mm`: the axis's position at the home (0x607C, in counts); default 0.
    pub offset_mm: f64,
    /// `order`: lower homes first; equal orders home together. Default 0.
    pub order: u32,
    /// `timeout_ms`: the master's limit for the whole homing of the axis. Default 30000.
    pub timeout_ms: u32,
}

impl HomingConfig {
    /// The method to write to 0x6098: `Current` is 37, `Absolute` homes without the drive.
    pub fn drive_method(&self) -> Option<i8> {
        match self.method {
            HomingMethod::Drive(m) => Some(m),
            HomingMethod::Current => Some(37),
            HomingMethod::Absolute => None,
        }
    }

    /// Whether homing moves the axis (a search), so that speeds and acceleration are needed.
    pub fn moves(&self) -> bool {
        !matches!(self.drive_method(), None | Some(35) | Some(37))
    }
}

/// `[axis.sim]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSim {
    #[serde(default)]
    start_mm: f64,
    home_switch_mm: Option<f64>,
    limit_switches_mm: Option<[f64; 2]>,
}

/// `[axis.sim]`: options of the simulated drive only (a real drive ignores them).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SimOptions {
    /// `start_mm`: where the axis is at power-on; default 0.
    pub start_mm: f64,
    /// `home_switch_mm`: the home switch's edge; `None`: no home switch, and the switch
    /// methods end in a homing error. Methods 19/20 see it active above the edge, 21/22 below.
    pub home_switch_mm: Option<f64>,
    /// `limit_switches_mm`: the negative and positive limit switches (methods 17/18, and the
    /// end of every search); `None`: at `min_mm` and `max_mm`.
    pub limit_switches_mm: Option<[f64; 2]>,
}

/// `[operation]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawOperation {
    require_homing: Option<bool>,
    jog_timeout_ms: Option<u32>,
    unhomed_jog_fraction: Option<f64>,
    control_socket: Option<PathBuf>,
}

/// `[operation] jog_timeout_ms` when the file gives none (the dead-man time).
pub const DEFAULT_JOG_TIMEOUT_MS: u32 = 500;
/// The bounds of `jog_timeout_ms`: shorter than a few cycles of a client's repeat is a jog
/// that stutters; longer than 10 s is no dead-man.
pub const JOG_TIMEOUT_MS: std::ops::RangeInclusive<u32> = 50..=10_000;
/// `[operation] unhomed_jog_fraction` when the file gives none.
pub const DEFAULT_UNHOMED_JOG_FRACTION: f64 = 0.1;
/// `[operation] control_socket` when the file gives none.
pub const DEFAULT_CONTROL_SOCKET: &str = "/run/canmotion.sock";

/// `[operation]`: what `canmotion serve` requires and allows.
#[derive(Debug, Clone, PartialEq)]
pub struct OperationConfig {
    /// `require_homing`: programs and MDI motion need homed axes. Default true.
    pub require_homing: bool,
    /// `jog_timeout_ms`: a continuous jog stops unless repeated within this (dead-man).
    /// Default 500.
    pub jog_timeout_ms: u32,
    /// `unhomed_jog_fraction`: before homing, jogs are capped at this fraction of
    /// `max_vel_mm_s`, in (0, 1]. Default 0.1.
    pub unhomed_jog_fraction: f64,
    /// `control_socket`: the Unix socket `serve` listens on. Default `/run/canmotion.sock`.
    pub control_socket: PathBuf,
}

impl Default for OperationConfig {
    fn default() -> OperationConfig {
        OperationConfig {
            require_homing: true,
            jog_timeout_ms: DEFAULT_JOG_TIMEOUT_MS,
            unhomed_jog_fraction: DEFAULT_UNHOMED_JOG_FRACTION,
            control_socket: PathBuf::from(DEFAULT_CONTROL_SOCKET),
        }
    }
}

/// What the checks need of the axis the tables belong to.
pub(super) struct AxisLimits<'a> {
    pub table: &'a str,
    pub counts_per_mm: f64,
    pub min_mm: f64,
    pub max_mm: f64,
    pub max_vel_mm_s: f64,
    pub max_acc_mm_s2: f64,
}

/// An error of a table: (table, key, message).
pub(super) type TableError = (String, String, String);

fn err(table: &str, key: &str, message: impl Into<String>) -> TableError {
    (table.to_string(), key.to_string(), message.into())
}

/// The integer default of `index:sub` in `dict`, if it has one.
fn default_int(dict: &DriveDictionary, index: u16, sub: u8) -> Option<i128> {
    match &dict.sub(index, sub)?.default {
        DefaultValue::Fixed(v) => value_as_i128(v),
        _ => None,
    }
}

/// The homing methods the drive lists in 0x60E3; `None` when its dictionary has no 0x60E3.
fn supported_methods(dict: &DriveDictionary) -> Option<Vec<i8>> {
    let n = default_int(dict, index::SUPPORTED_HOMING_METHODS, 0)?;
    Some(
        (1..=n.clamp(0, 254) as u8)
            .filter_map(|s| default_int(dict, index::SUPPORTED_HOMING_METHODS, s))
            .map(|m| m as i8)
            .collect(),
    )
}

/// Validate `[axis.homing]` against the axis and its drive's dictionary.
pub(super) fn homing(
    axis: &AxisLimits,
    raw: &RawHoming,
    dict: &DriveDictionary,
) -> Result<HomingConfig, TableError> {
    let table = format!("{}.homing", axis.table);
    let t = table.as_str();
    let method = match &raw.method {
        toml::Value::Integer(m) => {
            // CiA 402-2 defines 1..=37 (0x6098 is INTEGER8; negatives are manufacturer's).
            if !(1..=37).contains(m) {
                return Err(err(
                    t,
                    "method",
                    format!("{m}: a CiA 402 homing method is 1..=37"),
                ));
            }
            HomingMethod::Drive(*m as i8)
        }
        toml::Value::String(s) if s == "absolute" => HomingMethod::Absolute,
        toml::Value::String(s) if s == "current" => HomingMethod::Current,
        other => {
            return Err(err(
                t,
                "method",
                format!(
                    "{other}: give a CiA 402 homing method number (0x6098, e.g. 19), \"current\" or \"absolute\""
                ),
            ));
        }
    };
    let h = HomingConfig {
        method,
        speed_search_mm_s: raw.speed_search_mm_s.unwrap_or(0.0),
        speed_zero_mm_s: raw.speed_zero_mm_s.unwrap_or(0.0),
        acc_mm_s2: raw.acc_mm_s2.unwrap_or(0.0),
        offset_mm: raw.offset_mm,
        order: raw.order,
        timeout_ms: raw.timeout_ms,
    };
    if let Some(m) = h.drive_method() {
        let file = dict.file.display();
        let modes = default_int(dict, index::SUPPORTED_MODES, 0).unwrap_or(0);
        if modes & i128::from(ModeOfOperation::Homing.supported_bit()) == 0 {
            return Err(err(
                t,
                "method",
                format!(
                    "the drive does not support homing mode 6 (0x6502 = 0x{modes:08X} in {file})"
                ),
            ));
        }
        let mut needed = vec![(index::HOMING_METHOD, 0, "homing method 0x6098")];
        needed.push((index::HOME_OFFSET, 0, "home offset 0x607C"));
        if h.moves() {
            needed.extend([
                (index::HOMING_SPEEDS, 1, "homing speed 0x6099:1"),
                (index::HOMING_SPEEDS, 2, "homing speed 0x6099:2"),
                (index::HOMING_ACCELERATION, 0, "homing acceleration 0x609A"),
            ]);
        }
        for (idx, sub, what) in needed {
            if dict.sub(idx, sub).is_none_or(|d| !d.access.writable()) {
                return Err(err(
                    t,
                    "method",
                    format!("method {m} needs a writable {what}, which {file} does not have"),
                ));
            }
        }
        if let Some(list) = supported_methods(dict)
            && !list.contains(&m)
        {
            return Err(err(
                t,
                "method",
                format!(
                    "method {m} is not among the drive's supported homing methods 0x60E3 = {list:?} ({file})"
                ),
            ));
        }
    }
    if h.moves() {
        for (key, v, max, what) in [
            (
                "speed_search_mm_s",
                raw.speed_search_mm_s,
                axis.max_vel_mm_s,
                "max_vel_mm_s",
            ),
            (
                "speed_zero_mm_s",
                raw.speed_zero_mm_s,
                axis.max_vel_mm_s,
                "max_vel_mm_s",
            ),
            (
                "acc_mm_s2",
                raw.acc_mm_s2,
                axis.max_acc_mm_s2,
                "max_acc_mm_s2",
            ),
        ] {
            let Some(v) = v else {
                return Err(err(
                    t,
                    key,
                    format!(
                        "missing: method {} searches a switch and needs it",
                        h.drive_method().unwrap_or(0)
                    ),
                ));
            };
            if !(v.is_finite() && v > 0.0 && v <= max) {
                return Err(err(
                    t,
                    key,
                    format!("{v} outside (0, {max}], the axis's {what}"),
                ));
            }
            if (v * axis.counts_per_mm).round() < 1.0
                || v * axis.counts_per_mm > f64::from(u32::MAX)
            {
                return Err(err(
                    t,
                    key,
                    format!(
                        "{v} is {} counts at counts_per_mm = {}, outside the drive's 1..=2³²−1 (UNSIGNED32)",
                        (v * axis.counts_per_mm).round(),
                        axis.counts_per_mm
                    ),
                ));
            }
        }
    } else {
        for (key, v) in [
            ("speed_search_mm_s", raw.speed_search_mm_s),
            ("speed_zero_mm_s", raw.speed_zero_mm_s),
            ("acc_mm_s2", raw.acc_mm_s2),
        ] {
            let max = if key == "acc_mm_s2" {
                axis.max_acc_mm_s2
            } else {
                axis.max_vel_mm_s
            };
            if let Some(v) = v
                && !(v.is_finite() && v >= 0.0 && v <= max)
            {
                return Err(err(t, key, format!("{v} outside [0, {max}]")));
            }
        }
    }
    if !(h.offset_mm.is_finite() && (axis.min_mm..=axis.max_mm).contains(&h.offset_mm)) {
        return Err(err(
            t,
            "offset_mm",
            format!(
                "{} outside the axis's travel [{}, {}] mm",
                h.offset_mm, axis.min_mm, axis.max_mm
            ),
        ));
    }
    if !HOMING_TIMEOUT_MS.contains(&h.timeout_ms) {
        return Err(err(
            t,
            "timeout_ms",
            format!(
                "{} outside {}..={} ms",
                h.timeout_ms,
                HOMING_TIMEOUT_MS.start(),
                HOMING_TIMEOUT_MS.end()
            ),
        ));
    }
    Ok(h)
}

/// Validate `[axis.sim]`.
pub(super) fn sim(axis: &AxisLimits, raw: &RawSim) -> Result<SimOptions, TableError> {
    let table = format!("{}.sim", axis.table);
    let t = table.as_str();
    let in_counts = |key: &str, v: f64| {
        if !v.is_finite() || (v * axis.counts_per_mm).abs() >= f64::from(i32::MAX) {
            Err(err(
                t,
                key,
                format!("{v} is not a position in the INT32 range of counts"),
            ))
        } else {
            Ok(())
        }
    };
    in_counts("start_mm", raw.start_mm)?;
    if let Some(h) = raw.home_switch_mm {
        in_counts("home_switch_mm", h)?;
    }
    if let Some([lo, hi]) = raw.limit_switches_mm {
        in_counts("limit_switches_mm", lo)?;
        in_counts("limit_switches_mm", hi)?;
        if lo >= hi {
            return Err(err(
                t,
                "limit_switches_mm",
                format!("[{lo}, {hi}]: the negative switch must be below the positive one"),
            ));
        }
    }
    Ok(SimOptions {
        start_mm: raw.start_mm,
        home_switch_mm: raw.home_switch_mm,
        limit_switches_mm: raw.limit_switches_mm,
    })
}

/// Validate `[operation]`.
pub(super) fn operation(raw: &RawOperation) -> Result<OperationConfig, TableError> {
    let t = "operation";
    let d = OperationConfig::default();
    let o = OperationConfig {
        require_homing: raw.require_homing.unwrap_or(d.require_homing),
        jog_timeout_ms: raw.jog_timeout_ms.unwrap_or(d.jog_timeout_ms),
        unhomed_jog_fraction: raw.unhomed_jog_fraction.unwrap_or(d.unhomed_jog_fraction),
        control_socket: raw.control_socket.clone().unwrap_or(d.control_socket),
    };
    if !JOG_TIMEOUT_MS.contains(&o.jog_timeout_ms) {
        return Err(err(
            t,
            "jog_timeout_ms",
            format!(
                "{} outside {}..={} ms",
                o.jog_timeout_ms,
                JOG_TIMEOUT_MS.start(),
                JOG_TIMEOUT_MS.end()
            ),
        ));
    }
    let f = o.unhomed_jog_fraction;
    if !(f.is_finite() && f > 0.0 && f <= 1.0) {
        return Err(err(
            t,
            "unhomed_jog_fraction",
            format!("{f} outside (0, 1]: a fraction of max_vel_mm_s"),
        ));
    }
    if o.control_socket.as_os_str().is_empty() {
        return Err(err(t, "control_socket", "must be a path"));
    }
    Ok(o)
}
