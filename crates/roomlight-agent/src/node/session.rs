//! One session of a node agent with the camera agent: the handshake (Hello with the values it
//! remembers, then Welcome, Assign and each node's attenuation), the message loop (errors in,
//! steps, contributions and acknowledgements out; calibration patterns shown as sent), and
//! beside it heartbeats and the display's state (`DisplayStatus` at the start and on every
//! change), each from a task of its own so that a display slow to present (lost, waiting to
//! come back) neither silences the node nor delays the report.
//!
//! It knows nothing of reconnecting or of the state file's format: it ends with a
//! [`SessionEnd`] or an error, and keeps what must outlive it in the node agent's [`Memory`].

use super::NodeConfig;
use super::state::Memory;
use super::wire::{
    Wire, assignment_from_wire, display_status_to_wire, pattern_from_wire, shade_from_wire,
};
use crate::AgentError;
use crate::hardware::{Display, DisplayFeed, Gains};
use roomlight_core::{AttenuationColumn, LinearRgb, NodeState};
use roomlight_proto::convert::{
    from_node_errors, from_rgb, from_sparse, node_change, to_rgb, to_sparse,
};
use roomlight_proto::refusal::Refusal;
use roomlight_proto::{PROTOCOL_VERSION, v1};
use std::collections::HashMap;
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tokio_stream::StreamExt;
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;

/// Heartbeat period until the camera agent's Welcome gives its own.
const FIRST_HEARTBEAT: Duration = Duration::from_secs(1);

/// How a session with the camera agent ended.
#[derive(Debug)]
pub(super) enum SessionEnd {
    /// `cancel` fired: the node said goodbye.
    Cancelled,
    /// The camera agent ended the stream or went away.
    Closed,
}

fn message(body: v1::node_message::Body) -> v1::NodeMessage {
    v1::NodeMessage { body: Some(body) }
}

/// Queues a message to the camera agent; a closed queue means the stream is gone.
async fn send(
    tx: &mpsc::Sender<v1::NodeMessage>,
    body: v1::node_message::Body,
) -> Result<(), AgentError> {
    tx.send(message(body))
        .await
        .map_err(|_| AgentError::Protocol("the outgoing stream closed".into()))
}

/// Runs one session until `cancel`, the camera agent's goodbye or the end of the stream;
/// `admitted` is set once the camera agent welcomed it.
pub(super) async fn run(
    config: &NodeConfig,
    endpoint: &tonic::transport::Endpoint,
    display: &mut impl Display,
    cancel: &CancellationToken,
    memory: &mut Memory,
    admitted: &mut bool,
) -> Result<SessionEnd, AgentError> {
    // The largest message is an Assign of this projector's weights (8 bytes a pixel) or a
    // node's attenuation: refused from its length prefix, before anything is allocated.
    let limit = roomlight_proto::bounds::room_message_limit(display.resolution());
    let channel = endpoint
        .connect()
        .await
        .map_err(|e| mismatch(endpoint, e.into()))?;
    let mut client = v1::room_client::RoomClient::new(channel).max_decoding_message_size(limit);
    let (tx, rx) = mpsc::channel(256);
    send(&tx, hello(config, display, memory)).await?;
    let mut request = tonic::Request::new(ReceiverStream::new(rx));
    // The token before any message (docs/protocol.md); a token that is no header value goes in
    // the Hello only.
    if let Ok(bearer) = format!("Bearer {}", config.token).parse() {
        request.metadata_mut().insert("authorization", bearer);
    }
    let mut inbound = client
        .attach(request)
        .await
        .map_err(|e| mismatch(endpoint, e.into()))?
        .into_inner();
    // The side tasks end with the session, whichever way it ends.
    let side = cancel.child_token();
    let _stop_side = side.clone().drop_guard();
    let (period, period_rx) = watch::channel(FIRST_HEARTBEAT);
    tokio::spawn(heartbeats(tx.clone(), period_rx, side.clone()));
    if let Some(feed) = display.state_feed() {
        tokio::spawn(report_display(tx.clone(), feed, side));
    }
    let mut session = Session {
        config,
        display,
        memory,
        tx,
        assigned: Vec::new(),
        nodes: HashMap::new(),
        started: false,
        identify_until: None,
    };
    loop {
        let identify_until = session.identify_until;
        let next = tokio::select! {
            () = sleep_until_some(identify_until) => {
                session.identify(None).await;
                continue;
            }
            () = cancel.cancelled() => {
                let goodbye = v1::Goodbye { reason: "shutting down".into() };
                // The stream may already be gone; the node stops either way.
                let _ = send(&session.tx, v1::node_message::Body::Goodbye(goodbye)).await;
                return Ok(SessionEnd::Cancelled);
            }
            next = inbound.next() => next,
        };
        let Some(msg) = next.transpose()? else {
            return Ok(SessionEnd::Closed);
        };
        use v1::room_message::Body;
        match msg.body {
            Some(Body::Welcome(w)) => {
                *admitted = true;
                period.send_replace(session.welcome(&w));
            }
            Some(Body::Assign(a)) => session.assign(&a)?,
            Some(Body::Attenuation(a)) => session.attenuation(&a).await?,
            Some(Body::Errors(e)) => session.errors(e).await?,
            Some(Body::Show(show)) => session.show(show).await?,
            Some(Body::Shade(shade)) => session.shade(shade).await?,
            Some(Body::Identify(i)) => {
                let seconds = u64::from(i.seconds.clamp(1, 60));
                session.identify(Some(Duration::from_secs(seconds))).await;
            }
            Some(Body::Goodbye(g)) => {
                tracing::info!(reason = %g.reason, "the camera agent said goodbye");
                return Ok(SessionEnd::Closed);
            }
            None => {}
        }
    }
}

