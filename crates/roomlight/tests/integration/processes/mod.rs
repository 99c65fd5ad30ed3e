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
        self.spawn_with(name, args, dir, &[])
    }

    /// `spawn` with more environment variables.
    fn spawn_with(
        &mut self,
        name: &str,
        args: &[&str],
        dir: &Path,
        env: &[(&str, &Path)],
    ) -> mpsc::Receiver<String> {
        let mut child = Command::new(env!("CARGO_BIN_EXE_roomlight"))
            .args(args)
            .envs(env.iter().copied())
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

    /// SIGTERM, as systemd stops a service; the child is reaped on drop.
    fn terminate(&mut self, name: &str) {
        let (_, child) = self.0.iter().find(|(n, _)| n == name).expect("started");
        let status = Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status()
            .expect("run kill");
        assert!(status.success(), "kill -TERM {name}");
    }

    fn kill(&mut self, name: &str) {
        if let Some(k) = self.0.iter().position(|(n, _)| n == name) {
            let (_, mut child) = self.0.remove(k);
            child.kill().expect("SIGKILL");
            child.wait().expect("reaped");
        }
    }
}

/// A stand-in for systemd's notification socket: what a process started with
/// `NOTIFY_SOCKET` pointing here says, datagram by datagram. A thread reads it all the time, as
/// systemd does (a full socket queue would block the sender).
struct Notifications(mpsc::Receiver<String>, std::path::PathBuf);

impl Notifications {
    fn bind(path: std::path::PathBuf) -> Self {
        let socket = std::os::unix::net::UnixDatagram::bind(&path).expect("bind notify socket");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = socket.recv(&mut buf) {
                if tx
                    .send(String::from_utf8_lossy(&buf[..n]).into_owned())
                    .is_err()
                {
                    return;
                }
            }
        });
        Self(rx, path)
    }

    /// Waits (at most `within`) for a datagram with the line `line`; the datagram.
    fn wait_for(&self, line: &str, within: Duration) -> String {
        let until = Instant::now() + within;
        let mut seen = Vec::new();
        loop {
            let left = until.saturating_duration_since(Instant::now());
            match self.0.recv_timeout(left) {
                Ok(message) if message.lines().any(|l| l == line) => return message,
                Ok(message) => seen.push(message),
                Err(_) => panic!("no {line:?} within {within:?}; got {seen:?}"),
            }
        }
    }
}

/// The first line that `pred` accepts, within `within`.
pub(crate) fn wait_line(
    rx: &mpsc::Receiver<String>,
    within: Duration,
    pred: impl Fn(&str) -> bool,
) -> String {
    let until = Instant::now() + within;
    let mut last = String::new();
    loop {
        let left = until.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok(line) if pred(&line) => return line,
            Ok(line) => last = line,
            Err(e) => panic!("no such line within {within:?} ({e}); the last: {last}"),
        }
    }
}

/// Projectors calibrated over the wire or hot, from a camera status line.
fn calibrated(line: &str) -> Option<u64> {
    Some(roomlight_lab::process::StatusLine::parse(line)?.calibrated)
}

/// The model file `d/model.json`: as JSON, its problem, and the problem's optimum.
fn model_in(
    d: &Path,
) -> (
    serde_json::Value,
    roomlight_core::Problem,
    roomlight_core::optimum::Optimum,
) {
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("model.json")).expect("model"))
            .expect("json");
    let problem: roomlight_core::Problem =
        serde_json::from_value(model["problem"].clone()).expect("problem");
    let best = roomlight_core::optimum::optimum(&problem).expect("optimum");
    (model, problem, best)
}

