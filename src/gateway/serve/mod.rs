//! `canmotion serve`: a long-running gateway. It starts the bus and every drive once, keeps the
//! drives enabled and holding between commands, and takes the operator's commands on a Unix
//! stream socket, one per line, each answered by one line `ok ...` or `error: ...`
//! ([`protocol`]): `enable`, `disable`, `home`, `jog`, `mdi`, `run`, `abort`, `reset`,
//! `override`, `hold`, `resume`, `status`, `watch`, `quit`.
//!
//! Three parts:
//! - the cyclic thread ([`thread`]): a [`crate::master::cyclic::CyclicMaster::service`] on the
//!   bus, from start-up to the orderly end;
//! - the controller (this module, on tokio): the job queue (MDI lines, programs, jogs, each
//!   interpreted and planned completely before it is queued), homing ([`homing`]), the jog's
//!   dead-man, alarms and reset, the orderly end;
//! - the socket's client threads: `status`, `watch`, `override`, `hold` and `resume` are
//!   answered there at once; `abort` is flagged there at once (a homing under way stops) and
//!   then queued; every other command goes to the controller, in order.

pub mod homing;
pub mod protocol;
pub mod status;
pub mod thread;

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use nalgebra::Vector3;

use super::control::{Control, ControlSocket};
use super::io::NodeIo;
use super::{GatewayError, startup};
use crate::bus::Bus;
use crate::config::Machine;
use crate::gcode::{AuxMove, AuxPos, Item, Program};
use crate::interpolator::{Interpolator, OverrideRamp};
use crate::master::cyclic::Phase;
use crate::rt;
use protocol::{Command, ServeError};
use thread::{Request, Snapshot, Thread};

/// Options of `canmotion serve`.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// The control socket's path.
    pub control_path: PathBuf,
    /// Start simulated drives in-process (with the in-process bus).
    pub simulate: bool,
    /// Misbehaviours of the simulated drives (tests).
    pub injects: Vec<crate::sim::Targeted>,
    /// A CSV log of every cycle (as `run --log`).
    pub log: Option<PathBuf>,
}

/// What kind of job moves the machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum JobKind {
    /// A jog.
    Jog,
    /// An MDI line.
    Mdi,
    /// A program file.
    Program,
}

/// A job, planned, waiting for its turn.
struct Job {
    kind: JobKind,
    name: String,
    interp: Interpolator,
    /// The interpreter's state after the job (the next job's start).
    carry_after: Option<crate::gcode::Carry>,
}

/// The job that moves the machine now.
#[derive(Debug, Clone)]
pub struct Current {
    /// Its kind.
    pub kind: JobKind,
    /// Program file name, `MDI`, or the jogged axis.
    pub name: String,
    /// Its number among the motions started ([`Snapshot::motions_started`]).
    seq: u64,
    /// Where it ends (the next job's start).
    end_mm: Vector3<f64>,
    /// Where it leaves the auxiliary axes (`None`: where they were).
    end_aux: Option<AuxPos>,
}

/// A jog under way.
#[derive(Debug, Clone, PartialEq)]
struct Jog {
    axis: usize,
    speed_mm_s: f64,
    dist_mm: Option<f64>,
    /// Continuous: it stops unless repeated by then (dead-man).
    deadline: Option<Instant>,
}

/// What the controller publishes for `status` (besides the cyclic thread's [`Snapshot`]).
#[derive(Debug, Clone, Default)]
pub struct Info {
    /// Homing under way.
    pub homing: bool,
    /// The job moving the machine.
    pub current: Option<Current>,
    /// Jobs waiting.
    pub queued: usize,
    /// The kind of the next job waiting.
    pub next: Option<JobKind>,
    /// Per axis, homed.
    pub homed: Vec<bool>,
    /// The interpreter's modal state, as G-codes.
    pub modal: String,
    /// The last homing error, until the next homing.
    pub homing_error: Option<String>,
    /// A drive start-up under way (after `reset` of a drive that reset).
    pub starting: bool,
}

/// What the client threads share with the controller.
pub struct Shared {
    machine: Machine,
    snapshot: Arc<Mutex<Snapshot>>,
    info: Mutex<Info>,
    control: Arc<Control>,
    /// Set by a client's `abort` or `quit` before it is queued: a homing under way stops.
    abort: AtomicBool,
    requests: tokio::sync::mpsc::UnboundedSender<(Command, tokio::sync::oneshot::Sender<String>)>,
}

