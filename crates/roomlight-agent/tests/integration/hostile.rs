//! Hostile and broken peers against a camera agent over loopback gRPC (issue 20): a projector
//! of hundreds of nodes, racing Hellos of one projector, floods of bad Hellos, idle connections,
//! a logged-in node sending garbage, and a fake camera agent sending a huge assignment. Every
//! wait has a deadline.

use roomlight_agent::camera::{self, RoomModel, RoomStatus};
use roomlight_agent::hardware::VirtualRoom;
use roomlight_agent::node::{self, NodeConfig};
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, Problem, StepRule};
use roomlight_proto::{PROTOCOL_VERSION, v1};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tokio_stream::StreamExt;
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;

use crate::common;
use common::{TOKEN, wait};

/// A camera agent over a synthetic room of `nodes` nodes split among `projectors` projectors
/// (`p0`, `p1`, ...), stopped when dropped.
struct Room {
    room: VirtualRoom,
    problem: Problem,
    owners: HashMap<String, Vec<u32>>,
    endpoint: String,
    status: watch::Receiver<RoomStatus>,
    cancel: CancellationToken,
}

async fn start(nodes: usize, projectors: usize, deadline: Duration) -> Room {
    let (problem, owners) = common::split_room(nodes, 7, projectors);
    let room =
        VirtualRoom::new(Plant::new(problem.clone(), PlantConfig::default()).expect("plant"));
    let (listener, endpoint) = common::listen().await;
    let cancel = CancellationToken::new();
    let config = common::camera_config(Duration::from_millis(200), deadline, 0);
    let model = common::model(problem.clone(), owners.clone());
    let (status, _task) =
        camera::serve(config, model, room.camera(), listener, cancel.child_token());
    Room {
        room,
        problem,
        owners,
        endpoint,
        status,
        cancel,
    }
}

impl Room {
    fn node(
        &self,
        projector: &str,
    ) -> tokio::task::JoinHandle<Result<(), roomlight_agent::AgentError>> {
        tokio::spawn(node::run(
            common::node_config(&self.endpoint, projector),
            self.room.display(),
            self.cancel.child_token(),
        ))
    }
}

impl Drop for Room {
    fn drop(&mut self) {
        self.cancel.cancel();
    }
}

fn message(body: v1::node_message::Body) -> v1::NodeMessage {
    v1::NodeMessage { body: Some(body) }
}

fn hello(projector: &str, token: &str) -> v1::NodeMessage {
    message(v1::node_message::Body::Hello(v1::Hello {
        protocol_version: PROTOCOL_VERSION,
        room: "lab".into(),
        token: token.into(),
        projector_id: projector.into(),
        ..Default::default()
    }))
}

/// Every event logged on this thread, one string each (`level target: field=value ...`), as
/// the fmt subscriber would write them: `%` fields raw, `?` fields escaped.
#[derive(Clone, Default)]
struct Captured(Arc<Mutex<Vec<String>>>);

impl Captured {
    fn lines(&self) -> Vec<String> {
        self.0.lock().expect("log").clone()
    }
}

struct Fields(String);

impl tracing::field::Visit for Fields {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        self.0.push_str(&format!(" {}={value:?}", field.name()));
    }
}

