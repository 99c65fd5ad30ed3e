//! One run of the real agents over loopback gRPC on a measured model: options, churn (a
//! projector leaving, another joining), the trace against the truth, bytes per round.
//!
//! A run is deterministic at a fixed seed: its captures and excess are the same on every run
//! and every machine. The rounds wait for every acknowledgement and contribution (the deadline
//! is far beyond any round, so no node is ever late on a loaded machine); the round controller
//! sums contributions in a fixed order; the camera's latency is a schedule in captures; and
//! the driver acts (a projector leaves or joins, the run stops) only between two captures,
//! each capture held until it has handled the last status ([`super::gate`]).

use anyhow::{Context, Result, bail};
use roomlight_agent::AgentError;
use roomlight_agent::camera::{self, CameraConfig, Overview, RoomModel, RoomStatus};
use roomlight_agent::node::{self, NodeConfig};
use roomlight_core::metrics::{PatchDeltaE, patch_delta_e};
use roomlight_core::optimum::{Optimum, optimum};
use roomlight_core::{LinearRgb, StepRule};
use roomlight_sim::scene::ProjectorKind;
use roomlight_sim::{CameraNoise, Room};
use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use super::gate;
use super::*;

/// How the agents run for one target.
#[derive(Debug, Clone, Copy)]
pub struct RunOptions {
    /// The node agents' update rule.
    pub rule: StepRule,
    /// Model rounds per capture (DESIGN §3.4).
    pub model_rounds: usize,
    /// Stop here if the camera agent has not reported settled before.
    pub max_captures: u64,
    /// Stop when the camera agent reports settled (DESIGN §3.6); otherwise run to
    /// `max_captures` (to compare rules over the same budget).
    pub stop_when_settled: bool,
    /// Seed of the capture noise.
    pub seed: u64,
    /// Captures of camera latency: the errors the nodes act on are this many captures stale.
    pub latency: usize,
    /// The camera agent knows the latency and discards that many captures before each measured
    /// round (fresh errors, more captures).
    pub discard_stale: bool,
    /// A projector leaving and another joining mid-run.
    pub churn: Option<Churn>,
}

/// A projector leaving the room (switched off, its node agent stopped) once `leave_at`
/// captures are taken, and another, off from the start, whose node agent joins after
/// `join_at` captures. Projectors are indices into the room's projectors. `hot`: the camera
/// agent does not know the joining projector's attenuation and measures it when it joins.
#[derive(Debug, Clone, Copy)]
pub struct Churn {
    pub leaving: usize,
    pub leave_at: u64,
    pub joining: usize,
    pub join_at: u64,
    pub hot: bool,
}

impl Churn {
    /// The first standard luminaire with nodes leaves, the last one (off until then) joins.
    pub fn pick(
        room: &Room,
        cal: &Calibrated,
        leave_at: u64,
        join_at: u64,
        hot: bool,
    ) -> Result<Self> {
        let standard: Vec<usize> = room
            .projectors()
            .iter()
            .enumerate()
            .filter(|(k, p)| {
                p.kind == ProjectorKind::Standard && cal.regions.iter().any(|r| r.projector == *k)
            })
            .map(|(k, _)| k)
            .collect();
        let (Some(&leaving), Some(&joining)) = (standard.first(), standard.last()) else {
            bail!("the room has no standard luminaire with nodes");
        };
        if leaving == joining {
            bail!("the room has a single standard luminaire: none to join after one left");
        }
        Ok(Self {
            leaving,
            leave_at,
            joining,
            join_at,
            hot,
        })
    }
}

