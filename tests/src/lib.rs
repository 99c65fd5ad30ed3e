//! roomlight-tests: a sandbox for multi-agent tests in one process. A [`Sandbox`] is a room of
//! N projectors on `127.0.0.1:0`: a camera agent ([`camera::serve`]) over an in-process virtual
//! room ([`roomlight_agent::hardware`]) and one node agent per projector, each a future under its
//! own `CancellationToken`. Tests add, kill and restart node agents, restart the camera agent,
//! wait for a predicate on the room's status with a deadline, and compare the room's true
//! objective with the optimum. Dropping the sandbox cancels and joins everything.
//!
//! It knows the agents only through their public API (`serve`, `run`, the wire contract); it
//! must not reach into their internals, so a test here reads like the system does.

use roomlight_agent::AgentError;
use roomlight_agent::camera::{self, CameraConfig, RoomModel, RoomStatus, Survey};
use roomlight_agent::hardware::{Camera, VirtualCamera, VirtualRoom};
use roomlight_agent::node::{self, NodeConfig};
use roomlight_calib::image_io::LinearImage;
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_core::optimum::optimum;
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, Problem, StepRule};
use roomlight_proto::v1;
use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

mod link;
pub use link::{Link, LinkState};

/// The sandbox's room name.
pub const ROOM: &str = "lab";
/// The sandbox's room token.
pub const TOKEN: &str = "s3cret";

/// The synthetic room's seed (every test's room is the same room).
const SEED: u64 = 4;

/// How long an agent may take to stop once cancelled.
const STOP_WITHIN: Duration = Duration::from_secs(10);

/// What the sandbox's room is: its size, the camera agent's configuration and model, and the
/// node agents' rule. Defaults: 12 nodes owned by three projectors `p0`..`p2` of four nodes
/// each, heartbeats every 200 ms, a 2 s deadline, no model rounds.
#[derive(Debug, Clone)]
pub struct SandboxBuilder {
    nodes: usize,
    projectors: usize,
    config: CameraConfig,
    start: Option<Vec<LinearRgb>>,
    plant: PlantConfig,
    hot: Option<String>,
    survey: Option<Survey>,
    rule: StepRule,
    exposure: Duration,
    lights: Option<LightsHandle>,
}

/// The room's LEDs as the camera agent switches them (for the console's preset).
#[derive(Clone)]
struct LightsHandle(Arc<dyn camera::Lights>);

impl std::fmt::Debug for LightsHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("Lights").field(&self.0.presets()).finish()
    }
}

impl Default for SandboxBuilder {
    fn default() -> Self {
        Self {
            nodes: 12,
            projectors: 3,
            config: CameraConfig {
                room: ROOM.into(),
                token: TOKEN.into(),
                heartbeat: Duration::from_millis(200),
                deadline: Duration::from_secs(2),
                model_rounds: 0,
                calibration_epoch: 1,
                stale_frames: 0,
                model_out: None,
                primaries: true,
                shading_passes: 0,
            },
            start: None,
            plant: PlantConfig::default(),
            hot: None,
            survey: None,
            rule: StepRule::Momentum { theta: 1.0 },
            exposure: Duration::ZERO,
            lights: None,
        }
    }
}

impl SandboxBuilder {
    /// `nodes` nodes shared evenly among `projectors` projectors `p0`, `p1`, …
    pub fn room(mut self, nodes: usize, projectors: usize) -> Self {
        assert!(
            projectors > 0 && nodes.is_multiple_of(projectors),
            "{nodes} nodes among {projectors}"
        );
        self.nodes = nodes;
        self.projectors = projectors;
        self
    }

    /// Model rounds after each measured round.
    pub fn model_rounds(mut self, rounds: usize) -> Self {
        self.config.model_rounds = rounds;
        self
    }

    /// The camera agent's heartbeat period and round deadline.
    pub fn timing(mut self, heartbeat: Duration, deadline: Duration) -> Self {
        self.config.heartbeat = heartbeat;
        self.config.deadline = deadline;
        self
    }

