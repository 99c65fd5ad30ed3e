//! Discovery over mDNS on loopback, on a port of this test's own (derived from the process id;
//! the only test of this binary, and of the suite's in-process tests, that uses mDNS): a node
//! agent finds the camera agent of its room, skips another room's, and attaches; a room nobody
//! advertises is not found.

use roomlight_agent::camera::{self, CameraConfig, RoomModel};
use roomlight_agent::discovery::{self, DiscoveryError, MdnsConfig};
use roomlight_agent::hardware::VirtualRoom;
use roomlight_agent::node::{self, NodeConfig};
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, StepRule};
use std::collections::HashMap;
use std::time::Duration;
use tokio_util::sync::CancellationToken;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_finds_the_camera_agent_of_its_room_over_mdns_on_loopback() {
    let mdns = MdnsConfig {
        port: 40_000 + (std::process::id() % 20_000) as u16,
        loopback_only: true,
    };
    let room_name = format!("mdns-test-{}", std::process::id());
    let problem = synthetic_room(&SyntheticConfig::new(4, 1))
        .expect("room")
        .problem;
    let owners: HashMap<String, Vec<u32>> = [("p0".to_string(), vec![0, 1, 2, 3])].into();
    let room =
        VirtualRoom::new(Plant::new(problem.clone(), PlantConfig::default()).expect("plant"));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let address = listener.local_addr().expect("address");
    let cancel = CancellationToken::new();
    let config = CameraConfig {
        room: room_name.clone(),
        token: "t".into(),
        heartbeat: Duration::from_millis(200),
        deadline: Duration::from_secs(2),
        model_rounds: 0,
        calibration_epoch: 1,
        stale_frames: 0,
        model_out: None,
        primaries: true,
        shading_passes: 0,
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
    // Another room's agent on the same network, advertised first: it must be skipped.
    let decoy = std::net::SocketAddr::from(([127, 0, 0, 1], address.port().wrapping_add(1)));
    let _other = discovery::advertise("kitchen", decoy, &mdns).expect("advertise the decoy");
    let _ours = discovery::advertise(&room_name, address, &mdns).expect("advertise");

    let lookup = {
        let (room_name, mdns) = (room_name.clone(), mdns.clone());
        tokio::task::spawn_blocking(move || {
            discovery::find_camera(&room_name, &mdns, Duration::from_secs(20))
        })
    };
    let endpoint = lookup.await.expect("task").expect("found over mDNS");
    assert_eq!(endpoint, format!("http://{address}"));

    let config = NodeConfig {
        endpoint,
        room: room_name.clone(),
        token: "t".into(),
        projector_id: "p0".into(),
        kind: roomlight_proto::v1::ProjectorKind::Standard,
        rule: StepRule::Safe { theta: 1.0 },
        start: LinearRgb::splat(0.5),
        state_file: None,
    };
    tokio::spawn(node::run(config, room.display(), cancel.child_token()));
    tokio::time::timeout(Duration::from_secs(20), async {
        loop {
            let s = status.borrow().clone();
            if s.live_projectors == 1 && s.captures >= 2 {
                return;
            }
            status.changed().await.expect("camera agent running");
        }
    })
    .await
    .expect("the node attached through the endpoint mDNS gave");

    // Nobody advertises this room: a clear error naming it, after the wait.
    let missing = {
        let mdns = mdns.clone();
        tokio::task::spawn_blocking(move || {
            discovery::find_camera("nobody-here", &mdns, Duration::from_millis(800))
        })
    };
    match missing.await.expect("task") {
        Err(e @ DiscoveryError::NotFound { .. }) => {
            assert!(e.to_string().contains("nobody-here"), "{e}")
        }
        other => panic!("expected NotFound, got {other:?}"),
    }
    cancel.cancel();
}
