//! The camera agent (DESIGN §6): serves `Room.Attach`, admits node agents that present the right
//! room, token and protocol version, sends each its attenuation and `s` on its support, and runs
//! rounds: wait until every live projector has shown the last frame (or a deadline passes: late
//! ones are logged and left out of the round), capture, send each node the errors on its support,
//! collect contributions, and run model rounds between captures.
//!
//! This module owns the public face ([`serve`] and the types it takes and reports) and the state
//! the parts share; it knows nothing of the wire messages' contents. The parts:
//! - `listener`: the connection limit and the handshake timeout in front of the service;
//! - `service`: the gRPC `Room.Attach` handshake, admission, and each peer's reader task;
//! - `registry`: the live peers (admission, readiness, removal by a guard's `Drop`);
//! - `rounds`: the round loop;
//! - `capture`: captures the nodes can act on (stale frames discarded, charts sampled, hung
//!   captures abandoned) and the camera's health;
//! - `faults`: the camera's typed state and the backoff after a failed capture;
//! - `calibration`: the calibration procedure driven over the wire (bring-up, joins, hot);
//! - `rig`: the procedure's rig over the peers (Show and Assign messages, the camera);
//! - `model`: the live model (attenuation, `s`, starts, patches left out) and its file;
//! - `shading`: per-pixel shading passes once the rounds settle (what they need, the pass);
//! - `survey`: the installer's survey, and how a photograph becomes the model's patches (the
//!   charts', and a dark target's, weighed);
//! - `operator`: what the installer's console sees and asks (pause, calibrate, preset,
//!   identify, photograph), carried out by the round loop between rounds.

mod calibration;
mod capture;
mod faults;
mod listener;
mod model;
mod operator;
mod registry;
mod rig;
mod rounds;
mod service;
mod shading;
mod survey;

use crate::hardware::Camera;
pub use faults::{CameraState, RETRY_FIRST, RETRY_MAX};
use model::Live;
pub use operator::{
    CalibrationProgress, CalibrationResult, Control, Frame, Lights, Overview, Photo,
    ProjectorState, ProjectorStatus, Refused,
};
use prost::Message;
use registry::{Outbox, Registry};
use roomlight_calib::image_io::LinearImage;
use roomlight_core::{LinearRgb, Problem};
use roomlight_proto::refusal::Refusal;
use roomlight_proto::v1;
use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError, RwLock, RwLockReadGuard, RwLockWriteGuard};
use std::time::Duration;
pub use survey::{DEFAULT_DARK_WEIGHT, MAX_DARK_WEIGHT, Survey};
use tokio::sync::{mpsc, watch};
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

/// Model rounds per capture by default, the same for the deployed camera agent, the lab's
/// pipeline and the bench's rule `model-100`: momentum needs about this many rounds between two
/// captures to reach the model's optimum from where a capture left it (on the quick hard cases
/// 20 rounds left the reflective room, the node without a chart and a stale capture at 4–6
/// captures to 1%, 100 took them to 1–2, 400 changed one case by one capture: docs/results.md).
/// A model round is messages and arithmetic, well under a millisecond on a LAN (0.3–0.6 ms per
/// round measured on loopback), so 100 of them cost tens of milliseconds against a capture.
pub const DEFAULT_MODEL_ROUNDS: usize = 100;