impl RunOptions {
    /// The default: FISTA momentum with restarts and `DEFAULT_MODEL_ROUNDS` (100) model rounds
    /// per capture, the bench's rule `model-100` and the deployed camera agent's default
    /// (`roomlight bench room` and `roomlight demo` print the comparisons). The rounds wait for
    /// every node's acknowledgement, so the errors are never stale and momentum keeps its
    /// guarantee.
    pub fn default_rule(seed: u64) -> Self {
        Self {
            rule: StepRule::Momentum { theta: 1.0 },
            model_rounds: camera::DEFAULT_MODEL_ROUNDS,
            max_captures: 60,
            stop_when_settled: true,
            seed,
            latency: 0,
            discard_stale: false,
            churn: None,
        }
    }
}

/// The room after each capture's rounds, against the simulator's truth.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct TracePoint {
    /// Captures taken (0: the conventional start, before any).
    pub capture: u64,
    /// Wall time since the agents started.
    pub seconds: f64,
    /// `(G − G*)/G*` of the measured model from the camera's capture of these values (noisy;
    /// none for the final values, which no capture saw).
    pub measured_excess: Option<f64>,
    /// `(G − G*)/G*` of the measured model for the values shown (noiseless: the quantity the
    /// rules minimise).
    pub model_excess: f64,
    /// The same on the true problem for the values shown after this capture's rounds.
    pub true_excess: f64,
    /// True mean ΔE00 against the LED target for those values.
    pub mean_de00: f64,
}

/// One run of the agents on one target.
#[derive(Debug, Clone)]
pub struct RunResult {
    /// Captures until the camera agent settled (or the cap).
    pub captures: u64,
    /// Whether the camera agent reported settled (DESIGN §3.6) before the cap.
    pub settled: bool,
    /// Every capture's point, the conventional start first.
    pub trace: Vec<TracePoint>,
    /// The values the nodes show at the end.
    pub x: Vec<LinearRgb>,
    /// The measured model's `G` for them and its optimum `G*`.
    pub g: f64,
    /// The measured model's optimum.
    pub g_star: f64,
    /// `(G − G*)/G*` on the measured model.
    pub final_excess: f64,
    /// The same on the true problem.
    pub true_excess: f64,
    /// True ΔE00 per model patch at the end and at the conventional start.
    pub de00: Vec<f64>,
    /// True ΔE00 per model patch at the conventional start.
    pub conventional_de00: Vec<f64>,
    /// Mean ΔE00 the true optimum would reach (what the room allows).
    pub best_mean_de00: f64,
    /// Wall time of the run.
    pub seconds: f64,
    /// Of which the simulated camera (render, noise, chart sampling).
    pub capture_seconds: f64,
    /// Rounds run (captures and model rounds).
    pub rounds: u64,
    /// Projectors the camera agent calibrated hot during the run.
    pub calibrated_hot: u64,
    /// The most captures the camera agent refused in a row as late (`RoomStatus::late_frames`).
    pub late_frames: usize,
    /// Protobuf bytes between the agents, both ways, per round once the agents are attached (the first capture's traffic, which
    /// carries every node's attenuation, left out).
    pub bytes_per_round: f64,
}

/// What the bench reads of a run beyond its [`RunResult`].
#[derive(Debug, Clone)]
pub struct RunDetail {
    pub result: RunResult,
    /// Per trace point: wall time of the rounds up to its values — the agents' computation
    /// and messages, without the simulated camera's time or the driver's (what a real room
    /// adds to the camera's shots).
    pub rounds_seconds: Vec<f64>,
    /// `(G_c − G*_c)/G*_c` per colour channel at the end, on the measured model (each
    /// channel's objective over its own optimum: the problem is separable by channel).
    pub final_excess_rgb: [f64; 3],
    /// The camera noise of the last captures (noisy minus noiseless sampling of the same
    /// frame, on the model's patches), oldest first.
    pub noise: Vec<Vec<LinearRgb>>,
    /// The measured model's optimum (of the room left behind after a leave).
    pub best: Optimum,
    /// With a leave and a join: the captures taken when the room was whole again, the joining
    /// projector in the rounds (after its join, or after its hot calibration).
    pub joined_after: Option<u64>,
}