    /// The start the camera agent hands out, one value per node.
    pub fn start(mut self, start: Vec<LinearRgb>) -> Self {
        self.start = Some(start);
        self
    }

    /// The virtual room's plant (noise, seed).
    pub fn plant(mut self, plant: PlantConfig) -> Self {
        self.plant = plant;
        self
    }

    /// `projector` is unknown to the camera agent until it joins and is measured hot. Its
    /// columns in the camera agent's model are another projector's (wrong), so a camera agent
    /// that used them instead of measuring would fail.
    pub fn hot(mut self, projector: &str) -> Self {
        self.hot = Some(projector.into());
        self
    }

    /// Calibration over the wire with this survey.
    pub fn survey(mut self, survey: Survey) -> Self {
        self.survey = Some(survey);
        self
    }

    /// The node agents' update rule.
    pub fn rule(mut self, rule: StepRule) -> Self {
        self.rule = rule;
        self
    }

    /// Every capture takes `exposure` of the agents' clock, as a real camera's does. Tests under
    /// `tokio::time::pause` need it: a virtual room that captures in no time keeps the
    /// runtime busy, so the paused clock (and every timer: backoff, deadlines) stands still.
    pub fn exposure(mut self, exposure: Duration) -> Self {
        self.exposure = exposure;
        self
    }

    /// The camera agent can switch the room's LEDs through `lights` (the console's preset).
    pub fn lights(mut self, lights: Arc<dyn camera::Lights>) -> Self {
        self.lights = Some(LightsHandle(lights));
        self
    }

    /// Starts the camera agent over the virtual room's camera; no node agent yet.
    pub async fn start_camera(self) -> Sandbox {
        self.start_with_camera(|camera, _, _| camera).await
    }

    /// Starts the camera agent over the camera `wrap` makes of the virtual room's (given the
    /// room and the camera agent's cancellation token, for cameras that watch or stop it).
    pub async fn start_with_camera<C: Camera>(
        self,
        wrap: impl FnOnce(VirtualCamera, VirtualRoom, CancellationToken) -> C,
    ) -> Sandbox {
        let per = self.nodes / self.projectors;
        let problem = synthetic_room(&SyntheticConfig::new(self.nodes, SEED))
            .expect("synthetic room")
            .problem;
        let owners: HashMap<String, Vec<u32>> = (0..self.projectors as u32)
            .map(|p| {
                (
                    format!("p{p}"),
                    (per as u32 * p..per as u32 * (p + 1)).collect(),
                )
            })
            .collect();
        let room = VirtualRoom::new(Plant::new(problem.clone(), self.plant).expect("plant"));
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind 127.0.0.1:0");
        let address = listener.local_addr().expect("address");
        let root = CancellationToken::new();
        let model = RoomModel {
            problem: camera_model(&problem, &owners, self.hot.as_deref()),
            owners: owners.clone(),
            start: self.start,
            hot: self.hot.into_iter().collect(),
            survey: self.survey,
        };
        let cancel = root.child_token();
        let camera = Exposed {
            inner: wrap(room.camera(), room.clone(), cancel.clone()),
            exposure: self.exposure,
        };
        let extras = camera::Extras {
            lights: self.lights.map(|l| l.0),
            preset: None,
            photographs: None,
        };
        let served = camera::serve_room(
            self.config.clone(),
            model,
            camera,
            listener,
            None,
            extras,
            cancel.clone(),
        );
        let (status, task) = (served.status, served.handle);
        Sandbox {
            control: Some(served.control),
            room,
            problem,
            owners,
            endpoint: format!("http://{address}"),
            address,
            config: self.config,
            rule: self.rule,
            exposure: self.exposure,
            status,
            camera: Some(Agent { cancel, task }),
            nodes: HashMap::new(),
            state_files: HashMap::new(),
            root,
        }
    }
}

