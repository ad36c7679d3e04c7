//! A virtual bus and clock for the sans-I/O master: simulated drives ([`SimDrive`]) and the
//! state machine under test exchange frames in memory, and time is a `Duration` the test
//! advances. No threads, no sleeps: a test runs the same way every time, and a time-out is
//! checked to the microsecond.
//!
//! The master's side: [`VirtualBus::send`] puts its frames on the bus (every drive handles them
//! at [`VirtualBus::now`]; their answers queue for the master and reach the other drives),
//! [`VirtualBus::recv`] takes the next frame for it, and [`VirtualBus::advance`] moves time to
//! the drives' next event or a limit (the master's `poll_at`), whichever is first.

use std::collections::VecDeque;
use std::time::Duration;

use canmotion::bus::Frame;
use canmotion::sim::SimDrive;

/// Drives on an in-memory bus, with a clock.
pub struct VirtualBus {
    /// The time now, since the drives were powered on.
    pub now: Duration,
    /// The drives, as given.
    pub drives: Vec<SimDrive>,
    /// Every frame that went on the bus, with when, in order (frames lost by
    /// [`VirtualBus::lose`] are not on it).
    pub log: Vec<(Duration, Frame)>,
    /// Frames for the master, not taken yet.
    inbox: VecDeque<Frame>,
    /// What becomes of a frame a drive sends: `None`, lost (a node that answers nothing), or
    /// the frame that reaches the bus (a drive that answers something else).
    tamper: Box<dyn FnMut(Frame) -> Option<Frame>>,
}

impl VirtualBus {
    /// `drives` powered on at time 0: each sends its boot-up.
    pub fn new(drives: Vec<SimDrive>) -> VirtualBus {
        let mut bus = VirtualBus {
            now: Duration::ZERO,
            drives,
            log: Vec::new(),
            inbox: VecDeque::new(),
            tamper: Box::new(Some),
        };
        let mut out = Vec::new();
        for i in 0..bus.drives.len() {
            bus.drives[i].boot(Duration::ZERO, &mut out);
            bus.route(Some(i), &mut out);
        }
        bus
    }

    /// From now on, frames the drives send for which `lost` is true never reach the bus.
    pub fn lose(&mut self, lost: impl Fn(&Frame) -> bool + 'static) {
        self.tamper(move |f| (!lost(&f)).then_some(f));
    }

    /// From now on, every frame a drive sends passes through `tamper`: `None` loses it, `Some`
    /// is what reaches the bus instead.
    pub fn tamper(&mut self, tamper: impl FnMut(Frame) -> Option<Frame> + 'static) {
        self.tamper = Box::new(tamper);
    }

    /// The master sends `frames` (drained) now.
    pub fn send(&mut self, frames: &mut Vec<Frame>) {
        let mut out = std::mem::take(frames);
        self.route(None, &mut out);
    }

    /// The next frame for the master, if one is waiting.
    pub fn recv(&mut self) -> Option<Frame> {
        self.inbox.pop_front()
    }

    /// Moves time to the drives' next event, or to `limit` if that comes first (never back),
    /// and runs the drives there.
    pub fn advance(&mut self, limit: Duration) {
        let next = self
            .drives
            .iter()
            .map(|d| d.poll_at(self.now))
            .min()
            .unwrap_or(limit)
            .min(limit)
            .max(self.now);
        self.now = next;
        let mut out = Vec::new();
        for i in 0..self.drives.len() {
            self.drives[i].poll(self.now, &mut out);
            self.route(Some(i), &mut out);
        }
    }

    /// Runs time to `t` with no master on the bus but for `keep`, sent every `period` from now
    /// (the gateway's heartbeat, say).
    pub fn run_until(&mut self, t: Duration, keep: Option<(Frame, Duration)>) {
        let mut next_keep = self.now;
        while self.now < t {
            if let Some((f, period)) = keep
                && self.now >= next_keep
            {
                self.send(&mut vec![f]);
                next_keep += period;
            }
            let limit = if keep.is_some() { t.min(next_keep) } else { t };
            self.advance(limit);
            self.inbox.clear();
        }
    }

    /// Puts frames a drive (`from`) or the master (`None`) sent on the bus, and everything they
    /// cause, in order.
    fn route(&mut self, from: Option<usize>, out: &mut Vec<Frame>) {
        let mut queue: VecDeque<(Option<usize>, Frame)> =
            out.drain(..).map(|f| (from, f)).collect();
        while let Some((from, f)) = queue.pop_front() {
            let f = match from {
                Some(_) => match (self.tamper)(f) {
                    Some(f) => f,
                    None => continue,
                },
                None => f,
            };
            self.log.push((self.now, f));
            if from.is_some() {
                self.inbox.push_back(f);
            }
            let mut answers = Vec::new();
            for i in 0..self.drives.len() {
                if Some(i) != from {
                    self.drives[i].handle(self.now, &f, &mut answers);
                    queue.extend(answers.drain(..).map(|a| (Some(i), a)));
                }
            }
        }
    }
}