/// The optimum of the model in `d` and the excess over it of a measured objective `g` that
/// averages `k` captures once the camera's noise is taken out. A capture with patch noise `σ`
/// measures on average `G + ½ Σ σ²` over the patches still in the model (those left out have
/// their target at their black level and count no error), `k` of them averaged `G + ½ Σ σ²/k`:
/// about 1% of this room's G* with three projectors for one, so a measured G within 1% of G*
/// needed a lucky capture, and how many captures that took said more about the noise than
/// about convergence.
pub(crate) fn noise_free(
    d: &Path,
) -> (
    roomlight_core::optimum::Optimum,
    impl Fn((f64, usize)) -> f64,
) {
    let (_, problem, best) = model_in(d);
    let bias: f64 = (0..problem.patches())
        .filter(|&i| problem.target()[i] != problem.black()[i])
        .map(|i| 0.5 * problem.noise()[i].norm_squared())
        .sum();
    let optimum = best.clone();
    (best, move |(g, k): (f64, usize)| {
        optimum.excess(g - bias / k.max(1) as f64)
    })
}

/// `roomlight calibrate --scene small --camera 640x480 ARG --out .` in `d`, which must succeed.
fn calibrate_small(d: &Path, arg: &str) {
    let out = Command::new(env!("CARGO_BIN_EXE_roomlight"))
        .args([
            "calibrate",
            "--scene",
            "small",
            "--camera",
            "640x480",
            arg,
            "--out",
            ".",
        ])
        .current_dir(d)
        .output()
        .expect("run calibrate");
    assert!(
        out.status.success(),
        "calibrate {arg}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Serves the small rendered room (a 640×480 camera) and starts a camera agent on it, `source`
/// being the config lines that say where its model comes from; returns the two addresses and
/// the camera agent's output.
fn small_room_and_camera(
    procs: &mut Procs,
    d: &Path,
    source: &str,
) -> (String, String, mpsc::Receiver<String>) {
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
        d,
    );
    let sim = address(&wait_line(&sim_out, Duration::from_secs(60), |l| {
        l.starts_with("sim listening on")
    }));
    std::fs::write(
        d.join("camera.toml"),
        format!(
            "room = \"small\"\ntoken = \"t\"\nlisten = \"127.0.0.1:0\"\nhardware = {{ sim = \"http://{sim}\" }}\n{source}\nheartbeat_ms = 500\nmodel_rounds = 20\nmdns = false\n"
        ),
    )
    .expect("camera config");
    let cam_out = procs.spawn(
        "camera",
        &["camera", "--config", "camera.toml", "--status-lines"],
        d,
    );
    let camera = address(&wait_line(&cam_out, Duration::from_secs(30), |l| {
        l.starts_with("camera listening on")
    }));
    (sim, camera, cam_out)
}

pub(crate) fn address(line: &str) -> String {
    line.rsplit(' ').next().expect("an address").to_string()
}

/// `(captures, (objective, captures it averages), live)` of a camera status line.
fn status(line: &str) -> Option<(u64, (f64, usize), usize)> {
    let s = roomlight_lab::process::StatusLine::parse(line)?;
    Some((s.captures, (s.objective, s.averaged), s.live))
}

fn write_node(dir: &Path, projector: &str, camera: &str, sim: &str) {
    let text = format!(
        "room = \"lab\"\ntoken = \"t0k3n\"\ncamera = \"http://{camera}\"\nhardware = {{ sim = \"http://{sim}\" }}\nprojector = \"{projector}\"\nstate_file = \"{projector}.state.json\"\n"
    );
    std::fs::write(dir.join(format!("{projector}.toml")), text).expect("node config");
}

/// How well the weights that standard luminaires `names` keep in their state files (in `d`)
/// sum to one on the surface points of the small room as a 640×480 camera sees it, through the
/// simulator's true correspondence, away from the target (whose margin is black).
fn partition_from_states(d: &Path, names: &[&str]) -> roomlight_calib::nodes::Partition {
    let mut scene = roomlight_sim::scenes::small().expect("small scene");
    scene.camera.resolution = [640, 480];
    let room = roomlight_sim::Room::build(scene).expect("room");
    let (cw, ch) = (room.camera().width as usize, room.camera().height as usize);
    let mask: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let away = roomlight_calib::nodes::dilate(&mask, cw, ch, 16);
    let per: Vec<(Vec<Option<u32>>, Vec<f32>)> = names
        .iter()
        .map(|name| {
            let k = room
                .projectors()
                .iter()
                .position(|p| p.name == *name)
                .unwrap_or_else(|| panic!("no projector {name}"));
            let p = &room.projectors()[k].pinhole;
            let state: serde_json::Value = serde_json::from_str(
                &std::fs::read_to_string(d.join(format!("{name}.state"))).expect("state file"),
            )
            .expect("state json");
            let nodes: Vec<(u32, Vec<(u32, f32)>)> =
                serde_json::from_value(state["assignment"]["nodes"].clone()).expect("weights");
            let mut sum = vec![0.0f32; (p.width * p.height) as usize];
            for (_, weights) in nodes {
                for (px, w) in weights {
                    sum[px as usize] += w;
                }
            }
            (room.true_correspondence(k), sum)
        })
        .collect();
    let (truth, weights): (Vec<Vec<Option<u32>>>, Vec<Vec<f32>>) = per.into_iter().unzip();
    roomlight_calib::nodes::partition_of_unity(&truth, &weights, &[], &away)
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
    std::fs::write(d.join("camera.toml"), format!("room = \"lab\"\ntoken = \"t0k3n\"\nlisten = \"127.0.0.1:0\"\nhardware = {{ sim = \"http://{sim}\" }}\nmodel = \"model.json\"\nheartbeat_ms = 200\nmodel_rounds = 5\nmdns = true\nmdns_port = {mdns_port}\nmdns_loopback_only = true\n")).expect("camera config");
    // The camera agent and p0 run as systemd would run them (Type=notify, WatchdogSec=).
    let cam_notify = Notifications::bind(d.join("camera.notify"));
    let p0_notify = Notifications::bind(d.join("p0.notify"));
    let watchdog = Path::new("100000");
    let cam_out = procs.spawn_with(
        "camera",
        &["camera", "--config", "camera.toml", "--status-lines"],
        d,
        &[
            ("NOTIFY_SOCKET", &cam_notify.1),
            ("WATCHDOG_USEC", watchdog),
        ],
    );
    let camera = address(&wait_line(&cam_out, Duration::from_secs(30), |l| {
        l.starts_with("camera listening on")
    }));
    let ready = cam_notify.wait_for("READY=1", Duration::from_secs(10));
    assert!(
        ready.contains("STATUS=camera agent of room \"lab\" serving on"),
        "{ready}"
    );
    cam_notify.wait_for("WATCHDOG=1", Duration::from_secs(10));
    // The pre-flight of p0's PC, before its node agent starts: welcomed by the camera agent,
    // its simulator reached, its state file writable; with a wrong token, refused by name.
    write_node(d, "p0", &camera, &sim);
    let check = |config: &str| {
        Command::new(env!("CARGO_BIN_EXE_roomlight"))
            .args(["check", "--config", config])
            .current_dir(d)
            .output()
            .expect("run roomlight check")
    };
    let passed = check("p0.toml");
    let said = String::from_utf8_lossy(&passed.stdout);
    assert!(
        passed.status.success(),
        "{said}{}",
        String::from_utf8_lossy(&passed.stderr)
    );
    assert!(
        said.contains("welcomed (protocol version") && said.contains("every check passed"),
        "{said}"
    );
    let p0 = std::fs::read_to_string(d.join("p0.toml")).expect("p0 config");
    std::fs::write(d.join("bad.toml"), p0.replace("t0k3n", "wrong")).expect("bad config");
    let refused = check("bad.toml");
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && said.contains("wrong room token"),
        "{said}"
    );
    for p in ["p0", "p1", "p2"] {
        write_node(d, p, &camera, &sim);
        let env: &[(&str, &Path)] = if p == "p0" {
            &[("NOTIFY_SOCKET", &p0_notify.1), ("WATCHDOG_USEC", watchdog)]
        } else {
            &[]
        };
        procs.spawn_with(p, &["node", "--config", &format!("{p}.toml")], d, env);
    }
    let ready = p0_notify.wait_for("READY=1", Duration::from_secs(30));
    assert!(
        ready.contains("STATUS=projector p0 attached and showing"),
        "{ready}"
    );
    p0_notify.wait_for("WATCHDOG=1", Duration::from_secs(10));
    // G* of the room, from the model the simulator wrote.
    let (_, _, best) = model_in(d);
    let converged = |l: &str| {
        status(l).is_some_and(|(c, g, live)| live == 3 && c >= 10 && best.excess(g.0) < 1e-3)
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
        &format!(
            "camera = {{ mdns = \"lab\" }}\nmdns_port = {mdns_port}\nmdns_loopback_only = true"
        ),
    );
    assert!(p2.contains("mdns = \"lab\""), "{p2}");
    std::fs::write(d.join("p2-mdns.toml"), p2).expect("p2 config over mDNS");
    procs.spawn("p2-new", &["node", "--config", "p2-mdns.toml"], d);
    wait_line(&cam_out, Duration::from_secs(60), |l| {
        status(l).is_some_and(|(_, g, live)| live == 3 && best.excess(g.0) < 1e-3)
    });
    // Stopped as systemd stops it: it says so on its way out.
    procs.terminate("p0");
    p0_notify.wait_for("STOPPING=1", Duration::from_secs(10));
    drop(procs);
}

