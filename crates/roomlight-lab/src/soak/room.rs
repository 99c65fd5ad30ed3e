//! The soak's room: a synthetic room served by `roomlight sim`, its camera agent and one node
//! agent per present projector, each its own process with its config file in the soak's
//! folder, as `deploy/local-room.sh` runs them (explicit addresses on 127.0.0.1, no mDNS). It
//! follows the camera agent's status lines (`--status-lines`: one per round), counts the rounds
//! of every camera incarnation, and waits on conditions with deadlines.

use super::procs::Agent;
use crate::process::StatusLine;
use crate::process::{ModelFile, load_model};
use anyhow::{Context, Result, bail};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The room's token (a soak's own).
pub const TOKEN: &str = "soak-token";
pub const ROOM: &str = "soak";

/// How often the processes are measured while the driver waits.
pub(super) const SAMPLE_EVERY: Duration = Duration::from_millis(250);

/// What the room is.
#[derive(Debug, Clone)]
pub struct Layout {
    pub nodes: usize,
    /// Projectors of the room: the first `present` start lit, the next are spares added
    /// during the soak, and the last one is never started (the misbehaving peer claims it).
    pub projectors: usize,
    pub present: usize,
    pub seed: u64,
    /// Rounds an incarnation runs before its warm reading.
    pub warm_up: u64,
}

#[derive(Debug)]
pub struct Room {
    dir: PathBuf,
    exe: PathBuf,
    layout: Layout,
    sim: Agent,
    pub camera: Agent,
    pub nodes: BTreeMap<String, Agent>,
    pub camera_addr: String,
    pub model: ModelFile,
    /// The camera agent's last status line, this incarnation.
    pub status: Option<StatusLine>,
    /// Rounds run by each camera incarnation (the last one so far).
    pub camera_rounds: Vec<u64>,
    /// Agents that exited without being asked to, and how.
    pub unexpected: Vec<String>,
    last_sample: Instant,
}

impl Room {
    /// Starts the simulator, the camera agent and the first projectors' node agents, and waits
    /// until every one of them is attached.
    pub fn start(exe: &Path, dir: &Path, layout: Layout) -> Result<Self> {
        let (nodes, projectors, seed) = (
            layout.nodes.to_string(),
            layout.projectors.to_string(),
            layout.seed.to_string(),
        );
        let mut sim = Agent::new(
            exe,
            dir,
            "sim",
            &[
                "sim",
                "--synthetic",
                &nodes,
                "--projectors",
                &projectors,
                "--seed",
                &seed,
                "--listen",
                "127.0.0.1:0",
                "--model-out",
                "model.json",
            ],
        );
        sim.start(0)?;
        let sim_addr = address(&sim.wait_line("sim listening on", Duration::from_secs(60))?);
        let model = load_model(&dir.join("model.json"))?;
        let camera = Agent::new(
            exe,
            dir,
            "camera",
            &["camera", "--config", "camera.toml", "--status-lines"],
        );
        let mut room = Self {
            dir: dir.to_path_buf(),
            exe: exe.to_path_buf(),
            layout: layout.clone(),
            sim,
            camera,
            nodes: BTreeMap::new(),
            camera_addr: String::new(),
            model,
            status: None,
            camera_rounds: vec![0],
            unexpected: Vec::new(),
            last_sample: Instant::now(),
        };
        room.write_camera_config(&sim_addr, "127.0.0.1:0")?;
        room.camera.start(0)?;
        room.camera_addr = address(
            &room
                .camera
                .wait_line("camera listening on", Duration::from_secs(60))?,
        );
        // A restarted camera agent listens where the node agents look for it.
        room.write_camera_config(&sim_addr, &room.camera_addr.clone())?;
        // Every projector's but the last, which no node agent of the room runs.
        for p in 0..layout.projectors - 1 {
            room.write_node_config(&format!("p{p}"), &sim_addr)?;
        }
        for p in 0..layout.present {
            room.start_node(&format!("p{p}"))?;
        }
        let present = layout.present;
        room.wait(
            Duration::from_secs(60),
            "every first projector attached",
            |r| r.live() == Some(present),
        )?;
        Ok(room)
    }

    fn write_camera_config(&self, sim: &str, listen: &str) -> Result<()> {
        let text = format!(
            "room = \"{ROOM}\"\ntoken = \"{TOKEN}\"\nlisten = \"{listen}\"\nhardware = {{ sim = \"http://{sim}\" }}\nmodel = \"model.json\"\nheartbeat_ms = 200\ndeadline_ms = 1000\nmodel_rounds = 5\nmdns = false\n"
        );
        let path = self.dir.join("camera.toml");
        std::fs::write(&path, text).with_context(|| path.display().to_string())
    }