impl tracing::Subscriber for Captured {
    fn enabled(&self, meta: &tracing::Metadata<'_>) -> bool {
        meta.target().starts_with("roomlight")
    }
    fn new_span(&self, _: &tracing::span::Attributes<'_>) -> tracing::span::Id {
        tracing::span::Id::from_u64(1)
    }
    fn record(&self, _: &tracing::span::Id, _: &tracing::span::Record<'_>) {}
    fn record_follows_from(&self, _: &tracing::span::Id, _: &tracing::span::Id) {}
    fn event(&self, event: &tracing::Event<'_>) {
        let meta = event.metadata();
        let mut fields = Fields(format!("{} {}:", meta.level(), meta.target()));
        event.record(&mut fields);
        self.0.lock().expect("log").push(fields.0);
    }
    fn enter(&self, _: &tracing::span::Id) {}
    fn exit(&self, _: &tracing::span::Id) {}
}

/// A raw client's attach: its outgoing queue (the Hello sent) and the camera agent's answer.
async fn attach_raw(
    endpoint: &str,
    first: v1::NodeMessage,
) -> (
    mpsc::Sender<v1::NodeMessage>,
    Result<tonic::Streaming<v1::RoomMessage>, tonic::Status>,
) {
    let mut client = v1::room_client::RoomClient::connect(endpoint.to_string())
        .await
        .expect("connect");
    let (tx, rx) = mpsc::channel(64);
    tx.send(first).await.expect("queue hello");
    let answer = client
        .attach(ReceiverStream::new(rx))
        .await
        .map(tonic::Response::into_inner);
    (tx, answer)
}

/// Item 1: the greeting of a projector of 300 nodes (Welcome, Assign, 300 attenuations) does
/// not fill the queue it is pushed into before the stream is returned; the projector attaches
/// and its rounds run.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_projector_of_300_nodes_attaches_and_gets_its_rounds() {
    let mut room = start(300, 1, Duration::from_secs(2)).await;
    assert_eq!(room.owners["p0"].len(), 300);
    let _node = room.node("p0");
    let before = room.room.true_objective();
    let s = wait(&mut room.status, Duration::from_secs(20), |s| {
        s.live_projectors == 1 && s.captures >= 5
    })
    .await;
    assert!(s.measured_objective.is_finite());
    assert!(
        room.room.true_objective() < before,
        "the rounds lower G: {before} → {}",
        room.room.true_objective()
    );
    let _ = &room.problem;
}

/// Item 2: a flood of Hellos with a wrong token and ids full of newlines and escape sequences
/// writes a bounded number of log lines, none with a raw control character, and the room's name
/// is not revealed to a peer without the token. (One thread: the subscriber sees every task.)
#[tokio::test(flavor = "current_thread")]
async fn a_flood_of_bad_hellos_writes_few_escaped_lines_and_reveals_nothing() {
    let log = Captured::default();
    let _default = tracing::subscriber::set_default(log.clone());
    let room = start(4, 2, Duration::from_secs(2)).await;
    let channel = tonic::transport::Endpoint::from_shared(room.endpoint.clone())
        .expect("endpoint")
        .connect()
        .await
        .expect("connect");
    let forged = "p0\n2026-11-25T00:00:00Z INFO roomlight: admin logged in\u{1b}[2J\r";
    for i in 0..300 {
        let mut client = v1::room_client::RoomClient::new(channel.clone());
        let mut bad = hello(&format!("{forged}{i}"), "guess");
        if let Some(v1::node_message::Body::Hello(h)) = &mut bad.body {
            h.room = "kitchen".into();
        }
        let (tx, rx) = mpsc::channel(1);
        tx.send(bad).await.expect("queue");
        let status = client
            .attach(ReceiverStream::new(rx))
            .await
            .expect_err("refused");
        assert_eq!(status.code(), tonic::Code::Unauthenticated, "{status}");
        assert!(
            !status.message().contains("lab"),
            "the room's name leaked: {status}"
        );
    }
    let lines = log.lines();
    let refusals: Vec<&String> = lines.iter().filter(|l| l.contains("refused")).collect();
    assert!(
        (1..=3).contains(&refusals.len()),
        "300 bad Hellos in well under a second: {} lines\n{refusals:#?}",
        refusals.len()
    );
    for line in &lines {
        assert!(
            !line.chars().any(char::is_control),
            "a raw control character in the log: {line:?}"
        );
        assert!(line.len() < 400, "a long line: {line:?}");
    }
}