/// The model the camera agent is handed: the truth, except that a hot projector's columns are
/// another projector's.
fn camera_model(
    problem: &Problem,
    owners: &HashMap<String, Vec<u32>>,
    hot: Option<&str>,
) -> Problem {
    let Some(hot) = hot else {
        return problem.clone();
    };
    let mut others: Vec<&String> = owners.keys().filter(|p| p.as_str() != hot).collect();
    others.sort();
    let wrong = &owners[*others.first().expect("another projector")];
    let mut columns = problem.columns().to_vec();
    for (&n, &w) in owners[hot].iter().zip(wrong) {
        columns[n as usize] = problem.columns()[w as usize].clone();
    }
    Problem::new(
        columns,
        problem.black().to_vec(),
        problem.target().to_vec(),
        problem.noise().to_vec(),
    )
    .expect("the camera agent's model")
}

/// A camera whose captures take `exposure` of the agents' clock.
#[derive(Debug)]
struct Exposed<C> {
    inner: C,
    exposure: Duration,
}

impl<C: Camera> Camera for Exposed<C> {
    async fn capture(&mut self) -> Result<Vec<LinearRgb>, AgentError> {
        if !self.exposure.is_zero() {
            tokio::time::sleep(self.exposure).await;
        }
        self.inner.capture().await
    }

    async fn capture_image(&mut self) -> Result<LinearImage, AgentError> {
        if !self.exposure.is_zero() {
            tokio::time::sleep(self.exposure).await;
        }
        self.inner.capture_image().await
    }
}

/// One running agent: its token and its task.
#[derive(Debug)]
struct Agent {
    cancel: CancellationToken,
    task: JoinHandle<Result<(), AgentError>>,
}

impl Agent {
    /// Cancels the agent and waits for it; panics when it takes longer than [`STOP_WITHIN`].
    async fn stop(self) -> Result<(), AgentError> {
        self.cancel.cancel();
        tokio::time::timeout(STOP_WITHIN, self.task)
            .await
            .expect("the agent stops in time")
            .expect("the agent's task did not panic")
    }
}

/// A room of agents in one process; see the crate's doc.
#[derive(Debug)]
pub struct Sandbox {
    /// The virtual room the camera agent captures and the node agents show on.
    pub room: VirtualRoom,
    /// The room's true model.
    pub problem: Problem,
    /// Projector id → its node ids.
    pub owners: HashMap<String, Vec<u32>>,
    endpoint: String,
    address: SocketAddr,
    config: CameraConfig,
    rule: StepRule,
    exposure: Duration,
    status: watch::Receiver<RoomStatus>,
    /// The console's handle on the first camera agent started.
    control: Option<camera::Control>,
    camera: Option<Agent>,
    nodes: HashMap<String, Agent>,
    /// Projector → its state file, kept across kills so that a restart finds it.
    state_files: HashMap<String, PathBuf>,
    root: CancellationToken,
}

impl Sandbox {
    /// A room with the default size and timing; see [`SandboxBuilder`].
    pub fn builder() -> SandboxBuilder {
        SandboxBuilder::default()
    }

    /// The camera agent's address, `http://127.0.0.1:port`.
    pub fn endpoint(&self) -> &str {
        &self.endpoint
    }

    /// The projectors' ids, sorted.
    pub fn projectors(&self) -> Vec<String> {
        let mut ids: Vec<String> = self.owners.keys().cloned().collect();
        ids.sort();
        ids
    }

    /// The console's handle on the camera agent the builder started.
    pub fn control(&self) -> camera::Control {
        self.control.clone().expect("the builder's camera agent")
    }

    /// The camera agent's status, to follow.
    pub fn status_watch(&self) -> watch::Receiver<RoomStatus> {
        self.status.clone()
    }

    /// The room's status now.
    pub fn status(&self) -> RoomStatus {
        self.status.borrow().clone()
    }