impl Shared {
    fn snapshot(&self) -> Snapshot {
        self.snapshot
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    fn info(&self) -> Info {
        self.info.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// The `status` answer's JSON.
    pub fn status_json(&self) -> String {
        status::json(&self.machine, &self.snapshot(), &self.info())
    }
}

/// Runs `canmotion serve` until `quit` or a stop signal: the orderly end then stops any motion
/// on its path, disables the drives, has them stop consuming the gateway's heartbeat, and sends
/// them to Pre-operational.
pub fn serve(machine: &Machine, bus: &Bus, opts: &ServeOptions) -> Result<(), GatewayError> {
    rt::signal::STOP.begin_run();
    let _sims = if opts.simulate {
        Some(super::spawn_sims(machine, bus, &opts.injects)?)
    } else {
        None
    };
    super::runtime().block_on(serve_async(machine, bus, opts))
}

async fn serve_async(
    machine: &Machine,
    bus: &Bus,
    opts: &ServeOptions,
) -> Result<(), GatewayError> {
    let ramp = OverrideRamp::for_machine(&super::limits(machine), &machine.planner);
    let control = Arc::new(Control::new());
    control.reset(ramp.is_ok());
    let nodes: Vec<u8> = machine.axes.iter().map(|a| a.node).collect();
    let mut io = NodeIo::start(bus, &nodes)?;
    startup::start(machine, bus, &mut io, |_| Ok(())).await?;
    let (log_tx, log_thread) = match &opts.log {
        Some(path) => {
            let (tx, thread) = super::spawn_logger(path, machine)?;
            (Some(tx), Some(thread))
        }
        None => (None, None),
    };
    let snapshot = Arc::new(Mutex::new(Snapshot::default()));
    let thread = Thread::spawn(
        machine,
        bus,
        super::supervision_from(machine, &io.health()),
        control.clone(),
        snapshot.clone(),
        log_tx.clone(),
    )?;
    // The socket opens once the cyclic thread runs (its first snapshot is out).
    let first = tokio::time::Instant::now();
    while snapshot
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .phase
        .is_none()
    {
        if first.elapsed() > Duration::from_secs(2) {
            break;
        }
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    let (req_tx, req_rx) = tokio::sync::mpsc::unbounded_channel();
    let shared = Arc::new(Shared {
        machine: machine.clone(),
        snapshot,
        info: Mutex::new(Info {
            homed: vec![false; machine.axes.len()],
            ..Info::default()
        }),
        control: control.clone(),
        abort: AtomicBool::new(false),
        requests: req_tx,
    });
    let socket = ControlSocket::bind_with(&opts.control_path, shared.clone())?;
    set_socket_mode(&opts.control_path);
    tracing::info!(
        "canmotion serve: {} axes on {}; control socket {}",
        machine.axes.len(),
        bus.name(),
        opts.control_path.display()
    );
    let mut ctl = Controller {
        m: machine,
        bus,
        io,
        thread: Some(thread),
        shared: shared.clone(),
        ramp: ramp.ok(),
        homed: vec![false; machine.axes.len()],
        queue: VecDeque::new(),
        current: None,
        carry: None,
        started_carry: None,
        jog: None,
        alarm_seen: false,
        log_tx,
    };
    let result = ctl.run(req_rx).await;
    drop(socket);
    drop(ctl);
    if let Some(t) = log_thread {
        let _ = t.join();
    }
    result
}

/// Mode 0660: the socket's group controls the machine.
fn set_socket_mode(path: &Path) {
    use std::os::unix::fs::PermissionsExt;
    if let Err(e) = std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o660)) {
        tracing::warn!("{}: cannot set mode 0660: {e}", path.display());
    }
}

/// How often the controller looks at the machine between commands.
const TICK: Duration = Duration::from_millis(5);

struct Controller<'a> {
    m: &'a Machine,
    bus: &'a Bus,
    io: NodeIo,
    thread: Option<Thread>,
    shared: Arc<Shared>,
    ramp: Option<OverrideRamp>,
    homed: Vec<bool>,
    queue: VecDeque<Job>,
    current: Option<Current>,
    /// The interpreter's state after the last job queued (MDI lines and programs).
    carry: Option<crate::gcode::Carry>,
    /// The interpreter's state after the last job started: what an abort or an alarm, which
    /// drop the jobs still queued, go back to.
    started_carry: Option<crate::gcode::Carry>,
    jog: Option<Jog>,
    /// The standing alarm has been acted on (queue cleared, axes unhomed).
    alarm_seen: bool,
    log_tx: Option<std::sync::mpsc::SyncSender<crate::master::cyclic::CycleRecord>>,
}