/// How the camera agent runs. Its `Debug` leaves the token out (`roomlight camera --check`
/// prints it).
#[derive(Clone)]
pub struct CameraConfig {
    /// The room's name; node agents must name it.
    pub room: String,
    /// The pre-shared room token.
    pub token: String,
    /// How often nodes send heartbeats; three missed ones and the node has left.
    pub heartbeat: Duration,
    /// How long a round waits for acknowledgements and contributions.
    pub deadline: Duration,
    /// Model rounds after each measured round ([`DEFAULT_MODEL_ROUNDS`] unless configured).
    pub model_rounds: usize,
    /// Calibration epoch (a node's persisted state is accepted only for the same epoch).
    pub calibration_epoch: u64,
    /// Frames the camera hands over late (its latency, measured once at installation): before
    /// each measured round the camera agent discards this many captures, so that the nodes
    /// never act on errors of values they no longer show. Every capture is counted. Left at 0,
    /// late frames are still caught, up to `round::STALE_CAPTURES` in a row, by what they show
    /// (`Controller::stale`: the room before the nodes' last step), at the cost of judging
    /// each; the agent logs the most it refused in a row, which is the value to set here.
    pub stale_frames: usize,
    /// Where to write the model (`problem`, `owners`, `start`, as JSON, atomically) after each
    /// projector calibrated over the wire or hot, and after patches left the model; `None`:
    /// nowhere.
    pub model_out: Option<std::path::PathBuf>,
    /// Calibration over the wire codes up to three groups of projectors at once, each in its
    /// own primary ([`roomlight_calib::procedure::Settings::primaries`], the default); `false`:
    /// one group at a time in white, for projectors that do not show their primaries at once
    /// (a single-chip DLP's colour wheel photographed faster than it turns).
    pub primaries: bool,
    /// Per-pixel shading passes per target once the rounds have settled (`shading`); 0: none.
    /// Each takes one capture, and the rounds settle again after it.
    pub shading_passes: usize,
}

impl std::fmt::Debug for CameraConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CameraConfig")
            .field("room", &self.room)
            .field("token", &"<secret>")
            .field("heartbeat", &self.heartbeat)
            .field("deadline", &self.deadline)
            .field("model_rounds", &self.model_rounds)
            .field("calibration_epoch", &self.calibration_epoch)
            .field("stale_frames", &self.stale_frames)
            .field("shading_passes", &self.shading_passes)
            .field("model_out", &self.model_out)
            .field("primaries", &self.primaries)
            .finish()
    }
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

/// What the round loop has done so far (for tests, logs and the demo).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RoomStatus {
    /// Rounds run (measured and model).
    pub round: u64,
    /// Captures taken.
    pub captures: u64,
    /// `G` of the last measured round.
    pub measured_objective: f64,
    /// How many captures the errors of `measured_objective` average (the round controller's
    /// [`roomlight_core::round::Controller::averaged`]): its camera noise is at most about
    /// `½ Σ σ²/k`.
    pub averaged: usize,
    /// The most captures in a row refused as late (they showed the room before the nodes'
    /// last step, [`roomlight_core::round::Controller::stale`]); 0 when none was: the camera's
    /// latency in frames, which the configuration's `stale_frames` can name instead.
    pub late_frames: usize,
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
    /// Captures taken when the last calibration (hot or over the wire) ended, its own included;
    /// 0 before any: the rounds after it are those of the room with its new projectors.
    pub calibrated_at: u64,
    /// Whether the camera works; while it fails, rounds are abandoned and the projectors keep
    /// their light.
    pub camera: CameraState,
    /// Attached projectors whose node agent says its display is lost (they stay attached).
    pub displays_lost: Vec<DisplayLost>,
    /// Per-pixel shading passes sent for the current target (`CameraConfig::shading_passes`).
    pub shading_passes: usize,
}

/// A projector whose display is lost, as its node agent reported it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DisplayLost {
    pub projector: String,
    /// The display's output (e.g. `HDMI-1`).
    pub output: String,
    /// Why, in the display's words.
    pub reason: String,
}

/// A node agent's contributions for a round, as its reader passed them on: each node it owns
/// and its finite change of value `Δx_n` (checked at the boundary by `roomlight_proto::convert`;
/// the round loop forms `p_n Δx_n` from the model's column).
#[derive(Debug)]
struct Contribution {
    round: u64,
    nodes: Vec<(u32, LinearRgb)>,
}

