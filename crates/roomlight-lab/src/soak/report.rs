//! The soak's report: rounds run and cut short (and why), each agent's runs with its resident
//! set, descriptors and log volume, the events, the final excess over the optimum of the
//! projectors present at the end, and the criteria it is held to, each failure named.

use super::procs::Incarnation;
use super::room::Room;
use super::{Event, SoakArgs};
use crate::bench::results::Stamp;
use crate::process::StatusLine;
use roomlight_core::optimum::optimum;
use serde::Serialize;
use std::collections::BTreeMap;

/// What a soak must show.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Criteria {
    /// The final excess `(G − G*)/G*` over the optimum of the projectors present at the end.
    pub max_excess: f64,
    /// An agent's resident set may grow this fraction over its warm reading...
    pub max_rss_growth: f64,
    /// ...and this much (small processes move by allocator pages, not by leaks).
    pub rss_slack_kb: u64,
    /// Only runs of an agent this many rounds long are held to the memory criterion.
    pub rss_min_rounds: u64,
    /// An agent's log (stderr, at `info`) may hold this many bytes...
    pub log_base_bytes: u64,
    /// ...plus this many per event of the soak: logs grow with what happens, not with rounds.
    pub log_per_event_bytes: u64,
}

impl Criteria {
    pub fn for_rounds(rounds: u64) -> Self {
        Self {
            max_excess: 0.01,
            max_rss_growth: 0.10,
            rss_slack_kb: 1024,
            rss_min_rounds: (rounds / 4).max(500),
            log_base_bytes: 16 * 1024,
            log_per_event_bytes: 2 * 1024,
        }
    }
}

/// How the room was at the end of the run.
#[derive(Debug, Clone)]
pub struct End {
    pub status: Option<StatusLine>,
    /// Projectors whose node agent ran at the end.
    pub present: Vec<String>,
    /// Why the run stopped early, if it did.
    pub error: Option<String>,
    pub seconds: f64,
}

/// One agent over the soak.
#[derive(Debug, Clone, Serialize)]
pub struct AgentReport {
    pub name: String,
    pub runs: Vec<Incarnation>,
    /// Bytes of its log (stderr, every run).
    pub log_bytes: u64,
    /// Bytes of its stdout (the camera agent's status lines: one per round, `--status-lines`).
    pub stdout_bytes: u64,
    /// Its warnings and errors, by message.
    pub warnings: BTreeMap<String, usize>,
}

/// The final objective against the optimum of the projectors present.
#[derive(Debug, Clone, Serialize)]
pub struct Excess {
    pub present: Vec<String>,
    pub objective: f64,
    pub optimum: f64,
    pub excess: f64,
}

/// What `soak.json` holds.
#[derive(Debug, Clone, Serialize)]
pub struct SoakReport {
    pub utc: String,
    pub commit: String,
    pub machine: String,
    pub seed: u64,
    pub rounds_planned: u64,
    /// Every camera agent run's rounds added up.
    pub rounds_completed: u64,
    pub rounds_per_camera_run: Vec<u64>,
    pub captures_last_run: u64,
    /// Rounds that did not complete as planned, by cause.
    pub rounds_cut_short: BTreeMap<String, usize>,
    pub events: Vec<Event>,
    pub agents: Vec<AgentReport>,
    pub excess: Option<Excess>,
    pub seconds: f64,
    pub criteria: Criteria,
    pub failures: Vec<String>,
}

/// What the camera agent's warnings say about rounds, as the cause reported.
const CUT_SHORT: [(&str, &str); 4] = [
    (
        "contributions missing at the deadline",
        "closed at the deadline with contributions missing",
    ),
    ("round abandoned", "capture failed or hung: round abandoned"),
    ("capture refused", "capture refused"),
    ("late: left out", "a projector late: left out of the round"),
];

impl SoakReport {
    pub fn new(args: &SoakArgs, room: &Room, events: Vec<Event>, end: End) -> Self {
        let stamp = Stamp::now();
        let agents: Vec<AgentReport> = room
            .agents()
            .map(|a| {
                let (log_bytes, stdout_bytes) = a.written();
                let log = std::fs::read_to_string(a.log_path()).unwrap_or_default();
                AgentReport {
                    name: a.name.clone(),
                    runs: a.incarnations.clone(),
                    log_bytes,
                    stdout_bytes,
                    warnings: warnings(&log),
                }
            })
            .collect();
        let mut cut = BTreeMap::new();
        if let Some(camera) = agents.iter().find(|a| a.name == "camera") {
            for (message, n) in &camera.warnings {
                if let Some((_, cause)) = CUT_SHORT.iter().find(|(m, _)| message.contains(m)) {
                    *cut.entry(cause.to_string()).or_default() += n;
                }
            }
            let killed = camera
                .runs
                .iter()
                .filter(|r| r.end.as_deref() == Some("killed"));
            let killed = killed.count();
            if killed > 0 {
                cut.insert(
                    "camera agent killed: its round in flight lost".into(),
                    killed,
                );
            }
        }
        let mut report = Self {
            utc: stamp.utc,
            commit: stamp.commit,
            machine: format!(
                "{} CPUs, {}, load {}",
                stamp.machine.cpus, stamp.machine.model, stamp.machine.load
            ),
            seed: args.seed,
            rounds_planned: args.rounds,
            rounds_completed: room.rounds(),
            rounds_per_camera_run: room.camera_rounds.clone(),
            captures_last_run: end.status.map_or(0, |s| s.captures),
            rounds_cut_short: cut,
            events,
            agents,
            excess: excess(room, &end),
            seconds: end.seconds,
            criteria: Criteria::for_rounds(args.rounds),
            failures: Vec::new(),
        };
        report.failures = report.check(room, &end);
        report
    }

