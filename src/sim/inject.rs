//! Misbehaviours a simulated drive can be told to show, for fault-reaction tests:
//! `--inject following-error@2.0s`, `--inject silent@1.5s`, `--inject reboot@1.0s`,
//! `--inject drop-rpdo=5%`, `--inject no-heartbeat@1s`, `--inject persistent-fault@1s`,
//! `--inject recurring-fault@1s`, `--inject fault@1s`, `--inject warning=0x4210@300ms`, `--inject slow-enable=2600ms`,
//! optionally for one node: `--inject 2:silent@1.5s`.
//!
//! `--inject bus-off@T` and `--inject error-passive@T` stand in for the *gateway's* CAN
//! controller: at T the drive sends the error frame a controller's driver would report
//! (`linux/can/error.h`), which every other socket with that class in its error mask receives as
//! if its own controller had reported it. vcan has no controller, so this is how a bus-off can
//! be tested on vcan0. The drive itself carries on.
//!
//! Times count from the moment the drive starts following setpoints (statusword bit 12 first
//! set), so a test can place a fault in the middle of a motion whatever the start-up took.

use std::str::FromStr;
use std::time::Duration;

/// One injected misbehaviour.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Inject {
    /// The motor jams (stops following): the following error grows until the drive faults
    /// (0x6065/0x6066, EMCY 0x8611).
    FollowingError {
        /// When, after motion start.
        after: Duration,
    },
    /// The drive falls silent: it sends nothing more and ignores every frame (a dead transceiver
    /// or a crashed communication stack). The motor holds.
    Silent {
        /// When, after motion start.
        after: Duration,
    },
    /// The drive resets (a watchdog, a power glitch): boot-up message, Pre-operational, power
    /// stage off.
    Reboot {
        /// When, after motion start.
        after: Duration,
    },
    /// The heartbeat producer stops (a hung communication task) while the process data goes on:
    /// only a heartbeat consumer notices. Until the next NMT reset.
    NoHeartbeat {
        /// When, after motion start.
        after: Duration,
    },
    /// The drive faults with EMCY 0x4310 (excess temperature) and the cause stays: a fault
    /// reset leaves it in Fault (CiA 402 transition 15 needs the cause gone).
    PersistentFault {
        /// When, after motion start.
        after: Duration,
    },
    /// The drive faults with EMCY 0x2310 (over-current); a fault reset clears it, but the fault
    /// comes back [`RECURRING_FAULT_DELAY`] after every reset (a short in the motor cable).
    RecurringFault {
        /// When, after motion start.
        after: Duration,
    },
    /// The drive faults once with EMCY 0x2310 (over-current, a transient): a fault reset
    /// clears it for good.
    Fault {
        /// When, after motion start.
        after: Duration,
    },
    /// This fraction of received RPDOs is lost (deterministic pseudo-random choice).
    DropRpdo {
        /// 0–100.
        percent: f64,
    },
    /// The drive warns: EMCY `code` and statusword bit 7 (warning), without the fault bit; the
    /// drive keeps running and the warning stays on until the next boot.
    Warning {
        /// EMCY code.
        code: u16,
        /// When, after motion start.
        after: Duration,
    },
    /// The drive takes this long (from the first controlword asking for it) to go from Switched
    /// on to Operation enabled: a drive with a brake to release or a commutation to find.
    SlowEnable {
        /// How long.
        delay: Duration,
    },
    /// A bus-off error frame is sent (see the module's documentation).
    BusOff {
        /// When, after motion start.
        after: Duration,
    },
    /// An error-passive error frame (both counters above 127) is sent.
    ErrorPassive {
        /// When, after motion start.
        after: Duration,
    },
}

/// How long after a fault reset a [`Inject::RecurringFault`] comes back.
pub const RECURRING_FAULT_DELAY: Duration = Duration::from_millis(50);

impl Inject {
    /// When a timed injection fires (after motion start); `None` for a rate.
    pub fn after(&self) -> Option<Duration> {
        match *self {
            Inject::FollowingError { after }
            | Inject::Silent { after }
            | Inject::Reboot { after }
            | Inject::NoHeartbeat { after }
            | Inject::PersistentFault { after }
            | Inject::RecurringFault { after }
            | Inject::Fault { after }
            | Inject::BusOff { after }
            | Inject::ErrorPassive { after }
            | Inject::Warning { after, .. } => Some(after),
            Inject::DropRpdo { .. } | Inject::SlowEnable { .. } => None,
        }
    }
}

/// An injection aimed at one node, or at every node of the process.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Targeted {
    /// `None` = every simulated node.
    pub node: Option<u8>,
    /// What to inject.
    pub inject: Inject,
}

fn parse_secs(s: &str, spec: &str) -> Result<Duration, String> {
    let n = s
        .strip_suffix("ms")
        .map(|v| (v, 1e-3))
        .or_else(|| s.strip_suffix('s').map(|v| (v, 1.0)));
    let (v, scale) =
        n.ok_or_else(|| format!("{spec:?}: a time needs a unit, e.g. 1.5s or 200ms"))?;
    let x: f64 = v
        .parse()
        .map_err(|_| format!("{spec:?}: {v:?} is not a number"))?;
    if !(x.is_finite() && x >= 0.0) {
        return Err(format!("{spec:?}: the time must be ≥ 0"));
    }
    Ok(Duration::from_secs_f64(x * scale))
}

impl FromStr for Targeted {
    type Err = String;

