//! The soak's children: `roomlight sim`, `camera` and `node` started from the binary as a real
//! installation runs them, each incarnation's stderr (the tracing log) appended to `NAME.log`
//! and its stdout to `NAME.out` (its lines also handed to the driver), killed with SIGKILL,
//! stopped with SIGTERM, and measured from `/proc/PID` (resident set, open file descriptors).

use crate::bench::memory;
use anyhow::{Context, Result};
use serde::Serialize;
use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Readings an incarnation's last one is chosen from (taken [`super::room`]'s sampling period
/// apart, 250 ms: two seconds). Four (one second) still let a descriptor held for a moment
/// through once under a loaded machine (camera 16 -> 17 with no new peer, 22:43 UTC).
pub const RECENT: usize = 8;

/// One reading of a process.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Sample {
    /// Rounds the room had run when it was taken.
    pub at_round: u64,
    pub rss_kb: u64,
    /// Entries of `/proc/PID/fd`.
    pub fds: u64,
    /// The peers this process is expected to hold one socket each for at that moment (the camera
    /// agent: projectors attached; the simulator: agents connected to it; a node: none).
    pub peers: u64,
}

/// One run of an agent, from its start to its end.
#[derive(Debug, Clone, Serialize)]
pub struct Incarnation {
    pub pid: u32,
    pub started_at_round: u64,
    /// Of the first [`RECENT`] readings once the room had run the warm-up past this
    /// incarnation's start, the one holding the most descriptors beyond its peers.
    pub warm: Option<Sample>,
    /// The last reading: of the last [`RECENT`] readings, the one holding the fewest descriptors
    /// beyond its peers (the latest of equals). A descriptor held for a moment (a reconnection
    /// in flight, a state file being written) is in one reading; a leak is in all of them.
    pub last: Option<Sample>,
    #[serde(skip)]
    recent: std::collections::VecDeque<Sample>,
    /// Readings taken since the warm-up ended, up to [`RECENT`]: the warm reading is the most
    /// held of the first [`RECENT`] (a socket down for a moment then, a node reconnecting to
    /// a camera agent restarted at that round, is not taken for a descriptor that the end
    /// leaked).
    #[serde(skip)]
    warm_readings: usize,
    pub max_rss_kb: u64,
    /// How it ended: `killed` (SIGKILL by the soak), `stopped` (exited 0 after SIGTERM), or
    /// what went wrong.
    pub end: Option<String>,
}

/// An agent of the room (one name, restarted any number of times).
#[derive(Debug)]
pub struct Agent {
    pub name: String,
    args: Vec<String>,
    dir: PathBuf,
    exe: PathBuf,
    child: Option<Child>,
    lines: Option<mpsc::Receiver<String>>,
    pub incarnations: Vec<Incarnation>,
}

impl Agent {
    pub fn new(exe: &Path, dir: &Path, name: &str, args: &[&str]) -> Self {
        Self {
            name: name.to_string(),
            args: args.iter().map(|a| a.to_string()).collect(),
            dir: dir.to_path_buf(),
            exe: exe.to_path_buf(),
            child: None,
            lines: None,
            incarnations: Vec::new(),
        }
    }

    pub fn log_path(&self) -> PathBuf {
        self.dir.join(format!("{}.log", self.name))
    }

    pub fn out_path(&self) -> PathBuf {
        self.dir.join(format!("{}.out", self.name))
    }

