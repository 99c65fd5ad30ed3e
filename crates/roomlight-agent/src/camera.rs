//! The camera agent (DESIGN §6): serves `Room.Attach`, admits node agents that present the right
//! room, token and protocol version, sends each its attenuation and `s` on its support, and runs
//! rounds: wait until every live projector has shown the last frame (or a deadline passes: late
//! ones are logged and left out of the round), capture, send each node the errors on its support,
//! collect contributions, and run model rounds between captures.

use crate::hardware::{Assignment, Camera, Pattern};
use prost::Message;
use roomlight_calib::charts::{COLUMNS, ChartCorners, ROWS, SampleConfig};
use roomlight_calib::graycode::{Coding, DecodeConfig, Manifest};
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::response::{fit_response, footprint_ramp, ramp_codes};
use roomlight_core::aggregator::{ErrorAggregator, ErrorKind, RoundSummary};
use roomlight_core::closed_loop::objective_noise;
use roomlight_core::conventional::conventional_value;
use roomlight_core::{AttenuationColumn, LinearRgb, Problem};
use roomlight_proto::convert::{from_sparse, to_rgb, to_sparse};
use roomlight_proto::{PROTOCOL_VERSION, v1};
use std::collections::{HashMap, HashSet};
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;
use subtle::ConstantTimeEq;
use tokio::sync::{Notify, mpsc, watch};
use tokio_stream::wrappers::ReceiverStream;
use tokio_stream::{Stream, StreamExt};
use tokio_util::sync::CancellationToken;
use tonic::{Request, Response, Status, Streaming};

/// How the camera agent runs.
#[derive(Debug, Clone)]
pub struct CameraConfig {
    /// The room's name; node agents must name it.
    pub room: String,
    /// The pre-shared room token.
    pub token: String,
    /// How often nodes send heartbeats; three missed ones and the node has left.
    pub heartbeat: Duration,
    /// How long a round waits for acknowledgements and contributions.
    pub deadline: Duration,
    /// Model rounds after each measured round.
    pub model_rounds: usize,
    /// Calibration epoch (a node's persisted state is accepted only for the same epoch).
    pub calibration_epoch: u64,
    /// Frames the camera hands over late (its latency, measured once at installation): before
    /// each measured round the camera agent discards this many captures, so that the nodes
    /// never act on errors of values they no longer show. Every capture is counted.
    pub stale_frames: usize,
    /// Where to write the model (`problem`, `owners`, `start`, as JSON, atomically) after each
    /// projector calibrated over the wire or hot, and after patches left the model; `None`:
    /// nowhere.
    pub model_out: Option<std::path::PathBuf>,
}

/// The calibrated room the camera agent holds: every node's attenuation, and which projector
/// owns which nodes.
#[derive(Debug, Clone)]
pub struct RoomModel {
    /// Columns, targets, black offsets, noise.
    pub problem: Problem,
    /// Projector id → its node ids (indices of `problem`'s columns).
    pub owners: HashMap<String, Vec<u32>>,
    /// Each node's start when it brings no value of its own (the conventional start); `None`:
    /// the node agents' own default. Clamped to [0, 1]; a non-finite entry is not sent.
    pub start: Option<Vec<LinearRgb>>,
    /// Projectors whose attenuation is measured when they join (DESIGN §4, hot calibration):
    /// each of their nodes at white against all at black, by differential captures while the
    /// other projectors keep their values. Their columns in `problem` are ignored (emptied).
    pub hot: HashSet<String>,
    /// Calibration over the wire: a projector the model does not know is admitted, and the
    /// camera agent shows it structured light and a response ramp through its node agent,
    /// decodes and segments it (roomlight-calib), sends it its nodes' weights and then measures
    /// their attenuation, all while the other projectors keep their values. `None`: only the
    /// projectors of `owners` are admitted.
    pub survey: Option<Survey>,
}

/// What a room's installer configures once for calibration over the wire (DESIGN §4): where the
/// charts are in the camera image, how to sample them, and which camera pixels are the target.
#[derive(Debug, Clone)]
pub struct Survey {
    pub corners: Vec<ChartCorners>,
    pub sample: SampleConfig,
    /// The target's camera pixels (row-major, the camera's resolution): luminaires keep them
    /// dark.
    pub target_mask: Vec<bool>,
    /// Room patch index (chart · patches per chart + patch) of each of the model's patches.
    pub patches: Vec<usize>,
}

impl Survey {
    /// The model's patches on chart `chart` (for a node's conventional start).
    fn chart_patches(&self, chart: usize) -> Vec<u32> {
        let per = COLUMNS * ROWS;
        self.patches
            .iter()
            .enumerate()
            .filter(|(_, i)| **i / per == chart)
            .map(|(k, _)| k as u32)
            .collect()
    }
}

/// What the round loop has done so far (for tests, logs and the demo).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RoomStatus {
    /// Rounds run (measured and model).
    pub round: u64,
    /// Captures taken.
    pub captures: u64,
    /// `G` of the last measured round.
    pub measured_objective: f64,
    /// Projectors attached now.
    pub live_projectors: usize,
    /// Protobuf bytes sent to node agents since the previous status (errors and setup).
    pub bytes_out: u64,
    /// Protobuf bytes received from node agents since the previous status.
    pub bytes_in: u64,
    /// The measured `G` moved less than its noise (3√2 σ_G) over each of the last two captures
    /// (DESIGN §3.6): further rounds only chase camera noise.
    pub settled: bool,
    /// Projectors calibrated hot so far.
    pub calibrated_hot: u64,
}

#[derive(Debug)]
struct Peer {
    connection: u64,
    tx: mpsc::Sender<Result<v1::RoomMessage, Status>>,
    nodes: Vec<u32>,
    /// The last round whose errors this projector has applied and shows (`Some(0)`: its start).
    shown: Option<u64>,
    /// The last round sent to it.
    awaiting: Option<u64>,
    /// False until its attenuation is known (a hot projector before its calibration): it takes
    /// part in no round.
    calibrated: bool,
    /// The last Show pattern it has on its display.
    pattern_shown: Option<u64>,
    /// Its resolution and kind, as its Hello said (for calibration over the wire).
    width: u32,
    height: u32,
    kind: v1::ProjectorKind,
}

#[derive(Debug, Default)]
struct Registry {
    peers: HashMap<String, Peer>,
    next_connection: u64,
}

impl Registry {
    /// The room is still dark: no projector has shown a round's frame yet (bring-up).
    fn dark(&self) -> bool {
        self.peers.values().all(|p| p.shown.is_none())
    }
}

#[derive(Debug)]
struct Contribution {
    round: u64,
    node: u32,
    delta: Vec<(u32, LinearRgb)>,
}

/// What hot calibration changes: the attenuation and `s`, and which projectors are still to be
/// measured.
struct Live {
    problem: Problem,
    white: Vec<LinearRgb>,
    uncalibrated: HashSet<String>,
    /// Projector id → its node ids (grows as projectors are segmented over the wire).
    owners: HashMap<String, Vec<u32>>,
    /// Each node's start (`None`: the node agent's own default).
    start: Vec<Option<LinearRgb>>,
    /// The weights and responses of the projectors segmented over the wire.
    assignments: HashMap<String, Assignment>,
    /// Per projector segmented over the wire (standard, lighting a chart): the share of the
    /// light it gives each camera pixel, which projectors segmented later leave to it.
    claims: HashMap<String, Vec<f32>>,
    /// The chart of each node segmented over the wire (for its conventional start).
    charts: HashMap<u32, usize>,
    /// Patches some projector's light made unmeasurable during its calibration over the wire
    /// (saturated, or crossed by an edge): no column covers them, their target is their black
    /// level, and their measured errors are taken as zero.
    excluded: Vec<bool>,
}