/// What the service, the readers and the round loop share.
struct Shared {
    config: CameraConfig,
    survey: Option<Survey>,
    /// What hot calibration and calibration over the wire change.
    live: RwLock<Live>,
    /// Sequence numbers of Show patterns.
    pattern_seq: AtomicU64,
    registry: Arc<Registry>,
    contributions: mpsc::Sender<Contribution>,
    bytes_out: AtomicU64,
    bytes_in: AtomicU64,
    /// Cancelled once the camera agent has stopped its rounds: ends every node's reader and
    /// the server (the caller's token only asks the rounds to stop after the current one).
    cancel: CancellationToken,
    /// The peers' reader tasks, joined on shutdown.
    tracker: TaskTracker,
    /// Peers dropped for lagging, logged at a limited rate.
    lagging: crate::throttle::Shared,
    /// Hellos refused, logged at a limited rate (a flood must not fill the disk).
    refusals: crate::throttle::Shared,
    /// Admitted peers dropped for sending what the protocol forbids, logged at a limited rate.
    misbehaving: crate::throttle::Shared,
    /// The largest message a node agent may send, derived from the room's size.
    max_message: usize,
    /// The room's status, as the round loop and the readers update it: once per round (and
    /// on the camera's and displays' changes).
    status: watch::Sender<RoomStatus>,
    /// What only the console follows (projector states, calibration, pause, preset): apart,
    /// so that a change of it is no round to those who follow the rounds.
    overview: watch::Sender<Overview>,
    /// How the room's LEDs are switched, to measure another preset's light.
    lights: Option<Arc<dyn Lights>>,
    /// Each node's value as the camera agent follows it (its start or remembered state, plus
    /// its contributions), for the console's frame thumbnails.
    values: Mutex<HashMap<u32, LinearRgb>>,
    /// The projectors left out of the last round.
    late: Mutex<Vec<String>>,
    /// The latest whole photograph, published only while someone watches.
    photos: watch::Sender<Option<Photo>>,
    photo_seq: AtomicU64,
    /// What per-pixel shading passes need, and how many were done.
    shading: Mutex<shading::Inputs>,
}

impl Shared {
    fn live(&self) -> RwLockReadGuard<'_, Live> {
        self.live.read().unwrap_or_else(PoisonError::into_inner)
    }

    fn live_mut(&self) -> RwLockWriteGuard<'_, Live> {
        self.live.write().unwrap_or_else(PoisonError::into_inner)
    }

    fn shading(&self) -> MutexGuard<'_, shading::Inputs> {
        self.shading.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn values(&self) -> MutexGuard<'_, HashMap<u32, LinearRgb>> {
        self.values.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Publishes a whole photograph for the console, if one watches (shared, not copied).
    fn publish_photo(&self, image: Arc<LinearImage>) -> u64 {
        let seq = self.photo_seq.fetch_add(1, Ordering::Relaxed) + 1;
        if self.photos.receiver_count() > 0 {
            self.photos.send_replace(Some(Photo { seq, image }));
        }
        seq
    }

    /// Publishes the attached projectors' states (on every change of the registry, a
    /// calibration's start and end, and each round's late ones).
    fn publish_projectors(&self) {
        let late = self
            .late
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        let calibrating = self
            .overview
            .borrow()
            .calibrating
            .as_ref()
            .map(|c| c.projectors.clone())
            .unwrap_or_default();
        let projectors = self.registry.lock().statuses(&calibrating, &late);
        self.overview.send_if_modified(|s| {
            let changed = s.projectors != projectors;
            s.projectors = projectors;
            changed
        });
    }

    /// Queues `bodies` to one peer without waiting, counting their bytes; false when the node
    /// has left or was dropped. A fan-out never waits for one slow node: a peer whose queue
    /// cannot take them (and keep one place for a goodbye) lags; it is told so, best effort, and
    /// dropped, and the others go on.
    fn offer(&self, projector: &str, tx: &Outbox, bodies: Vec<v1::room_message::Body>) -> bool {
        if tx.is_closed() {
            return false;
        }
        if tx.capacity() <= bodies.len() {
            // The refusal's wire name, which the node agent's log shows.
            let reason = Refusal::Lagging {
                queue: tx.max_capacity(),
            }
            .row()
            .key;
            let goodbye = v1::room_message::Body::Goodbye(v1::Goodbye {
                reason: reason.into(),
            });
            let _ = tx.try_send(Ok(v1::RoomMessage {
                body: Some(goodbye),
            }));
            if self.registry.drop_peer(projector, tx)
                && let Some(dropped) = self.lagging.hit()
            {
                tracing::warn!(%projector, dropped, "lagging: its queue is full; told and dropped (count since the last report)");
            }
            return false;
        }
        self.note_starts(&bodies);
        for body in bodies {
            let message = v1::RoomMessage { body: Some(body) };
            self.bytes_out
                .fetch_add(message.encoded_len() as u64, Ordering::Relaxed);
            // Only the round loop queues to an admitted peer: the place checked above is there.
            if tx.try_send(Ok(message)).is_err() {
                return false;
            }
        }
        true
    }

    /// A fresh node starts where it is told (a node that runs keeps its value): the console's
    /// view of its frame.
    fn note_starts(&self, bodies: &[v1::room_message::Body]) {
        let mut values = self.values();
        for body in bodies {
            if let v1::room_message::Body::Attenuation(a) = body
                && let Ok(start) = roomlight_proto::convert::from_rgb("start", a.start.as_ref())
            {
                values.entry(a.node).or_insert(start.clamp_unit());
            }
        }
    }

    /// Publishes the camera's state (at once: a failing camera runs no round to report it).
    fn publish_camera(&self, state: &CameraState) {
        self.status.send_if_modified(|s| {
            let changed = s.camera != *state;
            s.camera = state.clone();
            changed
        });
    }

    /// Publishes which displays are lost now (at once: the rounds go on without them).
    fn publish_displays(&self) {
        let lost = self.registry.lock().displays_lost();
        self.status.send_if_modified(|s| {
            let changed = s.displays_lost != lost;
            s.displays_lost = lost;
            changed
        });
    }

    /// Writes the model to `model_out`, if configured (a failure is logged: the rounds go on).
    fn save_model(&self) {
        if let Some(path) = &self.config.model_out
            && let Err(e) = self.live().write(self.survey.as_ref(), path)
        {
            tracing::warn!(path = %path.display(), error = %e, "could not write the model");
        }
    }
}