/// The rendered small room through separate processes: `roomlight calibrate` measures it (in
/// one process, through captures) and writes the files; `roomlight sim --scene small` serves it;
/// the camera agent samples the charts of its images and one node agent per luminaire draws its
/// nodes into its projector's image. The room converges and stays there: over
/// [`RENDERED_WINDOW`] captures in a row, the measured `G` less the camera's noise
/// ([`noise_free`]) is on average within [`RENDERED_EXCESS`] of the measured model's optimum.
/// Not within 1% of it: the rounds step with the measured model's columns on the rendered room's
/// errors, so they settle where that step is zero, which here is about 3% above the model's own
/// optimum (2026-12-06: every capture alone it wanders from -2% to +8% around that, averaged
/// captures from +1.5% to +4.5%). A single capture within 1% was a lucky draw of the noise.
#[test]
fn the_rendered_room_converges_through_separate_processes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    calibrate_small(d, "--seed=2");
    let (model, _, _) = model_in(d);
    let (best, excess) = noise_free(d);
    let projectors: Vec<String> = model["owners"]
        .as_object()
        .expect("owners")
        .keys()
        .cloned()
        .collect();
    assert!(projectors.len() >= 2, "{projectors:?}");
    let mut procs = Procs(Vec::new());
    let (sim, camera, cam_out) = small_room_and_camera(
        &mut procs,
        d,
        "model = \"model.json\"\ncharts = \"charts.json\"",
    );
    for p in &projectors {
        std::fs::write(
            d.join(format!("{p}.toml")),
            format!(
                "room = \"small\"\ntoken = \"t\"\ncamera = \"http://{camera}\"\nhardware = {{ sim = \"http://{sim}\" }}\nframe = \"frame-{p}.json\"\nprojector = \"{p}\"\n"
            ),
        )
        .expect("node config");
        procs.spawn(p, &["node", "--config", &format!("{p}.toml")], d);
    }
    let n = projectors.len();
    let window = std::cell::RefCell::new(std::collections::VecDeque::new());
    let line = wait_line(&cam_out, Duration::from_secs(120), |l| {
        let Some((c, g, live)) = status(l) else {
            return false;
        };
        let mut w = window.borrow_mut();
        // One entry per capture (the status line comes once per round), all with every node.
        if live != n || c < 3 {
            w.clear();
            return false;
        }
        if w.back().is_some_and(|&(last, _)| last == c) {
            return false;
        }
        w.push_back((c, excess(g)));
        if w.len() > RENDERED_WINDOW {
            w.pop_front();
        }
        w.len() == RENDERED_WINDOW && mean_excess(&w) < RENDERED_EXCESS
    });
    let (captures, _, _) = status(&line).expect("status");
    let w = window.borrow();
    eprintln!(
        "within {RENDERED_EXCESS} of G* = {:.4e} on average (noise taken out) over captures \
         {}..={captures}: {:?}",
        best.objective,
        w.front().map_or(0, |&(c, _)| c),
        w.iter().map(|&(_, e)| e).collect::<Vec<_>>()
    );
    assert!(captures < 60, "{line}");
    drop(procs);
}

