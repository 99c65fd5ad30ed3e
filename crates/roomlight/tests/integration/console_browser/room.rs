//! The small rendered room as separate processes, as `processes/main.rs` runs it for
//! calibration over the wire: `roomlight calibrate --survey-only` writes the survey,
//! `roomlight sim` serves the room, a camera agent with the console on and one node agent per
//! luminaire. Every process is killed and reaped on drop.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// The room token, which is the console's too.
pub const TOKEN: &str = "t";

/// Children killed and reaped on drop; after a panic the end of each one's stderr is printed.
struct Procs {
    children: Vec<(String, Child)>,
    dir: PathBuf,
}

impl Drop for Procs {
    fn drop(&mut self) {
        for (name, child) in &mut self.children {
            let _ = child.kill();
            let _ = child.wait();
            if std::thread::panicking() {
                let log = std::fs::read_to_string(self.dir.join(format!("{name}.err")))
                    .unwrap_or_default();
                let tail: Vec<&str> = log.lines().rev().take(15).collect();
                eprintln!("--- {name}, last lines of stderr:");
                for line in tail.iter().rev() {
                    eprintln!("{line}");
                }
            }
        }
    }
}

impl Procs {
    /// Starts `roomlight ARGS` in the room's folder, stderr to `NAME.err` there; a channel of
    /// its stdout lines.
    fn spawn(&mut self, name: &str, args: &[&str]) -> mpsc::Receiver<String> {
        let stderr = std::fs::File::create(self.dir.join(format!("{name}.err"))).expect("log");
        let mut child = Command::new(env!("CARGO_BIN_EXE_roomlight"))
            .args(args)
            .current_dir(&self.dir)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(stderr)
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
        self.children.push((name.to_string(), child));
        rx
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

/// The last word of a line such as `sim listening on 127.0.0.1:4242`.
fn address(line: &str) -> String {
    line.rsplit(' ').next().expect("an address").to_string()
}

/// The running room.
pub struct Room {
    procs: Procs,
    /// The console's `127.0.0.1:PORT`.
    pub console: String,
    /// The luminaires, each with a node agent.
    pub projectors: Vec<String>,
    /// The camera agent's stdout (kept open: the agent prints a status line now and then).
    _camera_out: mpsc::Receiver<String>,
}

impl Room {
    pub fn dir(&self) -> &Path {
        &self.procs.dir
    }

    /// Surveys, serves and attaches the small room in `dir`; returns once the camera agent says
    /// where its console is (the projectors are still being calibrated then).
    pub fn start(dir: &Path) -> Self {
        let out = Command::new(env!("CARGO_BIN_EXE_roomlight"))
            .args(["calibrate", "--scene", "small", "--camera", "640x480"])
            .args(["--survey-only", "--out", "."])
            .current_dir(dir)
            .output()
            .expect("run calibrate");
        assert!(
            out.status.success(),
            "calibrate --survey-only: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let mut procs = Procs {
            children: Vec::new(),
            dir: dir.to_path_buf(),
        };
        let sim_out = procs.spawn(
            "sim",
            &[
                "sim",
                "--scene",
                "small",
                "--camera",
                "640x480",
                "--seed",
                "9",
                "--listen",
                "127.0.0.1:0",
            ],
        );
        let sim = address(&wait_line(&sim_out, Duration::from_secs(60), |l| {
            l.starts_with("sim listening on")
        }));
        std::fs::write(
            dir.join("camera.toml"),
            format!(
                "room = \"small\"\ntoken = \"{TOKEN}\"\nlisten = \"127.0.0.1:0\"\nhardware = {{ sim = \"http://{sim}\" }}\nsurvey = \"survey.json\"\nmodel_out = \"model.json\"\nconsole = \"127.0.0.1:0\"\nheartbeat_ms = 500\nmodel_rounds = 20\nmdns = false\n"
            ),
        )
        .expect("camera config");
        let camera_out = procs.spawn("camera", &["camera", "--config", "camera.toml"]);
        let mut camera = None;
        let mut console = None;
        let deadline = Instant::now() + Duration::from_secs(30);
        while camera.is_none() || console.is_none() {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = wait_line(&camera_out, left, |l| {
                l.starts_with("camera listening on") || l.starts_with("console on http://")
            });
            if let Some(url) = line.strip_prefix("console on http://") {
                console = Some(url.trim_end_matches('/').to_string());
            } else {
                camera = Some(address(&line));
            }
        }
        let (camera, console) = (camera.expect("camera"), console.expect("console"));
        let scene = roomlight_sim::scenes::small().expect("small scene");
        let mut projectors = Vec::new();
        for p in &scene.projectors {
            if p.role != roomlight_sim::scene::ProjectorRole::Luminaire {
                continue;
            }
            let kind = if p.kind == roomlight_sim::scene::ProjectorKind::LargeAperture {
                "large-aperture"
            } else {
                "standard"
            };
            let name = &p.name;
            std::fs::write(
                dir.join(format!("{name}.toml")),
                format!(
                    "room = \"small\"\ntoken = \"{TOKEN}\"\ncamera = \"http://{camera}\"\nhardware = {{ sim = \"http://{sim}\" }}\nrendered = true\nkind = \"{kind}\"\nprojector = \"{name}\"\nstate_file = \"{name}.state\"\n"
                ),
            )
            .expect("node config");
            procs.spawn(name, &["node", "--config", &format!("{name}.toml")]);
            projectors.push(name.clone());
        }
        Room {
            procs,
            console,
            projectors,
            _camera_out: camera_out,
        }
    }
}
