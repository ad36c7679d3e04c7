//! The cyclic thread of `canmotion serve`: a [`CyclicMaster::service`] on the bus, cycle after
//! cycle from start-up to the orderly end. It takes the controller's requests between cycles
//! ([`Request`], answered at once), and publishes what it knows after every cycle
//! ([`Snapshot`], under a lock it only tries: a busy reader never delays a cycle).

use std::sync::{Arc, Mutex, mpsc};
use std::time::Duration;

use crate::bus::{Bus, Frame, Port};
use crate::config::Machine;
use crate::config::machine::MAX_AXES;
use crate::gateway::GatewayError;
use crate::gateway::control::Control;
use crate::gateway::cyclic_bus::CyclicBus;
use crate::interpolator::Interpolator;
use crate::master::alarm::SharedBusError;
use crate::master::alarm::{Alarm, Failure};
use crate::master::cyclic::{
    AxisControl, CycleRecord, CyclicMaster, DriveOpStatus, Phase, Refusal,
};
use crate::master::supervision::Supervision;
use crate::rt::{self, Ticker};

/// What the controller asks of the cyclic thread.
#[derive(Debug)]
pub enum Request {
    /// [`CyclicMaster::enable`].
    Enable,
    /// [`CyclicMaster::disable`].
    Disable,
    /// [`CyclicMaster::abort`].
    Abort,
    /// [`CyclicMaster::reset_alarm`].
    ResetAlarm,
    /// [`CyclicMaster::start_motion`].
    Start(Box<Interpolator>),
    /// [`CyclicMaster::release`].
    Release(u32),
    /// [`CyclicMaster::start_drive_op`].
    StartDriveOp(u32),
    /// [`CyclicMaster::end_drive_op`].
    EndDriveOp(u32),
    /// [`CyclicMaster::rearm`].
    Rearm(u32),
    /// [`CyclicMaster::set_travel_checked`].
    TravelChecked(usize, bool),
    /// End the thread once the drives are disabled (or at once, with `force`).
    Quit {
        /// Even with drives enabled (the bus is gone).
        force: bool,
    },
}

/// A request and where its answer goes.
pub type Envelope = (Request, tokio::sync::oneshot::Sender<Result<(), Refusal>>);

/// An answer waiting for its cycle's snapshot.
type Answer = (
    tokio::sync::oneshot::Sender<Result<(), Refusal>>,
    Result<(), Refusal>,
);

/// One axis in a [`Snapshot`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AxisSnapshot {
    /// Setpoint sent, mm.
    pub commanded_mm: f64,
    /// Position actual, mm.
    pub actual_mm: f64,
    /// Following error, mm.
    pub following_error_mm: f64,
    /// Latest statusword (0x6041).
    pub statusword: Option<u16>,
    /// Who commands the axis.
    pub control: Option<AxisControl>,
    /// The drive's own operation (homing), while one runs.
    pub drive_op: Option<DriveOpStatus>,
    /// Released, with its drive's IP mode inactive.
    pub released: bool,
}

/// What the cyclic thread publishes after each cycle.
#[derive(Debug, Clone, Default)]
pub struct Snapshot {
    /// The cycle.
    pub cycle: u64,
    /// The master's phase (`None` before the first cycle).
    pub phase: Option<Phase>,
    /// Enabled, holding, no motion.
    pub idle: bool,
    /// An abort under way.
    pub aborting: bool,
    /// The standing alarm.
    pub failure: Option<Failure>,
    /// A drive reset or the bus was lost: a start-up is needed.
    pub needs_startup: bool,
    /// The program line in execution.
    pub line: Option<usize>,
    /// Motions started and ended (ended: back to idle, or stopped by an alarm).
    pub motions_started: u64,
    /// See `motions_started`.
    pub motions_ended: u64,
    /// Override requested and effective, and the hold.
    pub override_requested: f64,
    /// See `override_requested`.
    pub override_effective: f64,
    /// A feed hold asked for.
    pub held: bool,
    /// The motion stands still (held, or 0 %).
    pub standing_still: bool,
    /// Per axis, machine order.
    pub axes: [AxisSnapshot; MAX_AXES],
    /// The thread has ended.
    pub ended: bool,
}

