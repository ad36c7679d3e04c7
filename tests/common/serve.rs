//! A `canmotion serve` under test on the in-process bus, and a client of its control socket.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use canmotion::bus::Bus;
use canmotion::bus::inproc::InProcBus;
use canmotion::config::Machine;
use canmotion::gateway::GatewayError;
use canmotion::gateway::serve::{ServeOptions, serve};

/// A service on its own thread, with simulated drives on an in-process bus.
pub struct Service {
    pub bus: Bus,
    pub socket: PathBuf,
    pub log: PathBuf,
    pub dir: tempfile::TempDir,
    pub machine: Machine,
    thread: Option<std::thread::JoinHandle<Result<(), GatewayError>>>,
}

impl Service {
    /// Starts `canmotion serve` on `machine` (simulated drives with `injects`).
    pub fn start(machine: &Machine, injects: Vec<canmotion::sim::Targeted>) -> Service {
        let dir = tempfile::tempdir().unwrap();
        let socket = dir.path().join("cm.sock");
        let log = dir.path().join("serve.csv");
        let bus = Bus::InProc(InProcBus::new());
        let opts = ServeOptions {
            control_path: socket.clone(),
            simulate: true,
            injects,
            log: Some(log.clone()),
        };
        let (m, b) = (machine.clone(), bus.clone());
        let thread = std::thread::spawn(move || serve(&m, &b, &opts));
        Service {
            bus,
            socket,
            log,
            dir,
            machine: machine.clone(),
            thread: Some(thread),
        }
    }

    /// A client, once the socket accepts (within 15 s: the drives' start-up comes first).
    pub fn client(&self) -> Client {
        Client::connect(&self.socket, Duration::from_secs(15))
    }

    /// `quit`, then the service's result.
    pub fn quit(&mut self) -> Result<(), GatewayError> {
        let mut c = self.client();
        let answer = c.cmd("quit");
        assert_eq!(answer, "ok bye");
        self.thread.take().unwrap().join().unwrap()
    }

    /// A file in the service's temporary folder, with `text`.
    pub fn file(&self, name: &str, text: &str) -> PathBuf {
        let p = self.dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    }
}

impl Drop for Service {
    fn drop(&mut self) {
        if let Some(t) = self.thread.take() {
            if let Ok(mut s) = UnixStream::connect(&self.socket) {
                let _ = writeln!(s, "quit");
                let mut line = String::new();
                let _ = BufReader::new(s).read_line(&mut line);
            }
            let _ = t.join();
        }
    }
}

/// A client of the control socket.
pub struct Client {
    reader: BufReader<UnixStream>,
    writer: UnixStream,
}

impl Client {
    /// Connects, retrying until `within` has passed.
    pub fn connect(path: &Path, within: Duration) -> Client {
        let deadline = Instant::now() + within;
        loop {
            match UnixStream::connect(path) {
                Ok(s) => {
                    s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
                    return Client {
                        reader: BufReader::new(s.try_clone().unwrap()),
                        writer: s,
                    };
                }
                Err(e) if Instant::now() < deadline => {
                    let _ = e;
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(e) => panic!("{}: no service: {e}", path.display()),
            }
        }
    }

    /// Sends a line; its answer line.
    pub fn cmd(&mut self, line: &str) -> String {
        writeln!(self.writer, "{line}").unwrap();
        self.line()
    }

    /// The next line received.
    pub fn line(&mut self) -> String {
        let mut s = String::new();
        self.reader.read_line(&mut s).unwrap();
        s.trim_end().to_string()
    }

    /// `status`, parsed.
    pub fn status(&mut self) -> serde_json::Value {
        let s = self.cmd("status");
        let json = s
            .strip_prefix("ok ")
            .unwrap_or_else(|| panic!("status: {s}"));
        serde_json::from_str(json).unwrap_or_else(|e| panic!("status is not JSON ({e}): {json}"))
    }

    /// Polls `status` until `state` (within `within`); the status then.
    pub fn wait_state(&mut self, state: &str, within: Duration) -> serde_json::Value {
        let deadline = Instant::now() + within;
        loop {
            let s = self.status();
            if s["state"] == state {
                return s;
            }
            assert!(
                Instant::now() < deadline,
                "state {state} not reached within {within:?}: {s}"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Sends `line` and expects `ok ...`.
    pub fn ok(&mut self, line: &str) -> String {
        let a = self.cmd(line);
        assert!(a.starts_with("ok"), "{line}: {a}");
        a
    }
}

/// An axis of a status, by index.
pub fn axis(s: &serde_json::Value, i: usize) -> &serde_json::Value {
    &s["axes"][i]
}
