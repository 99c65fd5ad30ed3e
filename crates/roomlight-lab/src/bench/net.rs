//! `roomlight bench net`: the cost of one round of the distributed runtime over loopback gRPC —
//! errors out to every node, its update, the contribution and acknowledgement back — with a
//! virtual camera whose capture costs microseconds, for 10 to 10 000 nodes. Timings are
//! printed, not asserted. A size whose agents do not join or whose rounds are too slow is
//! reported as such and the bench goes on. Memory is the process's resident set (camera
//! agent, node agents and their streams, all in this process; see `bench::memory`).

use anyhow::{Context, Result};
use roomlight_agent::camera::{self, CameraConfig, RoomModel};
use roomlight_agent::hardware::VirtualRoom;
use roomlight_agent::node::{self, NodeConfig};
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, StepRule};
use serde::Serialize;
use std::collections::HashMap;
use std::path::Path;
use std::time::{Duration, Instant};
use tokio_util::sync::CancellationToken;

pub const NODES_PER_AGENT: usize = 10;

/// One size of the scaling run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct NetPoint {
    pub nodes: usize,
    pub agents: usize,
    pub median_ms: f64,
    pub p99_ms: f64,
    /// Of a round: every node's update timed alone (the rest is messages and waiting).
    pub compute_ms: f64,
    pub bytes_out_per_round: u64,
    pub bytes_in_per_round: u64,
    /// Rounds measured (fewer than planned when they took too long).
    pub rounds: usize,
    /// How far the resident set grew while the node agents joined and the first rounds ran,
    /// per node, in KB (camera agent's per-node state and the streams included).
    pub rss_kb_per_node: Option<f64>,
    /// Why the figures are missing or partial, if they are.
    pub note: Option<String>,
}

/// The whole run, as `--json` writes it.
#[derive(Debug, Clone, Serialize)]
pub struct NetRun {
    pub sizes: Vec<NetPoint>,
    /// Least-squares slope of log(median round time) on log(nodes) over the sizes measured.
    pub growth_exponent: Option<f64>,
    /// The same for the compute alone.
    pub compute_exponent: Option<f64>,
    /// The same for the resident set per node (0: flat per node).
    pub memory_exponent: Option<f64>,
    pub memory: &'static str,
}

/// How long a size may take before it is reported too slow instead of measured.
const JOIN_LIMIT: Duration = Duration::from_secs(180);
const ROUND_LIMIT: Duration = Duration::from_secs(30);
const ROUNDS_LIMIT: Duration = Duration::from_secs(90);