/// The handles of a running cyclic thread.
pub struct Thread {
    /// Requests.
    pub tx: mpsc::Sender<Envelope>,
    /// The latest snapshot.
    pub snapshot: Arc<Mutex<Snapshot>>,
    handle: Option<std::thread::JoinHandle<Option<SharedBusError>>>,
}

impl Thread {
    /// Starts the cyclic thread on `bus` (the drives started up, Operational). `control` carries
    /// the operator's override and hold; `log`, when given, gets every cycle's record.
    pub fn spawn(
        machine: &Machine,
        bus: &Bus,
        sup: Supervision,
        control: Arc<Control>,
        snapshot: Arc<Mutex<Snapshot>>,
        log: Option<mpsc::SyncSender<CycleRecord>>,
    ) -> Result<Thread, GatewayError> {
        let mut port = bus.open(&crate::gateway::cyclic_filters(machine))?;
        let cyc_bus = CyclicBus::new(
            machine,
            bus.name(),
            port.as_mut(),
            bus.sync_tap(machine.sync_cob_id)?,
        )?;
        let (tx, rx) = mpsc::channel::<Envelope>();
        let snap = snapshot.clone();
        let m = machine.clone();
        let handle = std::thread::Builder::new()
            .name("canmotion-serve-cyclic".into())
            .spawn(move || run(&m, port.as_mut(), cyc_bus, sup, &rx, &snap, &control, log))
            .expect("spawn the cyclic thread");
        Ok(Thread {
            tx,
            snapshot,
            handle: Some(handle),
        })
    }

