//! Calibration over the wire in one process: the rendered room served on loopback, the camera
//! agent on its camera with a survey, and a node agent per projector drawing into the rendered
//! projectors. The procedure runs over the wire as it runs in process.

use roomlight_agent::AgentError;
use roomlight_agent::camera::{self, CameraConfig, RoomStatus};
use roomlight_agent::hardware::{Assignment, Display, Fill, Pattern};
use roomlight_agent::node::{self, NodeConfig};
use roomlight_calib::graycode::{Coding, Manifest};
use roomlight_core::{LinearRgb, StepRule};
use roomlight_lab::pipeline::{chart_corners, sample_config};
use roomlight_lab::rendered::{self, RenderedCamera, rendered_display};
use roomlight_lab::wire_room::survey_model;
use roomlight_proto::v1;
use roomlight_sim::Room;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio_util::sync::{CancellationToken, DropGuard};

use crate::support;
use support::apart_scene;

/// Waits until `done` holds for a status (the first one that does), within `limit`.
async fn first_status(
    status: &mut watch::Receiver<RoomStatus>,
    limit: Duration,
    done: impl Fn(&RoomStatus) -> bool,
) -> RoomStatus {
    tokio::time::timeout(limit, async {
        loop {
            if done(&status.borrow_and_update()) {
                return status.borrow().clone();
            }
            status.changed().await.expect("the camera agent stopped");
        }
    })
    .await
    .unwrap_or_else(|_| panic!("no such status within {limit:?}: {:?}", status.borrow()))
}

/// The apart room over the wire with only `projectors` live: the rendered room served on
/// loopback, the camera agent on its camera with a survey, and a node agent per projector,
/// started together. Dropping it stops everything; [`Wire::stop`] also joins every task.
struct Wire {
    status: watch::Receiver<RoomStatus>,
    agent: JoinHandle<Result<(), AgentError>>,
    nodes: Vec<JoinHandle<Result<(), AgentError>>>,
    guard: DropGuard,
}

impl Wire {
    /// `leaver`: a projector whose node agent stops (its connection drops) once its display
    /// has been asked for that many structured-light patterns, with the count it reached.
    async fn start(projectors: &[&str], leaver: Option<(&str, &Arc<AtomicUsize>, usize)>) -> Self {
        let mut scene = apart_scene();
        scene
            .projectors
            .retain(|p| projectors.contains(&p.name.as_str()));
        let room = Arc::new(Room::build(scene).expect("room"));
        let cancel = CancellationToken::new();
        let hardware = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let hardware_at = format!("http://{}", hardware.local_addr().expect("address"));
        tokio::spawn(rendered::serve(room.clone(), 3, hardware, cancel.clone()));
        let client = rendered::connect(hardware_at).await.expect("connect");
        let corners = chart_corners(&room).expect("corners");
        let sample = sample_config(&room);
        let probe = RenderedCamera::new(client.clone(), corners.clone(), Vec::new(), sample);
        // The apart room has no target: its mask is empty, as the survey's of a bare room.
        let (model, patches, _) = survey_model(&room, &probe, 0.0).await.expect("survey");
        let camera = RenderedCamera::new(client.clone(), corners, patches, sample);
        let config = CameraConfig {
            room: "apart".into(),
            token: "t".into(),
            heartbeat: Duration::from_millis(200),
            deadline: Duration::from_secs(10),
            model_rounds: 2,
            calibration_epoch: 1,
            stale_frames: 0,
            model_out: None,
            primaries: true,
            shading_passes: 0,
        };
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let endpoint = format!("http://{}", listener.local_addr().expect("address"));
        let (status, agent) = camera::serve(config, model, camera, listener, cancel.clone());
        let mut nodes = Vec::new();
        for p in &room.scene().projectors {
            let [w, h] = p.resolution;
            let own = cancel.child_token();
            let display =
                rendered_display(client.clone(), p.name.clone(), (w, h), None, own.clone());
            let config = NodeConfig {
                endpoint: endpoint.clone(),
                room: "apart".into(),
                token: "t".into(),
                projector_id: p.name.clone(),
                kind: v1::ProjectorKind::Standard,
                rule: StepRule::Momentum { theta: 1.0 },
                start: LinearRgb::splat(0.5),
                state_file: None,
            };
            nodes.push(match leaver {
                Some((id, shown, after)) if id == p.name => {
                    let display = Leaving {
                        inner: display,
                        shown: Arc::clone(shown),
                        after,
                        leave: own.clone(),
                    };
                    tokio::spawn(node::run(config, display, own))
                }
                _ => tokio::spawn(node::run(config, display, own)),
            });
        }
        Self {
            status,
            agent,
            nodes,
            guard: cancel.drop_guard(),
        }
    }

    /// Stops every agent and joins them: none failed or panicked.
    async fn stop(self) {
        drop(self.guard);
        self.agent.await.expect("agent task").expect("agent");
        for n in self.nodes {
            n.await.expect("node task").expect("node agent");
        }
    }
}