/// Serves the Room service on `listener` in plaintext and runs rounds until `cancel`. Returns
/// the status watch and the task's handle.
pub fn serve(
    config: CameraConfig,
    model: RoomModel,
    camera: impl Camera,
    listener: tokio::net::TcpListener,
    cancel: CancellationToken,
) -> (
    watch::Receiver<RoomStatus>,
    tokio::task::JoinHandle<Result<(), crate::AgentError>>,
) {
    serve_tls(config, model, camera, listener, None, cancel)
}

/// [`serve`], over TLS when `tls` is given (the listener accepts only TLS then).
pub fn serve_tls(
    config: CameraConfig,
    model: RoomModel,
    camera: impl Camera,
    listener: tokio::net::TcpListener,
    tls: Option<crate::tls::ServerTls>,
    cancel: CancellationToken,
) -> (
    watch::Receiver<RoomStatus>,
    tokio::task::JoinHandle<Result<(), crate::AgentError>>,
) {
    let served = serve_room(
        config,
        model,
        camera,
        listener,
        tls,
        Extras::default(),
        cancel,
    );
    (served.status, served.handle)
}

/// What a camera agent may be given beyond its config: how to switch the room's LEDs (for
/// the console's preset switch), which preset the model's target is, and the survey's
/// photographs of the room before any projector.
#[derive(Default)]
pub struct Extras {
    pub lights: Option<Arc<dyn Lights>>,
    pub preset: Option<String>,
    pub photographs: Option<SurveyPhotographs>,
}

/// The room as a survey photographed it before any projector joined, LEDs off (`dark`) and
/// under the preset's LEDs (`leds`): per-pixel shading starts from them, so the passes follow
/// the bring-up without a preset chosen again. Both the camera's size (else ignored, logged).
#[derive(Debug, Clone)]
pub struct SurveyPhotographs {
    pub dark: LinearImage,
    pub leds: LinearImage,
}

impl std::fmt::Debug for Extras {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Extras")
            .field("lights", &self.lights.as_ref().map(|l| l.presets()))
            .field("preset", &self.preset)
            .field("photographs", &self.photographs.is_some())
            .finish()
    }
}

/// A camera agent running: its status, the console's handle on it, and its task.
#[derive(Debug)]
pub struct Served {
    pub status: watch::Receiver<RoomStatus>,
    pub control: Control,
    pub handle: tokio::task::JoinHandle<Result<(), crate::AgentError>>,
}

