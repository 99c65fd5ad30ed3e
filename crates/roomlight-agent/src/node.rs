//! A node agent (DESIGN §6): one per projector. It owns its nodes' values and attenuation,
//! receives only the errors on its nodes' supports, computes its own steps, drives its display,
//! acknowledges each frame and reports its contribution changes for model rounds.

use crate::AgentError;
use crate::hardware::{Assignment, Display, Pattern};
use roomlight_core::{AttenuationColumn, LinearRgb, NodeState, StepRule};
use roomlight_proto::convert::{from_rgb, from_sparse, to_sparse};
use roomlight_proto::refusal::Refusal;
use roomlight_proto::{PROTOCOL_VERSION, v1};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio::sync::mpsc;
use tokio_stream::StreamExt;
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;

/// How a node agent runs.
#[derive(Debug, Clone)]
pub struct NodeConfig {
    /// The camera agent, e.g. `http://127.0.0.1:50051`.
    pub endpoint: String,
    /// The room to join.
    pub room: String,
    /// The room token.
    pub token: String,
    /// This projector's id in the room's calibration.
    pub projector_id: String,
    /// Standard or large aperture (sent in Hello: the camera agent decodes a large aperture's
    /// defocused light with plain Gray code and makes it one node).
    pub kind: v1::ProjectorKind,
    /// The update rule of every node of this projector.
    pub rule: StepRule,
    /// The value a node shows before its first update.
    pub start: LinearRgb,
    /// Where the node keeps its values between runs (written atomically, at most once a second
    /// and when it stops); `None` keeps nothing.
    pub state_file: Option<PathBuf>,
}

/// What a node agent keeps on disk: the values its nodes show, and the calibration they belong to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SavedState {
    /// Calibration epoch the values were computed under.
    pub calibration_epoch: u64,
    /// Node id → linear light shown.
    pub values: Vec<(u32, LinearRgb)>,
    /// The nodes' weights and response when the camera agent segmented this projector over
    /// the wire (so that a restarted node can draw its values before it reconnects).
    #[serde(default)]
    pub assignment: Option<Assignment>,
    /// Node id → its attenuation column as the camera agent last sent it (sent back in Hello
    /// with the values).
    #[serde(default)]
    pub attenuation: Vec<(u32, AttenuationColumn)>,
}