/// Runs the camera agent and one node agent per projector over loopback gRPC on `model`, from
/// its conventional start until the camera agent reports settled (or `max_captures`), and
/// measures the result against the simulator's truth.
pub fn run_agents(
    room: &Arc<Room>,
    cal: &Calibrated,
    model: &Model,
    transport: &Transport,
    truth: &Truth,
    options: RunOptions,
    bar: &indicatif::ProgressBar,
) -> Result<RunResult> {
    Ok(run_detailed(room, cal, model, transport, truth, options, bar)?.result)
}

/// [`run_agents`], with what the bench reads beyond the result.
pub fn run_detailed(
    room: &Arc<Room>,
    cal: &Calibrated,
    model: &Model,
    transport: &Transport,
    truth: &Truth,
    options: RunOptions,
    bar: &indicatif::ProgressBar,
) -> Result<RunDetail> {
    let churn = ChurnPlan::new(room, cal, &options)?;
    let mut initial = model.conventional.clone();
    for &n in &churn.joining {
        initial[n] = LinearRgb::ZERO;
    }
    let hw = sim_hardware(room, cal, model, transport, &options, &initial)?;
    let reference = Reference::new(model, truth, &hw, &churn, &initial)?;
    let owners = cal.owners(room);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let t0 = Instant::now();
    let mut steady = PerRound::default();
    let session = Session {
        model,
        truth,
        options,
        churn: &churn,
        hw: &hw,
        best: &reference.best,
        bar,
    };
    let end = runtime.block_on(session.drive(&owners, &mut steady))?;
    let mut detail = report(model, truth, &hw, &reference, &end, t0, &steady)?;
    // The room is whole again once the joining projector is in the rounds: from its join, or
    // from the end of its hot calibration (the camera agent's count of captures then).
    detail.joined_after = options
        .churn
        .map(|c| c.join_at.max(c.leave_at).max(end.status.calibrated_at));
    Ok(detail)
}

/// The nodes and agent names a churn moves, checked against the budget and the calibration
/// once, before any agent starts.
struct ChurnPlan {
    /// Nodes of the projector that leaves: the reference room is the one without them.
    gone: Vec<usize>,
    /// Nodes of the projector that joins: dark until its agent starts.
    joining: Vec<usize>,
    /// The leaving projector's agent id.
    leaving_id: Option<String>,
    /// The joining projector's agent id.
    joining_id: Option<String>,
}

impl ChurnPlan {
    fn new(room: &Room, cal: &Calibrated, options: &RunOptions) -> Result<Self> {
        let nodes_of = |projector: usize| -> Vec<usize> {
            (0..cal.regions.len())
                .filter(|&n| cal.regions[n].projector == projector)
                .collect()
        };
        let name_of = |projector: usize| -> Result<String> {
            room.projectors()
                .get(projector)
                .map(|p| p.name.clone())
                .with_context(|| format!("churn: the room has no projector {projector}"))
        };
        // With a projector leaving, the room it leaves behind is the reference: its optimum is
        // what the others can reach without it.
        let Some(c) = options.churn else {
            return Ok(Self {
                gone: Vec::new(),
                joining: Vec::new(),
                leaving_id: None,
                joining_id: None,
            });
        };
        if c.join_at >= options.max_captures || c.leave_at >= options.max_captures {
            bail!(
                "churn at captures {} and {} does not fit a budget of {} captures",
                c.leave_at,
                c.join_at,
                options.max_captures
            );
        }
        let (gone, joining) = (nodes_of(c.leaving), nodes_of(c.joining));
        if gone.is_empty() || joining.is_empty() || c.leaving == c.joining {
            bail!(
                "churn: projectors {} and {} must be two luminaires with nodes",
                name_of(c.leaving)?,
                name_of(c.joining)?
            );
        }
        Ok(Self {
            gone,
            joining,
            leaving_id: Some(name_of(c.leaving)?),
            joining_id: Some(name_of(c.joining)?),
        })
    }
}