    fn from_str(spec: &str) -> Result<Targeted, String> {
        let (node, rest) = match spec.split_once(':') {
            Some((n, r)) => {
                let n: u8 = n
                    .parse()
                    .map_err(|_| format!("{spec:?}: {n:?} is not a node id"))?;
                if !(1..=127).contains(&n) {
                    return Err(format!("{spec:?}: node {n} outside 1..=127"));
                }
                (Some(n), r)
            }
            None => (None, spec),
        };
        let inject = if let Some((what, t)) = rest.split_once('@') {
            let after = parse_secs(t, spec)?;
            if let Some(c) = what.strip_prefix("warning=") {
                let code = c
                    .strip_prefix("0x")
                    .and_then(|h| u16::from_str_radix(h, 16).ok())
                    .filter(|&c| c != 0)
                    .ok_or_else(|| {
                        format!("{spec:?}: {c:?} is not an EMCY code, e.g. warning=0x4210@300ms")
                    })?;
                return Ok(Targeted {
                    node,
                    inject: Inject::Warning { code, after },
                });
            }
            match what {
                "following-error" => Inject::FollowingError { after },
                "silent" => Inject::Silent { after },
                "reboot" => Inject::Reboot { after },
                "no-heartbeat" => Inject::NoHeartbeat { after },
                "persistent-fault" => Inject::PersistentFault { after },
                "recurring-fault" => Inject::RecurringFault { after },
                "fault" => Inject::Fault { after },
                "bus-off" => Inject::BusOff { after },
                "error-passive" => Inject::ErrorPassive { after },
                _ => {
                    return Err(format!(
                        "{spec:?}: unknown fault {what:?} (following-error, silent, reboot, no-heartbeat, persistent-fault, recurring-fault, fault, bus-off, error-passive, drop-rpdo)"
                    ));
                }
            }
        } else if let Some(d) = rest.strip_prefix("slow-enable=") {
            Inject::SlowEnable {
                delay: parse_secs(d, spec)?,
            }
        } else if let Some(p) = rest.strip_prefix("drop-rpdo=") {
            let v = p
                .strip_suffix('%')
                .ok_or_else(|| format!("{spec:?}: a percentage, e.g. drop-rpdo=5%"))?;
            let percent: f64 = v
                .parse()
                .map_err(|_| format!("{spec:?}: {v:?} is not a number"))?;
            if !(0.0..=100.0).contains(&percent) {
                return Err(format!("{spec:?}: {percent} % outside 0..=100"));
            }
            Inject::DropRpdo { percent }
        } else {
            return Err(format!(
                "{spec:?}: expected following-error@T, silent@T, reboot@T, no-heartbeat@T, persistent-fault@T, recurring-fault@T, fault@T, bus-off@T, error-passive@T, warning=CODE@T, slow-enable=T or drop-rpdo=P% (optionally NODE: first)"
            ));
        };
        Ok(Targeted { node, inject })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse() {
        let ms = Duration::from_millis;
        assert_eq!(
            "following-error@2.0s".parse(),
            Ok(Targeted {
                node: None,
                inject: Inject::FollowingError { after: ms(2000) }
            })
        );
        assert_eq!(
            "2:silent@150ms".parse(),
            Ok(Targeted {
                node: Some(2),
                inject: Inject::Silent { after: ms(150) }
            })
        );
        assert_eq!(
            "reboot@1s".parse(),
            Ok(Targeted {
                node: None,
                inject: Inject::Reboot { after: ms(1000) }
            })
        );
        assert_eq!(
            "drop-rpdo=5%".parse(),
            Ok(Targeted {
                node: None,
                inject: Inject::DropRpdo { percent: 5.0 }
            })
        );
        assert_eq!(
            "3:no-heartbeat@250ms".parse(),
            Ok(Targeted {
                node: Some(3),
                inject: Inject::NoHeartbeat { after: ms(250) }
            })
        );
        assert_eq!(
            "persistent-fault@1s".parse::<Targeted>().map(|t| t.inject),
            Ok(Inject::PersistentFault { after: ms(1000) })
        );
        assert_eq!(
            "recurring-fault@0.5s".parse::<Targeted>().map(|t| t.inject),
            Ok(Inject::RecurringFault { after: ms(500) })
        );
        assert_eq!(
            "bus-off@250ms".parse(),
            Ok(Targeted {
                node: None,
                inject: Inject::BusOff { after: ms(250) }
            })
        );
        assert_eq!(
            "3:error-passive@0s".parse(),
            Ok(Targeted {
                node: Some(3),
                inject: Inject::ErrorPassive { after: ms(0) }
            })
        );
        assert_eq!(
            "1:warning=0x4210@300ms".parse(),
            Ok(Targeted {
                node: Some(1),
                inject: Inject::Warning {
                    code: 0x4210,
                    after: ms(300)
                }
            })
        );
        assert_eq!(
            "slow-enable=2600ms".parse::<Targeted>().map(|t| t.inject),
            Ok(Inject::SlowEnable { delay: ms(2600) })
        );
        for bad in [
            "warning=4210@1s",
            "warning=0x0@1s",
            "slow-enable=2",
            "no-heartbeat",
            "silent@",
            "silent@2",
            "jam@1s",
            "drop-rpdo=5",
            "drop-rpdo=150%",
            "0:silent@1s",
            "x:silent@1s",
        ] {
            assert!(bad.parse::<Targeted>().is_err(), "{bad}");
        }
    }
}