impl SavedState {
    /// Reads a state file; a missing file is `Ok(None)`, an unreadable one an error naming it.
    pub fn load(path: &Path) -> Result<Option<Self>, AgentError> {
        match std::fs::read_to_string(path) {
            Ok(text) => {
                let mut state: Self = serde_json::from_str(&text).map_err(|e| {
                    AgentError::Protocol(format!("state file {}: {e}", path.display()))
                })?;
                if state.values.iter().any(|(_, v)| !v.is_finite()) {
                    return Err(AgentError::Protocol(format!(
                        "state file {}: a value is not finite",
                        path.display()
                    )));
                }
                if let Some(a) = &state.assignment {
                    a.validate(&format!("state file {}", path.display()))?;
                }
                // Deserialised columns are not checked: build them anew.
                for (node, column) in &mut state.attenuation {
                    *column =
                        AttenuationColumn::new(column.support().to_vec(), column.values().to_vec())
                            .map_err(|e| {
                                AgentError::Protocol(format!(
                                    "state file {}: attenuation of node {node}: {e}",
                                    path.display()
                                ))
                            })?;
                }
                Ok(Some(state))
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(AgentError::Protocol(format!(
                "state file {}: {e}",
                path.display()
            ))),
        }
    }

    /// Writes the state atomically: a temporary file beside it, synced, then renamed over it.
    pub fn save(&self, path: &Path) -> Result<(), AgentError> {
        let io =
            |e: std::io::Error| AgentError::Protocol(format!("state file {}: {e}", path.display()));
        let tmp = path.with_extension("tmp");
        let text = serde_json::to_string(self).map_err(|e| AgentError::Protocol(e.to_string()))?;
        {
            let mut f = std::fs::File::create(&tmp).map_err(io)?;
            f.write_all(text.as_bytes()).map_err(io)?;
            f.sync_all().map_err(io)?;
        }
        std::fs::rename(&tmp, path).map_err(io)
    }
}

fn message(body: v1::node_message::Body) -> v1::NodeMessage {
    v1::NodeMessage { body: Some(body) }
}

/// How a session with the camera agent ended.
enum SessionEnd {
    /// `cancel` fired: the node said goodbye.
    Cancelled,
    /// The camera agent ended the stream or went away.
    Closed,
}

/// Logs a status from the camera agent by its refusal when it carries one, so the node's log
/// reads as the camera agent's does.
fn log_refusal(projector: &str, status: &tonic::Status, what: &str) {
    match Refusal::from_status(status) {
        Some(refusal) if refusal.is_fatal() => tracing::error!(%projector, %refusal, "{what}"),
        Some(refusal) => tracing::warn!(%projector, %refusal, "{what}"),
        None if Refusal::is_fatal_status(status) => tracing::error!(%projector, %status, "{what}"),
        None => tracing::warn!(%projector, %status, "{what}"),
    }
}

/// Runs one node agent until `cancel`. When the camera agent goes away the display keeps its last
/// values (the lights stay on) and the agent reconnects with exponential backoff and jitter,
/// resuming from the values it shows. A refusal that retrying cannot fix ends it with an error.
pub async fn run(
    config: NodeConfig,
    mut display: impl Display,
    cancel: CancellationToken,
) -> Result<(), AgentError> {
    // A malformed address cannot heal by retrying. HTTP/2 pings notice a camera host that
    // vanished without closing the connection (power loss, cable pulled): the session ends and
    // the agent reconnects, and the lights stay on meanwhile.
    let endpoint = tonic::transport::Endpoint::from_shared(config.endpoint.clone())
        .map_err(|e| {
            AgentError::Protocol(format!(
                "camera endpoint {:?}: {e}; expected an address like http://host:port",
                config.endpoint
            ))
        })?
        .connect_timeout(Duration::from_secs(5))
        .http2_keep_alive_interval(Duration::from_secs(5))
        .keep_alive_timeout(Duration::from_secs(10))
        .keep_alive_while_idle(true)
        .tcp_nodelay(true);
    // The last value each node showed: the start of the next session.
    let mut memory: HashMap<u32, LinearRgb> = HashMap::new();
    let mut epoch = 0;
    let mut assignment: Option<Assignment> = None;
    let mut attenuation: HashMap<u32, AttenuationColumn> = HashMap::new();
    // Relight at once from the state file, before any camera agent is reachable.
    if let Some(path) = &config.state_file
        && let Some(saved) = SavedState::load(path)?
    {
        if let Some(a) = &saved.assignment {
            display.assign(a);
        }
        assignment = saved.assignment;
        attenuation = saved.attenuation.into_iter().collect();
        for &(node, value) in &saved.values {
            display.show(node, value);
            memory.insert(node, value);
        }
        epoch = saved.calibration_epoch;
        tracing::info!(projector = %config.projector_id, nodes = saved.values.len(), "relit from the state file");
    }
    let mut keeper = Keeper {
        path: config.state_file.clone(),
        last: None,
        assignment,
        attenuation,
    };
    let mut backoff = MIN_BACKOFF;
    loop {
        let outcome = session(
            &config,
            &endpoint,
            &mut display,
            &cancel,
            &mut memory,
            &mut epoch,
            &mut keeper,
        )
        .await;
        keeper.flush(epoch, &memory);
        match outcome {
            Ok(SessionEnd::Cancelled) => return Ok(()),
            Ok(SessionEnd::Closed) => backoff = MIN_BACKOFF,
            Err(AgentError::Status(status)) => {
                if Refusal::is_fatal_status(&status) {
                    log_refusal(&config.projector_id, &status, "refused by the camera agent");
                    return Err(AgentError::Status(status));
                }
                log_refusal(&config.projector_id, &status, "session lost");
            }
            Err(e) => tracing::warn!(projector = %config.projector_id, error = %e, "session lost"),
        }
        // Jitter: up to half the backoff, from the clock's nanoseconds (no need for a generator).
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let jitter = backoff.mul_f64(f64::from(nanos % 1000) / 2000.0);
        tokio::select! {
            () = cancel.cancelled() => return Ok(()),
            () = tokio::time::sleep(backoff + jitter) => {}
        }
        backoff = (backoff * 2).min(MAX_BACKOFF);
    }
}

/// Largest message a node agent takes from the camera agent (an Assign of a 4K projector's
/// weights is about 70 MB).
const MAX_ROOM_MESSAGE: usize = 256 << 20;

/// First and largest wait before reconnecting.
const MIN_BACKOFF: Duration = Duration::from_millis(100);
const MAX_BACKOFF: Duration = Duration::from_secs(5);

/// Writes the state file at most once a second, and when asked to flush.
struct Keeper {
    path: Option<PathBuf>,
    last: Option<std::time::Instant>,
    /// The assignment received over the wire, kept with the values.
    assignment: Option<Assignment>,
    /// Each node's last attenuation column.
    attenuation: HashMap<u32, AttenuationColumn>,
}

impl Keeper {
    fn maybe(&mut self, epoch: u64, memory: &HashMap<u32, LinearRgb>) {
        if self
            .last
            .is_none_or(|t| t.elapsed() >= Duration::from_secs(1))
        {
            self.flush(epoch, memory);
        }
    }