    /// Starts a new incarnation. Logs at `info`, the level the systemd units run the agents at.
    pub fn start(&mut self, at_round: u64) -> Result<()> {
        let append = |path: PathBuf| -> Result<File> {
            OpenOptions::new()
                .create(true)
                .append(true)
                .open(&path)
                .with_context(|| format!("opening {}", path.display()))
        };
        let mut child = Command::new(&self.exe)
            .args(&self.args)
            .current_dir(&self.dir)
            .env("RUST_LOG", "info")
            .env("NO_COLOR", "1")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(append(self.log_path())?)
            .spawn()
            .with_context(|| format!("starting {} ({})", self.name, self.exe.display()))?;
        let stdout = child.stdout.take().context("piped stdout")?;
        let mut out = append(self.out_path())?;
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                let _ = writeln!(out, "{line}");
                // The driver may have moved on to the next incarnation: keep writing the file.
                let _ = tx.send(line);
            }
        });
        self.incarnations.push(Incarnation {
            pid: child.id(),
            started_at_round: at_round,
            warm: None,
            last: None,
            recent: std::collections::VecDeque::new(),
            warm_readings: 0,
            max_rss_kb: 0,
            end: None,
        });
        self.child = Some(child);
        self.lines = Some(rx);
        Ok(())
    }

    pub fn running(&self) -> bool {
        self.child.is_some()
    }

    /// The stdout lines printed since the last call.
    pub fn new_lines(&mut self) -> Vec<String> {
        self.lines
            .as_ref()
            .map(|rx| rx.try_iter().collect())
            .unwrap_or_default()
    }

    /// Waits (at most `within`) for a stdout line starting with `prefix`; the line.
    pub fn wait_line(&mut self, prefix: &str, within: Duration) -> Result<String> {
        let rx = self.lines.as_ref().context("not started")?;
        let until = Instant::now() + within;
        loop {
            let left = until.saturating_duration_since(Instant::now());
            match rx.recv_timeout(left) {
                Ok(line) if line.starts_with(prefix) => return Ok(line),
                Ok(_) => {}
                Err(_) => anyhow::bail!(
                    "{}: no line {prefix:?} within {within:?} (see {})",
                    self.name,
                    self.log_path().display()
                ),
            }
        }
    }

    /// Whether the running incarnation has exited on its own; it is reaped and its end noted.
    pub fn exited(&mut self) -> Option<String> {
        let status = self.child.as_mut()?.try_wait().ok()??;
        let end = format!("exited on its own: {status}");
        self.ended(end.clone());
        Some(end)
    }

    /// SIGKILL, as a crash or `kill -9` ends a process.
    pub fn kill(&mut self) {
        if let Some(child) = self.child.as_mut() {
            let _ = child.kill();
            let _ = child.wait();
            self.ended("killed".into());
        }
    }

    /// SIGTERM, as systemd stops a service; SIGKILL if it has not exited within `within`.
    pub fn terminate(&mut self, within: Duration) {
        let Some(child) = self.child.as_mut() else {
            return;
        };
        let sent = Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status()
            .is_ok_and(|s| s.success());
        let until = Instant::now() + within;
        let end = loop {
            match child.try_wait() {
                Ok(Some(s)) if s.success() => break "stopped".to_string(),
                Ok(Some(s)) => break format!("exited after SIGTERM: {s}"),
                Ok(None) if sent && Instant::now() < until => {
                    std::thread::sleep(Duration::from_millis(20));
                }
                _ => {
                    let _ = child.kill();
                    let _ = child.wait();
                    break format!("did not stop within {within:?} of SIGTERM: killed");
                }
            }
        };
        self.ended(end);
    }

    fn ended(&mut self, end: String) {
        self.child = None;
        if let Some(i) = self.incarnations.last_mut() {
            i.end = Some(end);
        }
    }

    /// Reads the running incarnation's resident set and descriptors; the first reading taken
    /// `warm_up` rounds after its start is its warm one.
    pub fn sample(&mut self, at_round: u64, warm_up: u64, peers: u64) {
        let Some(child) = self.child.as_ref() else {
            return;
        };
        let pid = child.id();
        let (Some(resident), Some(fds)) = (memory::resident_of(pid), open_fds(pid)) else {
            return;
        };
        let sample = Sample {
            at_round,
            rss_kb: resident.now / 1024,
            fds,
            peers,
        };
        if let Some(i) = self.incarnations.last_mut() {
            i.max_rss_kb = i.max_rss_kb.max(sample.rss_kb);
            if i.warm_readings < RECENT && at_round >= i.started_at_round + warm_up {
                i.warm_readings += 1;
                i.warm = most_held(i.warm, sample);
            }
            i.recent.push_back(sample);
            if i.recent.len() > RECENT {
                i.recent.pop_front();
            }
            i.last = least_held(&i.recent);
        }
    }

    /// Bytes this agent has written to its log (stderr) and to its stdout, every incarnation.
    pub fn written(&self) -> (u64, u64) {
        let size = |p: PathBuf| std::fs::metadata(p).map_or(0, |m| m.len());
        (size(self.log_path()), size(self.out_path()))
    }
}

