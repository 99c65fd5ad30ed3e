//! Admission and faults: who the camera agent refuses and why (both sides read the same
//! refusal), a duplicate stream, a silent node, a rogue node's malformed contributions. Every
//! wait has a deadline.

use roomlight_agent::AgentError;
use roomlight_agent::camera::Survey;
use roomlight_core::LinearRgb;
use roomlight_proto::convert::node_change;
use roomlight_proto::refusal::Refusal;
use roomlight_proto::v1;
use roomlight_tests::{Sandbox, TOKEN, hello};
use std::time::Duration;
use tokio_stream::StreamExt;

const LONG: Duration = Duration::from_secs(30);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_wrong_token_another_room_or_version_is_refused_with_a_clear_status() {
    let sb = Sandbox::builder().start_camera().await;
    let speaks = roomlight_proto::PROTOCOL_VERSION;
    let other_room = Refusal::OtherRoom {
        asked: "kitchen".into(),
        room: "lab".into(),
    };
    for (room, token, version, expected, code) in [
        (
            "lab",
            "guess",
            speaks,
            Refusal::WrongToken,
            tonic::Code::Unauthenticated,
        ),
        (
            "kitchen",
            TOKEN,
            speaks,
            other_room,
            tonic::Code::FailedPrecondition,
        ),
        (
            "lab",
            TOKEN,
            99,
            Refusal::ProtocolVersion { got: 99, speaks },
            tonic::Code::FailedPrecondition,
        ),
    ] {
        let mut message = hello("p0");
        if let Some(v1::node_message::Body::Hello(h)) = &mut message.body {
            h.room = room.into();
            h.token = token.into();
            h.protocol_version = version;
        }
        let status = sb.attach_once(message).await.expect_err("refused");
        // The node reads the very refusal the camera agent made, with its code and words.
        assert_eq!(
            Refusal::from_status(&status).as_ref(),
            Some(&expected),
            "{room}/{token}/{version}: {status}"
        );
        assert_eq!(status.code(), code, "{status}");
        assert_eq!(status.message(), expected.to_string());
        assert!(expected.is_fatal(), "a node agent stops on {status}");
    }
    sb.shutdown().await;
}

/// A node agent refused for what retrying cannot fix stops with the camera agent's status, which
/// it judged fatal; the room goes on without it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_agent_refused_for_its_token_stops_with_the_refusal() {
    let mut sb = Sandbox::builder().start_camera().await;
    sb.add_node("p0");
    let mut intruder = sb.node_config("p1");
    intruder.token = "guess".into();
    sb.add_node_with(intruder);
    let ended = sb.node_ended("p1", Duration::from_secs(10)).await;
    let Err(AgentError::Status(status)) = ended else {
        panic!("expected the camera agent's refusal, got {ended:?}");
    };
    assert_eq!(
        Refusal::from_status(&status),
        Some(Refusal::WrongToken),
        "{status}"
    );
    assert_eq!(status.code(), tonic::Code::Unauthenticated, "{status}");
    assert!(Refusal::is_fatal_status(&status), "{status}");
    sb.wait_for(LONG, |s| s.live_projectors == 1 && s.captures >= 2)
        .await;
    assert!(sb.node_running("p0"));
    sb.shutdown().await;
}