impl Controller<'_> {
    async fn run(
        &mut self,
        mut rx: tokio::sync::mpsc::UnboundedReceiver<(
            Command,
            tokio::sync::oneshot::Sender<String>,
        )>,
    ) -> Result<(), GatewayError> {
        let mut tick = tokio::time::interval(TICK);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                r = rx.recv() => {
                    let Some((cmd, reply)) = r else { break };
                    let quit = cmd == Command::Quit;
                    let answer = match self.handle(cmd).await {
                        Ok(ok) => format!("ok {ok}").trim_end().to_string(),
                        Err(e) => format!("error: {e}"),
                    };
                    if quit {
                        let end = self.orderly_end().await;
                        let _ = reply.send(match &end {
                            Ok(()) => answer,
                            Err(e) => format!("error: {e}"),
                        });
                        return end;
                    }
                    let _ = reply.send(answer);
                }
                _ = tick.tick() => {
                    self.tick().await;
                }
            }
            if rt::signal::STOP.first().is_some() {
                tracing::info!("stop signal: orderly end");
                return self.orderly_end().await;
            }
        }
        self.orderly_end().await
    }

    fn snapshot(&self) -> Snapshot {
        self.shared.snapshot()
    }

    async fn ask(&self, req: Request) -> Result<(), ServeError> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        let thread = self.thread.as_ref().ok_or(ServeError::NotRunning)?;
        thread
            .tx
            .send((req, tx))
            .map_err(|_| ServeError::NotRunning)?;
        rx.await
            .map_err(|_| ServeError::NotRunning)?
            .map_err(ServeError::Refused)
    }

    /// Waits (a condition with a deadline) until `done` holds on the snapshot; `Err` with the
    /// alarm if one stands first (unless `alarm_ok`).
    async fn wait_for(
        &self,
        what: &'static str,
        timeout: Duration,
        alarm_ok: bool,
        done: impl Fn(&Snapshot) -> bool,
    ) -> Result<Snapshot, ServeError> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let s = self.snapshot();
            if done(&s) {
                return Ok(s);
            }
            if !alarm_ok && let Some(f) = &s.failure {
                return Err(ServeError::Alarm {
                    alarm: f.to_string(),
                });
            }
            if s.ended {
                return Err(ServeError::NotRunning);
            }
            if tokio::time::Instant::now() >= deadline {
                return Err(ServeError::TimedOut {
                    what,
                    timeout_ms: timeout.as_millis() as u64,
                });
            }
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
    }

    fn publish(&self) {
        let mut info = self.shared.info.lock().unwrap_or_else(|e| e.into_inner());
        info.current = self.current.clone();
        info.queued = self.queue.len();
        info.next = self.queue.front().map(|j| j.kind);
        info.homed.clone_from(&self.homed);
        info.modal = self
            .carry
            .as_ref()
            .map(crate::gcode::Carry::modal_summary)
            .unwrap_or_default();
    }

    /// Between commands: jobs that ended, the next job, the jog's dead-man, a new alarm.
    async fn tick(&mut self) {
        let s = self.snapshot();
        self.observe(&s).await;
        if let Some(j) = &self.jog
            && j.deadline.is_some_and(|d| Instant::now() >= d)
        {
            // The dead-man: the jog was not repeated in time.
            self.jog = None;
            let _ = self.ask(Request::Abort).await;
        }
        if self.current.is_none()
            && s.idle
            && s.failure.is_none()
            && let Some(job) = self.queue.pop_front()
        {
            let seq = s.motions_started + 1;
            let end_mm = job.interp.queued_end_mm();
            let end_aux = job.interp.queued_end_aux();
            match self.ask(Request::Start(Box::new(job.interp))).await {
                Ok(()) => {
                    if job.kind != JobKind::Jog {
                        self.started_carry = job.carry_after;
                    }
                    self.current = Some(Current {
                        kind: job.kind,
                        name: job.name,
                        seq,
                        end_mm,
                        end_aux,
                    });
                }
                Err(e) => {
                    tracing::warn!("{}: not started: {e}; queue cleared", job.name);
                    self.drop_queue();
                }
            }
        }
        self.publish();
    }

    /// Drops the jobs still queued; the interpreter's state goes back to the last job started.
    fn drop_queue(&mut self) {
        if !self.queue.is_empty() {
            self.queue.clear();
            self.carry.clone_from(&self.started_carry);
        }
    }

    /// What the cyclic thread did since the last look: the job that ended, and a new alarm (a
    /// fault stop: what was queued will not run, and the axes must be homed again, since a
    /// drive that faulted or reset may have lost its position). Runs between commands and
    /// before each one, so that no command sees a state the alarm made stale.
    async fn observe(&mut self, s: &Snapshot) {
        if let Some(c) = &self.current
            && s.motions_ended >= c.seq
        {
            if c.kind == JobKind::Jog {
                self.jog = None;
            }
            self.current = None;
        }
        if s.failure.is_some() && !self.alarm_seen {
            self.alarm_seen = true;
            self.drop_queue();
            self.current = None;
            self.jog = None;
            for (h, a) in self.homed.iter_mut().zip(&self.m.axes) {
                *h = a
                    .homing
                    .as_ref()
                    .is_some_and(|h| h.method == crate::config::operation::HomingMethod::Absolute);
            }
            for i in 0..self.m.axes.len() {
                let _ = self
                    .ask(Request::TravelChecked(i, self.travel_checked(i)))
                    .await;
            }
            self.publish();
        }
    }

    fn travel_checked(&self, i: usize) -> bool {
        self.homed[i] || !self.m.operation.require_homing
    }

    /// Where the next job starts: the end of the last one queued, or of the one running, or
    /// where the axes hold.
    fn tail_mm(&self, s: &Snapshot) -> Vector3<f64> {
        if let Some(j) = self.queue.back() {
            return j.interp.queued_end_mm();
        }
        if let Some(c) = &self.current {
            return c.end_mm;
        }
        let mut p = Vector3::zeros();
        for (i, a) in self.m.axes.iter().enumerate() {
            if let Some(k) = a.xyz() {
                p[k] = s.axes[i].commanded_mm;
            }
        }
        p
    }

    /// Where the next job starts on the auxiliary axes (A B C U V W; 0 for those the machine
    /// lacks), as [`tail_mm`](Self::tail_mm).
    fn tail_aux(&self, s: &Snapshot) -> AuxPos {
        let queued = match (self.queue.back(), &self.current) {
            (Some(j), _) => j.interp.queued_end_aux(),
            (None, Some(c)) => c.end_aux,
            (None, None) => None,
        };
        if let Some(aux) = queued {
            return aux;
        }
        let mut aux = [0.0; 6];
        for (i, a) in self.m.axes.iter().enumerate() {
            if let Some(k) = a.aux() {
                aux[k] = s.axes[i].commanded_mm;
            }
        }
        aux
    }

    fn busy(&self) -> bool {
        self.current.is_some() || !self.queue.is_empty()
    }

    fn check_ready(&self, s: &Snapshot) -> Result<(), ServeError> {
        if let Some(f) = &s.failure {
            return Err(ServeError::Alarm {
                alarm: f.to_string(),
            });
        }
        if self.shared.info().homing {
            return Err(ServeError::Busy { what: "homing" });
        }
        match s.phase {
            Some(Phase::Armed | Phase::Streaming | Phase::Settling | Phase::Stopping) => Ok(()),
            None | Some(Phase::Disabled | Phase::Done) => Err(ServeError::Disabled),
            Some(phase) => Err(ServeError::NotReady { phase }),
        }
    }

    async fn handle(&mut self, cmd: Command) -> Result<String, ServeError> {
        let s = self.snapshot();
        self.observe(&s).await;
        // Any command but the same jog again stops a jog.
        if let Some(j) = self.jog.clone() {
            let same = matches!(&cmd, Command::Jog { axis, speed_mm_s, dist_mm: None }
                if *axis == j.axis && *speed_mm_s == j.speed_mm_s && j.dist_mm.is_none());
            if same {
                let timeout = self.jog_timeout();
                if let Some(d) = self.jog.as_mut().and_then(|j| j.deadline.as_mut()) {
                    *d = Instant::now() + timeout;
                }
                return Ok(format!("jogging {}", self.m.axes[j.axis].name));
            }
            self.stop_motion().await?;
        }
        self.shared.abort.store(false, Ordering::Release);
        match cmd {
            Command::Enable => self.enable().await,
            Command::Disable => {
                if self.busy() {
                    return Err(ServeError::Busy { what: "a job" });
                }
                let s = self.snapshot();
                if s.phase == Some(Phase::Disabled) {
                    return Ok("disabled".into());
                }
                self.ask(Request::Disable).await?;
                self.wait_for("disable", Duration::from_secs(3), true, |s| {
                    s.phase == Some(Phase::Disabled)
                })
                .await?;
                Ok("disabled".into())
            }
            Command::Home(axes) => {
                let s = self.snapshot();
                self.check_ready(&s)?;
                if self.busy() {
                    return Err(ServeError::Busy { what: "a job" });
                }
                let axes = match axes {
                    Some(a) => a,
                    None => (0..self.m.axes.len()).collect(),
                };
                self.shared
                    .info
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .homing = true;
                let r = homing::home(self, &axes).await;
                {
                    let mut info = self.shared.info.lock().unwrap_or_else(|e| e.into_inner());
                    info.homing = false;
                    info.homing_error = r.as_ref().err().map(ToString::to_string);
                }
                for i in 0..self.m.axes.len() {
                    self.ask(Request::TravelChecked(i, self.travel_checked(i)))
                        .await?;
                }
                self.publish();
                r.map(|()| {
                    let names: Vec<&str> =
                        axes.iter().map(|i| self.m.axes[*i].name.as_str()).collect();
                    format!("homed {}", names.join(" "))
                })
            }
            Command::Jog {
                axis,
                speed_mm_s,
                dist_mm,
            } => self.jog(axis, speed_mm_s, dist_mm).await,
            Command::Mdi(text) => {
                let s = self.snapshot();
                self.check_ready(&s)?;
                let text = format!("{text}\n");
                self.queue_job(JobKind::Mdi, "MDI", &text, None, &s)
            }
            Command::Run { path, from_line } => {
                let s = self.snapshot();
                self.check_ready(&s)?;
                let text = std::fs::read_to_string(&path).map_err(|e| ServeError::Read {
                    path: path.clone(),
                    reason: e.to_string(),
                })?;
                let name = path.display().to_string();
                self.queue_job(JobKind::Program, &name, &text, from_line, &s)
            }
            Command::Abort => {
                self.drop_queue();
                self.jog = None;
                let s = self.snapshot();
                if s.phase == Some(Phase::Streaming) || self.current.is_some() {
                    self.stop_motion().await?;
                }
                self.publish();
                Ok("aborted".into())
            }
            Command::Reset => self.reset().await,
            Command::Quit => Ok("bye".into()),
            // Answered by the client's thread.
            Command::Status | Command::Watch(_) | Command::Operator(_) => Err(ServeError::NotHere),
        }
    }

    fn jog_timeout(&self) -> Duration {
        Duration::from_millis(u64::from(self.m.operation.jog_timeout_ms))
    }

    async fn enable(&mut self) -> Result<String, ServeError> {
        let s = self.snapshot();
        if let Some(f) = &s.failure {
            return Err(ServeError::Alarm {
                alarm: f.to_string(),
            });
        }
        if s.phase == Some(Phase::Disabled) {
            self.ask(Request::Enable).await?;
        } else if s.phase == Some(Phase::Disabling) {
            return Err(ServeError::NotReady {
                phase: Phase::Disabling,
            });
        }
        let timeout = self
            .m
            .axes
            .iter()
            .map(|a| a.enable_timeout_ms)
            .max()
            .unwrap_or(1000);
        self.wait_for(
            "enable",
            Duration::from_millis(2 * u64::from(timeout) + 500),
            false,
            |s| s.idle,
        )
        .await?;
        Ok("enabled".into())
    }

    /// Stops the motion under way on its path and waits until the axes hold.
    async fn stop_motion(&mut self) -> Result<(), ServeError> {
        self.jog = None;
        self.ask(Request::Abort).await?;
        self.wait_for("stop", Duration::from_secs(30), true, |s| {
            s.idle || s.failure.is_some() || s.phase == Some(Phase::Disabled)
        })
        .await?;
        self.current = None;
        self.publish();
        Ok(())
    }

    /// Interprets and plans a job completely, checks it against the machine (axes, travel,
    /// homing), and queues it.
    fn queue_job(
        &mut self,
        kind: JobKind,
        name: &str,
        text: &str,
        from_line: Option<usize>,
        s: &Snapshot,
    ) -> Result<String, ServeError> {
        let start = self.tail_mm(s);
        let start_aux = self.tail_aux(s);
        let mut setup = self.m.setup(start);
        setup.start_aux = start_aux;
        setup.carry = self.carry.clone();
        let program = if kind == JobKind::Mdi {
            crate::gcode::parse_mdi(text, setup)
        } else {
            crate::gcode::parse_program_with(text, name, setup)
        }
        .map_err(|e| ServeError::Program(Box::new(GatewayError::Program(e))))?;
        let mut program =
            crate::compensation::compensate_program(&program, self.m.program.compensation)
                .map_err(|e| ServeError::Program(Box::new(GatewayError::from(e))))?;
        if let Some(line) = from_line {
            from_line_on(&mut program, line, start, start_aux)
                .ok_or(ServeError::NoMotionFrom { line })?;
        }
        for item in &program.items {
            match item {
                Item::Motion(e) => {
                    super::check_element(self.m, name, e)
                        .map_err(|e| ServeError::Program(Box::new(e)))?;
                    self.check_homed(name, e)?;
                }
                Item::Stop(stop) => {
                    return Err(ServeError::Program(Box::new(GatewayError::Program(
                        crate::gcode::Error {
                            file: name.to_string(),
                            line: stop.line,
                            col: stop.col,
                            kind: crate::gcode::ErrorKind::Unsupported {
                                what: if stop.optional { "M1" } else { "M0" }.to_string(),
                                reason: "the gateway cannot pause a running program yet",
                            },
                            called_from: None,
                        },
                    ))));
                }
                _ => {}
            }
        }
        let carry_after = Some(program.carry.clone());
        let elements = program.elements().count();
        if elements == 0 {
            // Modal changes only: they take effect now (after the jobs queued before).
            if self.queue.is_empty() {
                self.started_carry.clone_from(&carry_after);
            }
            self.carry = carry_after;
            self.publish();
            return Ok(format!("{name}: no motion"));
        }
        let plan = crate::planner::plan_with(&program, &super::limits(self.m), &self.m.planner)
            .map_err(|source| {
                ServeError::Program(Box::new(GatewayError::Plan {
                    file: name.to_string(),
                    source,
                }))
            })?;
        let duration = plan.duration_s();
        let interp = self.interpolator(plan)?;
        self.carry = carry_after.clone();
        self.queue.push_back(Job {
            kind,
            name: name.to_string(),
            interp,
            carry_after,
        });
        self.publish();
        Ok(format!(
            "queued {name}: {elements} moves, {duration:.3} s{}",
            if self.queue.len() > 1 || self.current.is_some() {
                format!(
                    " ({} ahead)",
                    self.queue.len() - 1 + usize::from(self.current.is_some())
                )
            } else {
                String::new()
            }
        ))
    }

    fn interpolator(&self, plan: crate::planner::Plan) -> Result<Interpolator, ServeError> {
        let i = Interpolator::new(plan, self.m.cycle_s()).map_err(|e| {
            ServeError::Program(Box::new(GatewayError::Motion(super::MotionFailure::plain(
                e.into(),
                self.m.cycle_s(),
            ))))
        })?;
        Ok(match self.ramp {
            Some(r) => i.with_override_ramp(r),
            None => i,
        })
    }

    fn check_homed(&self, name: &str, e: &crate::gcode::Element) -> Result<(), ServeError> {
        if !self.m.operation.require_homing {
            return Ok(());
        }
        let (lo, hi) = e.bounds_mm();
        for (i, a) in self.m.axes.iter().enumerate() {
            let moves = match (a.xyz(), a.aux()) {
                (Some(k), _) => e.end_mm[k] != e.start_mm[k] || hi[k] > lo[k],
                (None, Some(k)) => e.aux.start[k] != e.aux.end[k],
                (None, None) => false,
            };
            if moves && !self.homed[i] {
                return Err(ServeError::NotHomed {
                    file: name.to_string(),
                    line: e.line,
                    axis: a.name.clone(),
                });
            }
        }
        Ok(())
    }

    async fn jog(
        &mut self,
        axis: usize,
        speed_mm_s: f64,
        dist_mm: Option<f64>,
    ) -> Result<String, ServeError> {
        let s = self.snapshot();
        self.check_ready(&s)?;
        if self.busy() {
            return Err(ServeError::Busy { what: "a job" });
        }
        let a = &self.m.axes[axis];
        if a.xyz().is_none() && a.aux().is_none() {
            return Err(ServeError::NotJoggable {
                axis: a.name.clone(),
            });
        }
        if speed_mm_s == 0.0 || dist_mm == Some(0.0) {
            return Ok(format!("{} stopped", a.name));
        }
        let homed = self.travel_checked(axis);
        let v_max = if homed {
            a.max_vel_mm_s
        } else {
            a.max_vel_mm_s * self.m.operation.unhomed_jog_fraction
        };
        let v = speed_mm_s.abs().min(v_max);
        let here = self.tail_mm(&s);
        let here_aux = self.tail_aux(&s);
        // Where the jogged axis stands: an X/Y/Z axis or an auxiliary one.
        let from = match (a.xyz(), a.aux()) {
            (Some(k), _) => here[k],
            (None, Some(k)) => here_aux[k],
            (None, None) => unreachable!("refused above"),
        };
        let dir = match dist_mm {
            Some(d) => d.signum(),
            None => speed_mm_s.signum(),
        };
        let to = match dist_mm {
            Some(d) => from + d.abs() * dir,
            None if homed => {
                if dir > 0.0 {
                    a.max_mm
                } else {
                    a.min_mm
                }
            }
            None => from + dir * (a.max_mm - a.min_mm),
        };
        if homed && a.has_travel() && !(a.min_mm..=a.max_mm).contains(&to) {
            return Err(ServeError::JogOutsideTravel {
                axis: a.name.clone(),
                target_mm: to,
                min_mm: a.min_mm,
                max_mm: a.max_mm,
            });
        }
        if (to - from).abs() < 0.5 / a.counts_per_mm {
            return Err(ServeError::AtTravelLimit {
                axis: a.name.clone(),
            });
        }
        let text = format!(
            "G21 G90 G94 G64 P0 G53 G1 {}{:.9} F{:.6}\n",
            a.name,
            to,
            v * 60.0
        );
        // The auxiliary axes start where they are (and only the jogged one moves).
        let mut setup = crate::gcode::Setup::new(here);
        setup.start_aux = here_aux;
        if let Some(k) = a.aux() {
            setup.aux_axes[k] = true;
        }
        let program = crate::gcode::parse_program_with(&text, "jog", setup)
            .map_err(|e| ServeError::Program(Box::new(GatewayError::Program(e))))?;
        // Jogs are jerk-limited whatever the machine's planner mode: the jerk-limited profile
        // with the axes' max_jerk_mm_s3 (a single straight move: time-optimal for the limits).
        let mut config = self.m.planner;
        if config.profile == crate::planner::ProfileKind::Trapezoid {
            config.profile = crate::planner::ProfileKind::SCurve;
        }
        let limits = super::limits(self.m);
        let plan = crate::planner::plan_with(&program, &limits, &config).map_err(|source| {
            ServeError::Program(Box::new(GatewayError::Plan {
                file: "jog".into(),
                source,
            }))
        })?;
        let interp = Interpolator::new(plan, self.m.cycle_s()).map_err(|e| {
            ServeError::Program(Box::new(GatewayError::Motion(super::MotionFailure::plain(
                e.into(),
                self.m.cycle_s(),
            ))))
        })?;
        let interp = match OverrideRamp::for_machine(&limits, &config) {
            Ok(r) => interp.with_override_ramp(r),
            Err(_) => interp,
        };
        let seq = s.motions_started + 1;
        let end_mm = interp.queued_end_mm();
        let end_aux = interp.queued_end_aux();
        self.ask(Request::Start(Box::new(interp))).await?;
        self.current = Some(Current {
            kind: JobKind::Jog,
            name: a.name.clone(),
            seq,
            end_mm,
            end_aux,
        });
        self.jog = Some(Jog {
            axis,
            speed_mm_s,
            dist_mm,
            deadline: dist_mm
                .is_none()
                .then(|| Instant::now() + self.jog_timeout()),
        });
        self.publish();
        Ok(match dist_mm {
            Some(d) => format!("jog {} {:+.4} mm at {v:.3} mm/s", a.name, d.abs() * dir),
            None => format!(
                "jogging {} at {:+.3} mm/s{}",
                a.name,
                v * dir,
                if homed {
                    ""
                } else {
                    " (not homed: reduced speed)"
                }
            ),
        })
    }

    /// `reset`: clears the standing alarm once the drives are healthy, and enables them again.
    /// After a drive reset or the loss of the bus the drives are started up again first.
    async fn reset(&mut self) -> Result<String, ServeError> {
        let s = self.snapshot();
        if s.failure.is_none() {
            return Ok("no alarm".into());
        }
        if s.needs_startup || s.ended {
            // The fault stop first: every drive disabled (or the bus gone).
            self.wait_for("stop", Duration::from_secs(5), true, |s| {
                s.ended || matches!(s.phase, Some(Phase::Disabled | Phase::Done))
            })
            .await?;
            self.restart().await?;
        } else {
            self.wait_for("stop", Duration::from_secs(5), true, |s| {
                s.phase == Some(Phase::Disabled)
            })
            .await?;
            self.ask(Request::ResetAlarm).await?;
            // The faulted drives get their fault reset: wait until none reports Fault.
            let n = self.m.axes.len();
            self.wait_for("fault reset", Duration::from_secs(3), false, |s| {
                s.axes[..n].iter().all(|a| {
                    a.statusword
                        .is_some_and(|w| w & crate::cia402::statusword::FAULT == 0)
                })
            })
            .await
            .map_err(|e| match e {
                ServeError::TimedOut { .. } => ServeError::StillFaulted,
                e => e,
            })?;
        }
        self.alarm_seen = false;
        self.enable().await?;
        Ok("alarm cleared, enabled".into())
    }

    /// Starts the drives up again (after a drive reset or the loss of the bus), with a new
    /// cyclic thread.
    async fn restart(&mut self) -> Result<(), ServeError> {
        if let Some(t) = self.thread.take() {
            let (tx, _rx) = tokio::sync::oneshot::channel();
            let _ = t.tx.send((Request::Quit { force: true }, tx));
            let _ = tokio::task::spawn_blocking(move || t.join()).await;
        }
        self.shared
            .info
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .starting = true;
        let r = startup::start(self.m, self.bus, &mut self.io, |_| Ok(())).await;
        self.shared
            .info
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .starting = false;
        r.map_err(|e| ServeError::Program(Box::new(e)))?;
        *self
            .shared
            .snapshot
            .lock()
            .unwrap_or_else(|e| e.into_inner()) = Snapshot::default();
        let t = Thread::spawn(
            self.m,
            self.bus,
            super::supervision_from(self.m, &self.io.health()),
            self.shared.control.clone(),
            self.shared.snapshot.clone(),
            self.log_tx.clone(),
        )
        .map_err(|e| ServeError::Program(Box::new(e)))?;
        self.thread = Some(t);
        self.wait_for("start-up", Duration::from_secs(2), true, |s| {
            s.phase == Some(Phase::Disabled)
        })
        .await?;
        Ok(())
    }

    /// The orderly end: any motion stopped on its path, the drives disabled, the cyclic thread
    /// ended (drives Pre-operational), the drives no longer consuming the gateway's heartbeat
    /// (unless an alarm stands: then they keep watching it), the heartbeat stopped.
    async fn orderly_end(&mut self) -> Result<(), GatewayError> {
        self.queue.clear();
        let Some(thread) = self.thread.take() else {
            return Ok(());
        };
        self.thread = Some(thread);
        let s = self.snapshot();
        if matches!(s.phase, Some(Phase::Streaming | Phase::Settling)) {
            let _ = self.stop_motion().await;
        }
        let _ = self.ask(Request::Disable).await;
        let _ = self
            .wait_for("disable", Duration::from_secs(3), true, |s| {
                s.phase == Some(Phase::Disabled) || s.phase == Some(Phase::Done)
            })
            .await;
        let alarm = self.snapshot().failure.is_some();
        let force = self.snapshot().phase != Some(Phase::Disabled);
        let _ = self.ask(Request::Quit { force }).await;
        let thread = self.thread.take().expect("put back above");
        let port_err = tokio::task::spawn_blocking(move || thread.join())
            .await
            .ok()
            .flatten();
        let r = if alarm || port_err.is_some() {
            Ok(())
        } else {
            startup::stop_consuming_heartbeat(self.m, self.bus, &mut self.io).await
        };
        self.io.stop_heartbeat();
        r
    }

    fn homing_aborted(&self) -> bool {
        self.shared.abort.load(Ordering::Acquire) || rt::signal::STOP.first().is_some()
    }
}