struct Shared {
    config: CameraConfig,
    survey: Option<Survey>,
    live: std::sync::RwLock<Live>,
    /// Sequence numbers of Show patterns.
    pattern_seq: AtomicU64,
    registry: Mutex<Registry>,
    changed: Notify,
    contributions: mpsc::Sender<Contribution>,
    bytes_out: AtomicU64,
    bytes_in: AtomicU64,
    /// Cancelled once the camera agent has stopped its rounds: ends every node's reader and
    /// the server (the caller's token only asks the rounds to stop after the current one).
    cancel: CancellationToken,
}

impl Shared {
    fn registry(&self) -> std::sync::MutexGuard<'_, Registry> {
        self.registry.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn live(&self) -> std::sync::RwLockReadGuard<'_, Live> {
        self.live.read().unwrap_or_else(PoisonError::into_inner)
    }

    /// Sends `body` to a node agent, counting its bytes; false when the node has left.
    async fn send(
        &self,
        tx: &mpsc::Sender<Result<v1::RoomMessage, Status>>,
        body: v1::room_message::Body,
    ) -> bool {
        let message = v1::RoomMessage { body: Some(body) };
        self.bytes_out
            .fetch_add(message.encoded_len() as u64, Ordering::Relaxed);
        tx.send(Ok(message)).await.is_ok()
    }

    /// Each of `nodes`' attenuation, `s` on its support and start, as message bodies.
    fn attenuation_bodies(&self, nodes: &[u32]) -> Vec<v1::room_message::Body> {
        let live = self.live();
        nodes
            .iter()
            .filter_map(|&n| {
                let column = live.problem.columns().get(n as usize)?;
                let s = live
                    .problem
                    .white_response_on_support(&live.white, n as usize);
                Some(v1::room_message::Body::Attenuation(v1::Attenuation {
                    node: n,
                    p: Some(to_sparse(column.support(), column.values())),
                    s: Some(to_sparse(column.support(), &s)),
                    start: live
                        .start
                        .get(n as usize)
                        .copied()
                        .flatten()
                        .filter(|x| x.is_finite())
                        .map(|x| to_rgb(x.clamp_unit())),
                }))
            })
            .collect()
    }
}

/// The gRPC service.
#[derive(Clone)]
struct Service(Arc<Shared>);

type AttachStream = Pin<Box<dyn Stream<Item = Result<v1::RoomMessage, Status>> + Send>>;

fn room_message(body: v1::room_message::Body) -> Result<v1::RoomMessage, Status> {
    Ok(v1::RoomMessage { body: Some(body) })
}

#[tonic::async_trait]
impl v1::room_server::Room for Service {
    type AttachStream = AttachStream;

    async fn attach(
        &self,
        request: Request<Streaming<v1::NodeMessage>>,
    ) -> Result<Response<AttachStream>, Status> {
        let shared = self.0.clone();
        let mut inbound = request.into_inner();
        let first = tokio::time::timeout(
            shared.config.deadline.max(Duration::from_secs(1)),
            inbound.next(),
        )
        .await
        .map_err(|_| Status::deadline_exceeded("no Hello within the deadline"))?
        .ok_or_else(|| Status::invalid_argument("the stream ended before Hello"))??;
        let Some(v1::node_message::Body::Hello(hello)) = first.body else {
            return Err(Status::invalid_argument("the first message must be Hello"));
        };
        if hello.protocol_version != PROTOCOL_VERSION {
            tracing::warn!(projector = %hello.projector_id, version = hello.protocol_version, "refused: protocol version");
            return Err(Status::failed_precondition(format!(
                "protocol version {}, this camera agent speaks {PROTOCOL_VERSION}",
                hello.protocol_version
            )));
        }
        if hello.room != shared.config.room {
            tracing::warn!(projector = %hello.projector_id, room = %hello.room, "refused: another room");
            return Err(Status::failed_precondition(format!(
                "room {:?}, this is room {:?}",
                hello.room, shared.config.room
            )));
        }
        if !bool::from(hello.token.as_bytes().ct_eq(shared.config.token.as_bytes())) {
            tracing::warn!(projector = %hello.projector_id, "refused: wrong room token");
            return Err(Status::unauthenticated("wrong room token"));
        }
        let known = shared.live().owners.get(&hello.projector_id).cloned();
        let nodes = match known {
            Some(nodes) => nodes,
            // Calibrated over the wire once it is here: it must say how large it is.
            None if shared.survey.is_some() => {
                if hello.width == 0 || hello.height == 0 {
                    tracing::warn!(projector = %hello.projector_id, "refused: no resolution to calibrate");
                    return Err(Status::failed_precondition(format!(
                        "projector {:?} is not calibrated in room {:?}, and its Hello gives no resolution to calibrate it with (a display that draws pixels does)",
                        hello.projector_id, shared.config.room
                    )));
                }
                shared
                    .live
                    .write()
                    .unwrap_or_else(PoisonError::into_inner)
                    .uncalibrated
                    .insert(hello.projector_id.clone());
                Vec::new()
            }
            None => {
                return Err(Status::not_found(format!(
                    "projector {:?} is not calibrated in room {:?}",
                    hello.projector_id, shared.config.room
                )));
            }
        };
        // One stream per projector: a second one while the first is alive is refused (a
        // reconnecting node is admitted once its old stream has ended or missed its heartbeats).
        if shared.registry().peers.contains_key(&hello.projector_id) {
            tracing::warn!(projector = %hello.projector_id, "refused: already attached");
            return Err(Status::already_exists(format!(
                "projector {:?} is already attached to room {:?}",
                hello.projector_id, shared.config.room
            )));
        }
        let (tx, rx) = mpsc::channel(256);
        // Welcome, the node list, then each node's column and s on its support (for a hot
        // projector not yet measured: after its calibration).
        let calibrated = !shared.live().uncalibrated.contains(&hello.projector_id);
        let mut hello_msgs = vec![
            room_message(v1::room_message::Body::Welcome(v1::Welcome {
                protocol_version: PROTOCOL_VERSION,
                room: shared.config.room.clone(),
                calibration_epoch: shared.config.calibration_epoch,
                heartbeat_ms: u32::try_from(shared.config.heartbeat.as_millis())
                    .unwrap_or(u32::MAX),
                // A node's values are worth keeping only under the same calibration.
                state_accepted: hello
                    .state
                    .as_ref()
                    .is_some_and(|st| st.calibration_epoch == shared.config.calibration_epoch),
            })),
            room_message(v1::room_message::Body::Assign(
                match shared.live().assignments.get(&hello.projector_id) {
                    Some(a) => assign_message(a),
                    None => v1::Assign {
                        nodes: nodes
                            .iter()
                            .map(|&n| v1::NodeAssignment {
                                node: n,
                                chart: n,
                                ..Default::default()
                            })
                            .collect(),
                        ..Default::default()
                    },
                },
            )),
        ];
        if calibrated {
            hello_msgs.extend(
                shared
                    .attenuation_bodies(&nodes)
                    .into_iter()
                    .map(room_message),
            );
        }
        for m in hello_msgs {
            tx.send(m)
                .await
                .map_err(|_| Status::unavailable("the node left during the handshake"))?;
        }
        let projector = hello.projector_id.clone();
        let connection = {
            let mut reg = shared.registry();
            reg.next_connection += 1;
            let connection = reg.next_connection;
            reg.peers.insert(
                projector.clone(),
                Peer {
                    connection,
                    tx,
                    nodes: nodes.clone(),
                    shown: None,
                    awaiting: None,
                    calibrated,
                    pattern_shown: None,
                    width: hello.width,
                    height: hello.height,
                    kind: v1::ProjectorKind::try_from(hello.kind)
                        .unwrap_or(v1::ProjectorKind::Unspecified),
                },
            );
            connection
        };
        tracing::info!(%projector, nodes = nodes.len(), "joined");
        shared.changed.notify_waiters();
        tokio::spawn(read_node(shared, projector, connection, inbound));
        Ok(Response::new(Box::pin(ReceiverStream::new(rx))))
    }
}