/// Least squares on log-log: `y ∝ x^b` over the points with both positive; `None` with fewer
/// than two such points or when every `x` is the same (no slope to fit).
pub fn growth_exponent(points: &[(f64, f64)]) -> Option<f64> {
    let logs: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| *x > 0.0 && *y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    if logs.len() < 2 {
        return None;
    }
    let k = logs.len() as f64;
    let mx = logs.iter().map(|p| p.0).sum::<f64>() / k;
    let my = logs.iter().map(|p| p.1).sum::<f64>() / k;
    let sxx: f64 = logs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = logs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// The room sizes measured, in nodes.
pub const SIZES: [usize; 5] = [10, 100, 1000, 5000, 10_000];
/// The room sizes measured with `--quick`.
pub const QUICK_SIZES: [usize; 2] = [10, 100];

/// `10, 100, 1000, 5000 and 10 000`: sizes as the help and the docs say them.
pub fn said(sizes: &[usize]) -> String {
    let one = |n: usize| {
        if n >= 10_000 {
            format!("{} {:03}", n / 1000, n % 1000)
        } else {
            n.to_string()
        }
    };
    match sizes {
        [] => String::new(),
        [only] => one(*only),
        [rest @ .., last] => format!(
            "{} and {}",
            rest.iter().map(|&n| one(n)).collect::<Vec<_>>().join(", "),
            one(*last)
        ),
    }
}

/// Runs every size ([`QUICK_SIZES`] with `quick`, else [`SIZES`]), prints the table and the
/// growth exponents, and writes the run to `json` if given.
pub fn run(quick: bool, json: Option<&Path>) -> Result<NetRun> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the runtime")?;
    let sizes: &[usize] = if quick { &QUICK_SIZES } else { &SIZES };
    println!("{}", header());
    let mut points = Vec::new();
    for &n in sizes {
        let point = runtime.block_on(case(n))?;
        println!("{}", row(&point));
        points.push(point);
    }
    let fit = |f: fn(&NetPoint) -> f64| {
        let xy: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.rounds > 0)
            .map(|p| (p.nodes as f64, f(p)))
            .collect();
        growth_exponent(&xy)
    };
    let run = NetRun {
        growth_exponent: fit(|p| p.median_ms),
        compute_exponent: fit(|p| p.compute_ms),
        memory_exponent: fit(|p| p.rss_kb_per_node.unwrap_or(0.0)),
        sizes: points,
        memory: "resident set growth (VmRSS) while the node agents join, per node",
    };
    let show = |e: Option<f64>| e.map_or_else(|| "n/a".to_string(), |e| format!("{e:.2}"));
    println!(
        "growth exponent: round time as nodes^{} (its compute as nodes^{}), resident memory per node as nodes^{} (least squares on log-log over the sizes measured; supports of fixed size)",
        show(run.growth_exponent),
        show(run.compute_exponent),
        show(run.memory_exponent),
    );
    if let Some(path) = json {
        std::fs::write(path, serde_json::to_string_pretty(&run)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(run)
}

/// The table's header: 100 columns, as its rows.
fn header() -> String {
    format!(
        "{:>6} {:>7} {:>10} {:>10} {:>11} {:>14} {:>13} {:>7} {:>13}",
        "nodes",
        "agents",
        "median ms",
        "p99 ms",
        "compute ms",
        "bytes out/rnd",
        "bytes in/rnd",
        "rounds",
        "RSS KB/node"
    )
}

/// One size's row, and its note (a size too slow to measure) on a line of its own below it,
/// so that no line is wider than the header.
fn row(p: &NetPoint) -> String {
    let rss = p
        .rss_kb_per_node
        .map_or_else(|| "n/a".to_string(), |v| format!("{v:.1}"));
    let measured = |v: String| if p.rounds == 0 { "-".to_string() } else { v };
    let mut line = format!(
        "{:>6} {:>7} {:>10} {:>10} {:>11.3} {:>14} {:>13} {:>7} {rss:>13}",
        p.nodes,
        p.agents,
        measured(format!("{:.3}", p.median_ms)),
        measured(format!("{:.3}", p.p99_ms)),
        p.compute_ms,
        measured(p.bytes_out_per_round.to_string()),
        measured(p.bytes_in_per_round.to_string()),
        p.rounds,
    );
    if let Some(note) = &p.note {
        line.push_str(&format!("\n{:>6} {note}", "↳"));
    }
    line
}

/// A synthetic room served by a camera agent over loopback gRPC, with a virtual camera, and
/// its node agents (ten nodes each).
#[derive(Debug)]
pub struct SyntheticAgents {
    pub room: VirtualRoom,
    pub status: tokio::sync::watch::Receiver<camera::RoomStatus>,
    /// The console's handle on the camera agent.
    pub control: camera::Control,
    pub agents: usize,
    owners: HashMap<String, Vec<u32>>,
    endpoint: String,
    cancel: CancellationToken,
    /// The node agents' token: they stop before the camera agent.
    nodes: CancellationToken,
    camera: tokio::task::JoinHandle<Result<(), roomlight_agent::AgentError>>,
    /// The node agents.
    tasks: Vec<tokio::task::JoinHandle<Result<(), roomlight_agent::AgentError>>>,
}

impl SyntheticAgents {
    /// The camera agent alone (node agents come with [`Self::spawn_nodes`]).
    pub async fn camera(
        problem: &roomlight_core::Problem,
        plant: PlantConfig,
        start: Option<Vec<LinearRgb>>,
        model_rounds: usize,
    ) -> Result<Self> {
        Self::camera_with(problem, plant, start, model_rounds, VirtualRoom::camera).await
    }

    /// [`Self::camera`] with the camera `camera` makes of the virtual room (e.g. one that
    /// holds or logs its captures).
    pub async fn camera_with<C: roomlight_agent::hardware::Camera>(
        problem: &roomlight_core::Problem,
        plant: PlantConfig,
        start: Option<Vec<LinearRgb>>,
        model_rounds: usize,
        camera: impl FnOnce(&VirtualRoom) -> C,
    ) -> Result<Self> {
        let nodes = problem.nodes();
        let agents = nodes.div_ceil(NODES_PER_AGENT);
        let owners: HashMap<String, Vec<u32>> = (0..agents)
            .map(|a| {
                let first = a * NODES_PER_AGENT;
                let ids = (first as u32..(first + NODES_PER_AGENT).min(nodes) as u32).collect();
                (format!("p{a}"), ids)
            })
            .collect();
        let room = VirtualRoom::new(Plant::new(problem.clone(), plant)?);
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let endpoint = format!("http://{}", listener.local_addr()?);
        let cancel = CancellationToken::new();
        let config = CameraConfig {
            room: "bench".into(),
            token: "t".into(),
            heartbeat: Duration::from_secs(1),
            deadline: Duration::from_secs(5),
            model_rounds,
            calibration_epoch: 1,
            stale_frames: 0,
            model_out: None,
            primaries: true,
            shading_passes: 0,
        };
        let served = camera::serve_room(
            config,
            RoomModel {
                problem: problem.clone(),
                owners: owners.clone(),
                start,
                hot: Default::default(),
                survey: None,
            },
            camera(&room),
            listener,
            None,
            camera::Extras::default(),
            cancel.clone(),
        );
        let (status, camera_task) = (served.status, served.handle);
        Ok(Self {
            room,
            status,
            control: served.control,
            agents,
            owners,
            endpoint,
            cancel,
            nodes: CancellationToken::new(),
            camera: camera_task,
            tasks: Vec::new(),
        })
    }

    /// One node agent per projector, every node on `rule`.
    pub fn spawn_nodes(&mut self, rule: StepRule) {
        for id in self.owners.keys() {
            let config = NodeConfig {
                endpoint: self.endpoint.clone(),
                room: "bench".into(),
                token: "t".into(),
                projector_id: id.clone(),
                kind: roomlight_proto::v1::ProjectorKind::Standard,
                rule,
                start: LinearRgb::splat(0.5),
                state_file: None,
            };
            let task = node::run(config, self.room.display(), self.nodes.child_token());
            self.tasks.push(tokio::spawn(task));
        }
    }

    /// Stops every agent and waits until they are gone, 10 s at most in all (a thousand
    /// agents must not wait 5 s each); those still running then are aborted. The node agents
    /// stop first, so that none of them sees the camera agent vanish (a warning each).
    pub async fn stop(self) {
        let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
        self.nodes.cancel();
        for task in self.tasks {
            join_or_abort(task, deadline).await;
        }
        self.cancel.cancel();
        join_or_abort(self.camera, deadline).await;
    }
}

/// Waits for `task` until `deadline`, then aborts it.
async fn join_or_abort<T>(task: tokio::task::JoinHandle<T>, deadline: tokio::time::Instant) {
    let abort = task.abort_handle();
    if tokio::time::timeout_at(deadline, task).await.is_err() {
        abort.abort();
    }
}

/// One size, bounded: agents that do not all join within `JOIN_LIMIT`, a round over
/// `ROUND_LIMIT` or rounds past `ROUNDS_LIMIT` end the size early with a note.
async fn case(nodes: usize) -> Result<NetPoint> {
    let problem = synthetic_room(&SyntheticConfig::new(nodes, 1))?.problem;
    let rule = StepRule::Safe { theta: 1.0 };
    let compute_ms = crate::bench::core::us_per_node_update(
        &problem,
        rule,
        &vec![LinearRgb::splat(0.5); nodes],
    )? * nodes as f64
        / 1e3;
    let mut room = SyntheticAgents::camera(&problem, PlantConfig::default(), None, 0).await?;
    let mut point = NetPoint {
        nodes,
        agents: room.agents,
        median_ms: f64::NAN,
        p99_ms: f64::NAN,
        compute_ms,
        bytes_out_per_round: 0,
        bytes_in_per_round: 0,
        rounds: 0,
        rss_kb_per_node: None,
        note: None,
    };
    let before = super::memory::resident();
    room.spawn_nodes(rule);
    let joined = tokio::time::timeout(JOIN_LIMIT, joined(&mut room)).await;
    match joined {
        Ok(result) => result?,
        Err(_) => {
            point.note = Some(format!("too slow: not all joined within {JOIN_LIMIT:?}"));
            room.stop().await;
            return Ok(point);
        }
    }
    if let (Some(b), Some(a)) = (before, super::memory::resident()) {
        point.rss_kb_per_node = Some(a.now.saturating_sub(b.now) as f64 / 1024.0 / nodes as f64);
    }
    measure_rounds(&mut room, &mut point).await?;
    room.stop().await;
    Ok(point)
}

/// Until every node agent is live and two captures are taken.
async fn joined(room: &mut SyntheticAgents) -> Result<()> {
    let agents = room.agents;
    loop {
        let s = room.status.borrow().clone();
        if s.live_projectors == agents && s.captures >= 2 {
            return Ok(());
        }
        room.status.changed().await?;
    }
}

/// Times rounds (the first left out, it waits on the join) into `point`.
async fn measure_rounds(room: &mut SyntheticAgents, point: &mut NetPoint) -> Result<()> {
    let planned = if point.nodes >= 1000 { 20 } else { 60 };
    let mut times = Vec::with_capacity(planned);
    let (mut out, mut inn) = (0u64, 0u64);
    let started = Instant::now();
    let mut last = started;
    for _ in 0..planned {
        if started.elapsed() > ROUNDS_LIMIT {
            point.note = Some(format!("too slow: rounds past {ROUNDS_LIMIT:?}"));
            break;
        }
        if tokio::time::timeout(ROUND_LIMIT, room.status.changed())
            .await
            .is_err()
        {
            point.note = Some(format!("too slow: a round over {ROUND_LIMIT:?}"));
            break;
        }
        let now = Instant::now();
        times.push((now - last).as_secs_f64() * 1e3);
        last = now;
        let s = room.status.borrow().clone();
        out += s.bytes_out;
        inn += s.bytes_in;
    }
    let counted = times.len() as u64;
    if counted >= 2 {
        times.remove(0);
    }
    if times.is_empty() {
        return Ok(());
    }
    times.sort_by(f64::total_cmp);
    let pct = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize];
    point.median_ms = pct(0.5);
    point.p99_ms = pct(0.99);
    point.rounds = times.len();
    point.bytes_out_per_round = out / counted;
    point.bytes_in_per_round = inn / counted;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{NetPoint, growth_exponent, header, row, said};

    #[test]
    fn every_line_of_the_table_fits_120_columns() {
        let p = NetPoint {
            nodes: 10_000,
            agents: 1000,
            median_ms: 129.812,
            p99_ms: 1234.5,
            compute_ms: 98.765,
            bytes_out_per_round: 123_456_789,
            bytes_in_per_round: 98_765_432,
            rounds: 1234,
            rss_kb_per_node: Some(12.3),
            note: None,
        };
        let slow = NetPoint {
            rounds: 0,
            note: Some("too slow: not all joined within 180s, and then some more words".into()),
            ..p.clone()
        };
        let lines = [header(), row(&p), row(&slow)].join("\n");
        assert_eq!(lines.lines().count(), 4, "{lines}");
        for line in lines.lines() {
            assert!(line.chars().count() <= 120, "{line}");
        }
        assert!(lines.contains("↳ too slow"), "{lines}");
    }

    #[test]
    fn sizes_are_said_as_a_person_writes_them() {
        assert_eq!(said(&[10, 100]), "10 and 100");
        assert_eq!(
            said(&[10, 100, 1000, 5000, 10_000]),
            "10, 100, 1000, 5000 and 10 000"
        );
        assert_eq!(said(&[12_345]), "12 345");
    }

    #[test]
    fn the_growth_exponent_is_the_log_log_slope() {
        let points: Vec<(f64, f64)> = [10.0_f64, 100.0, 1000.0, 5000.0]
            .iter()
            .map(|&n| (n, 3.0 * n.powf(1.5)))
            .collect();
        let b = growth_exponent(&points).expect("a slope");
        assert!((b - 1.5).abs() < 1e-9, "{b}");
        // Sizes without a figure (too slow: 0) are left out; one size has no slope.
        assert!(growth_exponent(&[(10.0, 1.0), (100.0, 0.0)]).is_none());
        assert!(growth_exponent(&[(10.0, 1.0), (10.0, 2.0)]).is_none());
    }
}
