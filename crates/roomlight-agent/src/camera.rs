//! The camera agent (DESIGN §6): serves `Room.Attach`, admits node agents that present the right
//! room, token and protocol version, sends each its attenuation and `s` on its support, and runs
//! rounds: wait until every live projector has shown the last frame (or a deadline passes: late
//! ones are logged and left out of the round), capture, send each node the errors on its support,
//! collect contributions, and run model rounds between captures.

use crate::hardware::Camera;
use prost::Message;
use roomlight_core::aggregator::{ErrorAggregator, ErrorKind, RoundSummary};
use roomlight_core::closed_loop::objective_noise;
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
}

#[derive(Debug, Default)]
struct Registry {
    peers: HashMap<String, Peer>,
    next_connection: u64,
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
}

struct Shared {
    config: CameraConfig,
    owners: HashMap<String, Vec<u32>>,
    start: Option<Vec<LinearRgb>>,
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

    /// Each of `nodes`' attenuation, `s` on its support and start, as messages.
    fn attenuation_messages(&self, nodes: &[u32]) -> Vec<Result<v1::RoomMessage, Status>> {
        let live = self.live();
        nodes
            .iter()
            .filter_map(|&n| {
                let column = live.problem.columns().get(n as usize)?;
                let s = live
                    .problem
                    .white_response_on_support(&live.white, n as usize);
                Some(room_message(v1::room_message::Body::Attenuation(
                    v1::Attenuation {
                        node: n,
                        p: Some(to_sparse(column.support(), column.values())),
                        s: Some(to_sparse(column.support(), &s)),
                        start: self
                            .start
                            .as_ref()
                            .and_then(|v| v.get(n as usize))
                            .filter(|x| x.is_finite())
                            .map(|x| to_rgb(x.clamp_unit())),
                    },
                )))
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
        let Some(nodes) = shared.owners.get(&hello.projector_id).cloned() else {
            return Err(Status::not_found(format!(
                "projector {:?} is not calibrated in room {:?}",
                hello.projector_id, shared.config.room
            )));
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
            room_message(v1::room_message::Body::Assign(v1::Assign {
                nodes: nodes
                    .iter()
                    .map(|&n| v1::NodeAssignment { node: n, chart: n })
                    .collect(),
            })),
        ];
        if calibrated {
            hello_msgs.extend(shared.attenuation_messages(&nodes));
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
                },
            );
            connection
        };
        tracing::info!(%projector, nodes = nodes.len(), "joined");
        shared.changed.notify_waiters();
        tokio::spawn(read_node(shared, projector, connection, nodes, inbound));
        Ok(Response::new(Box::pin(ReceiverStream::new(rx))))
    }
}