/// Reads one node agent's stream until it ends, errs, or misses three heartbeats.
async fn read_node(
    shared: Arc<Shared>,
    projector: String,
    connection: u64,
    mut inbound: Streaming<v1::NodeMessage>,
) {
    let silence = 3 * shared.config.heartbeat;
    loop {
        let next = tokio::select! {
            () = shared.cancel.cancelled() => break,
            next = tokio::time::timeout(silence, inbound.next()) => next,
        };
        let next = match next {
            Err(_) => {
                tracing::warn!(%projector, "no heartbeat: leaves");
                break;
            }
            Ok(None) => break,
            Ok(Some(Err(status))) => {
                tracing::info!(%projector, %status, "stream ended");
                break;
            }
            Ok(Some(Ok(m))) => {
                shared
                    .bytes_in
                    .fetch_add(m.encoded_len() as u64, Ordering::Relaxed);
                m
            }
        };
        match next.body {
            Some(v1::node_message::Body::Shown(s)) => {
                if let Some(peer) = shared
                    .registry()
                    .peers
                    .get_mut(&projector)
                    .filter(|p| p.connection == connection)
                {
                    if s.pattern {
                        peer.pattern_shown =
                            Some(peer.pattern_shown.map_or(s.seq, |old| old.max(s.seq)));
                    } else {
                        peer.shown = Some(peer.shown.map_or(s.seq, |old| old.max(s.seq)));
                    }
                }
                shared.changed.notify_waiters();
            }
            Some(v1::node_message::Body::Contribution(c)) => {
                let owns = shared
                    .registry()
                    .peers
                    .get(&projector)
                    .is_some_and(|p| p.connection == connection && p.nodes.contains(&c.node));
                if !owns {
                    tracing::warn!(%projector, node = c.node, "contribution for a node it does not own: ignored");
                    continue;
                }
                let Some(delta) = c.delta.as_ref() else {
                    continue;
                };
                match from_sparse("contribution", delta) {
                    Ok((patches, values)) => {
                        let delta = patches.into_iter().zip(values).collect();
                        if shared
                            .contributions
                            .send(Contribution {
                                round: c.round,
                                node: c.node,
                                delta,
                            })
                            .await
                            .is_err()
                        {
                            break;
                        }
                    }
                    Err(e) => {
                        tracing::warn!(%projector, error = %e, "malformed contribution: ignored")
                    }
                }
            }
            Some(v1::node_message::Body::Goodbye(g)) => {
                tracing::info!(%projector, reason = %g.reason, "goodbye");
                break;
            }
            Some(v1::node_message::Body::Heartbeat(_))
            | Some(v1::node_message::Body::Hello(_))
            | None => {}
        }
    }
    let mut reg = shared.registry();
    if reg
        .peers
        .get(&projector)
        .is_some_and(|p| p.connection == connection)
    {
        reg.peers.remove(&projector);
        tracing::info!(%projector, "left");
    }
    drop(reg);
    shared.changed.notify_waiters();
}

/// True when every attached, calibrated projector shows the last frame it was sent.
fn all_shown(r: &Registry) -> bool {
    r.peers
        .values()
        .filter(|p| p.calibrated)
        .all(|p| p.shown.is_some() && p.awaiting.is_none_or(|a| p.shown.is_some_and(|s| s >= a)))
}

/// Waits until `ready` holds or the deadline passes; true when it holds.
async fn wait_for(shared: &Shared, deadline: Duration, ready: impl Fn(&Registry) -> bool) -> bool {
    let until = tokio::time::Instant::now() + deadline;
    loop {
        let notified = shared.changed.notified();
        if ready(&shared.registry()) {
            return true;
        }
        if tokio::time::timeout_at(until, notified).await.is_err() {
            return ready(&shared.registry());
        }
    }
}

/// Sends every ready projector the errors of its nodes; returns the nodes that were sent.
async fn broadcast(shared: &Shared, errors: &[LinearRgb], summary: &RoundSummary) -> Vec<u32> {
    let kind = match summary.kind {
        ErrorKind::Measured => v1::ErrorKind::Measured,
        ErrorKind::Predicted => v1::ErrorKind::Predicted,
    };
    let mut outbox = Vec::new();
    {
        let mut reg = shared.registry();
        let live = shared.live();
        for (projector, peer) in reg.peers.iter_mut().filter(|(_, p)| p.calibrated) {
            let ready = peer.shown.is_some()
                && peer
                    .awaiting
                    .is_none_or(|a| peer.shown.is_some_and(|s| s >= a));
            if !ready {
                tracing::warn!(%projector, round = summary.round, "late: left out of this round");
                continue;
            }
            peer.awaiting = Some(summary.round);
            for &n in &peer.nodes {
                let column = &live.problem.columns()[n as usize];
                let e: Vec<LinearRgb> = column
                    .support()
                    .iter()
                    .map(|&i| errors[i as usize])
                    .collect();
                outbox.push((
                    peer.tx.clone(),
                    n,
                    v1::Errors {
                        round: summary.round,
                        kind: kind as i32,
                        objective: summary.objective,
                        restart: summary.restart,
                        node: n,
                        errors: Some(to_sparse(column.support(), &e)),
                    },
                ));
            }
        }
    }
    let mut sent = Vec::with_capacity(outbox.len());
    for (tx, n, msg) in outbox {
        shared
            .bytes_out
            .fetch_add(msg.encoded_len() as u64, Ordering::Relaxed);
        // A failed send means the node left; its reader removes it.
        if tx
            .send(room_message(v1::room_message::Body::Errors(msg)))
            .await
            .is_ok()
        {
            sent.push(n);
        }
    }
    sent
}

/// Collects the contributions of `nodes` for `round` into the aggregator (until the deadline).
async fn collect(
    shared: &Shared,
    rx: &mut mpsc::Receiver<Contribution>,
    aggregator: &mut ErrorAggregator,
    round: u64,
    mut nodes: Vec<u32>,
) {
    let until = tokio::time::Instant::now() + shared.config.deadline;
    while !nodes.is_empty() {
        let changed = shared.changed.notified();
        // A projector that left will not answer: its nodes are not waited for.
        {
            let reg = shared.registry();
            nodes.retain(|n| reg.peers.values().any(|p| p.nodes.contains(n)));
        }
        if nodes.is_empty() {
            return;
        }
        let received = tokio::select! {
            received = tokio::time::timeout_at(until, rx.recv()) => received,
            () = changed => continue,
        };
        match received {
            Ok(Some(c)) if c.round == round => {
                if let Some(k) = nodes.iter().position(|&n| n == c.node) {
                    nodes.swap_remove(k);
                    if let Err(e) = aggregator.add_contribution(c.delta) {
                        tracing::warn!(node = c.node, error = %e, "contribution refused");
                    }
                }
            }
            Ok(Some(c)) => tracing::debug!(
                node = c.node,
                round = c.round,
                expected = round,
                "out-of-order contribution ignored"
            ),
            Ok(None) | Err(_) => {
                tracing::warn!(
                    round,
                    missing = nodes.len(),
                    "contributions missing at the deadline"
                );
                return;
            }
        }
    }
}

/// One capture the nodes can act on: the camera's stale frames discarded first (every frame
/// counted). `None` when the camera failed or handed over the wrong number of patches (logged).
async fn capture_fresh<C: Camera>(
    shared: &Shared,
    camera: &mut C,
    captures: &mut u64,
) -> Option<Vec<LinearRgb>> {
    let y = latest(shared, camera, captures, async |c: &mut C| {
        c.capture().await
    })
    .await?;
    let patches = shared.live().problem.patches();
    if y.len() != patches {
        tracing::error!(
            got = y.len(),
            expected = patches,
            "capture has the wrong number of patches"
        );
        return None;
    }
    Some(y)
}

