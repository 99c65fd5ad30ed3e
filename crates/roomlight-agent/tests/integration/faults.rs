//! Faults over loopback gRPC against a virtual room: a camera that fails and hangs, then works
//! again (typed state, backoff, the projectors keep their light, the room still converges), and
//! a display that is lost and comes back (the camera agent's status says so; the projector stays
//! attached even while its display takes longer to present than three heartbeats). Every wait
//! has a deadline.

use roomlight_agent::AgentError;
use roomlight_agent::camera::{self, CameraState, DisplayLost, RETRY_FIRST, RoomStatus};
use roomlight_agent::hardware::{
    Camera, Display, DisplayFeed, DisplayReport, VirtualCamera, VirtualDisplay, VirtualRoom,
};
use roomlight_agent::node;
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_core::optimum::optimum;
use roomlight_core::{LinearRgb, Problem};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;
use tokio::sync::watch;
use tokio_util::sync::CancellationToken;

use crate::common;
use common::wait;
const LONG: Duration = Duration::from_secs(30);

/// What the scripted camera does on its next captures.
#[derive(Debug, Clone, Copy)]
enum Fault {
    /// Fails at once (an unplugged camera).
    Error,
    /// Never answers (a hung camera): abandoned after its timeout.
    Hang,
}

/// The virtual room's camera, failing as its script says.
#[derive(Debug, Clone)]
struct ScriptedCamera {
    inner: VirtualCamera,
    script: Arc<Mutex<VecDeque<Fault>>>,
}

impl Camera for ScriptedCamera {
    fn name(&self) -> &str {
        "scripted:cam0"
    }

    fn capture_timeout(&self) -> Duration {
        Duration::from_millis(300)
    }

    fn capture(&mut self) -> impl Future<Output = Result<Vec<LinearRgb>, AgentError>> + Send {
        let fault = self
            .script
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .pop_front();
        let y = fault.is_none().then(|| self.inner.capture_now());
        async move {
            match (fault, y) {
                (Some(Fault::Error), _) => Err(AgentError::Protocol("scripted: unplugged".into())),
                (Some(Fault::Hang), _) => std::future::pending().await,
                (None, Some(y)) => Ok(y),
                (None, None) => Err(AgentError::Protocol("no capture".into())),
            }
        }
    }
}

/// A virtual display whose state the test sets, and whose frames take `slow` long to present
/// while the flag is up (as a lost window display waits for its window).
struct ScriptedDisplay {
    inner: VirtualDisplay,
    state: watch::Receiver<DisplayReport>,
    slow: Arc<AtomicBool>,
}

const SLOW_FLUSH: Duration = Duration::from_millis(1500);

impl Display for ScriptedDisplay {
    fn show(&mut self, node: u32, value: LinearRgb) {
        self.inner.show(node, value);
    }

    fn flush(&mut self) -> impl Future<Output = ()> + Send {
        let slow = self.slow.load(Ordering::Relaxed);
        async move {
            if slow {
                // The fake's latency (a display that holds each frame), not a wait on a condition.
                tokio::time::sleep(SLOW_FLUSH).await;
            }
        }
    }

    fn state_feed(&self) -> Option<DisplayFeed> {
        Some(DisplayFeed::from_watch(self.state.clone(), Clone::clone))
    }
}

/// A room of 12 nodes, `p0` and `p1` of six each.
struct Room {
    room: VirtualRoom,
    problem: Problem,
    endpoint: String,
    status: watch::Receiver<RoomStatus>,
    cancel: CancellationToken,
}

async fn start(
    camera: impl FnOnce(VirtualCamera) -> ScriptedCamera,
    heartbeat: Duration,
    deadline: Duration,
) -> Room {
    let (problem, owners) = common::split_room(12, 4, 2);
    let room =
        VirtualRoom::new(Plant::new(problem.clone(), PlantConfig::default()).expect("plant"));
    let (listener, endpoint) = common::listen().await;
    let cancel = CancellationToken::new();
    let config = common::camera_config(heartbeat, deadline, 3);
    let model = common::model(problem.clone(), owners);
    let (status, _task) = camera::serve(
        config,
        model,
        camera(room.camera()),
        listener,
        cancel.child_token(),
    );
    Room {
        room,
        problem,
        endpoint,
        status,
        cancel,
    }
}

impl Room {
    fn node(&self, projector: &str, display: impl Display) {
        let config = common::node_config(&self.endpoint, projector);
        tokio::spawn(node::run(config, display, self.cancel.child_token()));
    }

    fn excess(&self) -> f64 {
        optimum(&self.problem)
            .expect("optimum")
            .excess(self.room.true_objective())
    }
}