/// Item 3: idle TCP connections beyond the limit do not lock out a node agent: it attaches
/// within a deadline, and every idle connection is closed (those over the limit at once, the
/// others after the handshake timeout, the deadline of 1 s).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idle_connections_beyond_the_limit_are_closed_and_a_node_still_attaches() {
    let mut room = start(4, 2, Duration::from_secs(1)).await;
    let limit = camera::connection_limit(&RoomModel {
        problem: room.problem.clone(),
        owners: room.owners.clone(),
        start: None,
        hot: Default::default(),
        survey: None,
    });
    let address = room.endpoint.trim_start_matches("http://").to_string();
    let mut idle = Vec::new();
    for _ in 0..limit + 20 {
        idle.push(
            tokio::net::TcpStream::connect(&address)
                .await
                .expect("connect"),
        );
    }
    let _node = room.node("p0");
    wait(&mut room.status, Duration::from_secs(15), |s| {
        s.live_projectors == 1 && s.captures >= 2
    })
    .await;
    let closed = tokio::time::timeout(Duration::from_secs(10), async {
        for mut stream in idle {
            let mut buf = [0u8; 64];
            // The server's HTTP/2 preface may come first; then the end (0 bytes) or a reset.
            loop {
                match tokio::io::AsyncReadExt::read(&mut stream, &mut buf).await {
                    Ok(0) | Err(_) => break,
                    Ok(_) => {}
                }
            }
        }
    })
    .await;
    assert!(closed.is_ok(), "idle connections still open 10 s later");
}

/// Answers every Errors of a raw peer with `contribution(round)` and acknowledges its frame.
fn rogue(
    mut inbound: tonic::Streaming<v1::RoomMessage>,
    tx: mpsc::Sender<v1::NodeMessage>,
    contribution: impl Fn(u64) -> Vec<v1::NodeChange> + Send + 'static,
) -> tokio::task::JoinHandle<Option<String>> {
    tokio::spawn(async move {
        // Its start is on its display (it shows nothing, but says so): rounds include it.
        let start = v1::Shown {
            seq: 0,
            pattern: false,
        };
        let _ = tx.send(message(v1::node_message::Body::Shown(start))).await;
        let mut heartbeat = tokio::time::interval(Duration::from_millis(100));
        loop {
            let m = tokio::select! {
                m = inbound.next() => m,
                _ = heartbeat.tick() => {
                    let beat = v1::node_message::Body::Heartbeat(v1::Heartbeat { sent_unix_ms: 0 });
                    let _ = tx.send(message(beat)).await;
                    continue;
                }
            };
            match m.map(|m| m.map(|m| m.body)) {
                Some(Ok(Some(v1::room_message::Body::Errors(e)))) => {
                    let c = v1::Contribution {
                        round: e.round,
                        nodes: contribution(e.round),
                    };
                    let _ = tx
                        .send(message(v1::node_message::Body::Contribution(c)))
                        .await;
                    let shown = v1::Shown {
                        seq: e.round,
                        pattern: false,
                    };
                    let _ = tx.send(message(v1::node_message::Body::Shown(shown))).await;
                }
                Some(Ok(Some(v1::room_message::Body::Goodbye(g)))) => return Some(g.reason),
                Some(Ok(_)) => {}
                Some(Err(_)) | None => return None,
            }
        }
    })
}