/// Sends `projector` a Show pattern and waits until it has it on its display; false when it
/// left or did not show it within the deadline (logged).
async fn show_pattern(
    shared: &Shared,
    projector: &str,
    tx: &mpsc::Sender<Result<v1::RoomMessage, Status>>,
    pattern: v1::show::Pattern,
) -> bool {
    let seq = shared.pattern_seq.fetch_add(1, Ordering::Relaxed) + 1;
    let show = v1::room_message::Body::Show(v1::Show {
        seq,
        pattern: Some(pattern),
    });
    if !shared.send(tx, show).await {
        return false;
    }
    let shown = wait_for(shared, shared.config.deadline, |r| {
        r.peers
            .get(projector)
            .is_some_and(|p| p.pattern_shown.is_some_and(|s| s >= seq))
    })
    .await;
    if !shown {
        tracing::warn!(%projector, seq, "pattern not shown within the deadline");
    }
    shown
}

/// Shows `lit` at white and the projector's other nodes at black (all black for `None`), waits
/// for the projector to acknowledge the pattern, and captures (see [`capture_measured`]).
async fn show_and_capture(
    shared: &Shared,
    camera: &mut impl Camera,
    projector: &str,
    (tx, nodes): (&mpsc::Sender<Result<v1::RoomMessage, Status>>, &[u32]),
    lit: Option<u32>,
    captures: &mut u64,
) -> Option<(Vec<LinearRgb>, Vec<bool>)> {
    let values = nodes
        .iter()
        .map(|&n| v1::NodeState {
            node: n,
            x: Some(to_rgb(if lit == Some(n) {
                LinearRgb::ONE
            } else {
                LinearRgb::ZERO
            })),
            attenuation: None,
        })
        .collect();
    let pattern = v1::show::Pattern::Nodes(v1::NodeValues { values });
    if !show_pattern(shared, projector, tx, pattern).await {
        return None;
    }
    capture_measured(shared, camera, captures).await
}

/// A calibration capture of the model's patches, with whether each could be measured: with a
/// survey, a whole image sampled at the charts (a saturated patch, or one an edge crosses, is
/// not measured: its trimmed mean is not linear in the light); without, the camera's patches,
/// all taken as measured.
async fn capture_measured(
    shared: &Shared,
    camera: &mut impl Camera,
    captures: &mut u64,
) -> Option<(Vec<LinearRgb>, Vec<bool>)> {
    let Some(survey) = &shared.survey else {
        let y = capture_fresh(shared, camera, captures).await?;
        let ok = vec![true; y.len()];
        return Some((y, ok));
    };
    let image = capture_image_fresh(shared, camera, captures).await?;
    let samples =
        match roomlight_calib::charts::sample_charts(&image, &survey.corners, &survey.sample) {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(error = %e, "the charts could not be sampled");
                return None;
            }
        };
    let mut means = Vec::with_capacity(survey.patches.len());
    let mut ok = Vec::with_capacity(survey.patches.len());
    for &i in &survey.patches {
        let Some(sample) = samples.get(i) else {
            tracing::error!(
                patch = i,
                charts = samples.len(),
                "the survey names a patch the charts lack"
            );
            return None;
        };
        means.push(sample.mean);
        ok.push(sample.status == roomlight_calib::charts::PatchStatus::Ok);
    }
    let patches = shared.live().problem.patches();
    if means.len() != patches {
        tracing::error!(
            surveyed = means.len(),
            expected = patches,
            "the survey's patches do not match the model's"
        );
        return None;
    }
    Some((means, ok))
}

/// One whole image, the camera's stale frames discarded first (every frame counted).
async fn capture_image_fresh<C: Camera>(
    shared: &Shared,
    camera: &mut C,
    captures: &mut u64,
) -> Option<LinearImage> {
    latest(shared, camera, captures, async |c: &mut C| {
        c.capture_image().await
    })
    .await
}

/// The last of `stale_frames + 1` captures taken with `take` (every one counted); `None` when
/// one failed (logged).
async fn latest<C: Camera, T>(
    shared: &Shared,
    camera: &mut C,
    captures: &mut u64,
    mut take: impl AsyncFnMut(&mut C) -> Result<T, crate::AgentError>,
) -> Option<T> {
    let mut last = None;
    for _ in 0..=shared.config.stale_frames {
        match take(camera).await {
            Ok(v) => {
                *captures += 1;
                last = Some(v);
            }
            Err(e) => {
                tracing::warn!(error = %e, "capture failed");
                return None;
            }
        }
    }
    last
}

/// Shows a whole-frame pattern on `projector`, waits for it, and captures a whole image (the
/// camera's stale frames discarded first, every frame counted).
async fn show_and_capture_image(
    shared: &Shared,
    camera: &mut impl Camera,
    projector: &str,
    tx: &mpsc::Sender<Result<v1::RoomMessage, Status>>,
    pattern: Pattern,
    captures: &mut u64,
) -> Option<LinearImage> {
    if !show_pattern(shared, projector, tx, wire_pattern(pattern)).await {
        return None;
    }
    capture_image_fresh(shared, camera, captures).await
}

/// A whole-frame pattern as a Show pattern (white and black as uniform codes).
fn wire_pattern(pattern: Pattern) -> v1::show::Pattern {
    use roomlight_calib::graycode::{Axis, Pattern as Gray};
    let uniform = |v: f64| {
        v1::show::Pattern::Uniform(v1::Uniform {
            code: Some(to_rgb(LinearRgb::splat(v))),
        })
    };
    match pattern {
        Pattern::Uniform(code) => v1::show::Pattern::Uniform(v1::Uniform {
            code: Some(to_rgb(LinearRgb(code.map(f64::from)))),
        }),
        Pattern::Structured {
            pattern: Gray::White,
            ..
        } => uniform(1.0),
        Pattern::Structured {
            pattern: Gray::Black,
            ..
        } => uniform(0.0),
        Pattern::Structured {
            pattern: Gray::Bit { axis, bit, inverse },
            coding,
        } => v1::show::Pattern::Gray(v1::GrayBit {
            axis: match axis {
                Axis::Column => v1::Axis::Column,
                Axis::Row => v1::Axis::Row,
            } as i32,
            bit,
            inverse,
            coding: match coding {
                Coding::Gray => v1::Coding::Gray,
                Coding::Xor04 => v1::Coding::Xor04,
            } as i32,
        }),
    }
}

/// An assignment as the Assign message that carries it.
fn assign_message(a: &Assignment) -> v1::Assign {
    v1::Assign {
        nodes: a
            .nodes
            .iter()
            .map(|(n, w)| v1::NodeAssignment {
                node: *n,
                chart: *n,
                pixels: w.iter().map(|p| p.0).collect(),
                weights: w.iter().map(|p| p.1).collect(),
            })
            .collect(),
        width: a.width,
        height: a.height,
        gamma: a.response.gamma.to_vec(),
    }
}

/// Levels of the response ramp shown over the wire (DESIGN §4: at least 9).
const RAMP_LEVELS: usize = 9;

/// A projector decoded over the wire and its response fitted, not yet segmented.
struct Decoded {
    projector: String,
    tx: mpsc::Sender<Result<v1::RoomMessage, Status>>,
    width: u32,
    height: u32,
    large: bool,
    corr: roomlight_calib::graycode::Correspondence,
    response: roomlight_calib::response::Response,
}