    /// The latest snapshot (a copy).
    pub fn snapshot(&self) -> Snapshot {
        self.snapshot
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Waits for the thread's end; the bus error it met, if any.
    pub fn join(mut self) -> Option<SharedBusError> {
        self.handle.take().and_then(|h| h.join().ok()).flatten()
    }
}

#[allow(clippy::too_many_arguments)]
fn run(
    machine: &Machine,
    port: &mut dyn Port,
    mut bus: CyclicBus,
    mut sup: Supervision,
    rx: &mpsc::Receiver<Envelope>,
    snapshot: &Mutex<Snapshot>,
    control: &Control,
    log: Option<mpsc::SyncSender<CycleRecord>>,
) -> Option<SharedBusError> {
    let _ = rt::make_realtime(rt::priority_from_env());
    let mut master = CyclicMaster::service(machine);
    let mut ticker = Ticker::new(Duration::from_micros(u64::from(machine.cycle_us)));
    let mut out: Vec<Frame> = Vec::with_capacity(machine.axes.len() + 1);
    let mut port_err: Option<SharedBusError> = None;
    let mut control_seen = 0u64;
    let (mut started, mut ended) = (0u64, 0u64);
    let mut active = false;
    let mut quit: Option<bool> = None;
    let n = machine.axes.len();
    // Answers wait for the snapshot of the cycle that acted on them: whoever reads the
    // snapshot after an answer sees the request's effect (a cleared alarm, a new phase).
    let mut answers: Vec<Answer> = Vec::with_capacity(16);
    loop {
        ticker.wait();
        if let Some((fraction, hold)) = control.poll(&mut control_seen) {
            master.set_override(fraction, hold);
        }
        while let Ok((req, reply)) = rx.try_recv() {
            let answer = match req {
                Request::Enable => master.enable(),
                Request::Disable => master.disable(),
                Request::Abort => {
                    master.abort();
                    Ok(())
                }
                Request::ResetAlarm => master.reset_alarm(),
                Request::Start(interp) => {
                    let r = master.start_motion(*interp);
                    if r.is_ok() {
                        started += 1;
                        active = true;
                    }
                    r
                }
                Request::Release(mask) => master.release(mask),
                Request::StartDriveOp(mask) => {
                    master.start_drive_op(mask);
                    Ok(())
                }
                Request::EndDriveOp(mask) => {
                    master.end_drive_op(mask);
                    Ok(())
                }
                Request::Rearm(mask) => {
                    master.rearm(mask);
                    Ok(())
                }
                Request::TravelChecked(i, on) => {
                    master.set_travel_checked(i, on);
                    Ok(())
                }
                Request::Quit { force } => {
                    quit = Some(force);
                    Ok(())
                }
            };
            answers.push((reply, answer));
        }
        let now = Duration::from_nanos(rt::now_ns());
        if let Err(e) = bus.receive(port, &mut master, &mut sup, now, ticker.timing.cycles) {
            port_err.get_or_insert(SharedBusError(Arc::new(e)));
        }
        if let Some(e) = &port_err {
            master.alarm(0, Alarm::Bus { error: e.clone() });
        }
        sup.poll(now, &mut master);
        out.clear();
        let rec = master.cycle(machine.sync_cob_id, &mut out);
        if active && (master.is_idle() || master.failure().is_some()) {
            active = false;
            ended += 1;
        }
        let deadline = ticker.this_deadline_ns();
        if let Some(e) = bus.send(port, &out, deadline, &mut master, ticker.timing.cycles) {
            port_err.get_or_insert(e);
        }
        bus.measure();
        if let Some(tx) = &log {
            let _ = tx.try_send(rec);
        }
        let published = snapshot.try_lock().map(|mut s| {
            s.cycle = rec.cycle;
            s.phase = Some(master.phase());
            s.idle = master.is_idle();
            s.aborting = master.is_aborting();
            if s.failure.as_ref() != master.failure() {
                s.failure = master.failure().cloned();
            }
            s.needs_startup = master.any_reset() || master.phase() == Phase::Done;
            s.line = master.line();
            s.motions_started = started;
            s.motions_ended = ended;
            let m = master.motion();
            s.override_requested = m.map_or(control.wanted().0, |m| m.requested_override());
            s.override_effective = m.map_or(0.0, |m| m.effective_override());
            s.held = m.is_some_and(|m| m.is_held());
            s.standing_still = m.is_none_or(|m| m.is_standing_still());
            for i in 0..n {
                let fb = master.feedback(i);
                s.axes[i] = AxisSnapshot {
                    commanded_mm: rec.cmd_mm[i],
                    actual_mm: rec.act_mm[i],
                    following_error_mm: rec.ferr_mm[i],
                    statusword: fb.map(|f| f.statusword),
                    control: Some(master.axis_control(i)),
                    drive_op: master.drive_op_status(i),
                    released: master.released(1 << i),
                };
            }
        });
        if published.is_ok() {
            for (reply, answer) in answers.drain(..) {
                let _ = reply.send(answer);
            }
        }
        let done = master.phase() == Phase::Done
            || match quit {
                Some(true) => true,
                Some(false) => master.phase() == Phase::Disabled,
                None => false,
            };
        if done {
            break;
        }
    }
    // Pre-operational right after the last SYNC, so that no drive waits for a SYNC that will
    // not come (unless the bus is gone).
    for a in machine.axes.iter().filter(|_| !bus.lost()) {
        let f = Frame::new(
            crate::canopen::cob::NMT,
            &[crate::canopen::nmt::PRE_OPERATIONAL, a.node],
        )
        .expect("NMT");
        if let Err(e) = port.send(&f) {
            port_err.get_or_insert(SharedBusError(Arc::new(e)));
        }
    }
    if let Ok(mut s) = snapshot.lock() {
        s.ended = true;
        s.phase = Some(master.phase());
        s.failure = master.failure().cloned();
    }
    for (reply, answer) in answers.drain(..) {
        let _ = reply.send(answer);
    }
    port_err
}