    /// The configuration `add_node` gives `projector`'s node agent: the sandbox's room and
    /// token, its rule, and the state file it was given before, if any.
    pub fn node_config(&self, projector: &str) -> NodeConfig {
        NodeConfig {
            endpoint: self.endpoint.clone(),
            room: ROOM.into(),
            token: TOKEN.into(),
            projector_id: projector.into(),
            kind: v1::ProjectorKind::Standard,
            rule: self.rule,
            start: LinearRgb::splat(0.5),
            state_file: self.state_files.get(projector).cloned(),
        }
    }

    /// Starts a node agent for `projector` that reaches the camera agent through a link of
    /// its own, which the test cuts and restores (a network partition); the link must outlive
    /// the node agent's use of it.
    pub async fn add_node_behind_link(&mut self, projector: &str) -> Link {
        let link = self.link().await;
        self.add_node_via(projector, &link);
        link
    }

    /// A new link to the camera agent (up), for [`Sandbox::add_node_via`].
    pub async fn link(&self) -> Link {
        Link::new(self.address).await
    }

    /// Starts a node agent for `projector` that reaches the camera agent through `link`.
    pub fn add_node_via(&mut self, projector: &str, link: &Link) {
        self.add_node_with(NodeConfig {
            endpoint: link.endpoint(),
            ..self.node_config(projector)
        });
    }

    /// Starts a node agent for `projector` (with the state file it was given before, if any).
    pub fn add_node(&mut self, projector: &str) {
        self.add_node_with(self.node_config(projector));
    }

    /// Starts a node agent with `config` (e.g. [`Sandbox::node_config`] with another token),
    /// known to the sandbox by its projector id.
    pub fn add_node_with(&mut self, config: NodeConfig) {
        let projector = config.projector_id.clone();
        assert!(
            !self.nodes.contains_key(&projector),
            "{projector} already runs"
        );
        let cancel = self.root.child_token();
        let task = tokio::spawn(node::run(config, self.room.display(), cancel.clone()));
        self.nodes.insert(projector, Agent { cancel, task });
    }

    /// Starts a node agent for `projector` that keeps its values in `state_file` (and will
    /// again when restarted).
    pub fn add_node_with_state(&mut self, projector: &str, state_file: PathBuf) {
        self.state_files.insert(projector.into(), state_file);
        self.add_node(projector);
    }

    /// Starts node agents for every projector.
    pub fn add_all_nodes(&mut self) {
        for p in self.projectors() {
            self.add_node(&p);
        }
    }

    /// Stops `projector`'s node agent (it says goodbye) and returns how it ended; its projector
    /// keeps showing what it showed.
    pub async fn kill_node(&mut self, projector: &str) -> Result<(), AgentError> {
        let agent = self.nodes.remove(projector).expect("a running node agent");
        agent.stop().await
    }

    /// Stops `projector`'s node agent and unplugs its projector: its light is gone.
    pub async fn remove_node(&mut self, projector: &str) {
        self.kill_node(projector).await.expect("a clean stop");
        self.room.unplug(&self.owners[projector]);
    }

    /// Stops `projector`'s node agent cleanly and starts a new one.
    pub async fn restart_node(&mut self, projector: &str) {
        self.kill_node(projector).await.expect("a clean stop");
        self.add_node(projector);
    }

    /// True while `projector`'s node agent runs.
    pub fn node_running(&self, projector: &str) -> bool {
        self.nodes
            .get(projector)
            .is_some_and(|a| !a.task.is_finished())
    }

    /// Waits for `projector`'s node agent to end by itself (within `within`) and returns how.
    pub async fn node_ended(
        &mut self,
        projector: &str,
        within: Duration,
    ) -> Result<(), AgentError> {
        let agent = self.nodes.remove(projector).expect("a node agent");
        tokio::time::timeout(within, agent.task)
            .await
            .expect("the node agent ends in time")
            .expect("the node agent did not panic")
    }