/// A failure to reach the camera agent, said as what it most likely is when the two ends do
/// not speak the same (plaintext against TLS, or the other way round): the connection was made
/// and then closed or garbled, with no refusal. Other errors are returned unchanged.
pub(super) fn mismatch(endpoint: &tonic::transport::Endpoint, e: AgentError) -> AgentError {
    if let AgentError::Status(status) = &e
        && (Refusal::from_status(status).is_some()
            || !matches!(
                status.code(),
                tonic::Code::Unavailable
                    | tonic::Code::Unknown
                    | tonic::Code::Internal
                    | tonic::Code::Cancelled
            ))
    {
        return e;
    }
    let mut causes = e.to_string();
    let mut source = std::error::Error::source(&e);
    while let Some(s) = source {
        causes.push_str(": ");
        causes.push_str(&s.to_string());
        source = s.source();
    }
    let lower = causes.to_lowercase();
    let elsewhere = [
        "connection refused",
        "timed out",
        "dns error",
        "no route",
        "unreachable",
        "certificate",
    ];
    if elsewhere.iter().any(|w| lower.contains(w)) {
        return e;
    }
    let at = endpoint.uri();
    AgentError::Protocol(if at.scheme_str() == Some("https") {
        format!(
            "the camera agent at {at} did not answer in TLS; does it lack tls in its config? ({causes})"
        )
    } else {
        format!(
            "the camera agent at {at} did not answer in plaintext; does it need tls? ({causes})"
        )
    })
}

/// Sends a heartbeat every period (the latest `period` says) until `stop`, the end of the
/// session (`period`'s sender dropped) or of the stream.
async fn heartbeats(
    tx: mpsc::Sender<v1::NodeMessage>,
    mut period: watch::Receiver<Duration>,
    stop: CancellationToken,
) {
    let mut ticker = tokio::time::interval(*period.borrow_and_update());
    loop {
        tokio::select! {
            () = stop.cancelled() => return,
            changed = period.changed() => {
                if changed.is_err() {
                    return;
                }
                ticker = tokio::time::interval(*period.borrow_and_update());
            }
            _ = ticker.tick() => {
                let beat = v1::node_message::Body::Heartbeat(v1::Heartbeat { sent_unix_ms: 0 });
                if send(&tx, beat).await.is_err() {
                    return;
                }
            }
        }
    }
}

/// Tells the camera agent the display's state now, then each change, until `stop` or the end
/// of the stream. The display logs its own losses; the camera agent records and publishes them.
async fn report_display(
    tx: mpsc::Sender<v1::NodeMessage>,
    mut feed: DisplayFeed,
    stop: CancellationToken,
) {
    let mut last = feed.now();
    loop {
        let body = v1::node_message::Body::DisplayStatus(display_status_to_wire(&last));
        if send(&tx, body).await.is_err() {
            return;
        }
        let next = tokio::select! {
            () = stop.cancelled() => return,
            next = feed.next(&last) => next,
        };
        match next {
            Some(report) => last = report,
            None => return,
        }
    }
}