/// Calibrates a projector the model does not know, over the wire (DESIGN §4.2–4.4, §4.7): its
/// node agent shows structured light and a response ramp while the other projectors keep their
/// values (the decode compares each pattern with its inverse and the response fit subtracts the
/// ramp's first level, so their light cancels); the camera agent decodes and segments it
/// (off the runtime's threads), appends its nodes to the model with empty columns, records
/// each node's chart for its conventional start, and sends it the nodes' weights and the
/// response. At bring-up (no projector lit yet) every other projector waiting for its nodes is
/// decoded too and all are segmented together, feathered against each other; a projector that
/// joins a lit room takes what the others' weights leave ([`assign_decoded`]). False when the
/// projector left, a pattern was not shown, the camera failed, or the decode or the response
/// fit was refused (logged; it is tried again).
async fn segment_over_wire(
    shared: &Shared,
    camera: &mut impl Camera,
    projector: &str,
    captures: &mut u64,
) -> bool {
    let Some(first) = decode_over_wire(shared, camera, projector, captures).await else {
        return false;
    };
    let mut batch = vec![first];
    let others: Vec<String> = {
        let reg = shared.registry();
        if reg.dark() {
            reg.peers
                .iter()
                .filter(|(id, p)| *id != projector && !p.calibrated && p.nodes.is_empty())
                .map(|(id, _)| id.clone())
                .collect()
        } else {
            Vec::new()
        }
    };
    for other in others {
        if let Some(d) = decode_over_wire(shared, camera, &other, captures).await {
            batch.push(d);
        }
    }
    assign_decoded(shared, batch)
        .await
        .iter()
        .any(|p| p == projector)
}

/// Shows a projector's structured light and response ramp, decodes the one and fits the other
/// (off the runtime's threads). `None` when it left, a pattern was not shown, the camera failed
/// or the decode or fit was refused (logged).
async fn decode_over_wire(
    shared: &Shared,
    camera: &mut impl Camera,
    projector: &str,
    captures: &mut u64,
) -> Option<Decoded> {
    let survey = shared.survey.clone()?;
    let (tx, width, height, kind) = shared
        .registry()
        .peers
        .get(projector)
        .map(|p| (p.tx.clone(), p.width, p.height, p.kind))?;
    // A large aperture's defocus blurs XOR-04's fine stripes: plain Gray code, one node.
    let large = kind == v1::ProjectorKind::LargeAperture;
    let coding = if large { Coding::Gray } else { Coding::Xor04 };
    let (manifest, codes) = match (
        Manifest::with_coding(width, height, coding),
        ramp_codes(RAMP_LEVELS),
    ) {
        (Ok(m), Ok(c)) => (m, c),
        (Err(e), _) | (_, Err(e)) => {
            tracing::error!(%projector, error = %e, "cannot calibrate over the wire");
            return None;
        }
    };
    tracing::info!(%projector, width, height, patterns = manifest.patterns.len(), "structured light over the wire");
    let mut images = Vec::with_capacity(manifest.patterns.len());
    for file in &manifest.patterns {
        let pattern = Pattern::Structured {
            pattern: file.pattern,
            coding,
        };
        images
            .push(show_and_capture_image(shared, camera, projector, &tx, pattern, captures).await?);
    }
    let mut ramp = Vec::with_capacity(codes.len());
    for &code in &codes {
        let pattern = Pattern::Uniform([code as f32; 3]);
        ramp.push(show_and_capture_image(shared, camera, projector, &tx, pattern, captures).await?);
    }
    // Dark again until its attenuation is measured: at bring-up others are decoded and measured
    // after it, and its last ramp level would light their captures.
    if !show_pattern(
        shared,
        projector,
        &tx,
        wire_pattern(Pattern::Uniform([0.0; 3])),
    )
    .await
    {
        return None;
    }
    let worked = tokio::task::spawn_blocking(move || {
        let corr = roomlight_calib::graycode::decode(&manifest, &DecodeConfig::default(), |f| {
            let k = manifest
                .patterns
                .iter()
                .position(|p| p.file == f.file)
                .unwrap_or(0);
            Ok(&images[k])
        })
        .map_err(|e| format!("decode: {e}"))?;
        if corr.map.len() != survey.target_mask.len() {
            return Err(format!(
                "the camera's images have {} pixels, the survey's target mask {}",
                corr.map.len(),
                survey.target_mask.len()
            ));
        }
        let (measured, noise) = footprint_ramp(&ramp, &corr);
        let response =
            fit_response(&codes, &measured, &noise).map_err(|e| format!("response: {e}"))?;
        Ok::<_, String>((corr, response))
    })
    .await;
    match worked {
        Ok(Ok((corr, response))) => Some(Decoded {
            projector: projector.to_string(),
            tx,
            width,
            height,
            large,
            corr,
            response,
        }),
        Ok(Err(e)) => {
            tracing::error!(%projector, error = %e, "calibration over the wire refused");
            None
        }
        Err(e) => {
            tracing::error!(%projector, error = %e, "calibration over the wire failed");
            None
        }
    }
}

/// Segments decoded projectors (off the runtime's threads) and assigns them their nodes: the
/// standard ones that light a chart together, feathered against each other, beside the
/// projectors segmented before (which keep their weights: the new ones share what those leave,
/// [`roomlight_calib::nodes::segment_beside`]); a large aperture, or a projector that lights no
/// chart, is one node over its frame but the target. Their nodes join the model with empty
/// columns. Returns the projectors whose assignment was sent.
async fn assign_decoded(shared: &Shared, batch: Vec<Decoded>) -> Vec<String> {
    let Some(survey) = shared.survey.clone() else {
        return Vec::new();
    };
    // What the attached projectors segmented before give each camera pixel (those decoded now
    // are segmented anew, whatever they had). One that is not attached now does not hold its
    // share: a projector that replaces a dead one takes its place (should the old one come
    // back, the model holds both where they overlap).
    let attached: HashSet<String> = shared.registry().peers.keys().cloned().collect();
    let claimed: Option<Vec<f32>> = {
        let live = shared.live();
        let mut sum: Option<Vec<f32>> = None;
        for (id, claim) in &live.claims {
            if !attached.contains(id)
                || batch.iter().any(|d| &d.projector == id)
                || claim.len() != survey.target_mask.len()
            {
                continue;
            }
            roomlight_calib::nodes::add_claim(
                sum.get_or_insert_with(|| vec![0.0; claim.len()]),
                claim,
            );
        }
        sum
    };
    let segmented = tokio::task::spawn_blocking(move || {
        let config = roomlight_calib::nodes::NodeConfig::default();
        let charted: Vec<bool> = batch
            .iter()
            .map(|d| {
                !d.large
                    && roomlight_calib::nodes::charts_lit(&d.corr, &survey.corners, &config)
                        .is_ok_and(|c| !c.is_empty())
            })
            .collect();
        let together: Vec<roomlight_calib::graycode::Correspondence> = batch
            .iter()
            .zip(&charted)
            .filter(|(_, c)| **c)
            .map(|(d, _)| d.corr.clone())
            .collect();
        let seg = roomlight_calib::nodes::segment_beside(
            &together,
            &survey.corners,
            Some(&survey.target_mask),
            &config,
            claimed.as_deref(),
        );
        let mut seg = match seg {
            Ok(seg) => Some(seg),
            Err(e) => {
                tracing::error!(error = %e, "segmentation over the wire refused");
                None
            }
        };
        let mut out = Vec::with_capacity(batch.len());
        let mut k = 0;
        for (d, charted) in batch.into_iter().zip(charted) {
            let decoded = d.corr.decoded_share();
            let whole = || {
                roomlight_calib::nodes::whole_frame(&d.corr, &survey.corners, &survey.target_mask)
            };
            let (nodes, claim) = if charted {
                let Some(seg) = seg.as_mut() else {
                    continue;
                };
                let nodes: Vec<(Vec<f32>, Option<usize>)> = seg
                    .nodes
                    .iter_mut()
                    .filter(|n| n.projector == k)
                    .map(|n| (std::mem::take(&mut n.weights), Some(n.chart)))
                    .collect();
                let claim = std::mem::take(&mut seg.claims[k]);
                k += 1;
                (nodes, Some(claim))
            } else {
                tracing::info!(projector = %d.projector, large = d.large, "one node over its frame");
                (vec![whole()], None)
            };
            out.push((d, nodes, claim, decoded));
        }
        out
    })
    .await;
    let segmented = match segmented {
        Ok(s) => s,
        Err(e) => {
            tracing::error!(error = %e, "segmentation over the wire failed");
            return Vec::new();
        }
    };
    let mut assigned = Vec::with_capacity(segmented.len());
    for (d, nodes, claim, decoded) in segmented {
        let projector = d.projector.as_str();
        let assignment = {
            let mut live = shared.live.write().unwrap_or_else(PoisonError::into_inner);
            let first = live.problem.nodes() as u32;
            let ids: Vec<u32> = (first..).take(nodes.len()).collect();
            let mut columns = live.problem.columns().to_vec();
            columns.extend(nodes.iter().map(|_| AttenuationColumn::default()));
            let problem = match Problem::new(
                columns,
                live.problem.black().to_vec(),
                live.problem.target().to_vec(),
                live.problem.noise().to_vec(),
            ) {
                Ok(p) => p,
                Err(e) => {
                    tracing::error!(%projector, error = %e, "calibration over the wire refused");
                    continue;
                }
            };
            live.problem = problem;
            live.start.extend(nodes.iter().map(|_| None));
            for (&n, (_, chart)) in ids.iter().zip(&nodes) {
                if let Some(c) = chart {
                    live.charts.insert(n, *c);
                }
            }
            let assignment = Assignment {
                width: d.width,
                height: d.height,
                response: d.response,
                nodes: ids
                    .iter()
                    .zip(&nodes)
                    .map(|(&n, (w, _))| {
                        let sparse = w
                            .iter()
                            .enumerate()
                            .filter(|(_, w)| **w > 0.0)
                            .map(|(i, w)| (i as u32, w.min(1.0)))
                            .collect();
                        (n, sparse)
                    })
                    .collect(),
            };
            live.owners.insert(projector.to_string(), ids.clone());
            live.assignments
                .insert(projector.to_string(), assignment.clone());
            match claim {
                Some(claim) => live.claims.insert(projector.to_string(), claim),
                None => live.claims.remove(projector),
            };
            assignment
        };
        let ids: Vec<u32> = assignment.nodes.iter().map(|(n, _)| *n).collect();
        if let Some(peer) = shared.registry().peers.get_mut(projector) {
            peer.nodes = ids.clone();
        }
        let assign = v1::room_message::Body::Assign(assign_message(&assignment));
        if !shared.send(&d.tx, assign).await {
            continue;
        }
        tracing::info!(%projector, nodes = ids.len(), decoded = format!("{:.1}%", 100.0 * decoded), gamma = ?assignment.response.gamma, "segmented over the wire");
        assigned.push(d.projector);
    }
    assigned
}