impl Drop for Room {
    fn drop(&mut self) {
        self.cancel.cancel();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_failing_then_hung_camera_backs_off_keeps_the_light_and_the_room_converges_after() {
    let script = Arc::new(Mutex::new(VecDeque::new()));
    let scripted = script.clone();
    let mut room = start(
        |inner| ScriptedCamera {
            inner,
            script: scripted,
        },
        Duration::from_millis(200),
        Duration::from_secs(2),
    )
    .await;
    room.node("p0", room.room.display());
    room.node("p1", room.room.display());
    let before = wait(&mut room.status, LONG, |s| {
        s.live_projectors == 2 && s.captures >= 3
    })
    .await;
    assert_eq!(before.camera, CameraState::Ok);

    // Unplugged for three captures, then hung for one.
    script
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .extend([Fault::Error, Fault::Error, Fault::Error, Fault::Hang]);
    let first = wait(&mut room.status, LONG, |s| {
        matches!(s.camera, CameraState::Failing { .. })
    })
    .await;
    // Every projector acknowledged its last frame before the capture was tried: what the room
    // shows now is what it must keep showing through the outage.
    let shown = room.room.shown();
    let mut seen = Vec::new();
    let outage = (first.round, first.captures);
    let mut status = first;
    while let CameraState::Failing {
        failures,
        retry_in,
        last_error,
        ..
    } = &status.camera
    {
        assert_eq!(room.room.shown(), shown, "the projectors keep their light");
        assert_eq!(
            (status.round, status.captures),
            outage,
            "no round runs while the camera fails"
        );
        seen.push((*failures, *retry_in, last_error.clone()));
        let failures = *failures;
        status = wait(&mut room.status, LONG, |s| match &s.camera {
            CameraState::Failing { failures: f, .. } => *f > failures,
            CameraState::Ok => true,
        })
        .await;
    }
    // Each failure waits twice as long as the one before; the last (hung) says so.
    let (first_failure, first_wait, first_error) = &seen[0];
    assert_eq!((*first_failure, *first_wait), (1, RETRY_FIRST), "{seen:?}");
    assert!(first_error.contains("unplugged"), "{first_error}");
    for pair in seen.windows(2) {
        assert!(pair[1].0 > pair[0].0 && pair[1].1 > pair[0].1, "{seen:?}");
    }
    for (failures, wait, _) in &seen {
        assert_eq!(*wait, RETRY_FIRST * (1 << (failures - 1)), "{seen:?}");
    }
    let (last_failure, _, last_error) = seen.last().expect("failures seen");
    assert_eq!(*last_failure, 4, "{seen:?}");
    assert!(last_error.contains("hung"), "{last_error}");

    // Back: rounds resume and the room converges.
    let after = wait(&mut room.status, LONG, |s| {
        s.camera == CameraState::Ok && s.captures >= before.captures + 12
    })
    .await;
    assert!(after.round > before.round);
    let excess = room.excess();
    assert!(
        excess < 1e-2,
        "after {} captures the excess is {excess}",
        after.captures
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lost_display_is_in_the_status_until_it_is_back_and_its_projector_stays_attached() {
    // Heartbeats every 100 ms: a node silent for 300 ms is dropped. A lost display takes 1.5 s
    // to present each frame, and its node must stay attached all the same.
    let mut room = start(
        |inner| ScriptedCamera {
            inner,
            script: Default::default(),
        },
        Duration::from_millis(100),
        Duration::from_millis(500),
    )
    .await;
    let showing = DisplayReport::Showing {
        output: "HDMI-1".into(),
    };
    let (state, state_rx) = watch::channel(showing.clone());
    let slow = Arc::new(AtomicBool::new(false));
    room.node(
        "p0",
        ScriptedDisplay {
            inner: room.room.display(),
            state: state_rx,
            slow: slow.clone(),
        },
    );
    room.node("p1", room.room.display());
    let before = wait(&mut room.status, LONG, |s| {
        s.live_projectors == 2 && s.captures >= 2
    })
    .await;
    assert!(before.displays_lost.is_empty(), "{before:?}");

    slow.store(true, Ordering::Relaxed);
    state.send_replace(DisplayReport::Lost {
        output: "HDMI-1".into(),
        reason: "output HDMI-1 is gone".into(),
    });
    let lost = vec![DisplayLost {
        projector: "p0".into(),
        output: "HDMI-1".into(),
        reason: "output HDMI-1 is gone".into(),
    }];
    let status = wait(&mut room.status, LONG, |s| s.displays_lost == lost).await;
    assert_eq!(status.live_projectors, 2);
    // Rounds go on while it is lost (p0 late for them), and p0 stays attached through them.
    let mut captures = status.captures;
    for _ in 0..4 {
        let s = wait(&mut room.status, LONG, |s| s.captures > captures).await;
        assert_eq!(s.live_projectors, 2, "the projector stays attached: {s:?}");
        assert_eq!(s.displays_lost, lost, "{s:?}");
        captures = s.captures;
    }

    slow.store(false, Ordering::Relaxed);
    state.send_replace(showing);
    let back = wait(&mut room.status, LONG, |s| s.displays_lost.is_empty()).await;
    assert_eq!(back.live_projectors, 2);
}
