//! Restarts: while the camera agent is away the lights stay on, and the node agents reconnect
//! and resume where they were; a node agent restarted with its state file relights before it
//! reaches any camera agent. Every wait has a deadline.
//!
//! They run under `tokio::time::pause`: the camera agent's absence, the node agents' backoff
//! and the deadlines are the agents' clock, whatever the machine's load. Captures take an
//! exposure of that clock, as a real camera's do (see `SandboxBuilder::exposure`).

use roomlight_agent::hardware::Display;
use roomlight_agent::node::SavedState;
use roomlight_core::LinearRgb;
use roomlight_tests::Sandbox;
use std::time::Duration;

const LONG: Duration = Duration::from_secs(30);
/// A camera's exposure: long enough for the paused clock to move during each capture.
const EXPOSURE: Duration = Duration::from_millis(30);

/// Starts a new camera agent and checks that the nodes resume where they were: all three
/// attached and the very first capture already within 0.1% of the optimum.
async fn restart_camera_and_expect_resumption(sb: &mut Sandbox) {
    sb.start_camera().await;
    let status = sb
        .wait_for(LONG, |s| s.live_projectors == 3 && s.captures >= 1)
        .await;
    let excess = sb.measured_excess(status.measured_objective);
    assert!(
        excess < 1e-3,
        "first capture after the restart: excess {excess}"
    );
}

#[tokio::test(start_paused = true)]
async fn the_lights_stay_on_while_the_camera_agent_restarts_and_the_nodes_resume() {
    let mut sb = Sandbox::builder()
        .model_rounds(5)
        .exposure(EXPOSURE)
        .start_camera()
        .await;
    sb.add_all_nodes();
    sb.wait_for(LONG, |s| s.live_projectors == 3 && s.captures >= 8)
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
    restart_camera_and_expect_resumption(&mut sb).await;
    sb.wait_for(LONG, |s| s.captures >= 4).await;
    assert!(sb.excess(&sb.problem) < 1e-3);
    for p in sb.projectors() {
        assert!(sb.node_running(&p), "node agent {p} must still run");
    }
    sb.shutdown().await;
}

#[tokio::test(start_paused = true)]
async fn a_restarted_node_relights_from_its_state_file_before_it_reconnects() {
    let dir = tempfile::tempdir().expect("temp dir");
    let state = dir.path().join("p0.state.json");
    let mut sb = Sandbox::builder()
        .model_rounds(5)
        .exposure(EXPOSURE)
        .start_camera()
        .await;
    sb.add_node_with_state("p0", state.clone());
    sb.add_node("p1");
    sb.add_node("p2");
    sb.wait_for(LONG, |s| s.live_projectors == 3 && s.captures >= 8)
        .await;
    let p0 = sb.owners["p0"].clone();
    let lit = sb.shown_by("p0");
    assert!(
        lit.iter().all(|v| v.max_abs() > 0.0),
        "p0 must be lit before the reboot"
    );
    // p0's host reboots while the camera agent is down too: its projector goes dark.
    sb.stop_camera().await;
    sb.kill_node("p0").await.expect("a clean stop");
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
        display.show(n, LinearRgb::ZERO);
    }
    // The new p0 agent relights from the file with no camera agent to talk to.
    sb.add_node("p0");
    let relit = tokio::time::timeout(Duration::from_secs(5), async {
        let mut tick = tokio::time::interval(Duration::from_millis(20));
        loop {
            tick.tick().await;
            let now = sb.shown_by("p0");
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
    restart_camera_and_expect_resumption(&mut sb).await;
    // A corrupt state file is refused with a message naming it.
    std::fs::write(&state, "{not json").expect("write");
    let err = SavedState::load(&state).expect_err("corrupt");
    assert!(err.to_string().contains("p0.state.json"), "{err}");
    sb.shutdown().await;
}

/// A node agent restarted without a state file (stopped cleanly, started again) rejoins from
/// its default start, and the room converges back to the optimum.
#[tokio::test(start_paused = true)]
async fn a_restarted_node_agent_rejoins_and_the_room_converges_again() {
    let mut sb = Sandbox::builder()
        .model_rounds(5)
        .exposure(EXPOSURE)
        .start_camera()
        .await;
    sb.add_all_nodes();
    let before = sb
        .wait_for(LONG, |s| s.live_projectors == 3 && s.captures >= 8)
        .await;
    sb.restart_node("p1").await;
    sb.wait_for(LONG, |s| {
        s.live_projectors == 3 && s.captures >= before.captures + 8
    })
    .await;
    let excess = sb.excess(&sb.problem);
    assert!(excess < 1e-3, "after p1's restart the excess is {excess}");
    assert!(sb.node_running("p1"));
    sb.shutdown().await;
}