/// The simulated projectors and camera both agents talk to, showing `initial` at the start.
fn sim_hardware(
    room: &Arc<Room>,
    cal: &Calibrated,
    model: &Model,
    transport: &Transport,
    options: &RunOptions,
    initial: &[LinearRgb],
) -> Result<SimHardware> {
    Ok(SimHardware {
        room: room.clone(),
        frames: Arc::new(FrameBuilder::new(
            room,
            &cal.regions,
            cal.responses.clone(),
        )?),
        setup: transport.setup.clone(),
        // A model without wall patches reads nothing of the walls: their pixels are not rendered.
        pixels: if model
            .patches
            .iter()
            .any(|i| cal.wall_patch_range().contains(i))
        {
            transport.pixels.clone()
        } else {
            transport.charts.clone()
        },
        shown: Arc::new(Mutex::new(initial.to_vec())),
        patches: Arc::new(model.patches.clone()),
        scale: Arc::new(model.target.scale.clone()),
        noise: Arc::new(Mutex::new(CameraNoise::with_seed(room, options.seed))),
        log: Arc::new(Mutex::new(Vec::new())),
        latency: options.latency,
        delayed: Arc::new(Mutex::new(VecDeque::new())),
        gate: Arc::new(super::gate::Gate::new()),
    })
}

/// What the run is measured against: the optima of the room left behind (measured model and
/// truth) and the conventional start's ΔE00.
struct Reference {
    best: Optimum,
    true_best: Optimum,
    de_conv: PatchDeltaE,
}

impl Reference {
    fn new(
        model: &Model,
        truth: &Truth,
        hw: &SimHardware,
        churn: &ChurnPlan,
        initial: &[LinearRgb],
    ) -> Result<Self> {
        Ok(Self {
            best: optimum(&model.problem.without_nodes(&churn.gone))?,
            true_best: optimum(&truth.problem.without_nodes(&churn.gone))?,
            de_conv: patch_delta_e(&truth.target, &hw.noiseless(initial)?)?,
        })
    }
}

/// What the async part of a run reads: the room, the options, the churn and the hardware.
struct Session<'a> {
    model: &'a Model,
    truth: &'a Truth,
    options: RunOptions,
    churn: &'a ChurnPlan,
    hw: &'a SimHardware,
    best: &'a Optimum,
    bar: &'a indicatif::ProgressBar,
}

/// A node agent's cancellation token and task.
type NodeTask = (CancellationToken, JoinHandle<Result<(), AgentError>>);

/// How long a round waits for acknowledgements and contributions: far beyond any round of the
/// bench (tens of milliseconds), so that no node is left out of a round because the machine
/// was busy. No case of the bench is about nodes that are late by the clock; the stale cases
/// delay the camera's images by a schedule in captures instead.
const ROUND_DEADLINE: Duration = Duration::from_secs(30);

/// How long a run may take: 10 s a capture, at least 120 s. A capture takes a fraction of a
/// second on a quiet machine, but several on a loaded one (2026-11-27, a 2-core VM at load 14:
/// 8 s), where a flat 120 s failed a 30-capture run of the demo.
fn run_limit(max_captures: u64) -> Duration {
    Duration::from_secs(max_captures.saturating_mul(10).max(120))
}

/// How long the driver waits for projectors to attach or leave.
const CHURN_LIMIT: Duration = Duration::from_secs(60);

/// The run at its end: the last status, what the nodes showed and how many captures were
/// taken then (the camera agent may take one more while it stops), and when.
struct End {
    status: RoomStatus,
    x: Vec<LinearRgb>,
    captures: usize,
    at: Instant,
}