/// Under paused time: the seconds are the agents' clock, whatever the machine's load.
#[tokio::test(start_paused = true)]
async fn a_duplicate_projector_is_refused_and_a_silent_one_leaves_within_two_seconds() {
    let mut sb = Sandbox::builder().start_camera().await;
    sb.add_node("p0");
    sb.wait_for(Duration::from_secs(10), |s| {
        s.live_projectors == 1 && s.captures >= 2
    })
    .await;
    let status = sb.attach_once(hello("p0")).await.expect_err("duplicate");
    let duplicate = Refusal::AlreadyAttached {
        projector: "p0".into(),
        room: "lab".into(),
    };
    assert_eq!(Refusal::from_status(&status), Some(duplicate), "{status}");
    assert_eq!(status.code(), tonic::Code::AlreadyExists, "{status}");
    assert!(
        !Refusal::is_fatal_status(&status),
        "a reconnecting node retries: {status}"
    );
    // p1 says hello, then goes silent with its stream open: no heartbeats, no acknowledgements.
    let mut p1 = sb.attach_by_hand("p1", false).await;
    let joined = tokio::time::Instant::now();
    // Its welcome and attenuation arrive; once it is dropped for silence its stream ends. (A
    // status with two projectors may never be published: the rounds wait for its
    // acknowledgement meanwhile.)
    let mut received = 0;
    loop {
        match tokio::time::timeout(Duration::from_secs(5), p1.inbound.message()).await {
            Ok(Ok(Some(_))) => received += 1,
            Ok(Ok(None) | Err(_)) => break,
            Err(_) => panic!("the silent projector's stream still open after 5 s"),
        }
    }
    assert!(
        received >= 2,
        "welcome and assignment expected, got {received}"
    );
    // Paused time: the silence is measured on the agents' clock, not the machine's load, so the
    // rule is exact: dropped once three heartbeats (200 ms each) are missed, not before.
    let silent = joined.elapsed();
    assert!(
        silent >= Duration::from_millis(600) && silent < Duration::from_millis(800),
        "left after {silent:?}"
    );
    sb.wait_for(Duration::from_secs(5), |s| s.live_projectors == 1)
        .await;
    // The room went on with p0 meanwhile.
    sb.wait_captures(Duration::from_secs(10), 3).await;
    drop(p1);
    sb.shutdown().await;
}

/// A contribution whose values are not finite, for each of `nodes`.
fn nan_contribution(round: u64, nodes: impl Iterator<Item = u32>) -> v1::NodeMessage {
    let nodes = nodes
        .map(|node| node_change(node, LinearRgb([f64::NAN, 0.0, 0.0])))
        .collect();
    v1::NodeMessage {
        body: Some(v1::node_message::Body::Contribution(v1::Contribution {
            round,
            nodes,
        })),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn malformed_contributions_are_refused_without_disturbing_the_others() {
    let mut sb = Sandbox::builder().model_rounds(5).start_camera().await;
    sb.add_node("p0");
    sb.add_node("p1");
    // p2 is a rogue: it answers every round with NaN contributions for a node it does not own
    // and for its own nodes, and acknowledges each round without showing anything.
    let mut p2 = sb.attach_by_hand("p2", true).await;
    let rogue = tokio::spawn(async move {
        while let Some(Ok(m)) = p2.inbound.next().await {
            let Some(v1::room_message::Body::Errors(e)) = m.body else {
                continue;
            };
            // Its own nodes and node 0, which p0 owns.
            let nodes = e.nodes.iter().map(|n| n.node).chain([0]);
            if p2.tx.send(nan_contribution(e.round, nodes)).await.is_err() {
                return;
            }
            let shown = v1::NodeMessage {
                body: Some(v1::node_message::Body::Shown(v1::Shown {
                    seq: e.round,
                    pattern: false,
                })),
            };
            let _ = p2.tx.send(shown).await;
        }
    });
    let status = sb.wait_for(LONG, |s| s.captures >= 10).await;
    assert!(status.measured_objective.is_finite());
    // p2's nodes show nothing (it never drives a display): the optimum is the room without them.
    sb.room.unplug(&sb.owners["p2"]);
    sb.wait_captures(LONG, 6).await;
    let excess = sb.excess(&sb.without("p2"));
    assert!(
        excess < 1e-2,
        "the honest projectors still converge: excess {excess}"
    );
    rogue.abort();
    sb.shutdown().await;
}

/// Calibration over the wire needs a projector that says its size: a projector the model does
/// not know and whose Hello gives no resolution is refused with a status that says so.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_projector_without_a_resolution_cannot_be_calibrated_over_the_wire() {
    let survey = Survey::new(
        Vec::new(),
        roomlight_calib::charts::SampleConfig::default(),
        Vec::new(),
        (0, 0),
        0.0,
    )
    .expect("an empty survey");
    let sb = Sandbox::builder()
        .model_rounds(5)
        .survey(survey)
        .start_camera()
        .await;
    let refused = sb
        .attach_once(hello("newcomer"))
        .await
        .expect_err("no resolution: refused");
    let expected = Refusal::NoResolution {
        projector: "newcomer".into(),
        room: "lab".into(),
    };
    assert_eq!(
        Refusal::from_status(&refused).as_ref(),
        Some(&expected),
        "{refused}"
    );
    assert_eq!(refused.code(), tonic::Code::FailedPrecondition, "{refused}");
    assert!(
        refused.message().contains("newcomer") && refused.message().contains("resolution"),
        "{refused}"
    );
    sb.shutdown().await;
}
