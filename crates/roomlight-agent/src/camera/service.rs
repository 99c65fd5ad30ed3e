//! The gRPC `Room.Attach` service: the handshake (Hello → checks → Welcome, Assign and each
//! node's attenuation), admission into the registry, and the per-peer reader task that turns a
//! node agent's messages into registry updates (readiness, its display's state) and
//! contributions. It knows nothing of rounds or
//! the camera: the round loop reads what the readers leave in the registry and the channel.
//!
//! The token comes as `authorization: Bearer TOKEN` metadata, checked before any message of the
//! stream is read; a stream without it is authenticated by its Hello's token (node agents that
//! predate the metadata). With mTLS, a node's certificate must be valid for the projector its
//! Hello names.
//!
//! Nothing a peer chose is logged or echoed before its token is checked (in constant time):
//! refusals are logged at a limited rate with the peer's id escaped and cut. An admitted peer
//! that sends what the protocol forbids (nodes it does not own, values that are not finite or
//! beyond ±1) is told why in a Goodbye and disconnected; the round goes on without it.

use super::listener::Handshake;
use super::registry::{Peer, PeerGuard};
use super::{Contribution, Shared};
use crate::hardware::DisplayReport;
use prost::Message;
use roomlight_proto::bounds::{MAX_PROJECTOR_ID, check_projector_id, cut, escaped, token_matches};
use roomlight_proto::convert::{check_display_status, from_node_changes};
use roomlight_proto::refusal::Refusal;
use roomlight_proto::{PROTOCOL_VERSION, v1};
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;
use tokio_stream::{Stream, StreamExt};
use tonic::{Request, Response, Status, Streaming};

/// Rounds a node agent may fall behind in reading its stream before it is told it lags and is
/// dropped (the rounds never wait for one node). A round queues one `Errors` message per node
/// agent, so its queue holds this many rounds, beyond its handshake and one attenuation message
/// per node (what a relight of the room sends at once); a healthy node is never near it.
const LAG_ROUNDS: usize = 256;

/// The gRPC service.
#[derive(Clone)]
pub(super) struct Service(Arc<Shared>);

impl Service {
    pub(super) fn new(shared: Arc<Shared>) -> Self {
        Self(shared)
    }
}

type AttachStream = Pin<Box<dyn Stream<Item = Result<v1::RoomMessage, Status>> + Send>>;

fn room_message(body: v1::room_message::Body) -> Result<v1::RoomMessage, Status> {
    Ok(v1::RoomMessage { body: Some(body) })
}

#[tonic::async_trait]
impl v1::room_server::Room for Service {
    type AttachStream = AttachStream;

    async fn attach(
        &self,
        request: Request<Streaming<v1::NodeMessage>>,
    ) -> Result<Response<AttachStream>, Status> {
        let shared = self.0.clone();
        let handshake = request.extensions().get::<Handshake>().cloned();
        // The metadata's token, before anything of the stream is read.
        let bearer = check_bearer(&shared, request.metadata())?;
        let mut inbound = request.into_inner();
        let first = tokio::time::timeout(
            shared.config.deadline.max(Duration::from_secs(1)),
            inbound.next(),
        )
        .await
        .map_err(|_| Refusal::NoHello)?
        .ok_or(Refusal::EndedBeforeHello)??;
        let Some(v1::node_message::Body::Hello(hello)) = first.body else {
            return Err(Refusal::FirstNotHello.into());
        };
        let client_cert = handshake.as_ref().and_then(Handshake::client_cert);
        let checked = check_hello(&shared, &hello, bearer)
            .and_then(|nodes| check_certificate(client_cert, &hello).map(|()| nodes));
        let nodes = checked.inspect_err(|refusal| {
            if let Some(count) = shared.refusals.hit() {
                // The id is the peer's choice: escaped and cut, never raw.
                let projector = escaped(&hello.projector_id);
                let refusal = refusal.row().key;
                tracing::warn!(%projector, refusal, count, "refused (count since the last report)");
            }
        })?;
        let calibrated = !shared.live().uncalibrated.contains(&hello.projector_id);
        let greeting = greeting(&shared, &hello, &nodes, calibrated);
        // The greeting is queued before admission, so that it precedes anything the rounds send.
        let (tx, rx) = mpsc::channel(greeting.len() + nodes.len() + LAG_ROUNDS);
        for m in greeting {
            // The queue was made to hold the greeting: this cannot fail.
            if tx.try_send(m).is_err() {
                return Err(Refusal::LeftDuringHandshake.into());
            }
        }
        let projector = hello.projector_id.clone();
        let peer = Peer::new(tx, &hello, shared.cancel.child_token());
        let guard = match shared
            .registry
            .admit(&projector, peer, nodes.clone(), calibrated)
        {
            Ok(guard) => guard,
            Err(_) => {
                let refusal = Refusal::AlreadyAttached {
                    projector: projector.clone(),
                    room: shared.config.room.clone(),
                };
                if let Some(count) = shared.refusals.hit() {
                    let key = refusal.row().key;
                    tracing::warn!(%projector, refusal = key, count, "refused (count since the last report)");
                }
                return Err(refusal.into());
            }
        };
        // Authenticated and admitted: this connection is no longer closed at its handshake
        // timeout.
        if let Some(handshake) = handshake {
            handshake.admitted();
        }
        tracing::info!(%projector, nodes = nodes.len(), "joined");
        let tracker = shared.tracker.clone();
        tracker.spawn(read_node(shared, guard, inbound));
        Ok(Response::new(Box::pin(ReceiverStream::new(rx))))
    }
}

