//! The camera agent and node agents in one process over loopback gRPC, against a virtual room:
//! the distributed loop reaches the optimum; a projector that leaves is corrected for by the
//! others; a wrong token is refused. Every wait has a deadline.

use roomlight_agent::camera::{self, CameraConfig, RoomModel, RoomStatus};
use roomlight_agent::hardware::{Camera, VirtualCamera, VirtualRoom};
use roomlight_agent::node::{self, NodeConfig, SavedState};
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_core::optimum::optimum;
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, Problem, StepRule};
use std::collections::HashMap;
use std::time::Duration;
use tokio::sync::watch;
use tokio_util::sync::CancellationToken;

const TOKEN: &str = "s3cret";

struct Sandbox {
    room: VirtualRoom,
    problem: Problem,
    status: watch::Receiver<RoomStatus>,
    endpoint: String,
    address: std::net::SocketAddr,
    config: CameraConfig,
    camera: (
        CancellationToken,
        tokio::task::JoinHandle<Result<(), roomlight_agent::AgentError>>,
    ),
    cancel: CancellationToken,
    nodes: HashMap<
        String,
        (
            CancellationToken,
            tokio::task::JoinHandle<Result<(), roomlight_agent::AgentError>>,
        ),
    >,
    owners: HashMap<String, Vec<u32>>,
}

impl Sandbox {
    /// A 12-node synthetic room owned by three projectors of four nodes each.
    async fn start(model_rounds: usize) -> Self {
        Self::start_with(model_rounds, None, PlantConfig::default(), |c, _| c).await
    }

    /// The room with `hot` unknown to the camera agent until it joins and is measured.
    async fn start_hot(model_rounds: usize, hot: &str, plant: PlantConfig) -> Self {
        Self::start_full(model_rounds, None, plant, Some(hot), None, |c, _| c).await
    }