/// A node agent's display that ends its node agent (cancels `leave`) once it has been asked
/// for `after` structured-light patterns: a projector switched off partway through its
/// calibration.
struct Leaving<D> {
    inner: D,
    shown: Arc<AtomicUsize>,
    after: usize,
    leave: CancellationToken,
}

impl<D: Display> Display for Leaving<D> {
    fn show(&mut self, node: u32, value: LinearRgb) {
        self.inner.show(node, value);
    }

    fn show_pattern(&mut self, pattern: Pattern) -> bool {
        if matches!(pattern.fill, Fill::Structured { .. })
            && self.shown.fetch_add(1, Ordering::SeqCst) + 1 >= self.after
        {
            self.leave.cancel();
        }
        self.inner.show_pattern(pattern)
    }

    fn assign(&mut self, assignment: &Assignment) {
        self.inner.assign(assignment);
    }

    fn resolution(&self) -> Option<(u32, u32)> {
        self.inner.resolution()
    }

    fn flush(&mut self) -> impl Future<Output = ()> + Send {
        self.inner.flush()
    }
}

/// Brings up the apart room with only `projectors` live, their node agents started together,
/// and returns the first status with all of them calibrated, once the room has run a measured
/// round lit by them.
async fn bring_up(projectors: &[&str]) -> RoomStatus {
    let mut wire = Wire::start(projectors, None).await;
    let n = projectors.len() as u64;
    let calibrated = first_status(&mut wire.status, Duration::from_secs(600), |s| {
        s.calibrated_hot == n
    })
    .await;
    assert_eq!(calibrated.live_projectors, projectors.len());
    // They take part in the rounds: a later measured round sees the room lit.
    let lit = first_status(&mut wire.status, Duration::from_secs(120), |s| {
        s.captures > calibrated.captures + 2
    })
    .await;
    assert!(lit.measured_objective.is_finite(), "{lit:?}");
    wire.stop().await;
    calibrated
}

/// Two projectors whose footprints do not overlap join a dark room together: the camera agent
/// brings them up in one procedure and codes them at the same time, so that the room is
/// calibrated in fewer captures than bringing up each alone takes (each count is the camera
/// agent's own, and includes one measured round).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn projectors_with_disjoint_footprints_joining_together_are_coded_at_the_same_time() {
    let together = bring_up(&["left", "right"]).await;
    let left = bring_up(&["left"]).await;
    let right = bring_up(&["right"]).await;
    let one_after_the_other = left.captures + right.captures - 1;
    eprintln!(
        "calibrated over the wire: together at capture {}, alone at {} and {}",
        together.captures, left.captures, right.captures
    );
    // Together saves at least one set of structured light: the smaller projector's bit
    // patterns, shown once in a dark room (white and black are the footprint captures, one
    // per projector either way), counted over the largest cells (the fewest bits, whichever
    // cell the procedure chose).
    let patterns = apart_scene()
        .projectors
        .iter()
        .map(|p| {
            let m = Manifest::with_cell(
                p.resolution[0],
                p.resolution[1],
                Coding::Xor04,
                roomlight_calib::procedure::LARGEST_CELL,
            )
            .expect("manifest");
            u64::from(m.column_bits + m.row_bits)
        })
        .min()
        .expect("projectors");
    assert!(
        together.captures + patterns <= one_after_the_other,
        "together {together:?}, alone {left:?} and {right:?}: coded together should save at least {patterns} captures"
    );
}

/// A projector switched off partway through its structured light, brought up together with
/// another: the camera agent finds it gone (the rig's `RigError::Gone`), brings the other up
/// without it, and the room converges with the rest; no agent fails or panics.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_projector_that_leaves_during_structured_light_does_not_hold_the_bring_up_back() {
    const AFTER: usize = 4;
    let shown = Arc::new(AtomicUsize::new(0));
    let mut wire = Wire::start(&["left", "right"], Some(("right", &shown, AFTER))).await;
    let calibrated = first_status(&mut wire.status, Duration::from_secs(600), |s| {
        s.calibrated_hot >= 1
    })
    .await;
    eprintln!(
        "with right gone, left calibrated over the wire at capture {}",
        calibrated.captures
    );
    assert!(
        shown.load(Ordering::SeqCst) >= AFTER,
        "right left before its structured light: {} patterns",
        shown.load(Ordering::SeqCst)
    );
    assert_eq!(calibrated.calibrated_hot, 1, "{calibrated:?}");
    assert_eq!(calibrated.live_projectors, 1, "{calibrated:?}");
    let settled = first_status(&mut wire.status, Duration::from_secs(300), |s| {
        s.settled && s.captures > calibrated.captures + 2
    })
    .await;
    eprintln!("settled at capture {}: {settled:?}", settled.captures);
    assert!(settled.measured_objective.is_finite(), "{settled:?}");
    assert_eq!(
        (settled.calibrated_hot, settled.live_projectors),
        (1, 1),
        "{settled:?}"
    );
    wire.stop().await;
}