/// [`serve_tls`] with [`Extras`], returning the console's [`Control`] too.
pub fn serve_room(
    config: CameraConfig,
    model: RoomModel,
    camera: impl Camera,
    listener: tokio::net::TcpListener,
    tls: Option<crate::tls::ServerTls>,
    extras: Extras,
    cancel: CancellationToken,
) -> Served {
    let (contributions, contrib_rx) = mpsc::channel(4096);
    let size = model.survey.as_ref().map(|s| (s.width, s.height));
    // Photographed by this survey, or kept by this agent before it was restarted.
    let shading = match (&extras.photographs, &config.model_out, size) {
        (None, Some(out), Some(size)) => shading::Inputs::resumed(
            out,
            size,
            |id| model.owners.contains_key(id),
            config.shading_passes,
        ),
        (photographs, _, _) => shading::Inputs::surveyed(photographs.as_ref(), size),
    };
    if let Some(weight) = model
        .survey
        .as_ref()
        .map(Survey::dark_weight)
        .filter(|&w| w > survey::SHADED_DARK_WEIGHT && config.shading_passes > 0)
    {
        tracing::warn!(
            dark_target_weight = weight,
            shading_passes = config.shading_passes,
            "per-pixel shading brightens what the rounds dim for the dark target: above a weight \
             of {} the two fight (docs/calibration.md); lower one of them",
            survey::SHADED_DARK_WEIGHT
        );
    }
    let live = Live::new(&model);
    let max_message = max_node_message(&model);
    let connections = connection_limit(&model);
    let (status, status_rx) = watch::channel(RoomStatus::default());
    let (overview, overview_rx) = watch::channel(Overview {
        preset: extras.preset,
        ..Overview::default()
    });
    let (photos, photos_rx) = watch::channel(None);
    // A console's requests wait here for the round loop; a few are plenty (each answers).
    let (requests, requests_rx) = mpsc::channel(16);
    let shared = Arc::new(Shared {
        config,
        survey: model.survey,
        live: RwLock::new(live),
        pattern_seq: AtomicU64::new(0),
        registry: Arc::new(Registry::default()),
        contributions,
        bytes_out: AtomicU64::new(0),
        bytes_in: AtomicU64::new(0),
        cancel: CancellationToken::new(),
        tracker: TaskTracker::new(),
        lagging: Default::default(),
        refusals: Default::default(),
        misbehaving: Default::default(),
        max_message,
        status,
        overview,
        lights: extras.lights,
        values: Mutex::new(HashMap::new()),
        late: Mutex::new(Vec::new()),
        photos,
        photo_seq: AtomicU64::new(0),
        shading: Mutex::new(shading),
    });
    let control = Control {
        shared: shared.clone(),
        requests,
        photos: photos_rx,
        overview: overview_rx,
    };
    let rounds = rounds::Rounds::new(shared.clone(), camera, contrib_rx, requests_rx);
    let handle = tokio::spawn(run(shared, rounds, (listener, connections, tls), cancel));
    Served {
        status: status_rx,
        control,
        handle,
    }
}

/// Deadlines a stop waits for the round in flight before it gives up on it: the capture, the
/// acknowledgements and the contributions of one round (model rounds stop at a stop request).
const STOP_ROUNDS: u32 = 3;