    /// The same room with a start handed out by the camera agent, a plant of one's own and the
    /// camera wrapped by `wrap`.
    async fn start_with<C: Camera + Send + 'static>(
        model_rounds: usize,
        start: Option<Vec<LinearRgb>>,
        plant: PlantConfig,
        wrap: impl FnOnce(VirtualCamera, VirtualRoom) -> C,
    ) -> Self {
        Self::start_full(model_rounds, start, plant, None, None, wrap).await
    }

    async fn start_full<C: Camera + Send + 'static>(
        model_rounds: usize,
        start: Option<Vec<LinearRgb>>,
        plant: PlantConfig,
        hot: Option<&str>,
        survey: Option<camera::Survey>,
        wrap: impl FnOnce(VirtualCamera, VirtualRoom) -> C,
    ) -> Self {
        let problem = synthetic_room(&SyntheticConfig::new(12, 4))
            .expect("room")
            .problem;
        let owners: HashMap<String, Vec<u32>> = (0..3)
            .map(|p| (format!("p{p}"), (4 * p..4 * p + 4).collect()))
            .collect();
        let room = VirtualRoom::new(Plant::new(problem.clone(), plant).expect("plant"));
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let address = listener.local_addr().expect("address");
        let endpoint = format!("http://{address}");
        let cancel = CancellationToken::new();
        let config = CameraConfig {
            room: "lab".into(),
            token: TOKEN.into(),
            heartbeat: Duration::from_millis(200),
            deadline: Duration::from_secs(2),
            model_rounds,
            calibration_epoch: 1,
            stale_frames: 0,
            model_out: None,
        };
        let camera_cancel = cancel.child_token();
        // A hot projector's columns in the camera agent's model are wrong (another projector's):
        // the camera agent must ignore them and measure the projector when it joins.
        let handed = match hot {
            Some(id) => {
                let wrong: Vec<u32> = owners
                    .iter()
                    .find(|(other, _)| other.as_str() != id)
                    .map(|(_, nodes)| nodes.clone())
                    .expect("another projector");
                let mut columns = problem.columns().to_vec();
                for (&n, &w) in owners[id].iter().zip(&wrong) {
                    columns[n as usize] = problem.columns()[w as usize].clone();
                }
                Problem::new(
                    columns,
                    problem.black().to_vec(),
                    problem.target().to_vec(),
                    problem.noise().to_vec(),
                )
                .expect("the camera's model")
            }
            None => problem.clone(),
        };
        let (status, handle) = camera::serve(
            config.clone(),
            RoomModel {
                problem: handed,
                owners: owners.clone(),
                start: start.clone(),
                hot: hot.into_iter().map(String::from).collect(),
                survey,
            },
            wrap(room.camera(), room.clone()),
            listener,
            camera_cancel.clone(),
        );
        Self {
            room,
            problem,
            status,
            endpoint,
            address,
            config,
            camera: (camera_cancel, handle),
            cancel,
            nodes: HashMap::new(),
            owners,
        }
    }

    /// Stops the camera agent and waits until it is gone.
    async fn stop_camera(&mut self) {
        self.camera.0.cancel();
        let handle = std::mem::replace(&mut self.camera.1, tokio::spawn(async { Ok(()) }));
        tokio::time::timeout(Duration::from_secs(10), handle)
            .await
            .expect("camera agent stops in time")
            .expect("task")
            .expect("clean stop");
    }

    /// Starts a new camera agent on the same address.
    async fn start_camera(&mut self) {
        let listener = tokio::net::TcpListener::bind(self.address)
            .await
            .expect("rebind the same address");
        let cancel = self.cancel.child_token();
        let model = RoomModel {
            problem: self.problem.clone(),
            owners: self.owners.clone(),
            start: None,
            hot: Default::default(),
            survey: None,
        };
        let (status, handle) = camera::serve(
            self.config.clone(),
            model,
            self.room.camera(),
            listener,
            cancel.clone(),
        );
        self.status = status;
        self.camera = (cancel, handle);
    }

    fn join(&mut self, projector: &str) {
        self.join_with_state(projector, None);
    }

    fn join_with_state(&mut self, projector: &str, state_file: Option<std::path::PathBuf>) {
        let cancel = self.cancel.child_token();
        let config = NodeConfig {
            endpoint: self.endpoint.clone(),
            room: "lab".into(),
            token: TOKEN.into(),
            projector_id: projector.into(),
            kind: roomlight_proto::v1::ProjectorKind::Standard,
            rule: StepRule::Momentum { theta: 1.0 },
            start: LinearRgb::splat(0.5),
            state_file,
        };
        let handle = tokio::spawn(node::run(config, self.room.display(), cancel.clone()));
        self.nodes.insert(projector.into(), (cancel, handle));
    }

    async fn leave(&mut self, projector: &str) {
        if let Some((cancel, handle)) = self.nodes.remove(projector) {
            cancel.cancel();
            let _ = tokio::time::timeout(Duration::from_secs(5), handle).await;
        }
        self.room.unplug(&self.owners[projector]);
    }

    /// Waits (at most `within`) until the status satisfies `pred`.
    async fn wait(&mut self, within: Duration, pred: impl Fn(&RoomStatus) -> bool) -> RoomStatus {
        let result = tokio::time::timeout(within, async {
            loop {
                if pred(&self.status.borrow()) {
                    return self.status.borrow().clone();
                }
                if self.status.changed().await.is_err() {
                    return self.status.borrow().clone();
                }
            }
        })
        .await;
        match result {
            Ok(s) => s,
            Err(_) => panic!(
                "condition not reached within {within:?}; last status {:?}",
                self.status.borrow()
            ),
        }
    }

    /// Starts a new camera agent and checks that the nodes resume where they were: all three
    /// attached and the very first capture already within 0.1% of the optimum.
    async fn restart_camera_and_expect_resumption(&mut self) {
        self.start_camera().await;
        let status = self
            .wait(Duration::from_secs(30), |s| {
                s.live_projectors == 3 && s.captures >= 1
            })
            .await;
        let excess = optimum(&self.problem)
            .expect("optimum")
            .excess(status.measured_objective);
        assert!(
            excess < 1e-3,
            "first capture after the restart: excess {excess}"
        );
    }

    fn excess(&self, truth: &Problem) -> f64 {
        let best = optimum(truth).expect("optimum");
        best.excess(self.room.true_objective())
    }
}