impl Drop for Agent {
    /// Nothing is left behind, whatever happened.
    fn drop(&mut self) {
        self.kill();
    }
}

/// Of `recent` readings, the one holding the fewest descriptors beyond its peers, the latest of
/// equals.
fn least_held(recent: &std::collections::VecDeque<Sample>) -> Option<Sample> {
    recent
        .iter()
        .rev()
        .min_by_key(|s| s.fds.saturating_sub(s.peers))
        .copied()
}

/// Of the warm reading so far and a new one, the one holding the most descriptors beyond its
/// peers (the earlier of equals).
fn most_held(warm: Option<Sample>, new: Sample) -> Option<Sample> {
    let held = |s: &Sample| s.fds.saturating_sub(s.peers);
    match warm {
        Some(w) if held(&w) >= held(&new) => Some(w),
        _ => Some(new),
    }
}

/// Entries of `/proc/PID/fd`; `None` once the process has gone (or off Linux).
fn open_fds(pid: u32) -> Option<u64> {
    Some(std::fs::read_dir(format!("/proc/{pid}/fd")).ok()?.count() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(at_round: u64, fds: u64, peers: u64) -> Sample {
        Sample {
            at_round,
            rss_kb: 0,
            fds,
            peers,
        }
    }

    /// A descriptor in one reading (held for a moment) is not in the last reading; one in every
    /// recent reading (a leak) is; a new peer's socket is explained by the peer.
    #[test]
    fn the_last_reading_is_the_least_held_of_the_recent_ones() {
        use std::collections::VecDeque;
        let spike: VecDeque<Sample> =
            [reading(1, 12, 0), reading(2, 13, 0), reading(3, 12, 0)].into();
        assert_eq!(
            least_held(&spike).map(|s| (s.at_round, s.fds)),
            Some((3, 12))
        );
        let leak: VecDeque<Sample> =
            [reading(1, 13, 0), reading(2, 13, 0), reading(3, 14, 0)].into();
        assert_eq!(
            least_held(&leak).map(|s| (s.at_round, s.fds)),
            Some((2, 13))
        );
        let peer: VecDeque<Sample> = [reading(1, 16, 4), reading(2, 17, 5)].into();
        assert_eq!(least_held(&peer).map(|s| s.at_round), Some(2));
        assert!(least_held(&VecDeque::new()).is_none());
    }

    /// The warm reading is the most held of the first ones after the warm-up: a socket down
    /// for a moment then (a node reconnecting to a restarted camera agent) does not make the end
    /// look like a leak.
    #[test]
    fn the_warm_reading_is_the_most_held_of_the_first_ones() {
        let warm = [
            reading(108, 12, 0),
            reading(109, 13, 0),
            reading(110, 13, 0),
        ]
        .into_iter()
        .fold(None, most_held);
        assert_eq!(warm.map(|s| (s.at_round, s.fds)), Some((109, 13)));
        let peer = most_held(Some(reading(1, 16, 4)), reading(2, 17, 5));
        assert_eq!(
            peer.map(|s| s.at_round),
            Some(1),
            "a new peer's socket is explained"
        );
    }
}