/// Measures a hot projector's attenuation (DESIGN §4): its nodes all at black, then each alone
/// at white, one capture each, while every other projector keeps its values (no errors are
/// sent meanwhile). `p = max(y_white − y_black, 0)`, entries at or below √2 σ (one standard
/// deviation of a difference of two captures) dropped: about the level the Hadamard path's 3σ
/// cut reaches with its lower variance. At 3√2 σ the calibrated lab's model dropped enough
/// faint light that the room measured 6% below the model's optimum (1.4% at √2 σ). Also
/// patches a capture could not measure leave the model (see [`capture_measured`]). Then the
/// projector gets its attenuation and every
/// attached projector its `s` anew (the new light changes it). False when the projector left,
/// did not show a pattern in time, or the camera failed: it stays uncalibrated and is tried
/// again.
async fn calibrate_hot(
    shared: &Shared,
    camera: &mut impl Camera,
    projector: &str,
    errors: Option<&[LinearRgb]>,
    captures: &mut u64,
) -> bool {
    let needs_nodes = shared
        .registry()
        .peers
        .get(projector)
        .is_some_and(|p| p.nodes.is_empty());
    if needs_nodes && !segment_over_wire(shared, camera, projector, captures).await {
        return false;
    }
    let Some((tx, nodes)) = shared
        .registry()
        .peers
        .get(projector)
        .map(|p| (p.tx.clone(), p.nodes.clone()))
    else {
        return false;
    };
    tracing::info!(%projector, nodes = nodes.len(), "hot calibration");
    let Some((black, mut measurable)) =
        show_and_capture(shared, camera, projector, (&tx, &nodes), None, captures).await
    else {
        return false;
    };
    let threshold: Vec<LinearRgb> = shared
        .live()
        .problem
        .noise()
        .iter()
        .map(|s| *s * (1.0 * std::f64::consts::SQRT_2))
        .collect();
    let mut measured = Vec::with_capacity(nodes.len());
    for &n in &nodes {
        let Some((white, ok)) =
            show_and_capture(shared, camera, projector, (&tx, &nodes), Some(n), captures).await
        else {
            return false;
        };
        for (m, o) in measurable.iter_mut().zip(ok) {
            *m &= o;
        }
        let dense: Vec<LinearRgb> = white
            .iter()
            .zip(&black)
            .map(|(w, b)| (*w - *b).map(|v| v.max(0.0)))
            .collect();
        match AttenuationColumn::from_dense_with_cutoff(&dense, &threshold) {
            Ok(column) => measured.push((n, column)),
            Err(e) => {
                tracing::error!(%projector, node = n, error = %e, "hot calibration refused");
                return false;
            }
        }
    }
    {
        let mut live = shared.live.write().unwrap_or_else(PoisonError::into_inner);
        let mut columns = live.problem.columns().to_vec();
        for (n, column) in measured {
            if let Some(slot) = columns.get_mut(n as usize) {
                *slot = column;
            }
        }
        // Patches this projector's light makes unmeasurable leave the model for good: every
        // column loses them, their target becomes their black level and their errors are
        // zero, so the model and the measured G agree and no node acts on them.
        let newly: Vec<usize> = (0..measurable.len())
            .filter(|&i| !measurable[i] && !live.excluded.get(i).copied().unwrap_or(true))
            .collect();
        if !newly.is_empty() {
            tracing::info!(%projector, patches = ?newly, "patches not measurable under its light: left out");
        }
        let live = &mut *live;
        let problem = match leave_out(&mut live.excluded, &newly, columns, &live.problem) {
            Ok(p) => p,
            Err(e) => {
                tracing::error!(%projector, error = %e, "hot calibration refused");
                return false;
            }
        };
        // Nodes segmented over the wire start from the conventional value of their chart.
        if let Some(survey) = &shared.survey {
            for &n in &nodes {
                let (Some(&chart), Some(column)) =
                    (live.charts.get(&n), problem.columns().get(n as usize))
                else {
                    continue;
                };
                let start = conventional_value(
                    column,
                    &survey.chart_patches(chart),
                    problem.target(),
                    problem.black(),
                    LinearRgb::splat(0.5),
                );
                if let (Ok(x), Some(slot)) = (start, live.start.get_mut(n as usize)) {
                    *slot = Some(x);
                }
            }
        }
        // Joining a lit room: the new nodes start where they best fill what the room lacks
        // now (the bounded least-squares fit of their columns to the current errors, the
        // others held), not where they would light their charts alone; the others then adjust
        // in the rounds.
        if let Some(e) = errors.filter(|e| e.len() == problem.patches()) {
            match joining_start(&problem, &nodes, e) {
                Ok(x) => {
                    for (&n, x) in nodes.iter().zip(x) {
                        if let Some(slot) = live.start.get_mut(n as usize) {
                            *slot = Some(x);
                        }
                    }
                }
                Err(err) => {
                    tracing::warn!(%projector, error = %err, "no joining start: the conventional one")
                }
            }
        }
        live.white = problem.white_response();
        live.problem = problem;
        live.uncalibrated.remove(projector);
    }
    // Bring-up: while the room is still dark (no projector has shown a round's frame) and
    // others wait for their calibration, this one stays dark too, so that theirs is measured
    // in the dark as well (the light of lit projectors adds camera noise and costs decoded
    // pixels); all are lit once the last is measured.
    let dark = {
        let reg = shared.registry();
        reg.dark()
            && reg
                .peers
                .iter()
                .any(|(id, p)| id != projector && !p.calibrated)
    };
    if let Some(peer) = shared.registry().peers.get_mut(projector) {
        peer.calibrated = true;
    }
    if dark {
        let values = nodes
            .iter()
            .map(|&n| v1::NodeState {
                node: n,
                x: Some(to_rgb(LinearRgb::ZERO)),
                attenuation: None,
            })
            .collect();
        let black = v1::show::Pattern::Nodes(v1::NodeValues { values });
        if !show_pattern(shared, projector, &tx, black).await {
            light_all(shared).await;
        }
    } else {
        // Its attenuation to the new projector, `s` anew to everyone; then it joins the rounds.
        light_all(shared).await;
    }
    tracing::info!(%projector, dark, "hot calibration done");
    if let Some(path) = &shared.config.model_out
        && let Err(e) = write_model(shared, path)
    {
        tracing::warn!(path = %path.display(), error = %e, "could not write the model");
    }
    shared.changed.notify_waiters();
    true
}

