//! The protocol of `canmotion serve`'s control socket: one command per line, one answer line
//! per command, `ok ...` or `error: ...` (`watch` answers with a status line at its rate until
//! the client closes).
//!
//! | command | what it does |
//! |---|---|
//! | `enable` / `disable` | walk the drives to Operation enabled (holding position) / Switch on disabled |
//! | `home AXIS\|all` | home one axis, or every axis in the machine file's `order` ([`super::homing`]) |
//! | `jog AXIS SPEED` | continuous jog at SPEED mm/s (sign = direction) until `jog AXIS 0`, another command, or silence for `jog_timeout_ms` (dead-man: repeat the line to go on) |
//! | `jog AXIS SPEED DIST` | incremental jog of DIST mm (sign = direction) at SPEED mm/s |
//! | `mdi LINE` | one or more blocks, interpreted with the modal state of the earlier MDI lines and programs, queued |
//! | `run PATH [from LINE]` | a program file, interpreted completely, queued; `from LINE`: its motion from line LINE on, after a rapid move to where that line starts |
//! | `abort` | stop on the path, queue cleared (a homing under way stops too) |
//! | `reset` | clear the alarm once the drives are healthy, and enable them again |
//! | `override P`, `hold`, `resume` | feed override (0–200 %), feed hold, resume |
//! | `status` | `ok {json}` ([`super::status`]) |
//! | `watch [HZ]` | the status line HZ times a second (default 10, 0.1–100) until the client closes |
//! | `quit` | the orderly end, then the service exits |

use std::path::PathBuf;

use crate::config::Machine;
use crate::gateway::GatewayError;
use crate::master::cyclic::Refusal;

/// One command, parsed.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// `enable`.
    Enable,
    /// `disable`.
    Disable,
    /// `home AXIS` (axis indices) or `home all` (`None`).
    Home(Option<Vec<usize>>),
    /// `jog AXIS SPEED [DIST]`.
    Jog {
        /// Axis index, machine order.
        axis: usize,
        /// mm/s; its sign is the direction of a continuous jog.
        speed_mm_s: f64,
        /// Incremental jog: signed distance.
        dist_mm: Option<f64>,
    },
    /// `mdi LINE`.
    Mdi(String),
    /// `run PATH [from LINE]`.
    Run {
        /// The program file.
        path: PathBuf,
        /// Run from this line.
        from_line: Option<usize>,
    },
    /// `abort`.
    Abort,
    /// `reset`.
    Reset,
    /// `quit`.
    Quit,
    /// `status`.
    Status,
    /// `watch [HZ]`.
    Watch(f64),
    /// `override P`, `hold`, `resume` (and the keys of `run --control`): the run's
    /// [`crate::gateway::control::Control`] takes them.
    Operator(String),
}

/// Why a line is not a command.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParseError {
    /// Empty line.
    #[error("empty command")]
    Empty,
    /// Not UTF-8.
    #[error("the line is not UTF-8")]
    NotUtf8,
    /// Unknown command word.
    #[error(
        "unknown command '{word}' (enable, disable, home, jog, mdi, run, abort, reset, override, hold, resume, status, watch, quit)"
    )]
    Unknown {
        /// The word.
        word: String,
    },
    /// Wrong arguments.
    #[error("{command}: {problem}; usage: {usage}")]
    Usage {
        /// The command.
        command: &'static str,
        /// What is wrong.
        problem: String,
        /// Its usage.
        usage: &'static str,
    },
    /// An axis the machine does not have.
    #[error("no axis '{axis}' on this machine (axes: {axes})")]
    NoSuchAxis {
        /// The name given.
        axis: String,
        /// The machine's axes.
        axes: String,
    },
}

