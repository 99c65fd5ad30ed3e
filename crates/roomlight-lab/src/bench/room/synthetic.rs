//! The room bench's synthetic room: a thousand nodes (a hundred with `--quick`) and 24 patches
//! each, no rendering (the transport is written down), the camera's noise, through the agents
//! on loopback for every rule. Captures are held in step with the driver
//! ([`crate::pipeline::gate`]) and logged by the camera itself, so that a run is the same on
//! every run: the first capture once every node agent is in the rounds, the last one's rounds
//! the end.

use super::records::{Calibration, Point, Run, summarise};
use super::{Outcome, Plan, rules};
use crate::bench::net::SyntheticAgents;
use crate::pipeline::{self, gate};
use anyhow::{Context, Result};
use roomlight_agent::hardware::{Camera, VirtualCamera, VirtualRoom};
use roomlight_core::closed_loop::PlantConfig;
use roomlight_core::conventional::conventional_start;
use roomlight_core::metrics::patch_delta_e;
use roomlight_core::optimum::optimum;
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, Problem, StepRule};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// One capture of the synthetic room: when it was asked for and handed over, and what the
/// room showed.
#[derive(Debug)]
struct Shot {
    asked: Instant,
    at: Instant,
    shown: Vec<LinearRgb>,
}

/// The virtual camera, held by the gate and logging what each capture saw.
#[derive(Debug, Clone)]
struct HeldCamera {
    camera: VirtualCamera,
    room: VirtualRoom,
    gate: Arc<gate::Gate>,
    log: Arc<Mutex<Vec<Shot>>>,
}

impl Camera for HeldCamera {
    fn capture(
        &mut self,
    ) -> impl Future<Output = Result<Vec<LinearRgb>, roomlight_agent::AgentError>> + Send {
        let me = self.clone();
        async move {
            let asked = Instant::now();
            me.gate.wait().await;
            // The node agents are idle: the rounds wait for every acknowledgement first.
            let shown = me.room.shown();
            let y = me.camera.capture_now();
            me.log
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(Shot {
                    asked,
                    at: Instant::now(),
                    shown,
                });
            Ok(y)
        }
    }
}

/// Every rule on the synthetic room of `nodes` nodes, `plan.repeats` times each.
pub(super) fn synthetic_case(
    outcome: &mut Outcome,
    plan: &Plan,
    nodes: usize,
    budget: u64,
) -> Result<()> {
    let name = format!("synthetic-{nodes}");
    let room = synthetic_room(&SyntheticConfig::new(nodes, plan.seed))?;
    let problem = room.problem;
    println!(
        "{name}: {nodes} nodes over {} patches, optimum…",
        problem.patches()
    );
    let best = optimum(&problem)?;
    let start = conventional_start(&problem, &room.charts, LinearRgb::splat(0.5))?;
    outcome
        .sparsity
        .push(crate::bench::sparsity::synthetic_sparsity(
            &name, nodes, plan.seed,
        )?);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the runtime")?;
    let mut curves = Vec::new();
    for (rule_name, rule, model_rounds, _) in rules(&problem, false, 0) {
        let compute_us_per_round =
            crate::bench::core::us_per_node_update(&problem, rule, &start)? * nodes as f64;
        let mut runs = Vec::new();
        for k in 0..plan.repeats {
            let seed = plan.seed + k as u64;
            let (mut run, x) = runtime.block_on(synthetic_run(
                &problem,
                &start,
                (rule, model_rounds),
                budget,
                seed,
            ))?;
            run.compute_us_per_round = compute_us_per_round;
            run.trace.iter_mut().for_each(|p| {
                p.excess = best.excess(p.excess);
                // The synthetic room's transport is written down: the model is the room.
                p.true_excess = p.excess;
            });
            run.final_excess = run.trace.last().map_or(f64::NAN, |p| p.excess);
            run.final_true_excess = run.final_excess;
            run.final_excess_rgb = pipeline::channel_excess(&problem, &best, &x);
            runs.push(run);
        }
        let (record, curve) = summarise((&name, rule_name), &runs, Calibration::default(), None);
        println!(
            "  {name} {rule_name}: to 1% {}, final excess {:.1e}",
            record
                .captures_to_1pct
                .map_or("never".into(), |c| c.to_string()),
            record.final_excess
        );
        outcome.records.push(record);
        curves.push((rule_name.to_string(), curve));
    }
    outcome.curves.push((name, curves));
    Ok(())
}