/// Item 4: a logged-in node sending NaN, 1e300 and changes for nodes it does not own is told
/// why and disconnected, its contributions dropped: the objective does not grow, the rounds
/// keep their rate, and the warning is written once.
#[tokio::test(flavor = "current_thread")]
async fn a_node_sending_garbage_is_disconnected_and_the_rounds_go_on() {
    let log = Captured::default();
    let _default = tracing::subscriber::set_default(log.clone());
    let started = tokio::time::Instant::now();
    let mut room = start(8, 2, Duration::from_secs(2)).await;
    let _honest = room.node("p0");
    let settled = wait(&mut room.status, Duration::from_secs(20), |s| {
        s.live_projectors == 1 && s.captures >= 10
    })
    .await;
    let before = room.room.true_objective();
    let (tx, answer) = attach_raw(&room.endpoint, hello("p1", TOKEN)).await;
    let mine = room.owners["p1"].clone();
    let theirs = room.owners["p0"][0];
    let bad = rogue(answer.expect("admitted"), tx, move |round| {
        let mut nodes: Vec<v1::NodeChange> = mine
            .iter()
            .map(|&node| v1::NodeChange {
                node,
                change: Some(v1::Rgb {
                    r: if round % 2 == 0 { f64::NAN } else { 1e300 },
                    g: 0.0,
                    b: 0.0,
                }),
            })
            .collect();
        nodes.push(v1::NodeChange {
            node: theirs,
            change: Some(v1::Rgb {
                r: 0.5,
                g: 0.5,
                b: 0.5,
            }),
        });
        nodes
    });
    let reason = tokio::time::timeout(Duration::from_secs(10), bad)
        .await
        .expect("disconnected in time")
        .expect("task");
    let reason = reason.expect("a goodbye with a reason");
    assert!(reason.contains("malformed"), "{reason}");
    // The rounds go on at their pace: ten captures in far less than ten deadlines.
    let after = wait(&mut room.status, Duration::from_secs(10), |s| {
        s.captures >= settled.captures + 10 && s.live_projectors == 1
    })
    .await;
    assert!(after.measured_objective.is_finite());
    let now = room.room.true_objective();
    assert!(now <= before * 1.05 + 1e-9, "G grew: {before} → {now}");
    let warnings = log
        .lines()
        .into_iter()
        .filter(|l| l.contains("disconnected for a malformed contribution"))
        .count();
    assert_eq!(warnings, 1, "{:#?}", log.lines());
    // Past the handshake timeout (the deadline, 2 s) the honest node is still on its first
    // connection: an admitted connection is not closed by the listener.
    wait(&mut room.status, Duration::from_secs(10), |_| {
        started.elapsed() > Duration::from_millis(2500)
    })
    .await;
    let joined = log.lines().iter().filter(|l| l.contains("joined")).count();
    assert_eq!(joined, 2, "p0 once, p1 once: {:#?}", log.lines());
}

/// Item 5: two simultaneous Hellos of one projector: exactly one is admitted, every time.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn racing_hellos_of_one_projector_admit_exactly_one() {
    let room = start(40, 20, Duration::from_secs(2)).await;
    let mut keep = Vec::new();
    for p in 0..20 {
        let id = format!("p{p}");
        let (a, b) = tokio::join!(
            attach_raw(&room.endpoint, hello(&id, TOKEN)),
            attach_raw(&room.endpoint, hello(&id, TOKEN))
        );
        let admitted = usize::from(a.1.is_ok()) + usize::from(b.1.is_ok());
        assert_eq!(admitted, 1, "{id}: {:?} / {:?}", a.1.err(), b.1.err());
        for refused in [&a.1, &b.1].into_iter().filter_map(|r| r.as_ref().err()) {
            assert_eq!(refused.code(), tonic::Code::AlreadyExists, "{refused}");
        }
        // The winner stays attached while the next pair races.
        keep.push((a, b));
    }
}

/// A fake camera agent: answers every attach with `answer` (counted).
#[derive(Clone)]
struct Fake {
    attaches: Arc<std::sync::atomic::AtomicUsize>,
    answer: fn() -> Result<Vec<v1::RoomMessage>, tonic::Status>,
}

type FakeStream = std::pin::Pin<
    Box<dyn tokio_stream::Stream<Item = Result<v1::RoomMessage, tonic::Status>> + Send>,
>;

#[tonic::async_trait]
impl v1::room_server::Room for Fake {
    type AttachStream = FakeStream;

