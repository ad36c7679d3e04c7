//! Puts simulated drives on a bus: one thread per drive, woken by frames or by the drive's
//! own deadline ([`SimDrive::poll_at`]).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::SimDrive;
use crate::bus::{Bus, BusError, Port};

/// Running simulated drives; dropping it stops them.
pub struct SimHandle {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<Result<(), BusError>>>,
}

impl SimHandle {
    /// Stop the drives and wait for their threads; the first bus error, if any.
    pub fn stop(mut self) -> Result<(), BusError> {
        self.stop.store(true, Ordering::SeqCst);
        let mut r = Ok(());
        for t in self.threads.drain(..) {
            if let Ok(Err(e)) = t.join()
                && r.is_ok()
            {
                r = Err(e);
            }
        }
        r
    }

    /// Block until every drive thread ends (a bus error ends one), or forever.
    pub fn wait(mut self) -> Result<(), BusError> {
        let mut r = Ok(());
        for t in self.threads.drain(..) {
            if let Ok(Err(e)) = t.join()
                && r.is_ok()
            {
                r = Err(e);
            }
        }
        r
    }
}

impl Drop for SimHandle {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// Start `drives` on `bus`: one thread and one port for all of them (one socket read per frame,
/// however many drives), with receive filters from the drives' configuration. They boot (send
/// their boot-up messages) once the port is open.
pub fn spawn(bus: &Bus, drives: Vec<SimDrive>) -> Result<SimHandle, BusError> {
    let stop = Arc::new(AtomicBool::new(false));
    let epoch = Instant::now();
    let port = bus.open(&filters_of(&drives))?;
    let nodes: Vec<u8> = drives.iter().map(|d| d.node()).collect();
    let stop2 = stop.clone();
    let thread = std::thread::Builder::new()
        .name(format!("simdrive-{nodes:?}"))
        .spawn(move || {
            // The drives stand in for hardware with its own processor: one priority step below
            // the cyclic loop (`CANMOTION_RT_PRIORITY`), so that load on the PC delays neither
            // their SYNC handling nor their physics more than it delays the master.
            let priority = crate::rt::priority_from_env();
            let rt = crate::rt::make_realtime(if priority > 1 { priority - 1 } else { priority });
            tracing::debug!("simulated drives {nodes:?}: {rt}");
            let r = run(drives, port, epoch, &stop2);
            if let Err(e) = &r {
                tracing::error!("simulated drives {nodes:?} stopped: {e}");
                eprintln!("canmotion simdrive: nodes {nodes:?} stopped: {e}");
            }
            r
        })
        .expect("spawn a thread");
    Ok(SimHandle {
        stop,
        threads: vec![thread],
    })
}

fn filters_of(drives: &[SimDrive]) -> Vec<crate::bus::Filter> {
    let mut f: Vec<crate::bus::Filter> = drives.iter().flat_map(|d| d.rx_filters()).collect();
    f.sort_by_key(|f| (f.id, f.mask));
    f.dedup();
    f
}

/// A wake-up later than its deadline by more than this means the simulated world did not run.
///
/// A real drive has its own processor; the simulated one shares the PC (or a virtual machine's
/// CPUs, which the host deschedules for 10 ms and more). Charging that time to the motor would
/// move it against a demand that the drive, frozen too, never updated: a following error that no
/// drive would have. The motor skips it instead ([`SimDrive::skip`]). The drives' timers stay on
/// wall time: their heartbeats are not shifted by the freezes, and a master that is late while
/// the drives' thread runs on time is still seen as late (missing SYNCs, a stopping demand, a
/// lost heartbeat), as on real hardware.
const FROZEN_AFTER: Duration = Duration::from_millis(2);

fn run(
    mut drives: Vec<SimDrive>,
    mut port: Box<dyn Port>,
    epoch: Instant,
    stop: &AtomicBool,
) -> Result<(), BusError> {
    let mut out = Vec::new();
    for d in &mut drives {
        d.boot(epoch.elapsed(), &mut out);
    }
    let mut filters = filters_of(&drives);
    // A simulated drive has no controller: injected error frames are sent, never received.
    port.set_error_mask(0)?;
    while !stop.load(Ordering::Relaxed) {
        for f in out.drain(..) {
            port.send(&f)?;
        }
        for e in drives.iter_mut().flat_map(|d| d.take_bus_errors()) {
            port.send_error(&e)?;
        }
        let now = epoch.elapsed();
        let next = drives.iter().map(|d| d.poll_at(now)).min().unwrap_or(now);
        let wait = next.saturating_sub(now).min(Duration::from_millis(20));
        let due = Instant::now() + wait;
        let mut got = port.recv_timeout(wait)?;
        let ran = Instant::now();
        let late = ran.saturating_duration_since(due);
        if late > FROZEN_AFTER {
            for d in &mut drives {
                d.skip(late);
            }
        }
        // Handle everything queued, in order, before polling. Frames queued together arrived
        // together: one clock reading serves the batch (a system call saved per frame matters
        // inside User-Mode Linux, where each costs ~20 µs).
        let now = ran.duration_since(epoch);
        while let Some(f) = got {
            for d in &mut drives {
                d.handle(now, &f, &mut out);
            }
            got = port.recv_timeout(Duration::ZERO)?;
        }
        for d in &mut drives {
            d.poll(now, &mut out);
        }
        let f = filters_of(&drives);
        if f != filters {
            port.set_filters(&f)?;
            filters = f;
        }
    }
    Ok(())
}
