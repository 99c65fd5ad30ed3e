//! `roomlight bench net`: the cost of one round of the distributed runtime over loopback gRPC —
//! errors out to every node, its update, the contribution and acknowledgement back — with a
//! virtual camera whose capture costs microseconds. Timings are printed, not asserted.

use anyhow::{Context, Result};
use peak_alloc::PeakAlloc;
use roomlight_agent::camera::{self, CameraConfig, RoomModel};
use roomlight_agent::hardware::VirtualRoom;
use roomlight_agent::node::{self, NodeConfig};
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, StepRule};
use std::collections::HashMap;
use std::time::{Duration, Instant};
use tokio_util::sync::CancellationToken;

const NODES_PER_AGENT: usize = 10;

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
    /// Heap the node agents hold, over all of them.
    pub heap_mb: f64,
}

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

pub fn run(quick: bool, alloc: &PeakAlloc) -> Result<Vec<NetPoint>> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the runtime")?;
    let sizes: &[usize] = if quick {
        &[10, 100]
    } else {
        &[10, 100, 1000, 5000]
    };
    println!(
        "{:>6} {:>7} {:>13} {:>11} {:>11} {:>15} {:>14} {:>18}",
        "nodes",
        "agents",
        "median ms",
        "p99 ms",
        "compute ms",
        "bytes out/rnd",
        "bytes in/rnd",
        "heap per agent"
    );
    let mut points = Vec::new();
    for &n in sizes {
        points.push(runtime.block_on(case(n, alloc))?);
    }
    let time: Vec<(f64, f64)> = points
        .iter()
        .map(|p| (p.nodes as f64, p.median_ms))
        .collect();
    let heap: Vec<(f64, f64)> = points.iter().map(|p| (p.nodes as f64, p.heap_mb)).collect();
    let compute: Vec<(f64, f64)> = points
        .iter()
        .map(|p| (p.nodes as f64, p.compute_ms))
        .collect();
    if let (Some(t), Some(c), Some(m)) = (
        growth_exponent(&time),
        growth_exponent(&compute),
        growth_exponent(&heap),
    ) {
        println!(
            "round time grows as nodes^{t:.2} (its compute as nodes^{c:.2}), node agents' heap as nodes^{m:.2} (least squares on log-log over {} sizes, supports of fixed size)",
            points.len()
        );
    }
    Ok(points)
}

/// A synthetic room served by a camera agent over loopback gRPC, with a virtual camera, and
/// its node agents (ten nodes each).
#[derive(Debug)]
pub struct SyntheticAgents {
    pub room: VirtualRoom,
    pub status: tokio::sync::watch::Receiver<camera::RoomStatus>,
    pub agents: usize,
    owners: HashMap<String, Vec<u32>>,
    endpoint: String,
    cancel: CancellationToken,
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
        };
        let (status, camera_task) = camera::serve(
            config,
            RoomModel {
                problem: problem.clone(),
                owners: owners.clone(),
                start,
                hot: Default::default(),
                survey: None,
            },
            room.camera(),
            listener,
            cancel.clone(),
        );
        Ok(Self {
            room,
            status,
            agents,
            owners,
            endpoint,
            cancel,
            tasks: vec![camera_task],
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
            let task = node::run(config, self.room.display(), self.cancel.child_token());
            self.tasks.push(tokio::spawn(task));
        }
    }

    /// Stops every agent and waits (5 s at most each) until they are gone.
    pub async fn stop(self) {
        self.cancel.cancel();
        for task in self.tasks {
            let _ = tokio::time::timeout(Duration::from_secs(5), task).await;
        }
    }
}

/// One size: prints its row and returns it.
async fn case(nodes: usize, alloc: &PeakAlloc) -> Result<NetPoint> {
    let problem = synthetic_room(&SyntheticConfig::new(nodes, 1))?.problem;
    let rule = StepRule::Safe { theta: 1.0 };
    let compute_ms = crate::bench::core::us_per_node_update(
        &problem,
        rule,
        &vec![LinearRgb::splat(0.5); nodes],
    )? * nodes as f64
        / 1e3;
    let mut room = SyntheticAgents::camera(&problem, PlantConfig::default(), None, 0).await?;
    let agents = room.agents;
    let before = alloc.current_usage();
    room.spawn_nodes(rule);
    let status = &mut room.status;
    let ready = tokio::time::timeout(Duration::from_secs(180), async {
        loop {
            let s = status.borrow().clone();
            if s.live_projectors == agents && s.captures >= 2 {
                return Ok::<_, anyhow::Error>(());
            }
            status.changed().await?;
        }
    })
    .await;
    ready.context("the agents did not all join within 180 s")??;
    let heap_mb = alloc.current_usage().saturating_sub(before) as f64 / 1e6;
    let heap_per_agent = heap_mb / agents as f64;
    let rounds = if nodes >= 1000 { 20 } else { 60 };
    let mut times = Vec::with_capacity(rounds);
    let (mut out, mut inn) = (0u64, 0u64);
    let mut last = Instant::now();
    for _ in 0..rounds {
        tokio::time::timeout(Duration::from_secs(30), status.changed())
            .await
            .context("a round took over 30 s")??;
        let now = Instant::now();
        times.push((now - last).as_secs_f64() * 1e3);
        last = now;
        let s = status.borrow().clone();
        out += s.bytes_out;
        inn += s.bytes_in;
    }
    room.stop().await;
    times.remove(0);
    times.sort_by(f64::total_cmp);
    let pct = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize];
    println!(
        "{nodes:>6} {agents:>7} {:>13.3} {:>11.3} {:>11.3} {:>15} {:>14} {:>15.2} MB",
        pct(0.5),
        pct(0.99),
        compute_ms,
        out / rounds as u64,
        inn / rounds as u64,
        heap_per_agent
    );
    Ok(NetPoint {
        nodes,
        agents,
        median_ms: pct(0.5),
        p99_ms: pct(0.99),
        compute_ms,
        bytes_out_per_round: out / rounds as u64,
        bytes_in_per_round: inn / rounds as u64,
        heap_mb,
    })
}