/// Reads one node agent's stream until it ends, errs, or misses three heartbeats.
async fn read_node(
    shared: Arc<Shared>,
    projector: String,
    connection: u64,
    nodes: Vec<u32>,
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
                if !nodes.contains(&c.node) {
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
async fn capture_fresh(
    shared: &Shared,
    camera: &mut impl Camera,
    captures: &mut u64,
) -> Option<Vec<LinearRgb>> {
    let mut last = None;
    for _ in 0..=shared.config.stale_frames {
        match camera.capture().await {
            Ok(y) => {
                *captures += 1;
                last = Some(y);
            }
            Err(e) => {
                tracing::warn!(error = %e, "capture failed");
                return None;
            }
        }
    }
    let y = last?;
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

/// Shows `lit` at white and the projector's other nodes at black (all black for `None`), waits
/// for the projector to acknowledge the pattern, and captures.
async fn show_and_capture(
    shared: &Shared,
    camera: &mut impl Camera,
    projector: &str,
    (tx, nodes): (&mpsc::Sender<Result<v1::RoomMessage, Status>>, &[u32]),
    lit: Option<u32>,
    captures: &mut u64,
) -> Option<Vec<LinearRgb>> {
    let seq = shared.pattern_seq.fetch_add(1, Ordering::Relaxed) + 1;
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
    let show = v1::Show {
        seq,
        pattern: Some(v1::show::Pattern::Nodes(v1::NodeValues { values })),
    };
    shared
        .bytes_out
        .fetch_add(show.encoded_len() as u64, Ordering::Relaxed);
    tx.send(room_message(v1::room_message::Body::Show(show)))
        .await
        .ok()?;
    let shown = wait_for(shared, shared.config.deadline, |r| {
        r.peers
            .get(projector)
            .is_some_and(|p| p.pattern_shown.is_some_and(|s| s >= seq))
    })
    .await;
    if !shown {
        tracing::warn!(%projector, seq, "pattern not shown within the deadline");
        return None;
    }
    capture_fresh(shared, camera, captures).await
}

/// Measures a hot projector's attenuation (DESIGN §4): its nodes all at black, then each alone
/// at white, one capture each, while every other projector keeps its values (no errors are
/// sent meanwhile). `p = max(y_white − y_black, 0)`, entries at or below 3√2 σ (the noise of a
/// difference of two captures) dropped. Then the projector gets its attenuation and every
/// attached projector its `s` anew (the new light changes it). False when the projector left,
/// did not show a pattern in time, or the camera failed: it stays uncalibrated and is tried
/// again.
async fn calibrate_hot(
    shared: &Shared,
    camera: &mut impl Camera,
    projector: &str,
    captures: &mut u64,
) -> bool {
    let Some((tx, nodes)) = shared
        .registry()
        .peers
        .get(projector)
        .map(|p| (p.tx.clone(), p.nodes.clone()))
    else {
        return false;
    };
    tracing::info!(%projector, nodes = nodes.len(), "hot calibration");
    let Some(black) =
        show_and_capture(shared, camera, projector, (&tx, &nodes), None, captures).await
    else {
        return false;
    };
    let threshold: Vec<LinearRgb> = shared
        .live()
        .problem
        .noise()
        .iter()
        .map(|s| *s * (3.0 * std::f64::consts::SQRT_2))
        .collect();
    let mut measured = Vec::with_capacity(nodes.len());
    for &n in &nodes {
        let Some(white) =
            show_and_capture(shared, camera, projector, (&tx, &nodes), Some(n), captures).await
        else {
            return false;
        };
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
        let problem = match Problem::new(
            columns,
            live.problem.black().to_vec(),
            live.problem.target().to_vec(),
            live.problem.noise().to_vec(),
        ) {
            Ok(p) => p,
            Err(e) => {
                tracing::error!(%projector, error = %e, "hot calibration refused");
                return false;
            }
        };
        live.white = problem.white_response();
        live.problem = problem;
        live.uncalibrated.remove(projector);
    }
    // Its attenuation to the new projector, `s` anew to everyone; then it joins the rounds.
    let outbox: Vec<_> = shared
        .registry()
        .peers
        .values()
        .map(|p| (p.tx.clone(), p.nodes.clone()))
        .collect();
    for (tx, nodes) in outbox {
        for m in shared.attenuation_messages(&nodes) {
            if let Ok(msg) = &m {
                shared
                    .bytes_out
                    .fetch_add(msg.encoded_len() as u64, Ordering::Relaxed);
            }
            if tx.send(m).await.is_err() {
                break;
            }
        }
    }
    if let Some(peer) = shared.registry().peers.get_mut(projector) {
        peer.calibrated = true;
    }
    tracing::info!(%projector, "hot calibration done");
    shared.changed.notify_waiters();
    true
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
    let shared = Arc::new(Shared {
        config,
        owners: model.owners,
        start: model.start,
        live: std::sync::RwLock::new(Live {
            problem,
            white,
            uncalibrated: model.hot,
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
                let hot = shared
                    .registry()
                    .peers
                    .iter()
                    .find(|(_, p)| !p.calibrated)
                    .map(|(id, _)| id.clone());
                if let Some(projector) = hot {
                    if calibrate_hot(&shared, &mut camera, &projector, &mut captures).await {
                        calibrated_hot += 1;
                    } else {
                        tokio::time::sleep(Duration::from_millis(200)).await;
                    }
                    continue;
                }
                wait_for(&shared, shared.config.deadline, all_shown).await;
                let Some(y) = capture_fresh(&shared, &mut camera, &mut captures).await else {
                    // The camera is unreachable: the lights stay as they are; try again.
                    tokio::time::sleep(Duration::from_millis(200)).await;
                    continue;
                };
                let errors: Vec<LinearRgb> = target.iter().zip(&y).map(|(r, y)| *r - *y).collect();
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