/// The values of `nodes` (new, dark) that best fill the room's current errors `e` with the
/// other nodes held: `argmin ‖e − P_new x‖²` over `x ∈ [0, 1]`, per channel, solved exactly
/// as a problem of its own (target `max(e, 0)`, black `max(−e, 0)`, so that target − black = e).
fn joining_start(
    problem: &Problem,
    nodes: &[u32],
    e: &[LinearRgb],
) -> Result<Vec<LinearRgb>, String> {
    let columns = nodes
        .iter()
        .filter_map(|&n| problem.columns().get(n as usize).cloned())
        .collect();
    let sub = Problem::new(
        columns,
        e.iter().map(|v| v.map(|c| (-c).max(0.0))).collect(),
        e.iter().map(|v| v.map(|c| c.max(0.0))).collect(),
        problem.noise().to_vec(),
    )
    .map_err(|e| e.to_string())?;
    Ok(roomlight_core::optimum::optimum(&sub)
        .map_err(|e| e.to_string())?
        .x
        .into_iter()
        .map(LinearRgb::clamp_unit)
        .collect())
}

/// Leaves `newly` out of the model for good (marked in `excluded`): every one of `columns`
/// loses them and their target becomes their black level; the problem with `columns`.
fn leave_out(
    excluded: &mut [bool],
    newly: &[usize],
    mut columns: Vec<AttenuationColumn>,
    problem: &Problem,
) -> Result<Problem, roomlight_core::ModelError> {
    for &i in newly {
        if let Some(x) = excluded.get_mut(i) {
            *x = true;
        }
    }
    let target: Vec<LinearRgb> = problem
        .target()
        .iter()
        .zip(problem.black())
        .zip(excluded.iter())
        .map(|((t, b), &out)| if out { *b } else { *t })
        .collect();
    if !newly.is_empty() {
        for column in &mut columns {
            let (support, values): (Vec<u32>, Vec<LinearRgb>) = column
                .iter()
                .filter(|(i, _)| !excluded.get(*i as usize).copied().unwrap_or(true))
                .unzip();
            *column = AttenuationColumn::new(support, values)?;
        }
    }
    Problem::new(
        columns,
        problem.black().to_vec(),
        target,
        problem.noise().to_vec(),
    )
}

/// Sends every attached projector its nodes' attenuation, `s` and start: a projector measured
/// but not yet lit starts showing its start, a running one keeps its values with the new `s`.
async fn light_all(shared: &Shared) {
    let outbox: Vec<_> = shared
        .registry()
        .peers
        .values()
        .filter(|p| p.calibrated)
        .map(|p| (p.tx.clone(), p.nodes.clone()))
        .collect();
    for (tx, nodes) in outbox {
        for body in shared.attenuation_bodies(&nodes) {
            if !shared.send(&tx, body).await {
                break;
            }
        }
    }
}

/// Writes the live model as JSON through a temporary file beside `path`.
fn write_model(shared: &Shared, path: &std::path::Path) -> std::io::Result<()> {
    let text = {
        let live = shared.live();
        serde_json::to_string(&serde_json::json!({
            "problem": live.problem,
            "owners": live.owners,
            // Only when every node has one (else the node agents' own).
            "start": live.start.iter().copied().collect::<Option<Vec<LinearRgb>>>(),
            // Calibrated over the wire: the room patch of each model patch, so that a camera
            // agent restarted with the same survey resumes this model.
            "patches": shared.survey.as_ref().map(|s| &s.patches),
        }))?
    };
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)
}