/// `run PATH from LINE`: the program's motion from the first element of line `LINE` on (its
/// modal state and position established by the lines before), preceded by a straight rapid
/// move from `start` to where that element starts, which ends at rest (exact stop). `None`
/// without motion from there.
fn from_line_on(
    program: &mut Program,
    line: usize,
    start: Vector3<f64>,
    start_aux: AuxPos,
) -> Option<()> {
    let first = program
        .items
        .iter()
        .position(|i| matches!(i, Item::Motion(e) if e.line >= line))?;
    let Item::Motion(e) = &program.items[first] else {
        unreachable!()
    };
    let mut lead_in = *e;
    lead_in.kind = crate::gcode::ElementKind::Line;
    lead_in.rapid = true;
    lead_in.feed_mm_s = None;
    // It arrives where the line starts, at rest, before the line runs.
    lead_in.blend = crate::gcode::BlendMode::ExactStop;
    lead_in.start_mm = start;
    lead_in.end_mm = e.start_mm;
    lead_in.aux = AuxMove {
        start: start_aux,
        end: e.aux.start,
    };
    program.items.drain(..first);
    if lead_in.start_mm != lead_in.end_mm || lead_in.aux.moves() {
        program.items.insert(0, Item::Motion(lead_in));
    }
    program.start_mm = start;
    Some(())
}