    /// Every criterion missed, one line each.
    fn check(&self, room: &Room, end: &End) -> Vec<String> {
        let c = &self.criteria;
        let mut failed = Vec::new();
        if let Some(e) = &end.error {
            failed.push(format!("the run stopped early: {e}"));
        }
        failed.extend(room.unexpected.iter().map(|u| format!("exit: {u}")));
        if self.rounds_completed < self.rounds_planned {
            failed.push(format!(
                "rounds: {} of {}",
                self.rounds_completed, self.rounds_planned
            ));
        }
        for e in self.events.iter().filter(|e| !e.took_effect) {
            failed.push(format!(
                "event at round {}: {:?} {}",
                e.at_round, e.kind, e.outcome
            ));
        }
        match &self.excess {
            Some(x) if x.excess <= c.max_excess => {}
            Some(x) => failed.push(format!(
                "excess: {:.3}% over the optimum of {:?} (at most {:.1}%)",
                100.0 * x.excess,
                x.present,
                100.0 * c.max_excess
            )),
            None => failed.push("excess: no final objective".into()),
        }
        for a in &self.agents {
            failed.extend(agent_failures(a, c, self.events.len() as u64));
        }
        failed
    }

    /// The table printed at the end.
    pub fn table(&self) -> String {
        let mut t = comfy_table::Table::new();
        t.load_preset(comfy_table::presets::ASCII_MARKDOWN);
        t.set_header([
            "agent",
            "runs",
            "RSS warm → end (max), MB",
            "fds warm → end (peers)",
            "log KB",
            "stdout KB",
            "warnings",
        ]);
        for a in &self.agents {
            let longest = a.runs.iter().max_by_key(|r| span(r)).cloned();
            let (rss, fds) = longest.map_or_else(
                || ("n/a".into(), "n/a".into()),
                |r| match (r.warm, r.last) {
                    (Some(w), Some(l)) => (
                        format!(
                            "{:.1} → {:.1} ({:.1}) over {} rounds",
                            w.rss_kb as f64 / 1024.0,
                            l.rss_kb as f64 / 1024.0,
                            r.max_rss_kb as f64 / 1024.0,
                            l.at_round - w.at_round
                        ),
                        format!("{} → {} ({} → {})", w.fds, l.fds, w.peers, l.peers),
                    ),
                    _ => ("no warm reading".into(), "n/a".into()),
                },
            );
            t.add_row([
                a.name.clone(),
                a.runs.len().to_string(),
                rss,
                fds,
                format!("{:.1}", a.log_bytes as f64 / 1024.0),
                format!("{:.1}", a.stdout_bytes as f64 / 1024.0),
                a.warnings.values().sum::<usize>().to_string(),
            ]);
        }
        crate::bench::width::fit(&mut t);
        let mut out = format!(
            "soak {}, commit {}, {}\nrounds {} of {} (per camera agent run {:?}) in {:.0} s\n",
            self.utc,
            self.commit,
            self.machine,
            self.rounds_completed,
            self.rounds_planned,
            self.rounds_per_camera_run,
            self.seconds
        );
        out += &format!("cut short: {:?}\n", self.rounds_cut_short);
        let seen = self.events.iter().filter(|e| e.took_effect).count();
        out += &format!("events: {} of {} took effect\n", seen, self.events.len());
        if let Some(x) = &self.excess {
            out += &format!(
                "final: G {:.6e}, G* {:.6e} of {:?}: excess {:.4}%\n",
                x.objective,
                x.optimum,
                x.present,
                100.0 * x.excess
            );
        }
        out += &t.to_string();
        out +=
            "\n(RSS and fds of each agent's longest run; peers: sockets it is expected to hold)\n";
        if self.failures.is_empty() {
            out += "every criterion met\n";
        } else {
            for f in &self.failures {
                out += &format!("FAILED {f}\n");
            }
        }
        out
    }
}

