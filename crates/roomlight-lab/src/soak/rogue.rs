//! The soak's misbehaving peer: it attaches to the camera agent with the room's token as a
//! projector of the room that is absent, says it shows its frame, and answers every round's
//! errors with garbage (NaN and 1e300 changes for its own nodes, a change for a node it does
//! not own). The camera agent must tell it `Goodbye("malformed message: …")` and drop it.

use anyhow::{Context, Result, bail};
use roomlight_proto::{PROTOCOL_VERSION, v1};
use std::time::Duration;
use tokio::sync::mpsc;
use tokio_stream::StreamExt;
use tokio_stream::wrappers::ReceiverStream;

/// Who the peer claims to be and what it sends.
pub struct Rogue {
    pub endpoint: String,
    pub room: String,
    pub token: String,
    pub projector: String,
    /// Its projector's nodes.
    pub nodes: Vec<u32>,
    /// A node of another projector.
    pub foreign: u32,
}

fn message(body: v1::node_message::Body) -> v1::NodeMessage {
    v1::NodeMessage { body: Some(body) }
}

fn rgb(r: f64) -> Option<v1::Rgb> {
    Some(v1::Rgb { r, g: 0.0, b: 0.0 })
}

impl Rogue {
    /// Attaches, misbehaves, and returns the reason of the camera agent's Goodbye; an error if
    /// it was refused, not dropped within `within`, or dropped without a Goodbye.
    pub async fn misbehave(&self, within: Duration) -> Result<String> {
        let mut client = v1::room_client::RoomClient::connect(self.endpoint.clone())
            .await
            .with_context(|| format!("connecting to {}", self.endpoint))?;
        let (tx, rx) = mpsc::channel(64);
        let hello = v1::Hello {
            protocol_version: PROTOCOL_VERSION,
            room: self.room.clone(),
            token: self.token.clone(),
            projector_id: self.projector.clone(),
            ..Default::default()
        };
        tx.send(message(v1::node_message::Body::Hello(hello)))
            .await
            .context("queueing the Hello")?;
        let inbound = client
            .attach(ReceiverStream::new(rx))
            .await
            .with_context(|| format!("attaching as {}", self.projector))?
            .into_inner();
        tokio::time::timeout(within, self.answer(inbound, tx))
            .await
            .with_context(|| format!("still attached {within:?} later"))?
    }

    async fn answer(
        &self,
        mut inbound: tonic::Streaming<v1::RoomMessage>,
        tx: mpsc::Sender<v1::NodeMessage>,
    ) -> Result<String> {
        // Its start is on its display (it shows nothing, but says so): rounds include it.
        let shown = |seq| {
            message(v1::node_message::Body::Shown(v1::Shown {
                seq,
                pattern: false,
            }))
        };
        let _ = tx.send(shown(0)).await;
        let mut heartbeat = tokio::time::interval(Duration::from_millis(100));
        loop {
            let m = tokio::select! {
                m = inbound.next() => m,
                _ = heartbeat.tick() => {
                    let beat = v1::Heartbeat { sent_unix_ms: 0 };
                    let _ = tx.send(message(v1::node_message::Body::Heartbeat(beat))).await;
                    continue;
                }
            };
            match m.map(|m| m.map(|m| m.body)) {
                Some(Ok(Some(v1::room_message::Body::Errors(e)))) => {
                    let c = v1::Contribution {
                        round: e.round,
                        nodes: self.garbage(e.round),
                    };
                    let _ = tx
                        .send(message(v1::node_message::Body::Contribution(c)))
                        .await;
                    let _ = tx.send(shown(e.round)).await;
                }
                Some(Ok(Some(v1::room_message::Body::Goodbye(g)))) => return Ok(g.reason),
                Some(Ok(_)) => {}
                Some(Err(status)) => bail!("the stream failed without a Goodbye: {status}"),
                None => bail!("the stream ended without a Goodbye"),
            }
        }
    }

    fn garbage(&self, round: u64) -> Vec<v1::NodeChange> {
        let bad = if round.is_multiple_of(2) {
            f64::NAN
        } else {
            1e300
        };
        let mut nodes: Vec<v1::NodeChange> = self
            .nodes
            .iter()
            .map(|&node| v1::NodeChange {
                node,
                change: rgb(bad),
            })
            .collect();
        nodes.push(v1::NodeChange {
            node: self.foreign,
            change: rgb(0.5),
        });
        nodes
    }
}
