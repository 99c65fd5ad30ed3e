//! The virtual hardware over gRPC: a node agent's remote display has the values on the
//! (simulated) projector once `flush` returns, so that its acknowledgement never races the frame.

use roomlight_agent::hardware::{Display, VirtualRoom};
use roomlight_agent::remote::{remote_display, serve_hardware};
use roomlight_core::LinearRgb;
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use tokio_util::sync::CancellationToken;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_remote_display_has_shown_everything_once_flush_returns() {
    let problem = synthetic_room(&SyntheticConfig::new(4, 1))
        .expect("room")
        .problem;
    let room = VirtualRoom::new(Plant::new(problem, PlantConfig::default()).expect("plant"));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let endpoint = format!("http://{}", listener.local_addr().expect("address"));
    let cancel = CancellationToken::new();
    tokio::spawn(serve_hardware(room.clone(), listener, cancel.clone()));
    let mut display = remote_display(endpoint, cancel.clone())
        .await
        .expect("connect");
    for k in 0..200u32 {
        let node = k % 4;
        let value = LinearRgb([f64::from(k) / 200.0, 0.5, 1.0 - f64::from(k) / 200.0]);
        // Several values at once, as a node agent with several nodes shows them.
        display.show((node + 1) % 4, LinearRgb::splat(0.25));
        display.show(node, value);
        display.flush().await;
        let shown = room.shown()[node as usize];
        assert_eq!(shown, value, "step {k}: node {node} shows {shown:?}");
    }
    cancel.cancel();
}