    fn write_node_config(&self, projector: &str, sim: &str) -> Result<()> {
        let text = format!(
            "room = \"{ROOM}\"\ntoken = \"{TOKEN}\"\ncamera = \"http://{}\"\nhardware = {{ sim = \"http://{sim}\" }}\nprojector = \"{projector}\"\nstate_file = \"{projector}.state.json\"\n",
            self.camera_addr
        );
        let path = self.dir.join(format!("{projector}.toml"));
        std::fs::write(&path, text).with_context(|| path.display().to_string())
    }

    /// Starts (or restarts) `projector`'s node agent.
    pub fn start_node(&mut self, projector: &str) -> Result<()> {
        let rounds = self.rounds();
        let config = format!("{projector}.toml");
        let agent = self.nodes.entry(projector.to_string()).or_insert_with(|| {
            Agent::new(
                &self.exe,
                &self.dir,
                projector,
                &["node", "--config", &config],
            )
        });
        agent.start(rounds)
    }

    /// kill -9 the camera agent and start it again on the same address.
    pub fn restart_camera(&mut self) -> Result<()> {
        self.pump();
        self.camera.kill();
        self.camera_rounds.push(0);
        self.status = None;
        self.camera.start(self.rounds())?;
        self.camera
            .wait_line("camera listening on", Duration::from_secs(60))?;
        Ok(())
    }

    /// Rounds run by every camera incarnation so far.
    pub fn rounds(&self) -> u64 {
        self.camera_rounds.iter().sum()
    }

    /// Projectors attached, by the camera agent's last status line.
    pub fn live(&self) -> Option<usize> {
        self.status.map(|s| s.live)
    }

    /// Reads the camera agent's new status lines, notes agents that died on their own, and
    /// measures every process now and then.
    pub fn pump(&mut self) {
        for line in self.camera.new_lines() {
            if let Some(s) = StatusLine::parse(&line) {
                self.status = Some(s);
                if let Some(r) = self.camera_rounds.last_mut() {
                    *r = s.round;
                }
            }
        }
        let agents = std::iter::once(&mut self.sim)
            .chain(std::iter::once(&mut self.camera))
            .chain(self.nodes.values_mut());
        for agent in agents {
            if let Some(end) = agent.exited() {
                self.unexpected.push(format!("{}: {end}", agent.name));
            }
        }
        if self.last_sample.elapsed() >= SAMPLE_EVERY {
            self.sample();
        }
    }

    /// Measures every running process.
    pub fn sample(&mut self) {
        self.last_sample = Instant::now();
        let (rounds, warm) = (self.rounds(), self.layout.warm_up);
        let running_nodes = self.nodes.values().filter(|a| a.running()).count() as u64;
        let camera_peers = self.live().unwrap_or(0) as u64;
        // Each node agent's display and the camera agent's camera are one connection each.
        let sim_peers = running_nodes + u64::from(self.camera.running());
        self.sim.sample(rounds, warm, sim_peers);
        self.camera.sample(rounds, warm, camera_peers);
        for node in self.nodes.values_mut() {
            node.sample(rounds, warm, 0);
        }
    }

    /// Waits (at most `within`) until `done` holds, reading the room meanwhile; an error naming
    /// `what` and the last status otherwise.
    pub fn wait(
        &mut self,
        within: Duration,
        what: &str,
        done: impl Fn(&Room) -> bool,
    ) -> Result<Duration> {
        let start = Instant::now();
        loop {
            self.pump();
            if done(self) {
                return Ok(start.elapsed());
            }
            if start.elapsed() > within {
                bail!(
                    "{what}: not reached within {within:?} (last status {:?}, rounds {})",
                    self.status,
                    self.rounds()
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Every agent, the simulator first.
    pub fn agents(&self) -> impl Iterator<Item = &Agent> {
        [&self.sim, &self.camera]
            .into_iter()
            .chain(self.nodes.values())
    }

    /// Stops every agent as systemd would (SIGTERM), nodes first.
    pub fn stop(&mut self) {
        for node in self.nodes.values_mut() {
            node.terminate(Duration::from_secs(10));
        }
        self.camera.terminate(Duration::from_secs(10));
        self.sim.terminate(Duration::from_secs(10));
    }

    /// Whether `projector`'s node agent has written its state file (what it relights from).
    pub fn has_state(&self, projector: &str) -> bool {
        self.dir.join(format!("{projector}.state.json")).exists()
    }

    /// How many lines of `agent`'s log contain `text`.
    pub fn log_count(&self, agent: &str, text: &str) -> usize {
        let path = self.dir.join(format!("{agent}.log"));
        std::fs::read_to_string(path)
            .map(|log| log.lines().filter(|l| l.contains(text)).count())
            .unwrap_or(0)
    }
}

/// The address at the end of a `… listening on ADDR` line.
fn address(line: &str) -> String {
    line.rsplit(' ').next().unwrap_or_default().to_string()
}