    /// Waits (at most `within`) for the camera agent to stop by itself, and returns how.
    pub async fn camera_ended(&mut self, within: Duration) -> Result<(), AgentError> {
        let agent = self.camera.take().expect("a camera agent");
        tokio::time::timeout(within, agent.task)
            .await
            .expect("the camera agent stops in time")
            .expect("the camera agent did not panic")
    }

    /// Stops the camera agent and waits until it is gone; it must stop cleanly.
    pub async fn stop_camera(&mut self) {
        let agent = self.camera.take().expect("a camera agent");
        agent.stop().await.expect("the camera agent stops cleanly");
    }

    /// Starts a new camera agent on the same address, with the true model and no hot
    /// projector (as a restarted installation's camera agent would be).
    pub async fn start_camera(&mut self) {
        assert!(self.camera.is_none(), "stop the camera agent first");
        let listener = tokio::net::TcpListener::bind(self.address)
            .await
            .expect("rebind the same address");
        let model = RoomModel {
            problem: self.problem.clone(),
            owners: self.owners.clone(),
            start: None,
            hot: HashSet::new(),
            survey: None,
        };
        let cancel = self.root.child_token();
        let camera = Exposed {
            inner: self.room.camera(),
            exposure: self.exposure,
        };
        let (status, task) =
            camera::serve(self.config.clone(), model, camera, listener, cancel.clone());
        self.status = status;
        self.camera = Some(Agent { cancel, task });
    }

    /// Stops the camera agent and starts a new one on the same address.
    pub async fn restart_camera(&mut self) {
        self.stop_camera().await;
        self.start_camera().await;
    }

    /// Waits (at most `within`) until the status satisfies `pred`, and returns that status;
    /// panics with the last status otherwise.
    pub async fn wait_for(
        &mut self,
        within: Duration,
        pred: impl Fn(&RoomStatus) -> bool,
    ) -> RoomStatus {
        let reached = tokio::time::timeout(within, async {
            loop {
                if pred(&self.status.borrow_and_update()) {
                    return Some(self.status.borrow().clone());
                }
                if self.status.changed().await.is_err() {
                    return pred(&self.status.borrow()).then(|| self.status.borrow().clone());
                }
            }
        })
        .await;
        match reached {
            Ok(Some(status)) => status,
            Ok(None) => panic!(
                "the camera agent stopped before the condition; last status {:?}",
                self.status.borrow()
            ),
            Err(_) => panic!(
                "condition not reached within {within:?}; last status {:?}",
                self.status.borrow()
            ),
        }
    }

    /// Waits (at most `within`) for `more` captures after the current one.
    pub async fn wait_captures(&mut self, within: Duration, more: u64) -> RoomStatus {
        let from = self.status().captures;
        self.wait_for(within, |s| s.captures >= from + more).await
    }

    /// The node indices of `projector`.
    pub fn nodes_of(&self, projector: &str) -> Vec<usize> {
        self.owners[projector].iter().map(|&n| n as usize).collect()
    }

    /// The room's true model without `projector`'s nodes (it left, or never lit).
    pub fn without(&self, projector: &str) -> Problem {
        self.problem.without_nodes(&self.nodes_of(projector))
    }

    /// How far the room's true objective is above the optimum of `truth`.
    pub fn excess(&self, truth: &Problem) -> f64 {
        optimum(truth)
            .expect("optimum")
            .excess(self.room.true_objective())
    }

    /// How far a measured objective is above the optimum of the whole room.
    pub fn measured_excess(&self, measured_objective: f64) -> f64 {
        optimum(&self.problem)
            .expect("optimum")
            .excess(measured_objective)
    }

    /// What `projector`'s nodes show now.
    pub fn shown_by(&self, projector: &str) -> Vec<LinearRgb> {
        let shown = self.room.shown();
        self.owners[projector]
            .iter()
            .map(|&n| shown[n as usize])
            .collect()
    }