    async fn attach(
        &self,
        _request: tonic::Request<tonic::Streaming<v1::NodeMessage>>,
    ) -> Result<tonic::Response<FakeStream>, tonic::Status> {
        self.attaches
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let messages = (self.answer)()?;
        let stream =
            tokio_stream::iter(messages.into_iter().map(Ok)).chain(tokio_stream::pending());
        Ok(tonic::Response::new(Box::pin(stream)))
    }
}

/// Serves `fake` on loopback until `cancel`; its endpoint.
async fn serve_fake(fake: Fake, cancel: CancellationToken) -> String {
    common::serve_fake_room(fake, cancel).await
}

/// Item 7: a rogue advertiser of the room that refuses everyone (as a fatal wrong token) is
/// skipped, not fatal: the node agent goes on to the next candidate and attaches there.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refusing_candidate_is_skipped_and_the_node_attaches_to_the_next() {
    let mut room = start(4, 2, Duration::from_secs(2)).await;
    let rogue = Fake {
        attaches: Default::default(),
        answer: || Err(roomlight_proto::refusal::Refusal::WrongToken.into()),
    };
    let tried = rogue.attaches.clone();
    let rogue_endpoint = serve_fake(rogue, room.cancel.child_token()).await;
    let candidates = [rogue_endpoint, room.endpoint.clone()];
    let find = move |skip: &[String]| candidates.iter().find(|c| !skip.contains(c)).cloned();
    let config = NodeConfig {
        endpoint: String::new(),
        room: "lab".into(),
        token: TOKEN.into(),
        projector_id: "p0".into(),
        kind: v1::ProjectorKind::Standard,
        rule: StepRule::Momentum { theta: 1.0 },
        start: LinearRgb::splat(0.5),
        state_file: None,
    };
    let node = tokio::spawn(node::run_with_candidates(
        config,
        find,
        room.room.display(),
        room.cancel.child_token(),
    ));
    wait(&mut room.status, Duration::from_secs(15), |s| {
        s.live_projectors == 1 && s.captures >= 3
    })
    .await;
    assert!(!node.is_finished(), "the refusal was not fatal");
    assert!(
        tried.load(std::sync::atomic::Ordering::Relaxed) >= 1,
        "the rogue was tried first"
    );
}

