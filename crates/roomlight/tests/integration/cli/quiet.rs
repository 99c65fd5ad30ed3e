//! A room of processes at full speed is quiet (issue 22): the camera agent summarises its
//! rounds at most once a second, the node agents say nothing in the steady state, and nothing
//! piped carries a colour code, even at `RUST_LOG=info`.

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// One line of a child's output: who, from which stream, what, when it was read.
struct Line {
    who: String,
    stream: &'static str,
    text: String,
    at: Instant,
}

/// Children killed and reaped on drop; their stdout and stderr lines on one channel.
struct Room {
    children: Vec<Child>,
    tx: mpsc::Sender<Line>,
    rx: mpsc::Receiver<Line>,
}

impl Drop for Room {
    fn drop(&mut self) {
        for child in &mut self.children {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

impl Room {
    fn new() -> Self {
        let (tx, rx) = mpsc::channel();
        Self {
            children: Vec::new(),
            tx,
            rx,
        }
    }

    /// Starts `roomlight ARGS` in `dir` at `RUST_LOG=info`, both streams piped.
    fn spawn(&mut self, who: &str, args: &[&str], dir: &Path) {
        let mut child = Command::new(env!("CARGO_BIN_EXE_roomlight"))
            .args(args)
            .current_dir(dir)
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("starting {who}: {e}"));
        let out: Box<dyn Read + Send> = Box::new(child.stdout.take().expect("stdout"));
        let err: Box<dyn Read + Send> = Box::new(child.stderr.take().expect("stderr"));
        for (stream, pipe) in [("stdout", out), ("stderr", err)] {
            let (tx, who) = (self.tx.clone(), who.to_string());
            std::thread::spawn(move || {
                for text in BufReader::new(pipe).lines().map_while(Result::ok) {
                    let line = Line {
                        who: who.clone(),
                        stream,
                        text,
                        at: Instant::now(),
                    };
                    if tx.send(line).is_err() {
                        return;
                    }
                }
            });
        }
        self.children.push(child);
    }

    /// Lines until one of `who`'s that `pred` accepts, within `within`; all of them, that one
    /// last.
    fn until(&self, who: &str, within: Duration, pred: impl Fn(&str) -> bool) -> Vec<Line> {
        let deadline = Instant::now() + within;
        let mut seen = Vec::new();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.rx.recv_timeout(left) {
                Ok(line) => {
                    let done = line.who == who && pred(&line.text);
                    seen.push(line);
                    if done {
                        return seen;
                    }
                }
                Err(_) => panic!(
                    "no such line from {who} within {within:?}; seen:\n{}",
                    shown(&seen)
                ),
            }
        }
    }

    /// Every line read until `deadline`.
    fn collect_until(&self, deadline: Instant) -> Vec<Line> {
        let mut seen = Vec::new();
        while let Ok(line) = self
            .rx
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
        {
            seen.push(line);
        }
        seen
    }
}

fn shown(lines: &[Line]) -> String {
    lines
        .iter()
        .map(|l| format!("{} {}: {}", l.who, l.stream, l.text))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The first and last round of a summary line `rounds A–B (…)` or `round A, …`.
fn summarised(text: &str) -> Option<(u64, u64)> {
    if let Some(rest) = text.strip_prefix("rounds ") {
        let span = rest.split_whitespace().next()?.trim_end_matches(',');
        let (a, b) = span.split_once('–')?;
        return Some((a.parse().ok()?, b.parse().ok()?));
    }
    let r = text
        .strip_prefix("round ")?
        .split_once(',')?
        .0
        .parse()
        .ok()?;
    Some((r, r))
}

/// An event a line is allowed for: a projector live or calibrated changing (the camera
/// agent's stdout), a join or a leave, a warning (rate-limited where it repeats: a loaded
/// machine may make contributions late).
fn is_event(text: &str) -> bool {
    let stdout_event = text
        .strip_prefix("round ")
        .and_then(|r| r.split_once(": "))
        .is_some_and(|(n, _)| n.parse::<u64>().is_ok());
    stdout_event
        || [" joined", " left", " goodbye", "stream ended", " WARN "]
            .iter()
            .any(|e| text.contains(e))
}

#[test]
fn a_room_at_full_speed_logs_a_line_a_second_and_no_colour_codes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let mut room = Room::new();
    room.spawn(
        "sim",
        &[
            "sim",
            "--synthetic",
            "30",
            "--projectors",
            "3",
            "--listen",
            "127.0.0.1:0",
            "--model-out",
            "model.json",
        ],
        d,
    );
    let mut before = room.until("sim", Duration::from_secs(30), |l| {
        l.starts_with("sim listening on")
    });
    let sim = before
        .last()
        .expect("a line")
        .text
        .rsplit(' ')
        .next()
        .expect("addr")
        .to_string();
    std::fs::write(
        d.join("camera.toml"),
        format!(
            "room = \"quiet\"\ntoken = \"t0k3n\"\nlisten = \"127.0.0.1:0\"\n\
             hardware = {{ sim = \"http://{sim}\" }}\nmodel = \"model.json\"\n\
             model_rounds = 5\nmdns = false\n"
        ),
    )
    .expect("camera config");
    room.spawn("camera", &["camera", "--config", "camera.toml"], d);
    before.extend(room.until("camera", Duration::from_secs(30), |l| {
        l.starts_with("camera listening on")
    }));
    let camera = before
        .last()
        .expect("a line")
        .text
        .rsplit(' ')
        .next()
        .expect("addr")
        .to_string();
    for p in ["p0", "p1", "p2"] {
        std::fs::write(
            d.join(format!("{p}.toml")),
            format!(
                "room = \"quiet\"\ntoken = \"t0k3n\"\ncamera = \"http://{camera}\"\n\
                 hardware = {{ sim = \"http://{sim}\" }}\nprojector = \"{p}\"\n\
                 state_file = \"{p}.state.json\"\n"
            ),
        )
        .expect("node config");
        room.spawn(p, &["node", "--config", &format!("{p}.toml")], d);
    }
    // Every projector live, then the steady state: five seconds of rounds at full speed.
    before.extend(room.until("camera", Duration::from_secs(60), |l| {
        l.contains(" 3 live") && summarised(l).is_some()
    }));
    let started = Instant::now();
    let window = Duration::from_secs(5);
    let steady = room.collect_until(started + window);
    let seconds = window.as_secs_f64();

    let all: Vec<&Line> = before.iter().chain(&steady).collect();
    for line in &all {
        assert!(
            !line.text.contains('\u{1b}'),
            "a colour code in {}'s piped {}: {:?}",
            line.who,
            line.stream,
            line.text
        );
    }
    // The rounds went on at full speed: summarised, not one line each.
    let rounds: Vec<(u64, u64)> = steady
        .iter()
        .filter(|l| l.who == "camera")
        .filter_map(|l| summarised(&l.text))
        .collect();
    let (first, last) = (
        rounds.first().map_or(0, |r| r.0),
        rounds.last().map_or(0, |r| r.1),
    );
    assert!(
        last >= first + 50,
        "rounds {first}–{last} in {seconds} s:\n{}",
        shown(&steady)
    );
    for who in ["camera", "p0", "p1", "p2", "sim"] {
        let lines: Vec<&Line> = steady
            .iter()
            .filter(|l| l.who == who && l.at <= started + window)
            .collect();
        let events = lines.iter().filter(|l| is_event(&l.text)).count();
        let others = lines.len() - events;
        // One a second, and one for the window's start.
        assert!(
            (others as f64) <= seconds + 1.0,
            "{who}: {others} lines in {seconds} s besides {events} events (rounds {first}–{last}):\n{}",
            shown(&steady)
        );
    }
    eprintln!(
        "rounds {first}–{last} in {seconds} s; lines: {}",
        ["camera", "p0", "p1", "p2", "sim"]
            .map(|w| format!("{w} {}", steady.iter().filter(|l| l.who == w).count()))
            .join(", ")
    );
}