/// The `authorization: Bearer TOKEN` metadata, checked before anything of the stream is read:
/// `Ok(true)` when it holds the room's token, `Ok(false)` when there is none (the Hello's token
/// decides), refused when it holds anything else.
fn check_bearer(shared: &Shared, metadata: &tonic::metadata::MetadataMap) -> Result<bool, Status> {
    let Some(value) = metadata.get("authorization") else {
        return Ok(false);
    };
    let token = value.to_str().ok().and_then(|v| v.strip_prefix("Bearer "));
    if token.is_some_and(|t| token_matches(t, &shared.config.token)) {
        return Ok(true);
    }
    if let Some(count) = shared.refusals.hit() {
        let refusal = Refusal::WrongToken.row().key;
        tracing::warn!(
            refusal,
            count,
            "refused before the Hello: bearer metadata (count since the last report)"
        );
    }
    Err(Refusal::WrongToken.into())
}

/// mTLS: a node that showed a certificate (verified against the room CA by the TLS handshake)
/// may only be the projector it names.
fn check_certificate(
    cert: Option<&tokio_rustls::rustls::pki_types::CertificateDer<'static>>,
    hello: &v1::Hello,
) -> Result<(), Refusal> {
    let Some(cert) = cert else {
        return Ok(());
    };
    crate::tls::certificate_names(cert, &hello.projector_id).map_err(|names| {
        Refusal::CertificateName {
            projector: cut(&hello.projector_id, MAX_PROJECTOR_ID).to_string(),
            certificate: names,
        }
    })
}

/// Checks a Hello: the token first (in constant time: nothing the peer chose is read, logged
/// or echoed before), then protocol version, room, the projector id's form, and that the
/// projector is known (or can be calibrated over the wire, then marked uncalibrated). Its
/// nodes (none yet for a projector to calibrate). The caller logs a refusal, rate-limited.
///
/// `bearer`: the stream's metadata carried the token (checked already); the Hello's is then not
/// read.
fn check_hello(shared: &Shared, hello: &v1::Hello, bearer: bool) -> Result<Vec<u32>, Refusal> {
    let config = &shared.config;
    if !bearer && !token_matches(&hello.token, &config.token) {
        return Err(Refusal::WrongToken);
    }
    if hello.protocol_version != PROTOCOL_VERSION {
        return Err(Refusal::ProtocolVersion {
            got: hello.protocol_version,
            speaks: PROTOCOL_VERSION,
        });
    }
    if hello.room != config.room {
        return Err(Refusal::OtherRoom {
            // Echoed to the peer only (it was authenticated), cut to a bounded length.
            asked: cut(&hello.room, MAX_PROJECTOR_ID).to_string(),
            room: config.room.clone(),
        });
    }
    check_projector_id(&hello.projector_id).map_err(|what| Refusal::Malformed { what })?;
    let known = shared.live().owners.get(&hello.projector_id).cloned();
    match known {
        Some(nodes) => Ok(nodes),
        // Calibrated over the wire once it is here: it must say how large it is.
        None if shared.survey.is_some() => {
            if hello.width == 0 || hello.height == 0 {
                return Err(Refusal::NoResolution {
                    projector: hello.projector_id.clone(),
                    room: config.room.clone(),
                });
            }
            shared
                .live_mut()
                .uncalibrated
                .insert(hello.projector_id.clone());
            Ok(Vec::new())
        }
        None => Err(Refusal::UnknownProjector {
            projector: hello.projector_id.clone(),
            room: config.room.clone(),
        }),
    }
}