/// Serves the Room service on `listener` and runs rounds until `cancel`. Returns the status
/// watch and the task's handle.
pub fn serve(
    config: CameraConfig,
    model: RoomModel,
    mut camera: impl Camera,
    listener: tokio::net::TcpListener,
    cancel: CancellationToken,
) -> (
    watch::Receiver<RoomStatus>,
    tokio::task::JoinHandle<Result<(), crate::AgentError>>,
) {
    let (contrib_tx, mut contrib_rx) = mpsc::channel(4096);
    // Nothing is known of a hot projector until it is measured: not its light in `s`, not its
    // columns.
    let unknown: Vec<usize> = model
        .hot
        .iter()
        .filter_map(|id| model.owners.get(id))
        .flatten()
        .map(|&n| n as usize)
        .collect();
    let problem = model.problem.without_nodes(&unknown);
    let white = problem.white_response();
    // A model resumed over the wire keeps its left-out patches: uncovered, target = black.
    let excluded: Vec<bool> = (0..problem.patches())
        .map(|i| {
            model.survey.is_some()
                && problem.target()[i] == problem.black()[i]
                && problem
                    .columns()
                    .iter()
                    .all(|c| c.get(i as u32) == LinearRgb::ZERO)
        })
        .collect();
    let start = match model.start {
        Some(v) => v.into_iter().map(Some).collect(),
        None => vec![None; problem.nodes()],
    };
    let shared = Arc::new(Shared {
        config,
        survey: model.survey,
        live: std::sync::RwLock::new(Live {
            problem,
            white,
            uncalibrated: model.hot,
            owners: model.owners,
            start,
            assignments: HashMap::new(),
            claims: HashMap::new(),
            charts: HashMap::new(),
            excluded,
        }),
        pattern_seq: AtomicU64::new(0),
        registry: Mutex::new(Registry::default()),
        changed: Notify::new(),
        contributions: contrib_tx,
        bytes_out: AtomicU64::new(0),
        bytes_in: AtomicU64::new(0),
        cancel: CancellationToken::new(),
    });
    let (status_tx, status_rx) = watch::channel(RoomStatus::default());
    let server_cancel = shared.cancel.clone();
    let service = Service(shared.clone());
    let handle = tokio::spawn(async move {
        let server = tonic::transport::Server::builder()
            .http2_keepalive_interval(Some(Duration::from_secs(5)))
            .add_service(v1::room_server::RoomServer::new(service))
            .serve_with_incoming_shutdown(
                // Small messages both ways every round: Nagle's algorithm would add ~40 ms.
                tonic::transport::server::TcpIncoming::from(listener).with_nodelay(Some(true)),
                server_cancel.cancelled_owned(),
            );
        let rounds = async {
            let (target, sigma) = {
                let live = shared.live();
                (
                    live.problem.target().to_vec(),
                    live.problem.noise().to_vec(),
                )
            };
            let mut aggregator = ErrorAggregator::new(target.len());
            let mut captures = 0u64;
            let mut calibrated_hot = 0u64;
            // Projector → when to try its calibration again, and its failures so far.
            let mut retry: HashMap<String, (tokio::time::Instant, u32)> = HashMap::new();
            let mut previous: Option<f64> = None;
            let mut quiet = 0u32;
            // A stop request ends the rounds between two rounds, never inside one.
            while !cancel.is_cancelled() {
                // Someone must be there, and have shown its last frame (or wait to be measured).
                let present = tokio::select! {
                    present = wait_for(&shared, Duration::from_secs(3600), |r| {
                        r.peers.values().any(|p| p.shown.is_some() || !p.calibrated)
                    }) => present,
                    () = cancel.cancelled() => break,
                };
                if !present {
                    continue;
                }
                // Projectors waiting for their calibration; the next one whose retry is due.
                let now = tokio::time::Instant::now();
                let (waiting, due) = {
                    let reg = shared.registry();
                    let waiting: Vec<String> = reg
                        .peers
                        .iter()
                        .filter(|(_, p)| !p.calibrated)
                        .map(|(id, _)| id.clone())
                        .collect();
                    let due = waiting
                        .iter()
                        .find(|id| retry.get(*id).is_none_or(|(at, _)| now >= *at))
                        .cloned();
                    (waiting, due)
                };
                retry.retain(|id, _| waiting.contains(id));
                if let Some(projector) = due {
                    // The room's errors without it, once a round has measured them.
                    let errors = previous.is_some().then(|| aggregator.errors());
                    if calibrate_hot(&shared, &mut camera, &projector, errors, &mut captures).await
                    {
                        calibrated_hot += 1;
                        retry.remove(&projector);
                        continue;
                    }
                    // Tried again after the others, backing off to 3.2 s (the cause is logged
                    // each time).
                    let failures = retry.get(&projector).map_or(0, |r| r.1).saturating_add(1);
                    let wait = Duration::from_millis(200) * (1 << failures.min(4));
                    retry.insert(projector, (tokio::time::Instant::now() + wait, failures));
                    // Projectors kept dark for a bring-up light up now rather than wait for one
                    // that may never be measured.
                    let unlit = shared
                        .registry()
                        .peers
                        .values()
                        .any(|p| p.calibrated && p.shown.is_none());
                    if unlit {
                        light_all(&shared).await;
                    }
                }
                if !waiting.is_empty() {
                    // Meanwhile the calibrated projectors go on with their rounds: one that
                    // cannot be calibrated must not stop the others' corrections.
                    let others = shared
                        .registry()
                        .peers
                        .values()
                        .any(|p| p.calibrated && p.shown.is_some());
                    if !others {
                        let next = retry
                            .values()
                            .map(|(at, _)| *at)
                            .min()
                            .unwrap_or_else(tokio::time::Instant::now);
                        tokio::select! {
                            () = tokio::time::sleep_until(next) => {}
                            () = shared.changed.notified() => {}
                            () = cancel.cancelled() => break,
                        }
                        continue;
                    }
                }
                wait_for(&shared, shared.config.deadline, all_shown).await;
                let Some((y, ok)) = capture_measured(&shared, &mut camera, &mut captures).await
                else {
                    // The camera is unreachable: the lights stay as they are; try again.
                    tokio::time::sleep(Duration::from_millis(200)).await;
                    continue;
                };
                // Calibrated over the wire: a patch the room's light now saturates or an
                // edge now crosses leaves the model, and everyone gets the cut columns.
                let newly: Vec<usize> = {
                    let live = shared.live();
                    (0..ok.len())
                        .filter(|&i| !ok[i] && !live.excluded.get(i).copied().unwrap_or(true))
                        .collect()
                };
                if !newly.is_empty() {
                    let cut = {
                        let mut guard = shared.live.write().unwrap_or_else(PoisonError::into_inner);
                        let live = &mut *guard;
                        let columns = live.problem.columns().to_vec();
                        match leave_out(&mut live.excluded, &newly, columns, &live.problem) {
                            Ok(problem) => {
                                live.white = problem.white_response();
                                live.problem = problem;
                                true
                            }
                            Err(e) => {
                                tracing::error!(error = %e, "patches could not be left out");
                                false
                            }
                        }
                    };
                    if cut {
                        tracing::info!(patches = ?newly, "patches no longer measurable under the room's light: left out");
                        light_all(&shared).await;
                        if let Some(path) = &shared.config.model_out
                            && let Err(e) = write_model(&shared, path)
                        {
                            tracing::warn!(path = %path.display(), error = %e, "could not write the model");
                        }
                    }
                }
                let errors: Vec<LinearRgb> = {
                    let live = shared.live();
                    live.problem
                        .target()
                        .iter()
                        .zip(&y)
                        .zip(&live.excluded)
                        .map(|((r, y), &out)| if out { LinearRgb::ZERO } else { *r - *y })
                        .collect()
                };
                let summary = match aggregator.measured(errors) {
                    Ok(s) => s,
                    Err(e) => {
                        tracing::error!(error = %e, "capture refused");
                        continue;
                    }
                };
                let mut round = summary.round;
                let measured_objective = summary.objective;
                let noise = objective_noise(aggregator.errors(), &sigma);
                quiet = match previous {
                    // A noiseless camera: settled when G stops changing to rounding.
                    Some(g)
                        if (measured_objective - g).abs()
                            <= (3.0 * std::f64::consts::SQRT_2 * noise)
                                .max(1e-12 * measured_objective.max(g)) =>
                    {
                        quiet + 1
                    }
                    _ => 0,
                };
                previous = Some(measured_objective);
                let sent = broadcast(&shared, aggregator.errors(), &summary).await;
                collect(&shared, &mut contrib_rx, &mut aggregator, round, sent).await;
                for _ in 0..shared.config.model_rounds {
                    // Acknowledgements follow contributions: wait for them too.
                    wait_for(&shared, shared.config.deadline, all_shown).await;
                    let summary = aggregator.predicted();
                    round = summary.round;
                    let sent = broadcast(&shared, aggregator.errors(), &summary).await;
                    collect(&shared, &mut contrib_rx, &mut aggregator, round, sent).await;
                }
                let live_projectors = shared.registry().peers.len();
                status_tx.send_replace(RoomStatus {
                    round,
                    captures,
                    measured_objective,
                    live_projectors,
                    bytes_out: shared.bytes_out.swap(0, Ordering::Relaxed),
                    bytes_in: shared.bytes_in.swap(0, Ordering::Relaxed),
                    settled: quiet >= 2,
                    calibrated_hot,
                });
            }
        };
        // On a stop request the current round finishes (bounded: a round waits at most a
        // deadline for the acknowledgements and one per model round for the contributions).
        let grace = shared.config.deadline * (shared.config.model_rounds as u32 + 3);
        let stop_waiting = async {
            cancel.cancelled().await;
            tokio::time::sleep(grace).await;
        };
        tokio::pin!(server);
        tokio::select! {
            result = &mut server => return result.map_err(crate::AgentError::from),
            () = rounds => {}
            () = stop_waiting => tracing::warn!(?grace, "the round did not finish in time: stopped"),
        }
        shared.cancel.cancel();
        // Stopping: say goodbye and end every node's stream, so the node agents reconnect to
        // whichever camera agent comes next instead of waiting on a stream nobody writes to.
        let peers: Vec<Peer> = shared.registry().peers.drain().map(|(_, p)| p).collect();
        for peer in peers {
            let _ = peer
                .tx
                .try_send(room_message(v1::room_message::Body::Goodbye(v1::Goodbye {
                    reason: "the camera agent is stopping".into(),
                })));
        }
        // The server's graceful shutdown now only waits for the streams to drain.
        match tokio::time::timeout(Duration::from_secs(2), server).await {
            Ok(result) => result.map_err(crate::AgentError::from),
            Err(_) => {
                tracing::warn!("connections still open 2 s after stopping: dropped");
                Ok(())
            }
        }
    });
    (status_rx, handle)
}
