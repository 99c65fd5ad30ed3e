//! What this crate's multi-agent tests share: the room's name and token, a synthetic room split
//! evenly among projectors `p0`, `p1`, …, a listener on `127.0.0.1:0`, the configs of a camera
//! agent and a node agent over it, and a wait on the camera agent's status with a deadline.

// Each test module uses its own part of this module.
#![allow(dead_code)]

use roomlight_agent::camera::{CameraConfig, RoomModel, RoomStatus};
use roomlight_agent::node::NodeConfig;
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, Problem, StepRule};
use roomlight_proto::v1;
use std::collections::HashMap;
use std::time::Duration;
use tokio::sync::watch;

pub const ROOM: &str = "lab";
pub const TOKEN: &str = "s3cret";

/// Waits (at most `within`) until the status satisfies `pred`; panics with the last status
/// otherwise.
pub async fn wait(
    status: &mut watch::Receiver<RoomStatus>,
    within: Duration,
    pred: impl Fn(&RoomStatus) -> bool,
) -> RoomStatus {
    let reached = tokio::time::timeout(within, status.wait_for(|s| pred(s)))
        .await
        .is_ok_and(|r| r.is_ok());
    let last = status.borrow().clone();
    assert!(
        reached && pred(&last),
        "condition not reached within {within:?}; last status {last:?}"
    );
    last
}

/// A synthetic room of `nodes` nodes (seed `seed`) split evenly among `projectors` projectors
/// `p0`, `p1`, … (the last may have fewer).
pub fn split_room(
    nodes: usize,
    seed: u64,
    projectors: usize,
) -> (Problem, HashMap<String, Vec<u32>>) {
    let problem = synthetic_room(&SyntheticConfig::new(nodes, seed))
        .expect("room")
        .problem;
    let per = nodes.div_ceil(projectors);
    let owners = (0..projectors)
        .map(|p| {
            let first = p * per;
            let last = ((p + 1) * per).min(nodes);
            (format!("p{p}"), (first as u32..last as u32).collect())
        })
        .collect();
    (problem, owners)
}

/// The room's model as the camera agent is given it: no start, no hot projector, no survey.
pub fn model(problem: Problem, owners: HashMap<String, Vec<u32>>) -> RoomModel {
    RoomModel {
        problem,
        owners,
        start: None,
        hot: Default::default(),
        survey: None,
    }
}

/// A listener on `127.0.0.1:0` and its `http://` endpoint.
pub async fn listen() -> (tokio::net::TcpListener, String) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let endpoint = format!("http://{}", listener.local_addr().expect("address"));
    (listener, endpoint)
}

/// Serves `service` (a fake camera agent) on `127.0.0.1:0` until `cancel`; its endpoint.
pub async fn serve_fake_room<S: v1::room_server::Room>(
    service: S,
    cancel: tokio_util::sync::CancellationToken,
) -> String {
    let (listener, endpoint) = listen().await;
    tokio::spawn(
        tonic::transport::Server::builder()
            .add_service(v1::room_server::RoomServer::new(service))
            .serve_with_incoming_shutdown(
                tokio_stream::wrappers::TcpListenerStream::new(listener),
                cancel.cancelled_owned(),
            ),
    );
    endpoint
}

/// A camera agent's config for the room: heartbeats, round deadline, model rounds.
pub fn camera_config(heartbeat: Duration, deadline: Duration, model_rounds: usize) -> CameraConfig {
    CameraConfig {
        room: ROOM.into(),
        token: TOKEN.into(),
        heartbeat,
        deadline,
        model_rounds,
        calibration_epoch: 1,
        stale_frames: 0,
        model_out: None,
        primaries: true,
        shading_passes: 0,
    }
}

/// `projector`'s node agent config for the camera agent at `endpoint`: momentum, start 0.5,
/// no state file.
pub fn node_config(endpoint: &str, projector: &str) -> NodeConfig {
    NodeConfig {
        endpoint: endpoint.into(),
        room: ROOM.into(),
        token: TOKEN.into(),
        projector_id: projector.into(),
        kind: v1::ProjectorKind::Standard,
        rule: StepRule::Momentum { theta: 1.0 },
        start: LinearRgb::splat(0.5),
        state_file: None,
    }
}
