//! `roomlight demo`: the whole method on the simulated lab (calibration from captures, then the
//! real agents over loopback gRPC; see `crate::pipeline`), or with `--synthetic` the comparison of
//! update rules on a synthetic room against the exact optimum. The report of issue 6 builds on it.

use anyhow::{Context, Result};
use roomlight_core::closed_loop::{self, LoopConfig, Plant, PlantConfig};
use roomlight_core::conventional::conventional_start;
use roomlight_core::metrics::patch_delta_e;
use roomlight_core::optimum::optimum;
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, StepRule};
use std::time::Instant;

/// Options of the demo.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// A smaller room (for tests).
    #[arg(long)]
    pub quick: bool,
    /// The synthetic-room comparison of update rules instead of the simulated lab.
    #[arg(long)]
    pub synthetic: bool,
    /// Seed of the synthetic room and the camera noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

pub fn run(args: &DemoArgs) -> Result<()> {
    if args.synthetic {
        return synthetic(args);
    }
    let t0 = Instant::now();
    let mut scene = if args.quick {
        roomlight_sim::scenes::small()?
    } else {
        roomlight_sim::scenes::lab()?
    };
    if args.quick {
        // Enough camera pixels per chart patch.
        scene.camera.resolution = [640, 480];
    }
    let name = scene.name.clone();
    let room =
        roomlight_sim::Room::build(scene).with_context(|| format!("building the {name} room"))?;
    println!(
        "{name}: simulated room built in {:.1} s ({} projectors, {} charts)",
        t0.elapsed().as_secs_f64(),
        room.projectors().len(),
        room.geometry().charts.len()
    );
    let preset = 0;
    let preset_name = room
        .scene()
        .presets
        .first()
        .map_or("none".to_string(), |p| p.name.clone());
    let mut noise = roomlight_sim::CameraNoise::new(&room);
    let cal = crate::pipeline::calibrate(&room, preset, &mut noise, |line| println!("{line}"))?;
    println!(
        "calibration: {} captures; target: LED preset {preset_name}",
        cal.captures
    );
    crate::pipeline::run_agents(&room, preset, &cal, |line| println!("{line}"))?;
    println!("demo finished in {:.1} s", t0.elapsed().as_secs_f64());
    Ok(())
}

/// The synthetic-room comparison: the in-memory loop against the paper's rule, then the agents.
fn synthetic(args: &DemoArgs) -> Result<()> {
    let t0 = Instant::now();
    let nodes = if args.quick { 25 } else { 100 };
    let room = synthetic_room(&SyntheticConfig::new(nodes, args.seed))
        .context("building the synthetic room")?;
    let problem = &room.problem;
    println!(
        "synthetic room: {nodes} luminaire nodes, {} chart patches, {:.1}% of the attenuation entries above 3σ kept",
        problem.patches(),
        100.0 * problem.columns().iter().map(|c| c.len()).sum::<usize>() as f64
            / (nodes * problem.patches()) as f64
    );
    let best = optimum(problem).context("computing the reference optimum")?;
    let start = conventional_start(problem, &room.charts, LinearRgb::splat(0.5))?;
    let de_start = patch_delta_e(problem.target(), &problem.response(&start))?;
    println!(
        "conventional start (DESIGN §3.1): excess over G* {:.3}, mean ΔE00 {:.2}",
        best.excess(problem.objective(&start)),
        de_start.mean
    );
    // The camera sees the room with its real noise; the nodes follow momentum with 5 model
    // rounds between captures, and stop when every node moves less than half a code step.
    let plant_config = PlantConfig {
        noise_scale: 1.0,
        seed: args.seed,
        ..PlantConfig::default()
    };
    let config = LoopConfig {
        model_rounds: 5,
        stop_when_settled: true,
        ..LoopConfig::new(StepRule::Momentum { theta: 1.0 }, 30)
    };
    let mut plant = Plant::new(problem.clone(), plant_config.clone())?;
    println!("capture  model rounds  true G      excess     mean ΔE00");
    let trace =
        closed_loop::run_observed(problem, &mut plant, &start, &config, |r, shown, plant| {
            let de = patch_delta_e(problem.target(), &plant.true_response(shown, r.capture))
                .map_or(f64::NAN, |d| d.mean);
            println!(
                "{:>7}  {:>12}  {:>9.3e}  {:>9.2e}  {:>9.3}",
                r.capture,
                r.model_rounds,
                r.true_objective,
                best.excess(r.true_objective),
                de
            );
        })?;
    let last = trace.last().context("no capture")?;
    let de = patch_delta_e(
        problem.target(),
        &plant.true_response(&trace.shown, last.capture),
    )?;
    println!(
        "distributed result after {} captures ({:?}): excess {:.2e}, mean ΔE00 {:.2} (max {:.2}); optimum's mean ΔE00 {:.2}",
        last.capture,
        trace.stop,
        best.excess(last.true_objective),
        de.mean,
        de.max,
        patch_delta_e(problem.target(), &problem.response(&best.x))?.mean
    );
    // The paper's rule on the same room, for comparison.
    let mut plant = Plant::new(problem.clone(), plant_config)?;
    let paper = closed_loop::run(
        problem,
        &mut plant,
        &start,
        &LoopConfig::new(StepRule::paper(), 60),
    )?;
    let to = |t: &closed_loop::Trace| {
        t.records
            .iter()
            .find(|r| best.excess(r.true_objective) <= 0.01)
            .map_or("never".into(), |r| r.capture.to_string())
    };
    println!(
        "captures to 1% excess: paper's fixed step {}, momentum with model rounds {}",
        to(&paper),
        to(&trace)
    );
    agents_over_grpc(problem, &best, args)?;
    println!("demo finished in {:.2} s", t0.elapsed().as_secs_f64());
    Ok(())
}