/// Parses one line.
pub fn parse(machine: &Machine, line: &[u8]) -> Result<Command, ParseError> {
    let line = std::str::from_utf8(line).map_err(|_| ParseError::NotUtf8)?;
    let line = line.trim();
    let (word, rest) = line.split_once(char::is_whitespace).unwrap_or((line, ""));
    let rest = rest.trim();
    let args: Vec<&str> = rest.split_whitespace().collect();
    let usage = |command: &'static str, usage: &'static str, problem: &str| ParseError::Usage {
        command,
        problem: problem.to_string(),
        usage,
    };
    let axis = |name: &str| -> Result<usize, ParseError> {
        machine
            .axes
            .iter()
            .position(|a| a.name.eq_ignore_ascii_case(name))
            .ok_or_else(|| ParseError::NoSuchAxis {
                axis: name.to_string(),
                axes: machine
                    .axes
                    .iter()
                    .map(|a| a.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    };
    let number = |command: &'static str, u: &'static str, s: &str| -> Result<f64, ParseError> {
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| usage(command, u, &format!("'{s}' is not a number")))
    };
    let no_args = |command: &'static str, c: Command| {
        if args.is_empty() {
            Ok(c)
        } else {
            Err(usage(command, command, "takes no arguments"))
        }
    };
    match word.to_ascii_lowercase().as_str() {
        "" => Err(ParseError::Empty),
        "enable" => no_args("enable", Command::Enable),
        "disable" => no_args("disable", Command::Disable),
        "abort" => no_args("abort", Command::Abort),
        "reset" => no_args("reset", Command::Reset),
        "quit" => no_args("quit", Command::Quit),
        "status" => no_args("status", Command::Status),
        "home" => {
            const U: &str = "home AXIS|all";
            match args.as_slice() {
                [a] if a.eq_ignore_ascii_case("all") => Ok(Command::Home(None)),
                [] => Err(usage("home", U, "which axis?")),
                names => Ok(Command::Home(Some(
                    names.iter().map(|n| axis(n)).collect::<Result<_, _>>()?,
                ))),
            }
        }
        "jog" => {
            const U: &str = "jog AXIS SPEED_MM_S [DIST_MM]";
            match args.as_slice() {
                [a, v] => Ok(Command::Jog {
                    axis: axis(a)?,
                    speed_mm_s: number("jog", U, v)?,
                    dist_mm: None,
                }),
                [a, v, d] => Ok(Command::Jog {
                    axis: axis(a)?,
                    speed_mm_s: number("jog", U, v)?,
                    dist_mm: Some(number("jog", U, d)?),
                }),
                _ => Err(usage("jog", U, "wrong number of arguments")),
            }
        }
        "mdi" => {
            if rest.is_empty() {
                Err(usage("mdi", "mdi G-CODE", "no G-code"))
            } else {
                Ok(Command::Mdi(rest.to_string()))
            }
        }
        "run" => {
            const U: &str = "run PATH [from LINE]";
            match args.as_slice() {
                [p] => Ok(Command::Run {
                    path: PathBuf::from(p),
                    from_line: None,
                }),
                [p, f, l] if f.eq_ignore_ascii_case("from") => {
                    Ok(Command::Run {
                        path: PathBuf::from(p),
                        from_line: Some(l.parse::<usize>().ok().filter(|l| *l > 0).ok_or_else(
                            || usage("run", U, &format!("'{l}' is not a line number")),
                        )?),
                    })
                }
                _ => Err(usage("run", U, "wrong arguments")),
            }
        }
        "watch" => {
            const U: &str = "watch [HZ]";
            match args.as_slice() {
                [] => Ok(Command::Watch(10.0)),
                [hz] => {
                    let hz = number("watch", U, hz)?;
                    if (0.1..=100.0).contains(&hz) {
                        Ok(Command::Watch(hz))
                    } else {
                        Err(usage("watch", U, "HZ must be 0.1 to 100"))
                    }
                }
                _ => Err(usage("watch", U, "wrong arguments")),
            }
        }
        "override" | "hold" | "resume" => Ok(Command::Operator(line.to_string())),
        _ => Err(ParseError::Unknown {
            word: word.to_string(),
        }),
    }
}

/// Why a command was refused or failed (the answer `error: ...`).
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// The cyclic master refused.
    #[error("{0}")]
    Refused(Refusal),
    /// An alarm stands.
    #[error("alarm: {alarm}; `reset` clears it once the drives are healthy")]
    Alarm {
        /// The alarm.
        alarm: String,
    },
    /// The drives are disabled.
    #[error("the drives are disabled: `enable` first")]
    Disabled,
    /// The drives are on their way (enabling, disabling, homing hand-over).
    #[error("not ready: the cyclic master is in phase {phase:?}")]
    NotReady {
        /// The phase.
        phase: crate::master::cyclic::Phase,
    },
    /// Something else is under way.
    #[error("busy with {what}: wait, or `abort`")]
    Busy {
        /// What.
        what: &'static str,
    },
    /// A condition did not come in time.
    #[error("{what} did not complete within {timeout_ms} ms")]
    TimedOut {
        /// What.
        what: &'static str,
        /// The limit.
        timeout_ms: u64,
    },
    /// The program (or MDI line) failed to interpret, plan or check.
    #[error("{0}")]
    Program(Box<GatewayError>),
    /// A program or MDI motion on an axis not homed.
    #[error(
        "{file}:{line}: axis {axis} is not homed: `home {axis}` first (or require_homing = false in [operation])"
    )]
    NotHomed {
        /// File (or `MDI`).
        file: String,
        /// Line.
        line: usize,
        /// The axis.
        axis: String,
    },
    /// A program file that cannot be read.
    #[error("{}: {reason}", path.display())]
    Read {
        /// The path.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// `run ... from LINE` without motion from there.
    #[error("no motion from line {line} on")]
    NoMotionFrom {
        /// The line.
        line: usize,
    },
    /// An axis the motion front end does not command.
    #[error("axis {axis} cannot be jogged (not an axis the motion front end commands)")]
    NotJoggable {
        /// The axis.
        axis: String,
    },
    /// An incremental jog beyond the travel of a homed axis.
    #[error("jog of {axis} to {target_mm:.4} mm: outside its travel {min_mm} .. {max_mm} mm")]
    JogOutsideTravel {
        /// The axis.
        axis: String,
        /// Where it would end.
        target_mm: f64,
        /// Travel.
        min_mm: f64,
        /// Travel.
        max_mm: f64,
    },
    /// A continuous jog towards a travel limit the axis stands at.
    #[error("axis {axis} stands at its travel limit in that direction")]
    AtTravelLimit {
        /// The axis.
        axis: String,
    },
    /// A drive still in Fault after its fault reset.
    #[error("a drive is still in Fault after its fault reset: remove the cause, then `reset`")]
    StillFaulted,
    /// Homing failed.
    #[error("{0}")]
    Homing(#[from] super::homing::HomingError),
    /// The cyclic thread is not running.
    #[error("the cyclic thread is not running (restart canmotion serve)")]
    NotRunning,
    /// A command the client's thread answers reached the controller.
    #[error("internal: command answered elsewhere")]
    NotHere,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_parse_with_their_arguments_and_errors_name_the_problem() {
        let m = Machine::demo();
        let p = |s: &str| parse(&m, s.as_bytes());
        assert_eq!(p("enable"), Ok(Command::Enable));
        assert_eq!(p("  home all "), Ok(Command::Home(None)));
        assert_eq!(p("home z x"), Ok(Command::Home(Some(vec![2, 0]))));
        assert_eq!(
            p("jog X -12.5"),
            Ok(Command::Jog {
                axis: 0,
                speed_mm_s: -12.5,
                dist_mm: None
            })
        );
        assert_eq!(
            p("jog Y 5 -0.1"),
            Ok(Command::Jog {
                axis: 1,
                speed_mm_s: 5.0,
                dist_mm: Some(-0.1)
            })
        );
        assert_eq!(p("mdi G0 X10 Y10"), Ok(Command::Mdi("G0 X10 Y10".into())));
        assert_eq!(
            p("run /tmp/part.ngc from 12"),
            Ok(Command::Run {
                path: "/tmp/part.ngc".into(),
                from_line: Some(12)
            })
        );
        assert_eq!(p("watch 2"), Ok(Command::Watch(2.0)));
        assert_eq!(
            p("override 50"),
            Ok(Command::Operator("override 50".into()))
        );
        assert!(matches!(p("home Q"), Err(ParseError::NoSuchAxis { .. })));
        assert!(matches!(
            p("jog X fast"),
            Err(ParseError::Usage { command: "jog", .. })
        ));
        assert!(matches!(p("watch 1000"), Err(ParseError::Usage { .. })));
        assert!(matches!(p("run a from 0"), Err(ParseError::Usage { .. })));
        assert!(matches!(p("enable now"), Err(ParseError::Usage { .. })));
        assert!(matches!(p("fly"), Err(ParseError::Unknown { .. })));
        assert_eq!(p(""), Err(ParseError::Empty));
        assert_eq!(parse(&m, b"\xff"), Err(ParseError::NotUtf8));
    }
}