/// Welcome, the node list, then each node's column and s on its support (for a hot projector not
/// yet measured: after its calibration).
fn greeting(
    shared: &Shared,
    hello: &v1::Hello,
    nodes: &[u32],
    calibrated: bool,
) -> Vec<Result<v1::RoomMessage, Status>> {
    let config = &shared.config;
    // The values it remembers, when they are kept: the console's view of its frame.
    if let Some(state) = hello
        .state
        .as_ref()
        .filter(|st| st.calibration_epoch == config.calibration_epoch)
    {
        let mut values = shared.values();
        for n in state.nodes.iter().filter(|n| nodes.contains(&n.node)) {
            if let Ok(x) = roomlight_proto::convert::from_rgb("state", n.x.as_ref()) {
                values.insert(n.node, x.clamp_unit());
            }
        }
    }
    let live = shared.live();
    let assign = match live.assignments.get(&hello.projector_id) {
        Some(a) => super::calibration::assign_message(a),
        None => v1::Assign {
            nodes: nodes
                .iter()
                .map(|&n| v1::NodeAssignment {
                    node: n,
                    chart: n,
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        },
    };
    let mut messages = vec![
        room_message(v1::room_message::Body::Welcome(v1::Welcome {
            protocol_version: PROTOCOL_VERSION,
            room: config.room.clone(),
            calibration_epoch: config.calibration_epoch,
            heartbeat_ms: u32::try_from(config.heartbeat.as_millis()).unwrap_or(u32::MAX),
            // A node's values are worth keeping only under the same calibration.
            state_accepted: hello
                .state
                .as_ref()
                .is_some_and(|st| st.calibration_epoch == config.calibration_epoch),
        })),
        room_message(v1::room_message::Body::Assign(assign)),
    ];
    if calibrated {
        let bodies = live.attenuation_bodies(nodes);
        shared.note_starts(&bodies);
        messages.extend(bodies.into_iter().map(room_message));
    }
    messages
}

/// Reads one node agent's stream until it ends, errs, or misses three heartbeats; the guard
/// removes the peer whichever way it ends (and its display leaves the status).
async fn read_node(shared: Arc<Shared>, guard: PeerGuard, mut inbound: Streaming<v1::NodeMessage>) {
    let projector = guard.projector().to_string();
    let silence = 3 * shared.config.heartbeat;
    loop {
        let next = tokio::select! {
            () = guard.cancelled().cancelled() => break,
            next = tokio::time::timeout(silence, inbound.next()) => next,
        };
        let next = match next {
            Err(_) => {
                tracing::warn!(%projector, "no heartbeat: leaves");
                break;
            }
            Ok(None) => break,
            Ok(Some(Err(status))) => {
                tracing::info!(%projector, %status, "stream ended");
                break;
            }
            Ok(Some(Ok(m))) => {
                shared
                    .bytes_in
                    .fetch_add(m.encoded_len() as u64, Ordering::Relaxed);
                m
            }
        };
        match next.body {
            Some(v1::node_message::Body::Shown(s)) => {
                guard.shown(s.seq, s.pattern);
            }
            Some(v1::node_message::Body::Contribution(c)) => {
                let owned = guard.owned(c.nodes.iter().map(|e| e.node));
                // Anything but a well-formed contribution for its own nodes is not a slip but
                // a broken or hostile peer: all of the message is dropped, the peer told why
                // and disconnected, and the round goes on without its nodes.
                let refused = match from_node_changes(c.nodes, |n| owned.contains(&n)) {
                    Ok(batch) if batch.refused.is_empty() => Ok(batch.entries),
                    Ok(batch) => Err(batch.refused[0].to_string()),
                    Err(e) => Err(e.to_string()),
                };
                let entries = match refused {
                    Ok(entries) => entries,
                    Err(what) => {
                        let refusal = Refusal::Malformed { what };
                        guard.goodbye(refusal.to_string());
                        if let Some(count) = shared.misbehaving.hit() {
                            tracing::warn!(%projector, %refusal, count, "disconnected for a malformed contribution; its contributions dropped (count since the last report)");
                        }
                        break;
                    }
                };
                if entries.is_empty() {
                    continue;
                }
                let contribution = Contribution {
                    round: c.round,
                    nodes: entries,
                };
                if shared.contributions.send(contribution).await.is_err() {
                    break;
                }
            }
            Some(v1::node_message::Body::DisplayStatus(d)) => {
                display_status(&shared, &guard, d);
            }
            Some(v1::node_message::Body::Goodbye(g)) => {
                tracing::info!(%projector, reason = %escaped(&g.reason), "goodbye");
                break;
            }
            Some(v1::node_message::Body::Heartbeat(_))
            | Some(v1::node_message::Body::Hello(_))
            | None => {}
        }
    }
    // It left: its display, lost or not, is no longer the room's concern.
    drop(guard);
    shared.publish_displays();
}

/// A node agent's report of its display (read only after the stream was authenticated by its
/// Hello): checked at the boundary, recorded in the registry and published; a change between
/// showing and lost is logged once. The projector stays attached either way.
fn display_status(shared: &Shared, guard: &PeerGuard, d: v1::DisplayStatus) {
    let projector = guard.projector();
    let state = match check_display_status(&d) {
        Ok(state) => state,
        Err(e) => {
            if let Some(count) = shared.misbehaving.hit() {
                tracing::warn!(%projector, error = %e, count, "malformed display status: ignored (count since the last report)");
            }
            return;
        }
    };
    let report = match state {
        v1::DisplayState::Lost => DisplayReport::Lost {
            output: d.output,
            reason: d.reason,
        },
        _ => DisplayReport::Showing { output: d.output },
    };
    let Some(previous) = guard.display(report.clone()) else {
        return;
    };
    let was_lost = matches!(previous, Some(DisplayReport::Lost { .. }));
    match &report {
        DisplayReport::Lost { output, reason } if !was_lost => {
            let (output, reason) = (escaped(output), escaped(reason));
            tracing::warn!(%projector, %output, %reason, "display lost: the projector stays attached; its node agent retries it");
        }
        DisplayReport::Showing { output } if was_lost => {
            tracing::info!(%projector, output = %escaped(output), "display back");
        }
        _ => {}
    }
    shared.publish_displays();
}