/// Rounds between a run's warm and last readings.
fn span(r: &Incarnation) -> u64 {
    match (r.warm, r.last) {
        (Some(w), Some(l)) => l.at_round.saturating_sub(w.at_round),
        _ => 0,
    }
}

/// An agent's memory, descriptors and log against the criteria. Memory and descriptors are
/// judged on the runs still going at the end (`stopped` by SIGTERM), read in the quiet end of
/// the soak; descriptors net of one socket per peer it holds then and at its warm reading.
fn agent_failures(a: &AgentReport, c: &Criteria, events: u64) -> Vec<String> {
    let mut failed = Vec::new();
    for r in a
        .runs
        .iter()
        .filter(|r| r.end.as_deref() == Some("stopped"))
    {
        let (Some(w), Some(l)) = (r.warm, r.last) else {
            continue;
        };
        let grown = l.rss_kb.saturating_sub(w.rss_kb);
        if span(r) >= c.rss_min_rounds
            && grown as f64 > c.max_rss_growth * w.rss_kb as f64
            && grown > c.rss_slack_kb
        {
            failed.push(format!(
                "memory: {} (pid {}) grew from {} KB to {} KB over rounds {}–{}",
                a.name, r.pid, w.rss_kb, l.rss_kb, w.at_round, l.at_round
            ));
        }
        if l.fds.saturating_sub(l.peers) > w.fds.saturating_sub(w.peers) {
            failed.push(format!(
                "fds: {} (pid {}) from {} to {} (peers {} → {}) over rounds {}–{}",
                a.name, r.pid, w.fds, l.fds, w.peers, l.peers, w.at_round, l.at_round
            ));
        }
    }
    for r in a.runs.iter() {
        if let Some(end) = r
            .end
            .as_deref()
            .filter(|e| *e != "stopped" && *e != "killed")
        {
            failed.push(format!("exit: {} (pid {}): {end}", a.name, r.pid));
        }
    }
    let bound = c.log_base_bytes + c.log_per_event_bytes * events;
    if a.log_bytes > bound {
        failed.push(format!(
            "logs: {} wrote {} bytes (at most {bound} for {events} events)",
            a.name, a.log_bytes
        ));
    }
    failed
}

/// The final objective against the optimum of the projectors present at the end.
fn excess(room: &Room, end: &End) -> Option<Excess> {
    let status = end.status?;
    let model = &room.model;
    let gone: Vec<usize> = model
        .owners
        .iter()
        .filter(|(p, _)| !end.present.contains(p))
        .flat_map(|(_, nodes)| nodes.iter().map(|&n| n as usize))
        .collect();
    let best = optimum(&model.problem.without_nodes(&gone)).ok()?;
    Some(Excess {
        present: end.present.clone(),
        objective: status.objective,
        optimum: best.objective,
        excess: best.excess(status.objective),
    })
}

/// Warning and error lines of a log, counted by message: the fmt subscriber's line (`TIME
/// LEVEL [spans:] target: message field=value …`) without time, spans, target and fields.
fn warnings(log: &str) -> BTreeMap<String, usize> {
    let mut counts = BTreeMap::new();
    for line in log.lines() {
        let mut words = line.split_whitespace().skip(1);
        let level = words.next().unwrap_or_default();
        if level != "WARN" && level != "ERROR" {
            continue;
        }
        let message: Vec<&str> = words
            .skip_while(|w| w.ends_with(':') && (w.contains("::") || w.contains('{')))
            .take_while(|w| !is_field(w))
            .collect();
        *counts
            .entry(format!("{level} {}", message.join(" ")))
            .or_default() += 1;
    }
    counts
}

/// `name=value`, as the fmt subscriber writes an event's fields.
fn is_field(word: &str) -> bool {
    word.split_once('=').is_some_and(|(name, _)| {
        !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warnings_are_counted_by_message_without_time_target_or_fields() {
        let log = "2026-11-26T05:40:00.123Z  WARN roomlight_agent::camera::rounds: contributions missing at the deadline round=5 missing=3\n\
                   2026-11-26T05:40:01.123Z  INFO roomlight_agent::camera::service: joined projector=p1 nodes=10\n\
                   2026-11-26T05:40:02.123Z  WARN roomlight_agent::camera::rounds: contributions missing at the deadline round=9 missing=1\n\
                   2026-11-26T05:40:03.123Z ERROR attach{projector=p5}: roomlight_agent::camera::service: disconnected for a malformed contribution: NaN reason=\"x y\"\n";
        let w = warnings(log);
        assert_eq!(
            w.get("WARN contributions missing at the deadline"),
            Some(&2)
        );
        assert_eq!(
            w.get("ERROR disconnected for a malformed contribution: NaN"),
            Some(&1)
        );
        assert_eq!(w.len(), 2);
    }
}
