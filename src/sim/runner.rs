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

/// Start `drives` on `bus`, each on its own port and thread. They boot (send their boot-up
/// message) once their port is open.
pub fn spawn(bus: &Bus, drives: Vec<SimDrive>) -> Result<SimHandle, BusError> {
    let stop = Arc::new(AtomicBool::new(false));
    let epoch = Instant::now();
    let mut threads = Vec::new();
    for drive in drives {
        let port = bus.open(&[])?;
        let stop = stop.clone();
        let name = format!("simdrive-{}", drive.node());
        threads.push(
            std::thread::Builder::new()
                .name(name)
                .spawn(move || run(drive, port, epoch, &stop))
                .expect("spawn a thread"),
        );
    }
    Ok(SimHandle { stop, threads })
}

fn run(mut drive: SimDrive, mut port: Box<dyn Port>, epoch: Instant, stop: &AtomicBool) -> Result<(), BusError> {
    let mut out = Vec::new();
    drive.boot(epoch.elapsed(), &mut out);
    while !stop.load(Ordering::Relaxed) {
        for f in out.drain(..) {
            port.send(&f)?;
        }
        let now = epoch.elapsed();
        let wait = drive.poll_at(now).saturating_sub(now).min(Duration::from_millis(20));
        if let Some(f) = port.recv_timeout(wait)? {
            drive.handle(epoch.elapsed(), &f, &mut out);
            // Drain whatever else is queued before polling, so a burst is handled in order.
            while let Some(f) = port.recv_timeout(Duration::ZERO)? {
                drive.handle(epoch.elapsed(), &f, &mut out);
            }
        }
        drive.poll(epoch.elapsed(), &mut out);
    }
    Ok(())
}