/// One run on the synthetic room, and the values shown at its end; the trace holds the true
/// `G` (the caller turns it into excess).
async fn synthetic_run(
    problem: &Problem,
    start: &[LinearRgb],
    (rule, model_rounds): (StepRule, usize),
    budget: u64,
    seed: u64,
) -> Result<(Run, Vec<LinearRgb>)> {
    let plant = PlantConfig {
        noise_scale: 1.0,
        seed,
        ..PlantConfig::default()
    };
    let gate = Arc::new(gate::Gate::new());
    let log = Arc::new(Mutex::new(Vec::new()));
    let mut agents =
        SyntheticAgents::camera_with(problem, plant, Some(start.to_vec()), model_rounds, |room| {
            HeldCamera {
                camera: room.camera(),
                room: room.clone(),
                gate: gate.clone(),
                log: log.clone(),
            }
        })
        .await?;
    gate.follow(agents.status.clone());
    let mut overview = agents.control.overview();
    agents.spawn_nodes(rule);
    let t0 = Instant::now();
    let expected = agents.agents;
    let mut bytes = pipeline::PerRound::default();
    let driven = async {
        // The first capture once every node agent is in the rounds (the rounds start with the
        // first that joins, as in a room; here the others would join at whatever capture the
        // scheduler put them).
        gate::wait_for_projectors(&mut overview, Duration::from_secs(120), |ps| {
            ps.len() == expected && ps.iter().all(|p| gate::live(ps, &p.id))
        })
        .await?;
        gate.handled(0);
        loop {
            agents.status.changed().await?;
            let s = agents.status.borrow_and_update().clone();
            bytes.add(&s);
            if s.captures >= budget {
                // The next capture is held: what the nodes show is the run's end.
                let taken = log.lock().unwrap_or_else(PoisonError::into_inner).len();
                return Ok::<_, anyhow::Error>((s, agents.room.shown(), taken, Instant::now()));
            }
            gate.handled(s.captures);
        }
    };
    let outcome = tokio::time::timeout(Duration::from_secs(300), driven).await;
    gate.open();
    agents.stop().await;
    let (last, x, taken, end) =
        outcome.context("the synthetic room's agents did not finish within 300 s")??;
    let mut shots = std::mem::take(&mut *log.lock().unwrap_or_else(PoisonError::into_inner));
    shots.truncate(taken);
    // The room after k captures' rounds is what capture k + 1 saw; after the last, what it
    // showed at the end.
    let mut rounds = 0.0;
    let mut previous: Option<Instant> = None;
    let trace = shots
        .iter()
        .map(|s| (s.asked, s.at, &s.shown))
        .chain(std::iter::once((end, end, &x)))
        .enumerate()
        .map(|(k, (asked, at, shown))| {
            if let Some(p) = previous {
                rounds += asked.saturating_duration_since(p).as_secs_f64();
            }
            previous = Some(at);
            Ok(Point {
                capture: k as u64,
                seconds: at.saturating_duration_since(t0).as_secs_f64(),
                excess: problem.objective(shown),
                true_excess: f64::NAN,
                mean_de00: patch_delta_e(problem.target(), &problem.response(shown))?.mean,
                rounds_seconds: rounds,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let de_final = patch_delta_e(problem.target(), &problem.response(&x))?;
    let seconds = end.saturating_duration_since(t0).as_secs_f64();
    let run = Run {
        trace,
        joined_after: None,
        final_excess: f64::NAN,
        final_true_excess: f64::NAN,
        final_excess_rgb: [f64::NAN; 3],
        mean_de00: de_final.mean,
        max_de00: de_final.per_patch.iter().copied().fold(0.0, f64::max),
        compute_us_per_round: 0.0,
        message_ms_per_round: seconds * 1e3 / last.round.max(1) as f64,
        capture_ms: 0.0,
        bytes_per_round: bytes.bytes_per_round(),
        captures: last.captures,
    };
    Ok((run, x))
}

/// The excess over `G*` after each capture's rounds (capture 0: the conventional start) of one
/// run of `captures` captures on the synthetic room of `nodes` nodes, rooms and noise from
/// `seed`: what the bench records of a run, for checking that a run is the same on every run.
pub fn synthetic_trace(
    nodes: usize,
    (rule, model_rounds): (StepRule, usize),
    captures: u64,
    seed: u64,
) -> Result<Vec<f64>> {
    let room = synthetic_room(&SyntheticConfig::new(nodes, seed))?;
    let best = optimum(&room.problem)?;
    let start = conventional_start(&room.problem, &room.charts, LinearRgb::splat(0.5))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the runtime")?;
    let (run, _) = runtime.block_on(synthetic_run(
        &room.problem,
        &start,
        (rule, model_rounds),
        captures,
        seed,
    ))?;
    Ok(run.trace.iter().map(|p| best.excess(p.excess)).collect())
}