/// Captures in a row whose mean excess the rendered room's test judges.
const RENDERED_WINDOW: usize = 8;

/// The most mean excess over the model's optimum the rendered room's test accepts: its fixed
/// point's (about 3%) and some noise.
const RENDERED_EXCESS: f64 = 0.05;

/// The mean of the excesses in `(capture, excess)` pairs (0 for none).
fn mean_excess(w: &std::collections::VecDeque<(u64, f64)>) -> f64 {
    if w.is_empty() {
        return 0.0;
    }
    w.iter().map(|&(_, e)| e).sum::<f64>() / w.len() as f64
}

/// Calibration over the wire (DESIGN §4, §6): only the survey (chart corners, sampling, target
/// mask) is written beforehand; the camera agent measures the room's black and target itself,
/// and as each node agent joins it shows that projector structured light and a response ramp
/// through the node's own display, decodes and segments it, sends it its nodes' weights, and
/// measures their attenuation while the others keep their values. Checked against the
/// simulator: every luminaire gets nodes, each response recovers the scene's hidden gamma
/// within 2%, and the room converges to within 1% of the optimum of the model built over the
/// wire — first without one luminaire, then again after it joined the lit room (its optimum
/// lower: the joiner's light is measured and used). Then a node is killed with SIGKILL and
/// restarted: it relights from its state file (values and weights), is admitted without being
/// calibrated again, and the room converges again. Last the camera agent is killed and restarted: it resumes the model it wrote and the
/// room is within 1% again, nothing calibrated anew. Nothing is left behind.
#[test]
fn the_room_is_calibrated_over_the_wire_and_survives_killed_processes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    calibrate_small(d, "--survey-only");
    assert!(
        !d.join("model.json").exists(),
        "the survey calibrates nothing"
    );
    let mut procs = Procs(Vec::new());
    let (sim, camera, cam_out) = small_room_and_camera(
        &mut procs,
        d,
        "survey = \"survey.json\"\nmodel_out = \"model.json\"",
    );
    let scene = roomlight_sim::scenes::small().expect("small scene");
    let luminaires: Vec<(String, bool, [f64; 3])> = scene
        .projectors
        .iter()
        .filter(|p| p.role == roomlight_sim::scene::ProjectorRole::Luminaire)
        .map(|p| {
            let large = p.kind == roomlight_sim::scene::ProjectorKind::LargeAperture;
            (p.name.clone(), large, p.gamma)
        })
        .collect();
    assert!(luminaires.len() >= 3, "{luminaires:?}");
    let start_node = |procs: &mut Procs, name: &str, large: bool| {
        std::fs::write(
            d.join(format!("{name}.toml")),
            format!(
                "room = \"small\"\ntoken = \"t\"\ncamera = \"http://{camera}\"\nhardware = {{ sim = \"http://{sim}\" }}\nrendered = true\nkind = \"{}\"\nprojector = \"{name}\"\nstate_file = \"{name}.state\"\n",
                if large { "large-aperture" } else { "standard" }
            ),
        )
        .expect("node config");
        procs.spawn(name, &["node", "--config", &format!("{name}.toml")], d);
    };
    // All but one join a dark room; the last joins the lit, converged room.
    let joiner = luminaires
        .iter()
        .rposition(|(_, large, _)| !large)
        .expect("a standard luminaire");
    for (k, (name, large, _)) in luminaires.iter().enumerate() {
        if k != joiner {
            start_node(&mut procs, name, *large);
        }
    }
    let n = luminaires.len();
    let model_of = |count: usize| {
        let ready = wait_line(&cam_out, Duration::from_secs(180), |l| {
            status(l).is_some_and(|(_, _, live)| live == count)
                && calibrated(l) == Some(count as u64)
        });
        let (model, problem, best) = model_in(d);
        let (captures, g, _) = status(&ready).expect("status");
        (captures, g, model, problem, best)
    };
    // Against the model as the camera agent last wrote it: patches the room's light makes
    // unmeasurable during the rounds leave it (and its G*) for good. Returns that optimum.
    let converge = |count: usize, since: u64| {
        // Two-sided: a room measured below the model's optimum means a wrong model.
        let line = wait_line(&cam_out, Duration::from_secs(120), |l| {
            status(l).is_some_and(|(_, g, live)| live == count && noise_free(d).1(g).abs() < 1e-2)
        });
        let (best, excess) = noise_free(d);
        let (captures, g, _) = status(&line).expect("status");
        assert!(excess(g).abs() < 1e-2, "{line}: excess {}", excess(g));
        eprintln!(
            "{count} projectors: within 1% of G* = {:.4e} (noise taken out) {} captures after their calibration ({line})",
            best.objective,
            captures - since
        );
        assert!(captures - since < 30, "{line}");
        (best, excess)
    };
    let (calibrated_at, _, _, without, first) = model_of(n - 1);
    let _ = converge(n - 1, calibrated_at);
    start_node(&mut procs, &luminaires[joiner].0, false);
    let (calibrated_at, (g_joined, _), model, problem, best) = model_of(n);
    // The joiner starts where it best fills what the room lacks: the very first capture with
    // it is already better than the room could do without it.
    assert!(
        g_joined < first.objective,
        "first capture after the join: G {g_joined:.4e}, G* without the joiner {:.4e}",
        first.objective
    );
    // The room without the joiner, on the patches the final model still measures (the
    // joiner's light may leave more out), for a fair comparison of the optima.
    let out: Vec<bool> = (0..problem.patches())
        .map(|i| {
            problem.target()[i] == problem.black()[i]
                && problem
                    .columns()
                    .iter()
                    .all(|c| c.get(i as u32) == roomlight_core::LinearRgb::ZERO)
        })
        .collect();
    let columns = without
        .columns()
        .iter()
        .map(|c| {
            let (s, v): (Vec<u32>, Vec<roomlight_core::LinearRgb>) =
                c.iter().filter(|(i, _)| !out[*i as usize]).unzip();
            roomlight_core::AttenuationColumn::new(s, v).expect("column")
        })
        .collect();
    let target = (0..without.patches())
        .map(|i| {
            if out[i] {
                without.black()[i]
            } else {
                without.target()[i]
            }
        })
        .collect();
    let without = roomlight_core::Problem::new(
        columns,
        without.black().to_vec(),
        target,
        without.noise().to_vec(),
    )
    .expect("problem");
    let first_common = roomlight_core::optimum::optimum(&without).expect("optimum");
    let owners = model["owners"].as_object().expect("owners");
    for (name, large, gamma) in &luminaires {
        let nodes = owners[name.as_str()].as_array().expect("nodes").len();
        assert!(nodes >= 1, "{name} has no node");
        if *large {
            assert_eq!(nodes, 1, "a large aperture is one node");
        }
        // The weights and response it was sent, as its state file keeps them.
        let state: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(d.join(format!("{name}.state"))).expect("state file"),
        )
        .expect("state json");
        let fitted: [f64; 3] =
            serde_json::from_value(state["assignment"]["response"]["gamma"].clone())
                .expect("assigned response");
        for c in 0..3 {
            assert!(
                (fitted[c] / gamma[c] - 1.0).abs() < 0.02,
                "{name}: γ {fitted:?}, the scene's {gamma:?}"
            );
        }
        let weights = state["assignment"]["nodes"].as_array().expect("weights");
        assert_eq!(weights.len(), nodes, "{name}: weights for every node");
    }
    // `roomlight optimum` reads the same model and prints the same G*.
    let printed = Command::new(env!("CARGO_BIN_EXE_roomlight"))
        .args(["optimum", "--model", "model.json"])
        .current_dir(d)
        .output()
        .expect("run optimum");
    let printed = String::from_utf8_lossy(&printed.stdout).to_string();
    let g_star: f64 = printed
        .split("G* ")
        .nth(1)
        .and_then(|r| r.split(',').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no G* in {printed:?}"));
    assert!((g_star / best.objective - 1.0).abs() < 1e-5, "{printed}");
    let left_out = out.iter().filter(|&&o| o).count();
    assert!(
        printed.contains(&format!("({left_out} left out)")),
        "{printed}: {left_out} left out"
    );
    // Its light is measured and used: the optimum with it is lower than without, on the same
    // patches. It lights only what the projector already there leaves (partition of unity:
    // measured 0.50 of the optimum without it; 0.02 when overlaps got the light of both).
    assert!(
        best.objective < 0.7 * first_common.objective,
        "G* with the joiner {} vs without {} (on the same patches; {} before)",
        best.objective,
        first_common.objective,
        first.objective
    );
    eprintln!(
        "G* without the joiner {:.3e} ({:.3e} on the patches kept after), with it {:.3e}; {} of {} patches left out",
        first.objective,
        first_common.objective,
        best.objective,
        out.iter().filter(|&&o| o).count(),
        out.len()
    );
    let (_, excess) = converge(n, calibrated_at);
    let converged =
        |l: &str| status(l).is_some_and(|(_, g, live)| live == n && excess(g).abs() < 1e-2);
    // SIGKILL a node and start it again: the camera agent notices it left, re-admits it with
    // its weights and attenuation, and does not calibrate it again.
    let (victim, large, _) = luminaires[0].clone();
    procs.kill(&victim);
    wait_line(&cam_out, Duration::from_secs(30), |l| {
        status(l).is_some_and(|(_, _, live)| live == n - 1)
    });
    start_node(&mut procs, &victim, large);
    let line = wait_line(&cam_out, Duration::from_secs(120), |l| {
        converged(l) && calibrated(l) == Some(n as u64)
    });
    let (_, g, _) = status(&line).expect("status");
    assert!(excess(g).abs() < 1e-2, "{line}: excess {}", excess(g));
    // SIGKILL the camera agent and start it again on the same address: it resumes the model it
    // wrote (nothing measured again: the nodes kept their light), the nodes reconnect, and
    // the room is within 1% again without any projector calibrated anew.
    procs.kill("camera");
    std::fs::write(
        d.join("camera.toml"),
        std::fs::read_to_string(d.join("camera.toml"))
            .expect("camera config")
            .replace("127.0.0.1:0", &camera),
    )
    .expect("camera config");
    let cam_out = procs.spawn(
        "camera",
        &["camera", "--config", "camera.toml", "--status-lines"],
        d,
    );
    let resumed = wait_line(&cam_out, Duration::from_secs(30), |l| {
        l.starts_with("resumed")
    });
    assert!(resumed.contains(&format!("of {n} projectors")), "{resumed}");
    let line = wait_line(&cam_out, Duration::from_secs(120), |l| {
        status(l).is_some_and(|(_, g, live)| live == n && excess(g).abs() < 1e-2)
    });
    assert_eq!(
        calibrated(&line),
        Some(0),
        "{line}: nothing calibrated anew"
    );
    let (captures, _, _) = status(&line).expect("status");
    eprintln!("camera agent restarted: within 1% again at its capture {captures} ({line})");
    assert!(captures < 30, "{line}");
    // (Checked last: building the room for its truth takes a while, and the model file may be
    // rewritten meanwhile.) The joiner took what the projectors already there leave: the standard luminaires' weights
    // sum to one where any of them reaches (each segmented alone, overlaps got the light twice).
    let standard: Vec<&str> = luminaires
        .iter()
        .filter(|(_, large, _)| !large)
        .map(|(name, _, _)| name.as_str())
        .collect();
    let partition = partition_from_states(d, &standard);
    eprintln!("partition of unity over the wire: {partition}");
    assert!(
        partition.points > 1000 && partition.overlap > 200,
        "{partition}"
    );
    assert!(
        partition.within_1e3 > 0.95 && partition.within_0_05 > 0.99,
        "{partition}"
    );
    drop(procs);
}

mod local_room;
mod rendered;
