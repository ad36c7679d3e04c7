//! The `status` answer: `ok ` and one line of JSON (`watch` repeats it). Its keys:
//!
//! | key | type | meaning |
//! |---|---|---|
//! | `state` | string | `disabled`, `enabling`, `idle`, `homing`, `jogging`, `mdi`, `running`, `held`, `stopping`, `alarm` or `starting` |
//! | `cycle` | integer | the cyclic thread's cycle number |
//! | `phase` | string | the cyclic master's phase (`Disabled`, `Enabling`, `Arming`, `Armed`, `Streaming`, `Settling`, `Stopping`, `Disabling`, `DriveControl`, `Done`) |
//! | `axes` | array | one object per axis, machine order: |
//! | `axes[].name` | string | axis letter |
//! | `axes[].node` | integer | CANopen node id |
//! | `axes[].commanded_mm` | number | setpoint sent this cycle |
//! | `axes[].actual_mm` | number | position actual (0x6064) |
//! | `axes[].following_error_mm` | number | setpoint in force at the drive minus position actual |
//! | `axes[].homed` | bool | homed since the service started (or since the last alarm) |
//! | `axes[].drive_state` | string or null | CiA 402 state decoded from the statusword |
//! | `axes[].statusword` | integer or null | 0x6041 |
//! | `axes[].control` | string | `cyclic`, `released`, `drive` (homing) or `rearming` |
//! | `job` | object or null | the job moving the machine: `kind` (`jog`, `mdi`, `program`) and `name` |
//! | `program` | string or null | the program file running |
//! | `line` | integer or null | the program line in execution |
//! | `queued` | integer | jobs waiting |
//! | `override` | object | `requested` and `effective` (fractions, 1 = 100 %) and `held` (bool) |
//! | `alarm` | object or null | the standing alarm: `kind` (the [`crate::master::alarm::Alarm`] variant), `node` (or null) and `message` |
//! | `homing_error` | string or null | the last homing's error |
//! | `modal` | string | the interpreter's modal state (G-codes, F, T) carried to the next MDI line or program |

use serde::Serialize;

use super::thread::Snapshot;
use super::{Info, JobKind};
use crate::cia402::State;
use crate::config::Machine;
use crate::master::alarm::Alarm;
use crate::master::cyclic::{AxisControl, Phase};

#[derive(Serialize)]
struct Status<'a> {
    state: &'static str,
    cycle: u64,
    phase: Option<String>,
    axes: Vec<AxisStatus<'a>>,
    job: Option<JobStatus<'a>>,
    program: Option<&'a str>,
    line: Option<usize>,
    queued: usize,
    #[serde(rename = "override")]
    override_: Override,
    alarm: Option<AlarmStatus>,
    homing_error: Option<&'a str>,
    modal: &'a str,
}

#[derive(Serialize)]
struct AxisStatus<'a> {
    name: &'a str,
    node: u8,
    commanded_mm: f64,
    actual_mm: f64,
    following_error_mm: f64,
    homed: bool,
    drive_state: Option<String>,
    statusword: Option<u16>,
    control: &'static str,
}

#[derive(Serialize)]
struct JobStatus<'a> {
    kind: JobKind,
    name: &'a str,
}

#[derive(Serialize)]
struct Override {
    requested: f64,
    effective: f64,
    held: bool,
}

#[derive(Serialize)]
struct AlarmStatus {
    kind: String,
    node: Option<u8>,
    message: String,
}

/// The state word of `status`.
pub fn state(s: &Snapshot, info: &Info) -> &'static str {
    if info.starting {
        return "starting";
    }
    if s.failure.is_some() {
        return "alarm";
    }
    if info.homing {
        return "homing";
    }
    match s.phase {
        None | Some(Phase::Disabled | Phase::Disabling | Phase::Done) => "disabled",
        Some(Phase::Enabling | Phase::Arming) => "enabling",
        Some(Phase::DriveControl) => "homing",
        Some(Phase::Stopping) => "stopping",
        Some(Phase::Armed | Phase::Streaming | Phase::Settling) => match &info.current {
            // A job queued and not started yet is already what the machine does.
            None => match info.next {
                None => "idle",
                Some(JobKind::Jog) => "jogging",
                Some(JobKind::Mdi) => "mdi",
                Some(JobKind::Program) => "running",
            },
            Some(_) if s.held && s.standing_still => "held",
            Some(c) => match c.kind {
                JobKind::Jog => "jogging",
                JobKind::Mdi => "mdi",
                JobKind::Program => "running",
            },
        },
    }
}

/// The variant name and node of an alarm.
fn alarm_kind(a: &Alarm) -> (String, Option<u8>) {
    let debug = format!("{a:?}");
    let kind = debug
        .split(|c: char| !c.is_ascii_alphanumeric())
        .next()
        .unwrap_or("")
        .to_string();
    let node = a.node();
    (kind, node)
}

/// The status line's JSON.
pub fn json(machine: &Machine, s: &Snapshot, info: &Info) -> String {
    let program = info
        .current
        .as_ref()
        .filter(|c| c.kind == JobKind::Program)
        .map(|c| c.name.as_str());
    let status = Status {
        state: state(s, info),
        cycle: s.cycle,
        phase: s.phase.map(|p| format!("{p:?}")),
        axes: machine
            .axes
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let x = &s.axes[i];
                AxisStatus {
                    name: &a.name,
                    node: a.node,
                    commanded_mm: x.commanded_mm,
                    actual_mm: x.actual_mm,
                    following_error_mm: x.following_error_mm,
                    homed: info.homed.get(i).copied().unwrap_or(false),
                    drive_state: x
                        .statusword
                        .and_then(State::from_statusword)
                        .map(|st| st.to_string()),
                    statusword: x.statusword,
                    control: match x.control {
                        None | Some(AxisControl::Cyclic) => "cyclic",
                        Some(AxisControl::Released) => "released",
                        Some(AxisControl::DriveOp) => "drive",
                        Some(AxisControl::Rearming) => "rearming",
                    },
                }
            })
            .collect(),
        job: info.current.as_ref().map(|c| JobStatus {
            kind: c.kind,
            name: &c.name,
        }),
        program,
        line: program.and(s.line),
        queued: info.queued,
        override_: Override {
            requested: s.override_requested,
            effective: s.override_effective,
            held: s.held,
        },
        alarm: s.failure.as_ref().map(|f| {
            let (kind, node) = alarm_kind(&f.alarm);
            AlarmStatus {
                kind,
                node,
                message: f.to_string(),
            }
        }),
        homing_error: info.homing_error.as_deref(),
        modal: &info.modal,
    };
    serde_json::to_string(&status).expect("plain data serialises")
}