/// The server and the rounds together; on a stop request the current round finishes (bounded:
/// a round waits at most a deadline for the acknowledgements and one for the contributions, and
/// no further model round starts), then every node is told goodbye and the server drains.
///
/// Every connection counts against the limit (`listener`'s second part) and is closed unless a
/// node is admitted on it within the handshake timeout (as long as a Hello may take, the
/// deadline and at least a second), its TLS handshake (third part) included; a node agent's messages are bounded by the room's size;
/// a dead connection is found by HTTP/2 keepalive.
async fn run<C: Camera>(
    shared: Arc<Shared>,
    rounds: rounds::Rounds<C>,
    listener: (
        tokio::net::TcpListener,
        usize,
        Option<crate::tls::ServerTls>,
    ),
    cancel: CancellationToken,
) -> Result<(), crate::AgentError> {
    let (listener, limit, tls) = listener;
    let handshake = shared.config.deadline.max(Duration::from_secs(1));
    let incoming = listener::guarded(listener, limit, handshake, tls, shared.cancel.clone());
    let service = v1::room_server::RoomServer::new(service::Service::new(shared.clone()))
        .max_decoding_message_size(shared.max_message);
    let server = tonic::transport::Server::builder()
        .http2_keepalive_interval(Some(Duration::from_secs(5)))
        .http2_keepalive_timeout(Some(Duration::from_secs(10)))
        // A node agent opens one stream; a few more for a reconnect, none for a flood.
        .max_concurrent_streams(Some(8))
        .add_service(service)
        .serve_with_incoming_shutdown(incoming, shared.cancel.clone().cancelled_owned());
    // A stop request ends the model rounds at the next one (see `Rounds::run`): what is left
    // to wait for is one round, whatever `model_rounds` is — a deadline for the
    // acknowledgements, one for the contributions, one for the capture in flight.
    let grace = shared.config.deadline * STOP_ROUNDS;
    let stop_waiting = async {
        cancel.cancelled().await;
        tokio::time::sleep(grace).await;
    };
    tokio::pin!(server);
    let watcher = shared.clone();
    let projectors = async move {
        // At most five times a second: acknowledgements change the registry many times a
        // round, and listing the projectors is O(projectors).
        loop {
            let changed = watcher.registry.changed();
            watcher.publish_projectors();
            changed.await;
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    };
    tokio::select! {
        result = &mut server => return result.map_err(crate::AgentError::from),
        () = projectors => {}
        () = rounds.run(cancel.clone()) => {}
        () = stop_waiting => tracing::warn!(?grace, "the round did not finish in time: stopped"),
    }
    shared.cancel.cancel();
    // Stopping: say goodbye and end every node's stream, so the node agents reconnect to
    // whichever camera agent comes next instead of waiting on a stream nobody writes to.
    for tx in shared.registry.drain() {
        let _ = tx.try_send(Ok(v1::RoomMessage {
            body: Some(v1::room_message::Body::Goodbye(v1::Goodbye {
                reason: Refusal::ShuttingDown.to_string(),
            })),
        }));
    }
    // Every reader has been cancelled: join them.
    shared.tracker.close();
    if tokio::time::timeout(Duration::from_secs(2), shared.tracker.wait())
        .await
        .is_err()
    {
        tracing::warn!(
            readers = shared.tracker.len(),
            "readers still running 2 s after stopping"
        );
    }
    // The server's graceful shutdown now only waits for the streams to drain.
    match tokio::time::timeout(Duration::from_secs(2), server).await {
        Ok(result) => result.map_err(crate::AgentError::from),
        Err(_) => {
            tracing::warn!("connections still open 2 s after stopping: dropped");
            Ok(())
        }
    }
}

/// The largest message a node agent may send this room: its Hello carries the attenuation its
/// nodes remember, at most the room's columns (calibration over the wire: columns not yet
/// measured, so the room's patches for each of a generous 2 000 nodes).
fn max_node_message(model: &RoomModel) -> usize {
    let problem = &model.problem;
    let nonzeros: usize = problem.columns().iter().map(|c| c.support().len()).sum();
    let nodes = problem.columns().len();
    match &model.survey {
        Some(survey) => roomlight_proto::bounds::node_message_limit(
            nodes.max(2_000),
            nonzeros.max(survey.patches.len().saturating_mul(2_000)),
        ),
        None => roomlight_proto::bounds::node_message_limit(nodes, nonzeros),
    }
}

/// At most this many connections open at once: two per projector of the model (a reconnecting
/// node's new stream beside its old one) and some for calibration over the wire and tools.
pub fn connection_limit(model: &RoomModel) -> usize {
    let spare = if model.survey.is_some() { 256 } else { 32 };
    2 * model.owners.len() + spare
}

impl Shared {
    /// Sends every attached, calibrated projector its nodes' attenuation, `s` and start: a
    /// projector measured but not yet lit starts showing its start, a running one keeps its
    /// values with the new `s`.
    fn light_all(&self) {
        let outbox = self.registry.lock().calibrated();
        for (projector, tx, nodes) in outbox {
            let bodies = self.live().attenuation_bodies(&nodes);
            self.offer(&projector, &tx, bodies);
        }
    }
}