    fn flush(&mut self, epoch: u64, memory: &HashMap<u32, LinearRgb>) {
        let Some(path) = &self.path else { return };
        let mut values: Vec<(u32, LinearRgb)> = memory.iter().map(|(&n, &v)| (n, v)).collect();
        values.sort_by_key(|(n, _)| *n);
        let mut attenuation: Vec<(u32, AttenuationColumn)> = self
            .attenuation
            .iter()
            .map(|(&n, c)| (n, c.clone()))
            .collect();
        attenuation.sort_by_key(|(n, _)| *n);
        if let Err(e) = (SavedState {
            calibration_epoch: epoch,
            values,
            assignment: self.assignment.clone(),
            attenuation,
        })
        .save(path)
        {
            // The lights matter more than the file: log and carry on.
            tracing::warn!(error = %e, "could not write the state file");
        }
        self.last = Some(std::time::Instant::now());
    }
}

async fn session(
    config: &NodeConfig,
    endpoint: &tonic::transport::Endpoint,
    display: &mut impl Display,
    cancel: &CancellationToken,
    memory: &mut HashMap<u32, LinearRgb>,
    epoch: &mut u64,
    keeper: &mut Keeper,
) -> Result<SessionEnd, AgentError> {
    // An Assign with a projector's weights can be several megabytes.
    let mut client = v1::room_client::RoomClient::new(endpoint.connect().await?)
        .max_decoding_message_size(MAX_ROOM_MESSAGE);
    let (tx, rx) = mpsc::channel(256);
    let send = |tx: &mpsc::Sender<v1::NodeMessage>, m| {
        let tx = tx.clone();
        async move {
            tx.send(m)
                .await
                .map_err(|_| AgentError::Protocol("the outgoing stream closed".into()))
        }
    };
    send(
        &tx,
        message(v1::node_message::Body::Hello(v1::Hello {
            protocol_version: PROTOCOL_VERSION,
            room: config.room.clone(),
            token: config.token.clone(),
            projector_id: config.projector_id.clone(),
            width: display.resolution().map_or(0, |r| r.0),
            height: display.resolution().map_or(0, |r| r.1),
            kind: config.kind as i32,
            state: Some(v1::PersistedState {
                calibration_epoch: *epoch,
                nodes: memory
                    .iter()
                    .map(|(&node, &x)| v1::NodeState {
                        node,
                        x: Some(roomlight_proto::convert::to_rgb(x)),
                        attenuation: keeper
                            .attenuation
                            .get(&node)
                            .map(|c| to_sparse(c.support(), c.values())),
                    })
                    .collect(),
            }),
            ..Default::default()
        })),
    )
    .await?;
    let mut inbound = client.attach(ReceiverStream::new(rx)).await?.into_inner();
    let mut heartbeat = Duration::from_secs(1);
    let mut assigned: Vec<u32> = Vec::new();
    let mut nodes: HashMap<u32, NodeState> = HashMap::new();
    let mut applied: HashMap<u64, usize> = HashMap::new();
    let mut started = false;
    let mut ticker = tokio::time::interval(heartbeat);
    loop {
        let next = tokio::select! {
            () = cancel.cancelled() => {
                let _ = tx.send(message(v1::node_message::Body::Goodbye(v1::Goodbye { reason: "shutting down".into() }))).await;
                return Ok(SessionEnd::Cancelled);
            }
            _ = ticker.tick() => {
                send(&tx, message(v1::node_message::Body::Heartbeat(v1::Heartbeat { sent_unix_ms: 0 }))).await?;
                continue;
            }
            next = inbound.next() => next,
        };
        let Some(msg) = next.transpose()? else {
            return Ok(SessionEnd::Closed);
        };
        match msg.body {
            Some(v1::room_message::Body::Welcome(w)) => {
                heartbeat = Duration::from_millis(u64::from(w.heartbeat_ms.max(50)));
                ticker = tokio::time::interval(heartbeat);
                // Values from another calibration mean nothing now: start afresh.
                if !w.state_accepted {
                    memory.clear();
                    keeper.attenuation.clear();
                }
                *epoch = w.calibration_epoch;
            }
            Some(v1::room_message::Body::Assign(a)) => {
                assigned = a.nodes.iter().map(|n| n.node).collect();
                // Weights drawn by the camera agent (calibration over the wire): a malformed
                // assignment ends the session (the camera agent logs the stream's end).
                if a.width > 0 {
                    let assignment = assignment_from_wire(&a)?;
                    display.assign(&assignment);
                    keeper.assignment = Some(assignment);
                    keeper.flush(*epoch, memory);
                }
            }
            Some(v1::room_message::Body::Attenuation(a)) => {
                let (Some(p), Some(s)) = (a.p.as_ref(), a.s.as_ref()) else {
                    return Err(AgentError::Protocol(format!(
                        "attenuation of node {} lacks p or s",
                        a.node
                    )));
                };
                let (support, values) = from_sparse("attenuation p", p)
                    .map_err(|e| AgentError::Protocol(e.to_string()))?;
                let (_, white) = from_sparse("attenuation s", s)
                    .map_err(|e| AgentError::Protocol(e.to_string()))?;
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
                let start = nodes
                    .get(&a.node)
                    .map(NodeState::shown)
                    .or_else(|| memory.get(&a.node).copied())
                    .or(offered)
                    .unwrap_or(config.start);
                keeper.attenuation.insert(a.node, column.clone());
                let state = NodeState::new(column, &white, config.rule, start)?;
                display.show(a.node, state.shown());
                nodes.insert(a.node, state);
                if !started
                    && !assigned.is_empty()
                    && assigned.iter().all(|n| nodes.contains_key(n))
                {
                    started = true;
                    acknowledge(display, &tx, 0, false).await?;
                }
            }
            Some(v1::room_message::Body::Errors(e)) => {
                let Some(state) = nodes.get_mut(&e.node) else {
                    tracing::warn!(
                        node = e.node,
                        "errors for a node this projector does not own: ignored"
                    );
                    continue;
                };
                let Some(sparse) = e.errors.as_ref() else {
                    continue;
                };
                let errors = match from_sparse("errors", sparse) {
                    Ok((_, v)) => v,
                    Err(err) => {
                        tracing::warn!(node = e.node, error = %err, "malformed errors: ignored");
                        continue;
                    }
                };
                // Invalid errors leave the node where it is (and it still acknowledges the round).
                let delta = state.update(&errors, e.restart).unwrap_or(LinearRgb::ZERO);
                display.show(e.node, state.shown());
                memory.insert(e.node, state.shown());
                let contribution: Vec<(u32, LinearRgb)> = state.contribution(delta).collect();
                let (patches, values): (Vec<u32>, Vec<LinearRgb>) =
                    contribution.into_iter().unzip();
                send(
                    &tx,
                    message(v1::node_message::Body::Contribution(v1::Contribution {
                        round: e.round,
                        node: e.node,
                        delta: Some(to_sparse(&patches, &values)),
                    })),
                )
                .await?;
                let done = applied.entry(e.round).or_insert(0);
                *done += 1;
                if *done == nodes.len() {
                    // This round is complete; rounds before it will never be.
                    applied.retain(|r, _| *r > e.round);
                    keeper.maybe(*epoch, memory);
                    acknowledge(display, &tx, e.round, false).await?;
                }
            }
            Some(v1::room_message::Body::Goodbye(g)) => {
                tracing::info!(reason = %g.reason, "the camera agent said goodbye");
                return Ok(SessionEnd::Closed);
            }
            Some(v1::room_message::Body::Show(show)) => {
                // A calibration pattern: node values shown as they are, without touching the
                // node states (values for nodes it does not own, or not finite, are refused),
                // or a whole-frame pattern. One the display cannot show is not acknowledged.
                let values = match show.pattern.map(pattern_from_wire) {
                    Some(Ok(Wire::Nodes(values))) => values,
                    Some(Ok(Wire::Frame(pattern))) => {
                        if !display.show_pattern(pattern) {
                            tracing::warn!(
                                seq = show.seq,
                                "this display shows node values only: pattern ignored"
                            );
                            continue;
                        }
                        acknowledge(display, &tx, show.seq, true).await?;
                        continue;
                    }
                    Some(Err(e)) => {
                        tracing::warn!(seq = show.seq, error = %e, "malformed Show pattern: ignored");
                        continue;
                    }
                    None => {
                        tracing::warn!(seq = show.seq, "Show without a pattern: ignored");
                        continue;
                    }
                };
                for v in &values.values {
                    if !assigned.contains(&v.node) {
                        tracing::warn!(
                            node = v.node,
                            "Show for a node this projector does not own: ignored"
                        );
                        continue;
                    }
                    match from_rgb("show value", v.x.as_ref()) {
                        Ok(x) => display.show(v.node, x.clamp_unit()),
                        Err(e) => {
                            tracing::warn!(node = v.node, error = %e, "malformed Show value: ignored")
                        }
                    }
                }
                acknowledge(display, &tx, show.seq, true).await?;
            }
            None => {}
        }
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
    tx.send(message(v1::node_message::Body::Shown(v1::Shown {
        seq,
        pattern,
    })))
    .await
    .map_err(|_| AgentError::Protocol("the outgoing stream closed".into()))
}

/// A Show message's pattern: node values, or a whole frame.
enum Wire {
    Nodes(v1::NodeValues),
    Frame(Pattern),
}

fn pattern_from_wire(p: v1::show::Pattern) -> Result<Wire, String> {
    use roomlight_calib::graycode::{Axis, Coding, Pattern as Gray};
    Ok(match p {
        v1::show::Pattern::Nodes(values) => Wire::Nodes(values),
        v1::show::Pattern::Uniform(u) => {
            let code = from_rgb("uniform code", u.code.as_ref()).map_err(|e| e.to_string())?;
            if code.0.iter().any(|v| !(0.0..=1.0).contains(v)) {
                return Err(format!("uniform code {code:?}: expected values in [0, 1]"));
            }
            Wire::Frame(Pattern::Uniform(code.0.map(|v| v as f32)))
        }
        v1::show::Pattern::Gray(g) => {
            let axis = match v1::Axis::try_from(g.axis) {
                Ok(v1::Axis::Column) => Axis::Column,
                Ok(v1::Axis::Row) => Axis::Row,
                _ => return Err(format!("Gray bit axis {}: expected column or row", g.axis)),
            };
            let coding = match v1::Coding::try_from(g.coding) {
                Ok(v1::Coding::Gray) => Coding::Gray,
                Ok(v1::Coding::Xor04) => Coding::Xor04,
                _ => {
                    return Err(format!(
                        "Gray bit coding {}: expected gray or xor04",
                        g.coding
                    ));
                }
            };
            if g.bit >= 32 {
                return Err(format!("Gray bit {}: expected below 32", g.bit));
            }
            Wire::Frame(Pattern::Structured {
                pattern: Gray::Bit {
                    axis,
                    bit: g.bit,
                    inverse: g.inverse,
                },
                coding,
            })
        }
    })
}

/// The weights and response of an Assign message, checked.
fn assignment_from_wire(a: &v1::Assign) -> Result<Assignment, AgentError> {
    let gamma = match a.gamma.as_slice() {
        [] => [1.0; 3],
        [r, g, b] => [*r, *g, *b],
        other => {
            return Err(AgentError::Protocol(format!(
                "assignment: {} response exponents, expected 3",
                other.len()
            )));
        }
    };
    let mut nodes = Vec::with_capacity(a.nodes.len());
    for n in &a.nodes {
        if n.pixels.len() != n.weights.len() {
            return Err(AgentError::Protocol(format!(
                "assignment of node {}: {} pixels, {} weights",
                n.node,
                n.pixels.len(),
                n.weights.len()
            )));
        }
        nodes.push((
            n.node,
            n.pixels
                .iter()
                .copied()
                .zip(n.weights.iter().copied())
                .collect(),
        ));
    }
    let assignment = Assignment {
        width: a.width,
        height: a.height,
        response: roomlight_calib::response::Response {
            gamma,
            max_residual: [0.0; 3],
        },
        nodes,
    };
    assignment.validate("assignment")?;
    Ok(assignment)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assign(pixels: Vec<u32>, weights: Vec<f32>, gamma: Vec<f64>) -> v1::Assign {
        v1::Assign {
            nodes: vec![v1::NodeAssignment {
                node: 3,
                chart: 3,
                pixels,
                weights,
            }],
            width: 4,
            height: 2,
            gamma,
        }
    }

    /// A well-formed assignment is taken as sent; every malformed one is refused with a message
    /// that names the node or the field, never drawn.
    #[test]
    fn assignments_over_the_wire_are_checked() {
        let ok = assignment_from_wire(&assign(vec![0, 5, 7], vec![1.0, 0.5, 0.25], vec![]))
            .expect("well formed");
        assert_eq!(ok.nodes, vec![(3, vec![(0, 1.0), (5, 0.5), (7, 0.25)])]);
        assert!(
            ok.response.gamma.iter().all(|g| (g - 1.0).abs() < 1e-12),
            "no exponents: linear"
        );
        let refused = |a: v1::Assign, says: &str| {
            let e = assignment_from_wire(&a).expect_err("malformed").to_string();
            assert!(e.contains(says), "{e:?} should say {says:?}");
        };
        refused(
            assign(vec![0, 1], vec![1.0], vec![]),
            "node 3: 2 pixels, 1 weights",
        );
        refused(
            assign(vec![0, 8], vec![1.0, 1.0], vec![]),
            "outside the 4×2 frame",
        );
        refused(assign(vec![5, 2], vec![1.0, 1.0], vec![]), "not increasing");
        refused(assign(vec![0], vec![1.5], vec![]), "outside (0, 1]");
        refused(assign(vec![0], vec![f32::NAN], vec![]), "outside (0, 1]");
        refused(
            assign(vec![0], vec![1.0], vec![2.2, 2.2]),
            "2 response exponents",
        );
        refused(
            assign(vec![0], vec![1.0], vec![2.2, f64::INFINITY, 2.2]),
            "finite and positive",
        );
        let mut empty = assign(vec![0], vec![1.0], vec![]);
        empty.height = 0;
        refused(empty, "a 4×0 projector");
    }

    /// A state file whose attenuation is not a valid column (unsorted support) is refused
    /// with a message that names the file and the node; a valid one reads back as written.
    #[test]
    fn state_files_check_their_attenuation() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("p.state.json");
        let column = AttenuationColumn::new(
            vec![1, 4],
            vec![LinearRgb::splat(0.5), LinearRgb::splat(0.25)],
        )
        .expect("column");
        let saved = SavedState {
            calibration_epoch: 3,
            values: vec![(7, LinearRgb::splat(0.4))],
            assignment: None,
            attenuation: vec![(7, column)],
        };
        saved.save(&path).expect("save");
        assert_eq!(SavedState::load(&path).expect("load"), Some(saved));
        let text = std::fs::read_to_string(&path).expect("read");
        std::fs::write(&path, text.replace("[1,4]", "[4,1]")).expect("corrupt");
        let e = SavedState::load(&path)
            .expect_err("unsorted support")
            .to_string();
        assert!(e.contains("p.state.json") && e.contains("node 7"), "{e}");
    }

    /// Whole-frame patterns are read as sent; codes outside [0, 1], unknown axes or codings and
    /// impossible bits are refused.
    #[test]
    fn show_patterns_over_the_wire_are_checked() {
        use roomlight_calib::graycode::{Axis, Coding, Pattern as Gray};
        let uniform = |v: f64| {
            v1::show::Pattern::Uniform(v1::Uniform {
                code: Some(roomlight_proto::convert::to_rgb(LinearRgb::splat(v))),
            })
        };
        assert!(matches!(
            pattern_from_wire(uniform(0.25)),
            Ok(Wire::Frame(Pattern::Uniform([0.25, 0.25, 0.25])))
        ));
        for bad in [-0.1, 1.5, f64::NAN] {
            assert!(pattern_from_wire(uniform(bad)).is_err(), "code {bad}");
        }
        let gray = |axis: i32, bit: u32, coding: i32| {
            v1::show::Pattern::Gray(v1::GrayBit {
                axis,
                bit,
                inverse: true,
                coding,
            })
        };
        let row = v1::Axis::Row as i32;
        let xor = v1::Coding::Xor04 as i32;
        assert!(matches!(
            pattern_from_wire(gray(row, 3, xor)),
            Ok(Wire::Frame(Pattern::Structured {
                pattern: Gray::Bit {
                    axis: Axis::Row,
                    bit: 3,
                    inverse: true
                },
                coding: Coding::Xor04
            }))
        ));
        assert!(
            pattern_from_wire(gray(0, 3, xor)).is_err(),
            "unspecified axis"
        );
        assert!(pattern_from_wire(gray(9, 3, xor)).is_err(), "unknown axis");
        assert!(
            pattern_from_wire(gray(row, 3, 0)).is_err(),
            "unspecified coding"
        );
        assert!(pattern_from_wire(gray(row, 40, xor)).is_err(), "bit 40");
    }
}