impl Drop for Sandbox {
    fn drop(&mut self) {
        self.cancel.cancel();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn agents_reach_the_optimum_and_correct_for_a_projector_that_leaves() {
    let mut sb = Sandbox::start(5).await;
    for p in ["p0", "p1", "p2"] {
        sb.join(p);
    }
    let status = sb
        .wait(Duration::from_secs(30), |s| {
            s.live_projectors == 3 && s.captures >= 8
        })
        .await;
    let excess = sb.excess(&sb.problem.clone());
    assert!(
        excess < 1e-3,
        "after {} captures the excess is {excess}",
        status.captures
    );
    // p2 goes away: its light vanishes from the errors and the others make up for it.
    sb.leave("p2").await;
    let gone: Vec<usize> = sb.owners["p2"].iter().map(|&n| n as usize).collect();
    let without = sb.problem.without_nodes(&gone);
    let before = sb
        .wait(Duration::from_secs(10), |s| s.live_projectors == 2)
        .await
        .captures;
    sb.wait(Duration::from_secs(30), |s| s.captures >= before + 8)
        .await;
    let excess = sb.excess(&without);
    assert!(excess < 1e-3, "after p2 left the excess is {excess}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_projector_that_joins_later_enters_the_next_rounds() {
    let mut sb = Sandbox::start(0).await;
    sb.join("p0");
    sb.join("p1");
    sb.wait(Duration::from_secs(30), |s| {
        s.live_projectors == 2 && s.captures >= 3
    })
    .await;
    sb.join("p2");
    let at = sb
        .wait(Duration::from_secs(10), |s| s.live_projectors == 3)
        .await
        .captures;
    sb.wait(Duration::from_secs(30), |s| s.captures >= at + 12)
        .await;
    let excess = sb.excess(&sb.problem.clone());
    assert!(excess < 1e-2, "after the join the excess is {excess}");
}

/// A projector the camera agent has never measured joins mid-run: it is calibrated hot (its
/// nodes at black, then each alone at white, by differential captures while the others keep
/// their values), gets its attenuation, and the room converges to the optimum with it. The
/// camera agent is handed wrong columns for it and must not use them: without the measurement
/// its nodes would have no columns (or the wrong ones) and could not help.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_projector_joining_hot_is_measured_and_the_room_converges_to_the_new_optimum() {
    let plant = PlantConfig {
        noise_scale: 1.0,
        seed: 5,
        ..PlantConfig::default()
    };
    let mut sb = Sandbox::start_hot(5, "p2", plant).await;
    sb.join("p0");
    sb.join("p1");
    let both = sb
        .wait(Duration::from_secs(30), |s| s.live_projectors == 2)
        .await
        .captures;
    let before = sb
        .wait(Duration::from_secs(30), |s| s.captures >= both + 6)
        .await;
    assert_eq!(before.calibrated_hot, 0);
    let dark: Vec<usize> = sb.owners["p2"].iter().map(|&n| n as usize).collect();
    let without = sb.problem.without_nodes(&dark);
    let alone = sb.excess(&without);
    assert!(
        alone < 1e-2,
        "before the join the others reach their own optimum: excess {alone}"
    );
    sb.join("p2");
    let measured = sb
        .wait(Duration::from_secs(30), |s| s.calibrated_hot == 1)
        .await;
    // One capture with its nodes at black and one per node at white.
    assert!(
        measured.captures >= before.captures + 5,
        "{before:?} → {measured:?}"
    );
    sb.wait(Duration::from_secs(30), |s| {
        s.live_projectors == 3 && s.captures >= measured.captures + 10
    })
    .await;
    let full = sb.problem.clone();
    let excess = sb.excess(&full);
    assert!(excess < 1e-2, "after the hot join the excess is {excess}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_wrong_token_another_room_or_version_is_refused_with_a_clear_status() {
    use roomlight_proto::v1;
    let sb = Sandbox::start(0).await;
    for (room, token, version, code) in [
        (
            "lab",
            "guess",
            roomlight_proto::PROTOCOL_VERSION,
            tonic::Code::Unauthenticated,
        ),
        (
            "kitchen",
            TOKEN,
            roomlight_proto::PROTOCOL_VERSION,
            tonic::Code::FailedPrecondition,
        ),
        ("lab", TOKEN, 99, tonic::Code::FailedPrecondition),
    ] {
        let mut client = v1::room_client::RoomClient::connect(sb.endpoint.clone())
            .await
            .expect("connect");
        let hello = v1::NodeMessage {
            body: Some(v1::node_message::Body::Hello(v1::Hello {
                protocol_version: version,
                room: room.into(),
                token: token.into(),
                projector_id: "p0".into(),
                ..Default::default()
            })),
        };
        let outcome = tokio::time::timeout(
            Duration::from_secs(10),
            client.attach(tokio_stream::iter(vec![hello])),
        )
        .await
        .expect("an answer in time");
        let status = outcome.expect_err("refused");
        assert_eq!(status.code(), code, "{room}/{token}/{version}: {status}");
    }
}

/// Attaches `projector` by hand: Hello, then (with `shown`) the acknowledgement of its start.
/// Returns the sender of its further messages and the camera agent's stream to it.
async fn attach_by_hand(
    endpoint: &str,
    projector: &str,
    shown: bool,
) -> (
    tokio::sync::mpsc::Sender<roomlight_proto::v1::NodeMessage>,
    tonic::Streaming<roomlight_proto::v1::RoomMessage>,
) {
    use roomlight_proto::v1;
    let mut client = v1::room_client::RoomClient::connect(endpoint.to_string())
        .await
        .expect("connect");
    let (tx, rx) = tokio::sync::mpsc::channel(64);
    tx.send(hello(projector)).await.expect("queue hello");
    if shown {
        tx.send(v1::NodeMessage {
            body: Some(v1::node_message::Body::Shown(v1::Shown {
                seq: 0,
                pattern: false,
            })),
        })
        .await
        .expect("queue");
    }
    let inbound = client
        .attach(tokio_stream::wrappers::ReceiverStream::new(rx))
        .await
        .expect("admitted")
        .into_inner();
    (tx, inbound)
}

fn hello(projector: &str) -> roomlight_proto::v1::NodeMessage {
    use roomlight_proto::v1;
    v1::NodeMessage {
        body: Some(v1::node_message::Body::Hello(v1::Hello {
            protocol_version: roomlight_proto::PROTOCOL_VERSION,
            room: "lab".into(),
            token: TOKEN.into(),
            projector_id: projector.into(),
            ..Default::default()
        })),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_duplicate_projector_is_refused_and_a_silent_one_leaves_within_two_seconds() {
    use roomlight_proto::v1;
    let mut sb = Sandbox::start(0).await;
    sb.join("p0");
    sb.wait(Duration::from_secs(10), |s| {
        s.live_projectors == 1 && s.captures >= 2
    })
    .await;
    let mut client = v1::room_client::RoomClient::connect(sb.endpoint.clone())
        .await
        .expect("connect");
    let status = client
        .attach(tokio_stream::iter(vec![hello("p0")]))
        .await
        .expect_err("duplicate");
    assert_eq!(status.code(), tonic::Code::AlreadyExists, "{status}");
    // p1 says hello, then goes silent with its stream open: no heartbeats, no acknowledgements.
    let (tx, rx) = tokio::sync::mpsc::channel(4);
    tx.send(hello("p1")).await.expect("queue hello");
    let mut inbound = client
        .attach(tokio_stream::wrappers::ReceiverStream::new(rx))
        .await
        .expect("admitted")
        .into_inner();
    let joined = tokio::time::Instant::now();
    // Its welcome and attenuation arrive; once it is dropped for silence its stream ends. (A
    // status with two projectors may never be published: the rounds wait for its
    // acknowledgement meanwhile.)
    let mut received = 0;
    loop {
        match tokio::time::timeout(Duration::from_secs(5), inbound.message()).await {
            Ok(Ok(Some(_))) => received += 1,
            Ok(Ok(None) | Err(_)) => break,
            Err(_) => panic!("the silent projector's stream still open after 5 s"),
        }
    }
    assert!(
        received >= 2,
        "welcome and assignment expected, got {received}"
    );
    assert!(
        joined.elapsed() < Duration::from_secs(2),
        "left after {:?}",
        joined.elapsed()
    );
    sb.wait(Duration::from_secs(5), |s| s.live_projectors == 1)
        .await;
    // The room went on with p0 meanwhile.
    let before = sb.status.borrow().captures;
    sb.wait(Duration::from_secs(10), |s| s.captures >= before + 3)
        .await;
    drop(tx);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn malformed_contributions_are_refused_without_disturbing_the_others() {
    use roomlight_proto::v1;
    let mut sb = Sandbox::start(5).await;
    sb.join("p0");
    sb.join("p1");
    // p2 is a rogue: it answers every round with NaN contributions for a node it does not own
    // and for its own nodes, and acknowledges nothing.
    let (tx, mut inbound) = attach_by_hand(&sb.endpoint, "p2", true).await;
    let rogue = tokio::spawn(async move {
        use tokio_stream::StreamExt;
        while let Some(Ok(m)) = inbound.next().await {
            if let Some(v1::room_message::Body::Errors(e)) = m.body {
                for node in [e.node, 0] {
                    let bad = v1::SparseRgb {
                        patches: vec![0],
                        values: vec![f64::NAN, 0.0, 0.0],
                    };
                    let msg = v1::NodeMessage {
                        body: Some(v1::node_message::Body::Contribution(v1::Contribution {
                            round: e.round,
                            node,
                            delta: Some(bad),
                        })),
                    };
                    if tx.send(msg).await.is_err() {
                        return;
                    }
                }
                let shown = v1::NodeMessage {
                    body: Some(v1::node_message::Body::Shown(v1::Shown {
                        seq: e.round,
                        pattern: false,
                    })),
                };
                let _ = tx.send(shown).await;
            }
        }
    });
    let status = sb.wait(Duration::from_secs(30), |s| s.captures >= 10).await;
    assert!(status.measured_objective.is_finite());
    // p2's nodes show nothing (it never drives a display): the optimum is the room without them.
    let gone: Vec<usize> = sb.owners["p2"].iter().map(|&n| n as usize).collect();
    sb.room.unplug(&sb.owners["p2"]);
    let without = sb.problem.without_nodes(&gone);
    let before = sb.status.borrow().captures;
    sb.wait(Duration::from_secs(30), |s| s.captures >= before + 6)
        .await;
    let excess = sb.excess(&without);
    assert!(
        excess < 1e-2,
        "the honest projectors still converge: excess {excess}"
    );
    rogue.abort();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_lights_stay_on_while_the_camera_agent_restarts_and_the_nodes_resume() {
    let mut sb = Sandbox::start(5).await;
    for p in ["p0", "p1", "p2"] {
        sb.join(p);
    }
    sb.wait(Duration::from_secs(30), |s| {
        s.live_projectors == 3 && s.captures >= 8
    })
    .await;
    sb.stop_camera().await;
    // No camera agent: every node keeps showing what it showed (checked a few times over 300 ms).
    let lit = sb.room.shown();
    assert!(lit.iter().any(|v| v.max_abs() > 0.0));
    let mut ticks = tokio::time::interval(Duration::from_millis(100));
    for _ in 0..3 {
        ticks.tick().await;
        assert_eq!(
            sb.room.shown(),
            lit,
            "a node changed its light without a camera agent"
        );
    }
    // A new camera agent on the same address: the nodes reconnect and resume from their values,
    // so the first capture is already at the optimum.
    sb.restart_camera_and_expect_resumption().await;
    sb.wait(Duration::from_secs(30), |s| s.captures >= 4).await;
    assert!(sb.excess(&sb.problem.clone()) < 1e-3);
    for p in ["p0", "p1", "p2"] {
        assert!(
            sb.nodes.get(p).is_some_and(|(_, h)| !h.is_finished()),
            "node agent {p} must still run"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restarted_node_relights_from_its_state_file_before_it_reconnects() {
    let dir = tempfile::tempdir().expect("temp dir");
    let state = dir.path().join("p0.state.json");
    let mut sb = Sandbox::start(5).await;
    sb.join_with_state("p0", Some(state.clone()));
    sb.join("p1");
    sb.join("p2");
    sb.wait(Duration::from_secs(30), |s| {
        s.live_projectors == 3 && s.captures >= 8
    })
    .await;
    let p0 = sb.owners["p0"].clone();
    let lit: Vec<LinearRgb> = p0.iter().map(|&n| sb.room.shown()[n as usize]).collect();
    assert!(
        lit.iter().all(|v| v.max_abs() > 0.0),
        "p0 must be lit before the reboot"
    );
    // p0's host reboots while the camera agent is down too: its projector goes dark.
    sb.stop_camera().await;
    if let Some((cancel, handle)) = sb.nodes.remove("p0") {
        cancel.cancel();
        tokio::time::timeout(Duration::from_secs(5), handle)
            .await
            .expect("stops")
            .expect("task")
            .expect("clean");
    }
    let saved = SavedState::load(&state)
        .expect("readable")
        .expect("written");
    assert_eq!(saved.values.len(), p0.len());
    // With the attenuation the camera agent sent each node.
    assert_eq!(saved.attenuation.len(), p0.len());
    for (n, column) in &saved.attenuation {
        assert!(p0.contains(n), "node {n} is not p0's");
        assert_eq!(
            column,
            &sb.problem.columns()[*n as usize],
            "node {n}'s column"
        );
    }
    let mut display = sb.room.display();
    for &n in &p0 {
        roomlight_agent::hardware::Display::show(&mut display, n, LinearRgb::ZERO);
    }
    // The new p0 agent relights from the file with no camera agent to talk to.
    sb.join_with_state("p0", Some(state.clone()));
    let relit = tokio::time::timeout(Duration::from_secs(5), async {
        let mut tick = tokio::time::interval(Duration::from_millis(20));
        loop {
            tick.tick().await;
            let now: Vec<LinearRgb> = p0.iter().map(|&n| sb.room.shown()[n as usize]).collect();
            if now
                .iter()
                .zip(&lit)
                .all(|(a, b)| (*a - *b).max_abs() < 1e-9)
            {
                return;
            }
        }
    })
    .await;
    assert!(relit.is_ok(), "p0 did not relight from its state file");
    // The camera agent comes back: the calibration epoch matches, the state is accepted, and
    // the room is at the optimum from the first capture on.
    sb.restart_camera_and_expect_resumption().await;
    // A corrupt state file is refused with a message naming it.
    std::fs::write(&state, "{not json").expect("write");
    let err = SavedState::load(&state).expect_err("corrupt");
    assert!(err.to_string().contains("p0.state.json"), "{err}");
}

/// Records every capture it passes on.
/// A camera that records, for every capture, what each node showed.
struct Recording {
    inner: VirtualCamera,
    room: VirtualRoom,
    shown: std::sync::Arc<std::sync::Mutex<Vec<Vec<LinearRgb>>>>,
}

impl Camera for Recording {
    async fn capture(&mut self) -> Result<Vec<LinearRgb>, roomlight_agent::AgentError> {
        self.shown
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(self.room.shown());
        self.inner.capture().await
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nodes_start_from_the_camera_agents_start_and_the_room_reports_settled_at_the_noise_floor()
{
    // A start of the camera agent's own (as the conventional start would be), different per node.
    let start: Vec<LinearRgb> = (0..12)
        .map(|n| LinearRgb([0.1 + 0.05 * n as f64, 0.2, 0.9 - 0.05 * n as f64]))
        .collect();
    let shown = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let recorded = shown.clone();
    let mut sb = Sandbox::start_with(
        0,
        Some(start.clone()),
        PlantConfig {
            noise_scale: 1.0,
            seed: 3,
            ..PlantConfig::default()
        },
        move |inner, room| Recording {
            inner,
            room,
            shown: recorded,
        },
    )
    .await;
    for p in ["p0", "p1", "p2"] {
        sb.join(p);
    }
    let status = sb.wait(Duration::from_secs(60), |s| s.settled).await;
    // Every node's first light the camera saw was the camera agent's start, not its own 0.5
    // (the nodes attach one by one: each is checked at the first capture it was lit in).
    let shown = shown
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone();
    for (n, expected) in start.iter().enumerate() {
        let first = shown
            .iter()
            .map(|x| x[n])
            .find(|x| *x != LinearRgb::ZERO)
            .unwrap_or_else(|| panic!("node {n} never lit in {} captures", shown.len()));
        assert!(
            (first - *expected).max_abs() < 1e-12,
            "node {n} first showed {first:?}, the camera's start is {expected:?}"
        );
    }
    // Settled means at the noise floor: close to the optimum, and reached in a few captures.
    let excess = sb.excess(&sb.problem.clone());
    assert!(excess < 1e-2, "settled with excess {excess}");
    assert!(
        status.captures >= 3 && status.captures < 60,
        "settled after {} captures",
        status.captures
    );
}

/// A camera that asks the camera agent to stop while it takes capture `at`.
struct StopDuring {
    inner: VirtualCamera,
    at: u64,
    taken: u64,
    stop: CancellationToken,
}

impl Camera for StopDuring {
    async fn capture(&mut self) -> Result<Vec<LinearRgb>, roomlight_agent::AgentError> {
        self.taken += 1;
        if self.taken == self.at {
            self.stop.cancel();
        }
        self.inner.capture().await
    }
}

/// A stop request in the middle of a round (SIGINT, SIGTERM) lets that round finish — its
/// errors, contributions and model rounds — and publish its status before the camera agent
/// stops; it does not start another.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stop_request_lets_the_current_round_finish() {
    let problem = synthetic_room(&SyntheticConfig::new(12, 4))
        .expect("room")
        .problem;
    let owners: HashMap<String, Vec<u32>> = (0..3)
        .map(|p| (format!("p{p}"), (4 * p..4 * p + 4).collect()))
        .collect();
    let room =
        VirtualRoom::new(Plant::new(problem.clone(), PlantConfig::default()).expect("plant"));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let endpoint = format!("http://{}", listener.local_addr().expect("address"));
    let nodes_cancel = CancellationToken::new();
    let camera_cancel = CancellationToken::new();
    let model_rounds = 5;
    let config = CameraConfig {
        room: "lab".into(),
        token: TOKEN.into(),
        heartbeat: Duration::from_millis(200),
        deadline: Duration::from_secs(2),
        model_rounds,
        calibration_epoch: 1,
        stale_frames: 0,
        model_out: None,
    };
    // The stop comes during the fourth capture, once all three projectors take part.
    let at = 4;
    let (status, handle) = camera::serve(
        config,
        RoomModel {
            problem,
            owners: owners.clone(),
            start: None,
            hot: Default::default(),
            survey: None,
        },
        StopDuring {
            inner: room.camera(),
            at,
            taken: 0,
            stop: camera_cancel.clone(),
        },
        listener,
        camera_cancel.clone(),
    );
    for id in owners.keys() {
        let config = NodeConfig {
            endpoint: endpoint.clone(),
            room: "lab".into(),
            token: TOKEN.into(),
            projector_id: id.clone(),
            kind: roomlight_proto::v1::ProjectorKind::Standard,
            rule: StepRule::Momentum { theta: 1.0 },
            start: LinearRgb::splat(0.5),
            state_file: None,
        };
        tokio::spawn(node::run(
            config,
            room.display(),
            nodes_cancel.child_token(),
        ));
    }
    tokio::time::timeout(Duration::from_secs(30), handle)
        .await
        .expect("the camera agent stops in time")
        .expect("task")
        .expect("clean stop");
    let last = status.borrow().clone();
    nodes_cancel.cancel();
    assert_eq!(last.captures, at, "{last:?}");
    assert_eq!(last.round, at * (model_rounds as u64 + 1), "{last:?}");
    assert_eq!(
        room.captures(),
        at as usize,
        "no capture after the stop request"
    );
}

/// A projector that leaves in the middle of a round (its stream ends after it received its
/// errors) is not waited for: with a one-minute deadline, the round and the next ones go on
/// with the projector that stayed at once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_round_does_not_wait_for_a_projector_that_left_during_it() {
    use roomlight_proto::v1;
    let problem = synthetic_room(&SyntheticConfig::new(8, 4))
        .expect("room")
        .problem;
    let owners: HashMap<String, Vec<u32>> = (0..2)
        .map(|p| (format!("p{p}"), (4 * p..4 * p + 4).collect()))
        .collect();
    let room =
        VirtualRoom::new(Plant::new(problem.clone(), PlantConfig::default()).expect("plant"));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let endpoint = format!("http://{}", listener.local_addr().expect("address"));
    let cancel = CancellationToken::new();
    let config = CameraConfig {
        room: "lab".into(),
        token: TOKEN.into(),
        heartbeat: Duration::from_secs(20),
        deadline: Duration::from_secs(60),
        model_rounds: 0,
        calibration_epoch: 1,
        stale_frames: 0,
        model_out: None,
    };
    let (mut status, _camera) = camera::serve(
        config,
        RoomModel {
            problem,
            owners,
            start: None,
            hot: Default::default(),
            survey: None,
        },
        room.camera(),
        listener,
        cancel.clone(),
    );
    // p1 attaches by hand, shows its start, and goes away as soon as it has its first errors.
    let (tx, mut inbound) = attach_by_hand(&endpoint, "p1", true).await;
    let node = NodeConfig {
        endpoint,
        room: "lab".into(),
        token: TOKEN.into(),
        projector_id: "p0".into(),
        kind: v1::ProjectorKind::Standard,
        rule: StepRule::Safe { theta: 1.0 },
        start: LinearRgb::splat(0.5),
        state_file: None,
    };
    tokio::spawn(node::run(node, room.display(), cancel.child_token()));
    tokio::time::timeout(Duration::from_secs(20), async {
        loop {
            match inbound.message().await {
                Ok(Some(m)) if matches!(m.body, Some(v1::room_message::Body::Errors(_))) => return,
                Ok(Some(_)) => {}
                other => panic!("p1's stream ended before its errors: {other:?}"),
            }
        }
    })
    .await
    .expect("p1 gets its errors");
    drop(inbound);
    drop(tx);
    // Well inside the deadline: the round p1 left finishes, and more follow with p0 alone.
    tokio::time::timeout(Duration::from_secs(20), async {
        loop {
            let s = status.borrow().clone();
            if s.live_projectors == 1 && s.captures >= 4 {
                return;
            }
            status.changed().await.expect("camera agent running");
        }
    })
    .await
    .expect("the rounds went on without waiting for p1's contributions");
    cancel.cancel();
}

/// Calibration over the wire needs a projector that says its size: a projector the model does
/// not know and whose Hello gives no resolution is refused with a status that says so.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_projector_without_a_resolution_cannot_be_calibrated_over_the_wire() {
    use roomlight_proto::v1;
    let survey = camera::Survey {
        corners: Vec::new(),
        sample: roomlight_calib::charts::SampleConfig::default(),
        target_mask: Vec::new(),
        patches: Vec::new(),
    };
    let sb = Sandbox::start_full(
        5,
        None,
        PlantConfig::default(),
        None,
        Some(survey),
        |c, _| c,
    )
    .await;
    let mut client = v1::room_client::RoomClient::connect(sb.endpoint.clone())
        .await
        .expect("connect");
    let refused = tokio::time::timeout(
        Duration::from_secs(10),
        client.attach(tokio_stream::iter(vec![hello("newcomer")])),
    )
    .await
    .expect("an answer in time")
    .expect_err("no resolution: refused");
    assert_eq!(refused.code(), tonic::Code::FailedPrecondition, "{refused}");
    assert!(
        refused.message().contains("newcomer") && refused.message().contains("resolution"),
        "{refused}"
    );
}

/// A projector that cannot be calibrated (its node agent attaches and sends heartbeats but never
/// shows a pattern) is retried, backing off, and meanwhile the calibrated projectors go on with
/// their rounds and reach the optimum without it. Fails on the previous code, where the rounds
/// waited for the hot projector: no capture ever came.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_projector_that_cannot_be_calibrated_does_not_stop_the_room() {
    use roomlight_proto::v1;
    let mut sb = Sandbox::start_hot(5, "p2", PlantConfig::default()).await;
    sb.join("p0");
    sb.join("p1");
    let (tx, _stream) = attach_by_hand(&sb.endpoint, "p2", false).await;
    // Heartbeats keep it attached; it never acknowledges a pattern.
    let beats = tokio::spawn(async move {
        let mut every = tokio::time::interval(Duration::from_millis(100));
        loop {
            every.tick().await;
            let beat = v1::NodeMessage {
                body: Some(v1::node_message::Body::Heartbeat(v1::Heartbeat {
                    sent_unix_ms: 0,
                })),
            };
            if tx.send(beat).await.is_err() {
                return;
            }
        }
    });
    let attached = sb
        .wait(Duration::from_secs(60), |s| s.live_projectors == 3)
        .await;
    let gone: Vec<usize> = sb.owners["p2"].iter().map(|&n| n as usize).collect();
    let truth = sb.problem.without_nodes(&gone);
    let best = optimum(&truth).expect("optimum");
    let status = sb
        .wait(Duration::from_secs(60), |s| {
            s.live_projectors == 3
                && s.captures >= attached.captures + 5
                && best.excess(s.measured_objective) < 1e-2
        })
        .await;
    assert_eq!(status.calibrated_hot, 0, "p2 never shows its patterns");
    beats.abort();
}