/// The Hello that opens a session: who this is, its resolution, and the values (with their
/// calibration epoch and attenuation) it remembers, so a camera agent can resume it.
fn hello(config: &NodeConfig, display: &impl Display, memory: &Memory) -> v1::node_message::Body {
    let nodes = memory
        .values
        .iter()
        .map(|(&node, &x)| v1::NodeState {
            node,
            x: Some(to_rgb(x)),
            attenuation: memory
                .attenuation
                .get(&node)
                .map(|c| to_sparse(c.support(), c.values())),
        })
        .collect();
    v1::node_message::Body::Hello(v1::Hello {
        protocol_version: PROTOCOL_VERSION,
        room: config.room.clone(),
        token: config.token.clone(),
        projector_id: config.projector_id.clone(),
        width: display.resolution().map_or(0, |r| r.0),
        height: display.resolution().map_or(0, |r| r.1),
        kind: config.kind as i32,
        state: Some(v1::PersistedState {
            calibration_epoch: memory.epoch,
            nodes,
        }),
        ..Default::default()
    })
}

/// What one session knows beyond the node agent's memory.
struct Session<'a, D: Display> {
    config: &'a NodeConfig,
    display: &'a mut D,
    memory: &'a mut Memory,
    /// The outgoing stream.
    tx: mpsc::Sender<v1::NodeMessage>,
    /// The nodes the camera agent assigned to this projector.
    assigned: Vec<u32>,
    /// The running state of each node whose attenuation arrived.
    nodes: HashMap<u32, NodeState>,
    /// Whether the start (frame 0) has been acknowledged.
    started: bool,
    /// Showing the identify pattern until then.
    identify_until: Option<tokio::time::Instant>,
}