    /// Cancels every agent and joins them; each must stop in time without panicking, and the
    /// camera agent and every node agent cleanly.
    pub async fn shutdown(mut self) {
        for result in self.stop_all().await {
            result.expect("a clean stop");
        }
    }

    async fn stop_all(&mut self) -> Vec<Result<(), AgentError>> {
        self.root.cancel();
        let mut agents: Vec<Agent> = self.nodes.drain().map(|(_, a)| a).collect();
        agents.extend(self.camera.take());
        let mut results = Vec::new();
        for agent in agents {
            results.push(agent.stop().await);
        }
        results
    }
}

impl Drop for Sandbox {
    /// Cancels every agent. On a multi-threaded runtime it also joins them (so no agent of
    /// this test outlives it); on a current-thread runtime (paused time) it cannot block, and
    /// the runtime's shutdown at the end of the test drops what is left.
    fn drop(&mut self) {
        self.root.cancel();
        let Ok(runtime) = tokio::runtime::Handle::try_current() else {
            return;
        };
        let joinable = matches!(
            runtime.runtime_flavor(),
            tokio::runtime::RuntimeFlavor::MultiThread
        );
        if joinable
            && !std::thread::panicking()
            && (self.camera.is_some() || !self.nodes.is_empty())
        {
            tokio::task::block_in_place(|| {
                runtime.block_on(async {
                    let _ = self.stop_all().await;
                });
            });
        }
    }
}

/// A stream attached by hand, for tests that play a node agent message by message.
#[derive(Debug)]
pub struct ManualNode {
    /// Messages to the camera agent.
    pub tx: mpsc::Sender<v1::NodeMessage>,
    /// The camera agent's messages.
    pub inbound: tonic::Streaming<v1::RoomMessage>,
}

/// A Hello of `projector` with the sandbox's room, token and protocol version.
pub fn hello(projector: &str) -> v1::NodeMessage {
    v1::NodeMessage {
        body: Some(v1::node_message::Body::Hello(v1::Hello {
            protocol_version: roomlight_proto::PROTOCOL_VERSION,
            room: ROOM.into(),
            token: TOKEN.into(),
            projector_id: projector.into(),
            ..Default::default()
        })),
    }
}

impl Sandbox {
    /// Attaches `projector` by hand: Hello, then (with `shown`) the acknowledgement of its
    /// start; further messages are the test's.
    pub async fn attach_by_hand(&self, projector: &str, shown: bool) -> ManualNode {
        let (tx, rx) = mpsc::channel(64);
        tx.send(hello(projector)).await.expect("queue Hello");
        if shown {
            let ack = v1::NodeMessage {
                body: Some(v1::node_message::Body::Shown(v1::Shown {
                    seq: 0,
                    pattern: false,
                })),
            };
            tx.send(ack).await.expect("queue Shown");
        }
        let inbound = self
            .attach(tokio_stream::wrappers::ReceiverStream::new(rx))
            .await
            .expect("admitted");
        ManualNode { tx, inbound }
    }

    /// Sends `hello` alone (the stream then ends) and returns the camera agent's answer, within
    /// ten seconds.
    pub async fn attach_once(
        &self,
        hello: v1::NodeMessage,
    ) -> Result<tonic::Streaming<v1::RoomMessage>, tonic::Status> {
        tokio::time::timeout(
            Duration::from_secs(10),
            self.attach(tokio_stream::iter(vec![hello])),
        )
        .await
        .expect("an answer in time")
    }

    async fn attach(
        &self,
        messages: impl tokio_stream::Stream<Item = v1::NodeMessage> + Send + 'static,
    ) -> Result<tonic::Streaming<v1::RoomMessage>, tonic::Status> {
        let mut client = v1::room_client::RoomClient::connect(self.endpoint.clone())
            .await
            .expect("connect");
        client
            .attach(messages)
            .await
            .map(tonic::Response::into_inner)
    }
}