/// Item 8: a fake camera agent sending a 56 MB assignment to a node that draws no pixels is
/// refused by the node from its length, and the node's error names the limit.
#[tokio::test(flavor = "current_thread")]
async fn a_huge_assignment_is_refused_naming_the_limit() {
    let log = Captured::default();
    let _default = tracing::subscriber::set_default(log.clone());
    let cancel = CancellationToken::new();
    let _stop = cancel.clone().drop_guard();
    let fake = Fake {
        attaches: Default::default(),
        answer: || {
            let pixels = 7_000_000u32;
            let assign = v1::Assign {
                nodes: vec![v1::NodeAssignment {
                    node: 0,
                    chart: 0,
                    pixels: (0..pixels).collect(),
                    weights: vec![0.5; pixels as usize],
                }],
                width: 4000,
                height: 2000,
                gamma: Vec::new(),
            };
            Ok(vec![v1::RoomMessage {
                body: Some(v1::room_message::Body::Assign(assign)),
            }])
        },
    };
    let endpoint = serve_fake(fake, cancel.child_token()).await;
    let config = NodeConfig {
        endpoint,
        room: "lab".into(),
        token: TOKEN.into(),
        projector_id: "p0".into(),
        kind: v1::ProjectorKind::Standard,
        rule: StepRule::Momentum { theta: 1.0 },
        start: LinearRgb::splat(0.5),
        state_file: None,
    };
    let room = VirtualRoom::new(
        Plant::new(
            synthetic_room(&SyntheticConfig::new(2, 1))
                .expect("room")
                .problem,
            PlantConfig::default(),
        )
        .expect("plant"),
    );
    let node = tokio::spawn(node::run(config, room.display(), cancel.child_token()));
    let limit = roomlight_proto::bounds::room_message_limit(None).to_string();
    let named = tokio::time::timeout(Duration::from_secs(20), async {
        loop {
            if log
                .lines()
                .iter()
                .any(|l| l.contains("session lost") && l.contains(&limit))
            {
                return;
            }
            // Polling a log buffer, with the deadline above.
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await;
    assert!(named.is_ok(), "no error naming {limit}: {:#?}", log.lines());
    assert!(
        !node.is_finished(),
        "a node retries (its camera agent may be upgraded)"
    );
}

/// A TCP proxy in front of the camera agent that can cut every connection through it and
/// refuse new ones (a camera host lost without a goodbye, as under `kill -9`).
struct Proxy {
    endpoint: String,
    up: Arc<std::sync::atomic::AtomicBool>,
    cut: Arc<tokio::sync::Notify>,
}

async fn proxy(upstream: String) -> Proxy {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let endpoint = format!("http://{}", listener.local_addr().expect("address"));
    let up = Arc::new(std::sync::atomic::AtomicBool::new(true));
    let cut = Arc::new(tokio::sync::Notify::new());
    let (is_up, cuts) = (up.clone(), cut.clone());
    let upstream = upstream.trim_start_matches("http://").to_string();
    tokio::spawn(async move {
        while let Ok((mut down, _)) = listener.accept().await {
            if !is_up.load(std::sync::atomic::Ordering::Relaxed) {
                continue;
            }
            let (upstream, cuts) = (upstream.clone(), cuts.clone());
            tokio::spawn(async move {
                let Ok(mut up) = tokio::net::TcpStream::connect(upstream).await else {
                    return;
                };
                let cut = cuts.notified();
                tokio::select! {
                    _ = tokio::io::copy_bidirectional(&mut down, &mut up) => {}
                    () = cut => {}
                }
            });
        }
    });
    Proxy { endpoint, up, cut }
}

/// Item 9: after a good session the reconnect backoff starts afresh. The camera agent's host
/// is lost twice without a goodbye; the first outage lasts long enough for the node's wait to
/// grow past a second; after the second, short one the node is back within a second (without
/// the reset it would wait its grown step).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_reconnect_backoff_is_reset_after_a_good_session() {
    let mut room = start(4, 1, Duration::from_secs(1)).await;
    let proxy = proxy(room.endpoint.clone()).await;
    let config = NodeConfig {
        endpoint: proxy.endpoint.clone(),
        room: "lab".into(),
        token: TOKEN.into(),
        projector_id: "p0".into(),
        kind: v1::ProjectorKind::Standard,
        rule: StepRule::Momentum { theta: 1.0 },
        start: LinearRgb::splat(0.5),
        state_file: None,
    };
    let _node = tokio::spawn(node::run(
        config,
        room.room.display(),
        room.cancel.child_token(),
    ));
    let mut s = wait(&mut room.status, Duration::from_secs(15), |s| {
        s.captures >= 3
    })
    .await;
    // The first outage: 2 s, failed attempts at ~0.1, 0.3, 0.7 and 1.5 s grow the step.
    proxy.up.store(false, std::sync::atomic::Ordering::Relaxed);
    proxy.cut.notify_waiters();
    tokio::time::sleep(Duration::from_secs(2)).await; // the outage itself, not a wait
    proxy.up.store(true, std::sync::atomic::Ordering::Relaxed);
    s = wait(&mut room.status, Duration::from_secs(15), |t| {
        t.captures >= s.captures + 3
    })
    .await;
    // The second outage: connections cut, new ones taken at once.
    proxy.cut.notify_waiters();
    let cut_at = tokio::time::Instant::now();
    wait(&mut room.status, Duration::from_secs(15), |t| {
        t.captures >= s.captures + 3
    })
    .await;
    let back = cut_at.elapsed();
    assert!(back < Duration::from_millis(1500), "back after {back:?}");
}
