//! One process per part, as in a real installation: `roomlight sim`, `roomlight camera` and three
//! `roomlight node` processes on loopback. A node is killed with SIGKILL and another started in
//! its place; the room converges again. No process is left behind.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Children killed and reaped on drop, whatever happens in the test.
struct Procs(Vec<(String, Child)>);

impl Drop for Procs {
    fn drop(&mut self) {
        for (_, child) in &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

impl Procs {
    /// Starts `roomlight ARGS`, returning a channel of its stdout lines.
    fn spawn(&mut self, name: &str, args: &[&str], dir: &Path) -> mpsc::Receiver<String> {
        let mut child = Command::new(env!("CARGO_BIN_EXE_roomlight"))
            .args(args)
            .current_dir(dir)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("starting {name}: {e}"));
        let stdout = child.stdout.take().expect("piped stdout");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    return;
                }
            }
        });
        self.0.push((name.to_string(), child));
        rx
    }

    fn kill(&mut self, name: &str) {
        if let Some(k) = self.0.iter().position(|(n, _)| n == name) {
            let (_, mut child) = self.0.remove(k);
            child.kill().expect("SIGKILL");
            child.wait().expect("reaped");
        }
    }
}

/// The first line that `pred` accepts, within `within`.
fn wait_line(rx: &mpsc::Receiver<String>, within: Duration, pred: impl Fn(&str) -> bool) -> String {
    let until = Instant::now() + within;
    loop {
        let left = until.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok(line) if pred(&line) => return line,
            Ok(_) => {}
            Err(e) => panic!("no such line within {within:?}: {e}"),
        }
    }
}

fn address(line: &str) -> String {
    line.rsplit(' ').next().expect("an address").to_string()
}

/// `(captures, objective, live)` of a camera status line.
fn status(line: &str) -> Option<(u64, f64, usize)> {
    let w: Vec<&str> = line.split_whitespace().collect();
    match w.as_slice() {
        ["round", _, "captures", c, "objective", g, "live", l] => {
            Some((c.parse().ok()?, g.parse().ok()?, l.parse().ok()?))
        }
        _ => None,
    }
}

fn write_node(dir: &Path, projector: &str, camera: &str, sim: &str) {
    let text = format!(
        "room = \"lab\"\ntoken = \"t0k3n\"\ncamera = \"http://{camera}\"\nhardware = \"http://{sim}\"\nprojector = \"{projector}\"\nstate_file = \"{projector}.state.json\"\n"
    );
    std::fs::write(dir.join(format!("{projector}.toml")), text).expect("node config");
}

#[test]
fn processes_converge_survive_a_killed_node_and_leave_nothing_behind() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let mut procs = Procs(Vec::new());
    let sim_out = procs.spawn(
        "sim",
        &[
            "sim",
            "--synthetic",
            "12",
            "--projectors",
            "3",
            "--listen",
            "127.0.0.1:0",
            "--model-out",
            "model.json",
        ],
        d,
    );
    let sim = address(&wait_line(&sim_out, Duration::from_secs(30), |l| {
        l.starts_with("sim listening on")
    }));
    // The camera agent advertises itself over mDNS on loopback, on a port of this test's own;
    // the replacement node below finds it that way.
    let mdns_port = 20_000 + (std::process::id() % 20_000);
    std::fs::write(d.join("camera.toml"), format!("room = \"lab\"\ntoken = \"t0k3n\"\nlisten = \"127.0.0.1:0\"\nhardware = \"http://{sim}\"\nmodel = \"model.json\"\nheartbeat_ms = 200\nmodel_rounds = 5\nmdns = true\nmdns_port = {mdns_port}\nmdns_loopback_only = true\n")).expect("camera config");
    let cam_out = procs.spawn("camera", &["camera", "--config", "camera.toml"], d);
    let camera = address(&wait_line(&cam_out, Duration::from_secs(30), |l| {
        l.starts_with("camera listening on")
    }));
    for p in ["p0", "p1", "p2"] {
        write_node(d, p, &camera, &sim);
        procs.spawn(p, &["node", "--config", &format!("{p}.toml")], d);
    }
    // G* of the room, from the model the simulator wrote.
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("model.json")).expect("model"))
            .expect("json");
    let problem: roomlight_core::Problem =
        serde_json::from_value(model["problem"].clone()).expect("problem");
    let best = roomlight_core::optimum::optimum(&problem).expect("optimum");
    let converged = |l: &str| {
        status(l).is_some_and(|(c, g, live)| live == 3 && c >= 10 && best.excess(g) < 1e-3)
    };
    wait_line(&cam_out, Duration::from_secs(60), converged);
    // kill -9 p2 and start a replacement for the same projector: it finds the camera agent over
    // mDNS and resumes from p2's state file.
    procs.kill("p2");
    wait_line(&cam_out, Duration::from_secs(30), |l| {
        status(l).is_some_and(|(_, _, live)| live == 2)
    });
    let p2 = std::fs::read_to_string(d.join("p2.toml")).expect("p2 config");
    let p2 = p2.replace(
        &format!("camera = \"http://{camera}\""),
        &format!("camera = \"mdns\"\nmdns_port = {mdns_port}\nmdns_loopback_only = true"),
    );
    assert!(p2.contains("\"mdns\""), "{p2}");
    std::fs::write(d.join("p2-mdns.toml"), p2).expect("p2 config over mDNS");
    procs.spawn("p2-new", &["node", "--config", "p2-mdns.toml"], d);
    wait_line(&cam_out, Duration::from_secs(60), |l| {
        status(l).is_some_and(|(_, g, live)| live == 3 && best.excess(g) < 1e-3)
    });
    drop(procs);
}