impl super::control::Handler for Shared {
    fn handle(
        &self,
        line: &[u8],
        out: &mut std::os::unix::net::UnixStream,
        stop: &AtomicBool,
    ) -> std::io::Result<()> {
        use std::io::Write;
        let cmd = match protocol::parse(&self.machine, line) {
            Ok(c) => c,
            Err(e) => return writeln!(out, "error: {e}"),
        };
        match cmd {
            Command::Status => writeln!(out, "ok {}", self.status_json()),
            Command::Watch(hz) => {
                let period = Duration::from_secs_f64(1.0 / hz);
                let mut next = Instant::now();
                // Until the client closes (the write fails) or the service ends.
                while !stop.load(Ordering::Acquire) {
                    writeln!(out, "ok {}", self.status_json())?;
                    next += period;
                    std::thread::sleep(next.saturating_duration_since(Instant::now()));
                }
                Ok(())
            }
            Command::Operator(text) => writeln!(out, "{}", self.control.answer(text.as_bytes())),
            cmd => {
                if matches!(cmd, Command::Abort | Command::Quit) {
                    self.abort.store(true, Ordering::Release);
                }
                let (tx, rx) = tokio::sync::oneshot::channel();
                if self.requests.send((cmd, tx)).is_err() {
                    return writeln!(out, "error: the service is ending");
                }
                match rx.blocking_recv() {
                    Ok(answer) => writeln!(out, "{answer}"),
                    Err(_) => writeln!(out, "error: the service is ending"),
                }
            }
        }
    }
}
