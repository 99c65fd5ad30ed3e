//! A node agent's side of per-pixel shading, against a scripted camera agent on loopback: after
//! its Welcome and an Assign with weights, a Shade that does not fit its display is ignored and
//! not acknowledged (the display keeps its gains), a valid one steps the gains the display draws
//! with and is acknowledged as a pattern, and a reset alone brings the nodes' own light back.
//! With the blocks' light sent and its node at full red, a step asking more red takes the
//! closest colour the display can still give.

use roomlight_agent::hardware::{Assignment, Display, Gains};
use roomlight_agent::node;
use roomlight_core::LinearRgb;
use roomlight_proto::convert::{to_rgb, to_sparse};
use roomlight_proto::{PROTOCOL_VERSION, v1};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::mpsc;
use tokio_stream::StreamExt;
use tokio_util::sync::CancellationToken;

use crate::common;

const W: u32 = 40;
const H: u32 = 20;

/// What the display was last told to shade with (`Some(None)`: told to draw without gains).
type Told = Arc<Mutex<Vec<Option<Gains>>>>;

/// A display of `W`×`H` pixels that records its shading.
struct Recording(Told);

impl Display for Recording {
    fn show(&mut self, _: u32, _: LinearRgb) {}

    fn assign(&mut self, _: &Assignment) {}

    fn shade(&mut self, gains: Option<&Gains>) {
        self.0.lock().expect("display log").push(gains.cloned());
    }

    fn resolution(&self) -> Option<(u32, u32)> {
        Some((W, H))
    }
}

/// A camera agent that sends `script` after the node's Hello and passes on every node message.
#[derive(Clone)]
struct Scripted {
    script: Vec<v1::RoomMessage>,
    heard: mpsc::UnboundedSender<v1::NodeMessage>,
}

type Stream = std::pin::Pin<
    Box<dyn tokio_stream::Stream<Item = Result<v1::RoomMessage, tonic::Status>> + Send>,
>;

#[tonic::async_trait]
impl v1::room_server::Room for Scripted {
    type AttachStream = Stream;

    async fn attach(
        &self,
        request: tonic::Request<tonic::Streaming<v1::NodeMessage>>,
    ) -> Result<tonic::Response<Stream>, tonic::Status> {
        let mut inbound = request.into_inner();
        let heard = self.heard.clone();
        tokio::spawn(async move {
            while let Some(Ok(m)) = inbound.next().await {
                let _ = heard.send(m);
            }
        });
        let script = self.script.clone();
        let stream = tokio_stream::iter(script.into_iter().map(Ok)).chain(tokio_stream::pending());
        Ok(tonic::Response::new(Box::pin(stream)))
    }
}

fn room(body: v1::room_message::Body) -> v1::RoomMessage {
    v1::RoomMessage { body: Some(body) }
}

/// Ratios for the `W`×`H` display (3 × 2 blocks): red ×2 everywhere.
fn ratios(block: u32) -> Vec<u8> {
    [2.0f32, 1.0, 1.0]
        .repeat(6)
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .chain(std::iter::repeat_n(0, if block == 16 { 0 } else { 12 }))
        .collect()
}

/// A Shade of every block's ratios `r` at rate 1, no light.
fn shade_message(seq: u64, r: [f32; 3]) -> v1::Shade {
    v1::Shade {
        seq,
        block: 16,
        across: 3,
        down: 2,
        ratios: r.repeat(6).iter().flat_map(|v| v.to_le_bytes()).collect(),
        rate: 1.0,
        reset: false,
        light: Vec::new(),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_steps_its_gains_from_a_valid_shade_and_ignores_a_malformed_one() {
    let shade = |seq, block, ratios: Vec<u8>, reset| {
        room(v1::room_message::Body::Shade(v1::Shade {
            block,
            ratios,
            reset,
            ..shade_message(seq, [1.0; 3])
        }))
    };
    let script = vec![
        room(v1::room_message::Body::Welcome(v1::Welcome {
            protocol_version: PROTOCOL_VERSION,
            room: common::ROOM.into(),
            calibration_epoch: 1,
            heartbeat_ms: 200,
            state_accepted: false,
        })),
        room(v1::room_message::Body::Assign(v1::Assign {
            nodes: vec![v1::NodeAssignment {
                node: 0,
                chart: 0,
                pixels: (0..W * H).collect(),
                weights: vec![1.0; (W * H) as usize],
            }],
            width: W,
            height: H,
            gamma: Vec::new(),
        })),
        // Blocks of 8 pixels, and bytes for them: not this node's.
        shade(1, 8, ratios(8), false),
        shade(2, 16, ratios(16), false),
        shade(3, 0, Vec::new(), true),
        // The node at full red, asked for twice its red and a third more green.
        room(v1::room_message::Body::Attenuation(v1::Attenuation {
            node: 0,
            p: Some(to_sparse(&[0], &[LinearRgb::splat(0.5)])),
            s: Some(to_sparse(&[0], &[LinearRgb::splat(0.5)])),
            start: Some(to_rgb(LinearRgb([1.0, 0.4, 0.1]))),
        })),
        room(v1::room_message::Body::Shade(v1::Shade {
            light: [[0.36f32, 0.14, 0.03], [0.18, 0.105, 0.03]]
                .concat()
                .repeat(6)
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
            ..shade_message(4, [2.0, 0.14 / 0.105, 1.0])
        })),
    ];
    let (heard, mut hearing) = mpsc::unbounded_channel();
    let cancel = CancellationToken::new();
    let _stop = cancel.clone().drop_guard();
    let endpoint = common::serve_fake_room(Scripted { script, heard }, cancel.child_token()).await;
    let told: Told = Arc::default();
    let config = common::node_config(&endpoint, "p0");
    tokio::spawn(node::run(
        config,
        Recording(told.clone()),
        cancel.child_token(),
    ));
    // Every pattern the node acknowledged, until the reset's (the last scripted).
    let shown = tokio::time::timeout(Duration::from_secs(20), async {
        let mut shown = Vec::new();
        while let Some(m) = hearing.recv().await {
            if let Some(v1::node_message::Body::Shown(s)) = m.body
                && s.pattern
            {
                shown.push(s.seq);
                if s.seq == 4 {
                    return shown;
                }
            }
        }
        shown
    })
    .await
    .expect("the last Shade acknowledged within the deadline");
    assert_eq!(
        shown,
        vec![2, 3, 4],
        "the malformed Shade is not acknowledged"
    );
    let told = told.lock().expect("display log").clone();
    assert_eq!(told.len(), 3, "{told:?}");
    let stepped = told[0].as_ref().expect("gains drawn with");
    for (x, y) in [(0, 0), (W - 1, H - 1), (20, 10)] {
        let g = stepped.at(x, y);
        assert!(
            (g[0] - 2.0).abs() < 1e-6 && (g[1] - 1.0).abs() < 1e-6 && (g[2] - 1.0).abs() < 1e-6,
            "({x}, {y}): {g:?}"
        );
    }
    assert!(told[1].is_none(), "a reset draws the nodes' own light");
    // Red is drawn at full light: its gain holds; green comes down from the 1.33 its ratio
    // asks (the LEDs' hue is closer that way) rather than up to it.
    let closest = told[2].as_ref().expect("gains drawn with").at(20, 10);
    assert!((closest[0] - 1.0).abs() < 1e-3, "{closest:?}");
    assert!(closest[1] < 1.0, "{closest:?}");
}