/// The same room run by the real agents: a camera agent and one node agent per ten nodes, in
/// this process, talking gRPC over loopback; the virtual room stands in for displays and camera.
fn agents_over_grpc(
    problem: &roomlight_core::Problem,
    best: &roomlight_core::optimum::Optimum,
    args: &DemoArgs,
) -> Result<()> {
    use roomlight_agent::camera::{self, CameraConfig, RoomModel};
    use roomlight_agent::hardware::VirtualRoom;
    use roomlight_agent::node::{self, NodeConfig};
    use std::collections::HashMap;
    use std::time::Duration;
    use tokio_util::sync::CancellationToken;
    let per = 10;
    let agents = problem.nodes().div_ceil(per);
    let owners: HashMap<String, Vec<u32>> = (0..agents)
        .map(|a| {
            (
                format!("p{a}"),
                ((a * per) as u32..((a + 1) * per).min(problem.nodes()) as u32).collect(),
            )
        })
        .collect();
    let plant = Plant::new(
        problem.clone(),
        PlantConfig {
            noise_scale: 1.0,
            seed: args.seed,
            ..PlantConfig::default()
        },
    )?;
    let room = VirtualRoom::new(plant);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let endpoint = format!("http://{}", listener.local_addr()?);
        let cancel = CancellationToken::new();
        let config = CameraConfig { room: "demo".into(), token: "demo".into(), heartbeat: Duration::from_millis(500), deadline: Duration::from_secs(2), model_rounds: 5, calibration_epoch: 1 };
        let (mut status, _handle) = camera::serve(config, RoomModel { problem: problem.clone(), owners: owners.clone(), start: None }, room.camera(), listener, cancel.clone());
        for id in owners.keys() {
            let config = NodeConfig { endpoint: endpoint.clone(), room: "demo".into(), token: "demo".into(), projector_id: id.clone(), rule: StepRule::Momentum { theta: 1.0 }, start: LinearRgb::splat(0.5), state_file: None };
            tokio::spawn(node::run(config, room.display(), cancel.child_token()));
        }
        println!("the real agents over loopback gRPC: a camera agent and {agents} node agents (model rounds K = 5, camera noise on)");
        let flat = vec![LinearRgb::splat(0.5); problem.nodes()];
        println!("  start (every node at 0.5): true excess {:.2e}", best.excess(problem.objective(&flat)));
        let started = Instant::now();
        let mut last = 0;
        let outcome = tokio::time::timeout(Duration::from_secs(60), async {
            while last < 6 {
                status.changed().await?;
                let s = status.borrow().clone();
                if s.captures > last && s.live_projectors == agents {
                    last = s.captures;
                    println!("  after capture {:>2} and its model rounds: {} node agents, true excess {:.2e}", s.captures, s.live_projectors, best.excess(room.true_objective()));
                }
            }
            Ok::<_, anyhow::Error>(())
        })
        .await;
        cancel.cancel();
        outcome.context("the agents did not converge within 60 s")??;
        println!("agents: final excess {:.2e} after {last} captures in {:.2} s", best.excess(room.true_objective()), started.elapsed().as_secs_f64());
        Ok(())
    })
}