impl Session<'_> {
    /// Starts the camera agent and the node agents, runs the rounds until the camera agent
    /// stops the run, then stops and joins every agent; returns the run's end.
    async fn drive(
        &self,
        owners: &HashMap<String, Vec<u32>>,
        steady: &mut PerRound,
    ) -> Result<End> {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let endpoint = format!("http://{}", listener.local_addr()?);
        let cancel = CancellationToken::new();
        // A projector joining hot is measured by the camera agent when it joins.
        let hot = match (self.options.churn.filter(|c| c.hot), &self.churn.joining_id) {
            (Some(_), Some(id)) => [id.clone()].into(),
            _ => Default::default(),
        };
        let served = camera::serve_room(
            self.camera_config(),
            RoomModel {
                problem: self.model.problem.clone(),
                owners: owners.clone(),
                start: Some(self.model.conventional.clone()),
                hot,
                survey: None,
            },
            self.hw.clone(),
            listener,
            None,
            camera::Extras::default(),
            cancel.clone(),
        );
        self.hw.gate.follow(served.status.clone());
        let mut overview = served.control.overview();
        // Projectors in the order of their ids: the same spawn order on every run.
        let mut ids: Vec<&String> = owners
            .keys()
            .filter(|id| Some(*id) != self.churn.joining_id.as_ref())
            .collect();
        ids.sort();
        let mut node_tasks: HashMap<_, _> = ids
            .into_iter()
            .map(|id| self.spawn_node(&endpoint, &cancel, id))
            .collect();
        let limit = run_limit(self.options.max_captures);
        let outcome = tokio::time::timeout(
            limit,
            self.rounds(
                served.status,
                &mut overview,
                (&endpoint, &cancel),
                &mut node_tasks,
                steady,
            ),
        )
        .await;
        cancel.cancel();
        // The camera agent finishes the capture it was held at, and stops.
        self.hw.gate.open();
        for (_, (_, task)) in node_tasks {
            let _ = tokio::time::timeout(Duration::from_secs(5), task).await;
        }
        let _ = tokio::time::timeout(Duration::from_secs(5), served.handle).await;
        outcome.with_context(|| {
            format!(
                "the agents neither stopped nor took {} captures within {} s",
                self.options.max_captures,
                limit.as_secs()
            )
        })?
    }

    fn camera_config(&self) -> CameraConfig {
        let options = &self.options;
        CameraConfig {
            room: "lab".into(),
            token: "demo".into(),
            heartbeat: Duration::from_millis(500),
            deadline: ROUND_DEADLINE,
            model_rounds: options.model_rounds,
            calibration_epoch: 1,
            stale_frames: if options.discard_stale {
                options.latency
            } else {
                0
            },
            model_out: None,
            primaries: true,
            shading_passes: 0,
        }
    }

    fn spawn_node(
        &self,
        endpoint: &str,
        cancel: &CancellationToken,
        id: &str,
    ) -> (String, NodeTask) {
        let config = NodeConfig {
            endpoint: endpoint.to_string(),
            room: "lab".into(),
            token: "demo".into(),
            projector_id: id.to_string(),
            kind: roomlight_proto::v1::ProjectorKind::Standard,
            rule: self.options.rule,
            start: LinearRgb::splat(0.5),
            state_file: None,
        };
        let token = cancel.child_token();
        let task = tokio::spawn(node::run(config, self.hw.clone(), token.clone()));
        (id.to_string(), (token, task))
    }

    /// Follows the camera agent's status, in step with its captures (each is held until the
    /// status before it has been handled here): the first capture once every projector present
    /// from the start is in the rounds, the churn at its captures, and the stop (every agent
    /// live, the joiner in, settled or out of captures) right after a capture's rounds.
    async fn rounds(
        &self,
        mut status: watch::Receiver<RoomStatus>,
        overview: &mut watch::Receiver<Overview>,
        (endpoint, cancel): (&str, &CancellationToken),
        node_tasks: &mut HashMap<String, NodeTask>,
        steady: &mut PerRound,
    ) -> Result<End> {
        let options = self.options;
        let present: Vec<String> = node_tasks.keys().cloned().collect();
        gate::wait_for_projectors(overview, CHURN_LIMIT, |ps| {
            present.iter().all(|id| gate::live(ps, id))
        })
        .await
        .context("the node agents present from the start")?;
        self.hw.gate.handled(0);
        let (mut left, mut joined) = (false, self.churn.joining_id.is_none());
        loop {
            status.changed().await?;
            let s = status.borrow_and_update().clone();
            steady.add(&s);
            self.show_progress(&s);
            if let (Some(c), Some(id)) = (options.churn, &self.churn.leaving_id)
                && !left
                && s.captures >= c.leave_at
            {
                self.leave(node_tasks, id).await;
                gate::wait_for_projectors(overview, CHURN_LIMIT, |ps| !gate::attached(ps, id))
                    .await
                    .context("the leaving projector")?;
                left = true;
            }
            if let (Some(c), Some(id)) = (options.churn, &self.churn.joining_id)
                && !joined
                && s.captures >= c.join_at
            {
                let (id, handles) = self.spawn_node(endpoint, cancel, id);
                node_tasks.insert(id.clone(), handles);
                // In the rounds from the next capture on; one joining hot is calibrated first.
                let hot = c.hot;
                gate::wait_for_projectors(overview, CHURN_LIMIT, |ps| {
                    if hot {
                        gate::attached(ps, &id)
                    } else {
                        gate::live(ps, &id)
                    }
                })
                .await
                .context("the joining projector")?;
                joined = true;
            }
            let settled_or_done =
                s.settled && options.stop_when_settled || s.captures >= options.max_captures;
            if s.live_projectors == node_tasks.len() && joined && settled_or_done {
                // The next capture is held: nothing moves until the gate opens.
                let captures = self
                    .hw
                    .log
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .len();
                return Ok(End {
                    status: s,
                    x: self.hw.shown(),
                    captures,
                    at: Instant::now(),
                });
            }
            self.hw.gate.handled(s.captures);
        }
    }

    fn show_progress(&self, s: &RoomStatus) {
        if self.bar.is_hidden() {
            return;
        }
        // The live line: ΔE00 against the truth costs a render, so only when shown.
        let hw = self.hw;
        let de = hw
            .noiseless(&hw.shown())
            .and_then(|v| Ok(patch_delta_e(&self.truth.target, &v)?.mean))
            .unwrap_or(f64::NAN);
        self.bar.set_position(s.captures);
        self.bar.set_message(format!(
            "round {} · G {:.3e} · excess {:.1e} · ΔE00 {de:.2}",
            s.round,
            s.measured_objective,
            self.best.excess(s.measured_objective)
        ));
    }

    /// The projector is switched off: its agent stops, its light is gone.
    async fn leave(&self, node_tasks: &mut HashMap<String, NodeTask>, id: &str) {
        if let Some((token, task)) = node_tasks.remove(id) {
            token.cancel();
            let _ = tokio::time::timeout(Duration::from_secs(5), task).await;
        }
        let mut shown = self.hw.shown.lock().unwrap_or_else(PoisonError::into_inner);
        for &n in &self.churn.gone {
            shown[n] = LinearRgb::ZERO;
        }
    }
}

