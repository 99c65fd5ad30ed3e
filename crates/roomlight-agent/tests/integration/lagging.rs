//! A node agent that never reads its stream cannot hold up the room: its queue fills, it is told
//! it lags and dropped, and the rounds go on for the others. Every wait has a deadline.

use roomlight_agent::camera;
use roomlight_agent::hardware::VirtualRoom;
use roomlight_agent::node;
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_proto::v1;
use std::time::Duration;
use tokio_stream::StreamExt;
use tokio_util::sync::CancellationToken;

use crate::common;
use common::{TOKEN, wait};

fn message(body: v1::node_message::Body) -> v1::NodeMessage {
    v1::NodeMessage { body: Some(body) }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_that_never_reads_is_dropped_and_the_rounds_go_on_for_the_others() {
    let (problem, owners) = common::split_room(40, 3, 2);
    let room =
        VirtualRoom::new(Plant::new(problem.clone(), PlantConfig::default()).expect("plant"));
    let (listener, endpoint) = common::listen().await;
    let cancel = CancellationToken::new();
    let _stop = cancel.clone().drop_guard();
    let config = common::camera_config(Duration::from_millis(500), Duration::from_secs(2), 0);
    let model = common::model(problem, owners.clone());
    let (mut status, camera) =
        camera::serve(config, model, room.camera(), listener, cancel.child_token());
    let honest = tokio::spawn(node::run(
        common::node_config(&endpoint, "p0"),
        room.display(),
        cancel.child_token(),
    ));

    // p0 is attached and the rounds run before p1 joins: a status showing one projector after
    // p1's admission then means p1 was dropped, not that p0 is still on its way.
    wait(&mut status, Duration::from_secs(30), |s| {
        s.live_projectors == 1 && s.captures >= 1
    })
    .await;

    // p1 answers every round without reading its stream: it acknowledges every frame at once
    // (the largest sequence number) and sends zero contributions for the round after each
    // status, so the rounds never wait for it. A small HTTP/2 window keeps the bytes in flight
    // to it few.
    let channel = tonic::transport::Endpoint::from_shared(endpoint.clone())
        .expect("endpoint")
        .initial_stream_window_size(65_535)
        .initial_connection_window_size(65_535)
        .connect()
        .await
        .expect("connect");
    let mut client = v1::room_client::RoomClient::new(channel);
    let (tx, rx) = tokio::sync::mpsc::channel(64);
    tx.send(message(v1::node_message::Body::Hello(v1::Hello {
        protocol_version: roomlight_proto::PROTOCOL_VERSION,
        room: "lab".into(),
        token: TOKEN.into(),
        projector_id: "p1".into(),
        ..Default::default()
    })))
    .await
    .expect("queue hello");
    tx.send(message(v1::node_message::Body::Shown(v1::Shown {
        seq: u64::MAX,
        pattern: false,
    })))
    .await
    .expect("queue shown");
    let mut inbound = client
        .attach(tokio_stream::wrappers::ReceiverStream::new(rx))
        .await
        .expect("admitted")
        .into_inner();
    let mut rounds = status.clone();
    let p1_nodes = owners["p1"].clone();
    let answering = tokio::spawn(async move {
        let contributions = |round: u64| {
            let nodes = p1_nodes
                .iter()
                .map(|&node| v1::NodeChange {
                    node,
                    change: Some(v1::Rgb::default()),
                })
                .collect();
            vec![message(v1::node_message::Body::Contribution(
                v1::Contribution { round, nodes },
            ))]
        };
        let mut heartbeat = tokio::time::interval(Duration::from_millis(200));
        let mut outgoing = contributions(1);
        loop {
            for m in outgoing.drain(..) {
                if tx.send(m).await.is_err() {
                    return;
                }
            }
            // Its heartbeats keep it attached: it is dropped for lagging, not for silence.
            tokio::select! {
                _ = heartbeat.tick() => {
                    let beat = v1::Heartbeat { sent_unix_ms: 0 };
                    outgoing.push(message(v1::node_message::Body::Heartbeat(beat)));
                }
                changed = rounds.changed() => match changed {
                    Ok(()) => outgoing = contributions(rounds.borrow().round + 1),
                    Err(_) => return,
                },
            }
        }
    });

    // (No status need show both: under load the watch may skip to after p1 was dropped. So
    // the capture count at its admission marks the statuses that came after it.)
    let admitted_at = status.borrow_and_update().captures;
    // Its queue fills within some hundred rounds; then it is dropped and p0 goes on alone.
    let dropped = wait(&mut status, Duration::from_secs(60), |s| {
        s.live_projectors == 1 && s.captures >= admitted_at + 2
    })
    .await;
    wait(&mut status, Duration::from_secs(30), |s| {
        s.captures >= dropped.captures + 5 && s.live_projectors == 1
    })
    .await;
    answering.abort();

    // It was told why: read what it was sent; the last message is a goodbye for lagging.
    let mut last = None;
    let mut errors = 0;
    let read = tokio::time::timeout(Duration::from_secs(30), async {
        while let Some(Ok(m)) = inbound.next().await {
            errors += usize::from(matches!(m.body, Some(v1::room_message::Body::Errors(_))));
            last = m.body;
        }
    })
    .await;
    // It took part in the rounds until its queue was full (256 messages, one a round).
    assert!(
        errors >= 200,
        "only {errors} errors sent before it was dropped"
    );
    assert!(read.is_ok(), "the dropped node's stream did not end");
    match last {
        Some(v1::room_message::Body::Goodbye(g)) => assert_eq!(g.reason, "lagging"),
        other => panic!("last message to the lagging node: {other:?}"),
    }

    cancel.cancel();
    tokio::time::timeout(Duration::from_secs(10), camera)
        .await
        .expect("camera agent stops in time")
        .expect("task")
        .expect("clean stop");
    let _ = tokio::time::timeout(Duration::from_secs(5), honest).await;
}