impl<D: Display> Session<'_, D> {
    /// Takes the room's terms; returns the heartbeat period it asks for.
    fn welcome(&mut self, w: &v1::Welcome) -> Duration {
        // Values from another calibration mean nothing now: start afresh.
        if !w.state_accepted {
            self.memory.forget_values();
        }
        self.memory.epoch = w.calibration_epoch;
        Duration::from_millis(u64::from(w.heartbeat_ms.max(50)))
    }

    fn assign(&mut self, a: &v1::Assign) -> Result<(), AgentError> {
        self.assigned = a.nodes.iter().map(|n| n.node).collect();
        // Remembered values of nodes that are not this projector's are not its to show (an
        // empty list: a projector still to be segmented over the wire).
        if !self.assigned.is_empty() {
            self.memory.keep_only(&self.assigned);
        }
        // Weights drawn by the camera agent (calibration over the wire): a malformed
        // assignment ends the session (the camera agent logs the stream's end).
        if a.width > 0 {
            let assignment = assignment_from_wire(a)?;
            // New nodes: shading starts over from their own light.
            if self.memory.gains.take().is_some() {
                self.display.shade(None);
            }
            self.display.assign(&assignment);
            self.memory.assignment = Some(assignment);
            self.memory.flush();
        }
        Ok(())
    }

    /// A node's attenuation column and white response: it starts (or, for a node already
    /// running, takes the new response), and once every assigned node has started the
    /// projector acknowledges its start.
    async fn attenuation(&mut self, a: &v1::Attenuation) -> Result<(), AgentError> {
        let (Some(p), Some(s)) = (a.p.as_ref(), a.s.as_ref()) else {
            return Err(AgentError::Protocol(format!(
                "attenuation of node {} lacks p or s",
                a.node
            )));
        };
        let (support, values) =
            from_sparse("attenuation p", p).map_err(|e| AgentError::Protocol(e.to_string()))?;
        let (_, white) =
            from_sparse("attenuation s", s).map_err(|e| AgentError::Protocol(e.to_string()))?;
        let column = AttenuationColumn::new(support, values)?;
        // Its own last value, else the camera agent's start, else the configured one.
        let offered = match a
            .start
            .as_ref()
            .map(|v| from_rgb("attenuation start", Some(v)))
            .transpose()
        {
            Ok(v) => v.map(LinearRgb::clamp_unit),
            Err(e) => {
                tracing::warn!(node = a.node, error = %e, "malformed start: ignored");
                None
            }
        };
        // A node already running (new `s` after a projector joined) keeps its value.
        let start = self
            .nodes
            .get(&a.node)
            .map(NodeState::shown)
            .or_else(|| self.memory.values.get(&a.node).copied())
            .or(offered)
            .unwrap_or(self.config.start);
        self.memory.attenuation.insert(a.node, column.clone());
        let state = NodeState::new(column, &white, self.config.rule, start)?;
        self.display.show(a.node, state.shown());
        self.nodes.insert(a.node, state);
        if !self.started
            && !self.assigned.is_empty()
            && self.assigned.iter().all(|n| self.nodes.contains_key(n))
        {
            self.started = true;
            acknowledge(self.display, &self.tx, 0, false).await?;
        }
        Ok(())
    }

    /// A round's errors for this projector's nodes: each node steps and shows its new value,
    /// the changes of value go back in one message (the camera agent forms the contributions
    /// from its columns), and the round's frame is acknowledged. An entry for a node it does
    /// not own, or malformed, is refused (logged) and that node holds; valid errors a node
    /// cannot use (not as many as its support has patches) leave it where it is, reporting a
    /// zero change.
    async fn errors(&mut self, e: v1::Errors) -> Result<(), AgentError> {
        let nodes = &self.nodes;
        let batch = match from_node_errors(e.nodes, |n| nodes.contains_key(&n)) {
            Ok(batch) => batch,
            Err(err) => {
                tracing::warn!(round = e.round, error = %err, "malformed errors: ignored");
                return Ok(());
            }
        };
        for err in &batch.refused {
            tracing::warn!(round = e.round, error = %err, "errors refused: the node holds");
        }
        let mut contributions = Vec::with_capacity(batch.entries.len());
        for (node, errors) in batch.entries {
            let Some(state) = self.nodes.get_mut(&node) else {
                continue;
            };
            let delta = state.update(&errors, e.restart).unwrap_or(LinearRgb::ZERO);
            self.display.show(node, state.shown());
            self.memory.values.insert(node, state.shown());
            contributions.push(node_change(node, delta));
        }
        let contribution = v1::Contribution {
            round: e.round,
            nodes: contributions,
        };
        send(&self.tx, v1::node_message::Body::Contribution(contribution)).await?;
        self.memory.maybe_flush();
        acknowledge(self.display, &self.tx, e.round, false).await
    }

    /// A calibration pattern: node values shown as they are, without touching the node states
    /// (values for nodes it does not own, or not finite, are refused), or a whole-frame
    /// pattern. One the display cannot show is not acknowledged.
    /// A shading pass's ratios: the projector's gains step (from flat after a reset) and its
    /// node values are drawn with them from now on; acknowledged like a pattern once on the
    /// display. Malformed, or for a display that draws no pixels: ignored (logged) and not
    /// acknowledged, the gains as they were.
    async fn shade(&mut self, shade: v1::Shade) -> Result<(), AgentError> {
        let Some(size) = self.display.resolution() else {
            tracing::warn!(
                seq = shade.seq,
                "shading asked: this display draws no pixels"
            );
            return Ok(());
        };
        let step = match shade_from_wire(&shade, size) {
            Ok(step) => step,
            Err(e) => {
                tracing::warn!(seq = shade.seq, error = %e, "malformed Shade: ignored");
                return Ok(());
            }
        };
        let gains = &mut self.memory.gains;
        if step.reset || gains.as_ref().is_none_or(|g| g.size() != size) {
            *gains = Gains::flat(size.0, size.1);
        }
        match (step.ratios, gains.clone()) {
            (Some(ratios), Some(mut g)) => {
                // The nodes' values now (a node not stepped yet shows its start).
                let mut values: HashMap<u32, LinearRgb> = self.memory.values.clone();
                values.extend(self.nodes.iter().map(|(n, s)| (*n, s.shown())));
                let assignment = self.memory.assignment.clone();
                let rate = step.rate;
                // A whole frame drawn and a colour chosen per block short of headroom: off the
                // runtime's threads, so that heartbeats go on meanwhile.
                let stepped = tokio::task::spawn_blocking(move || {
                    let headroom = assignment.and_then(|a| {
                        let values: Vec<(u32, LinearRgb)> = values.into_iter().collect();
                        let light: Vec<[f64; 3]> = a
                            .light_shaded(&values, Some(&g))
                            .into_iter()
                            .map(|l| l.0)
                            .collect();
                        roomlight_calib::shading::headroom(&light, a.width, a.height)
                    });
                    let known = headroom.is_some();
                    g.step_within(&ratios, rate, headroom.as_deref())
                        .map(|short| (g, ratios.read(), known.then_some(short)))
                })
                .await;
                let (g, (read, blocks), short) = match stepped {
                    Ok(Ok(stepped)) => stepped,
                    Ok(Err(e)) => {
                        tracing::warn!(seq = shade.seq, error = %e, "Shade refused: ignored");
                        return Ok(());
                    }
                    Err(e) => {
                        tracing::error!(seq = shade.seq, error = %e, "shading step failed: ignored");
                        return Ok(());
                    }
                };
                let g = self.memory.gains.insert(g);
                let (lo, hi) = g.spread();
                tracing::info!(
                    read,
                    blocks,
                    short_of_headroom = ?short,
                    "shaded: gains {lo:.2}–{hi:.2} (5th–95th percentile)"
                );
                self.display.shade(Some(g));
            }
            // A reset alone: the nodes' light as it is.
            _ => self.display.shade(None),
        }
        // A restarted node draws with them before it reconnects.
        self.memory.flush();
        acknowledge(self.display, &self.tx, shade.seq, true).await
    }

    /// Shows the identify pattern for `seconds` (`None`: its time is up, the frame returns).
    async fn identify(&mut self, seconds: Option<Duration>) {
        let projector = self.config.projector_id.clone();
        let on = seconds.is_some();
        if !self.display.identify(&projector, on) {
            tracing::info!("identify asked: this display draws no pixels");
            return;
        }
        self.identify_until = seconds.map(|s| tokio::time::Instant::now() + s);
        if on {
            tracing::info!(?seconds, "showing the identify pattern");
        }
        self.display.flush().await;
    }

    async fn show(&mut self, show: v1::Show) -> Result<(), AgentError> {
        let resolution = self.display.resolution();
        let values = match show
            .pattern
            .map(|p| pattern_from_wire(p, &show.mask, resolution))
        {
            Some(Ok(Wire::Nodes(values))) => values,
            Some(Ok(Wire::Frame(pattern))) => {
                if !self.display.show_pattern(pattern) {
                    tracing::warn!(
                        seq = show.seq,
                        "this display shows node values only: pattern ignored"
                    );
                    return Ok(());
                }
                return acknowledge(self.display, &self.tx, show.seq, true).await;
            }
            Some(Err(e)) => {
                tracing::warn!(seq = show.seq, error = %e, "malformed Show pattern: ignored");
                return Ok(());
            }
            None => {
                tracing::warn!(seq = show.seq, "Show without a pattern: ignored");
                return Ok(());
            }
        };
        for v in &values.values {
            if !self.assigned.contains(&v.node) {
                tracing::warn!(
                    node = v.node,
                    "Show for a node this projector does not own: ignored"
                );
                continue;
            }
            match from_rgb("show value", v.x.as_ref()) {
                Ok(x) => self.display.show(v.node, x.clamp_unit()),
                Err(e) => {
                    tracing::warn!(node = v.node, error = %e, "malformed Show value: ignored")
                }
            }
        }
        acknowledge(self.display, &self.tx, show.seq, true).await
    }
}

/// Acknowledges frame `seq` (a round's, or with `pattern` a Show pattern's) once the display
/// has everything shown so far.
async fn acknowledge(
    display: &mut impl Display,
    tx: &mpsc::Sender<v1::NodeMessage>,
    seq: u64,
    pattern: bool,
) -> Result<(), AgentError> {
    display.flush().await;
    send(
        tx,
        v1::node_message::Body::Shown(v1::Shown { seq, pattern }),
    )
    .await
}

/// Resolves at `until`, never when `None`.
async fn sleep_until_some(until: Option<tokio::time::Instant>) {
    match until {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}