/// Captures whose camera noise a run keeps (see [`RunResult::noise`]).
const NOISE_CAPTURES: usize = 5;

/// The run's values against the truth, from what the agents showed at the run's end and the
/// log of the captures taken until then.
fn report(
    model: &Model,
    truth: &Truth,
    hw: &SimHardware,
    reference: &Reference,
    end: &End,
    t0: Instant,
    steady: &PerRound,
) -> Result<RunDetail> {
    let Reference {
        best,
        true_best,
        de_conv,
    } = reference;
    let last = &end.status;
    let x = end.x.clone();
    let final_values = hw.noiseless(&x)?;
    let de = patch_delta_e(&truth.target, &final_values)?;
    // The room after k captures' rounds is what capture k + 1 saw; after the last, what it
    // showed at the end.
    let mut log = std::mem::take(&mut *hw.log.lock().unwrap_or_else(PoisonError::into_inner));
    log.truncate(end.captures);
    let capture_seconds: f64 = log.iter().map(|l| l.took.as_secs_f64()).sum();
    // The rounds before each state: from the end of the capture before it to the request of
    // the next capture (or the end), less nothing else: the gate holds only after the request.
    let mut rounds = 0.0;
    let mut rounds_seconds = Vec::with_capacity(log.len() + 1);
    let mut previous_end: Option<Instant> = None;
    let states = log
        .iter()
        .map(|l| (l.asked, l.at, &l.shown, &l.noiseless, Some(&l.measured)))
        .chain(std::iter::once((end.at, end.at, &x, &final_values, None)));
    let trace = states
        .enumerate()
        .map(|(k, (asked, at, shown, values, measured))| {
            if let Some(p) = previous_end {
                rounds += asked.saturating_duration_since(p).as_secs_f64();
            }
            rounds_seconds.push(rounds);
            previous_end = Some(at);
            Ok(TracePoint {
                capture: k as u64,
                seconds: at.saturating_duration_since(t0).as_secs_f64(),
                measured_excess: measured.map(|y| {
                    best.excess(roomlight_core::metrics::objective(
                        &model
                            .problem
                            .target()
                            .iter()
                            .zip(y)
                            .map(|(r, y)| *r - *y)
                            .collect::<Vec<_>>(),
                    ))
                }),
                model_excess: best.excess(model.problem.objective(shown)),
                true_excess: true_best.excess(truth.objective(values)),
                mean_de00: patch_delta_e(&truth.target, values)?.mean,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let noise = log[log.len().saturating_sub(NOISE_CAPTURES)..]
        .iter()
        .map(|l| {
            l.measured
                .iter()
                .zip(&l.noiseless)
                .map(|(m, n)| *m - *n)
                .collect()
        })
        .collect();
    let de_best = patch_delta_e(&truth.target, &truth.problem.response(&true_best.x))?;
    let g = model.problem.objective(&x);
    let final_excess_rgb = channel_excess(&model.problem, best, &x);
    let result = RunResult {
        captures: last.captures,
        settled: last.settled,
        trace,
        g,
        g_star: best.objective,
        final_excess: best.excess(g),
        true_excess: true_best.excess(truth.objective(&final_values)),
        x,
        de00: de.per_patch,
        conventional_de00: de_conv.per_patch.clone(),
        best_mean_de00: de_best.mean,
        seconds: end.at.saturating_duration_since(t0).as_secs_f64(),
        capture_seconds,
        rounds: last.round,
        bytes_per_round: steady.bytes_per_round(),
        calibrated_hot: last.calibrated_hot,
        late_frames: last.late_frames,
    };
    Ok(RunDetail {
        result,
        rounds_seconds,
        final_excess_rgb,
        noise,
        best: best.clone(),
        joined_after: None,
    })
}

/// Bytes per round from the camera agent's status, the first status (attachment, attenuation)
/// left out.
#[derive(Debug, Default)]
pub struct PerRound {
    first_round: Option<u64>,
    last_round: u64,
    bytes: u64,
    all_bytes: u64,
}

impl PerRound {
    pub fn add(&mut self, s: &RoomStatus) {
        let b = s.bytes_in + s.bytes_out;
        self.all_bytes += b;
        if self.first_round.is_some() {
            self.bytes += b;
        } else {
            self.first_round = Some(s.round);
        }
        self.last_round = s.round;
    }

    /// Over the rounds after the first status; with none, over all (0 before any round).
    pub fn bytes_per_round(&self) -> f64 {
        match self.first_round {
            Some(first) if self.last_round > first => {
                self.bytes as f64 / (self.last_round - first) as f64
            }
            _ => self.all_bytes as f64 / self.last_round.max(1) as f64,
        }
    }
}
