//! A node agent (DESIGN §6): one per projector. It owns its nodes' values and attenuation,
//! receives only the errors on its nodes' supports, computes its own steps, drives its display,
//! acknowledges each frame and reports its contribution changes for model rounds.
//!
//! - `session`: one connection to the camera agent, handshake to goodbye.
//! - `state`: what the node remembers across sessions and restarts, and its state file.
//! - `backoff`: how long it waits before reconnecting.
//!
//! This module strings them together: relight from the state file, then sessions until
//! cancelled, reconnecting unless the camera agent's refusal is one retrying cannot fix (or,
//! for a camera agent found over mDNS, trying the next candidate). It knows nothing of the
//! camera agent's registry or rounds, only the wire contract.

mod backoff;
#[cfg(test)]
mod fuzz;
mod session;
mod state;
mod wire;

pub use state::SavedState;
pub(crate) use wire::shade_to_wire;

use crate::AgentError;
use crate::hardware::Display;
use crate::tls::ClientTls;
use backoff::Backoff;
use roomlight_core::{LinearRgb, StepRule};
use roomlight_proto::refusal::Refusal;
use roomlight_proto::v1;
use session::SessionEnd;
use state::Memory;
use std::path::PathBuf;
use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// How a node agent runs. Its `Debug` leaves the token out (`roomlight node --check` prints
/// it).
#[derive(Clone)]
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

impl std::fmt::Debug for NodeConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NodeConfig")
            .field("endpoint", &self.endpoint)
            .field("room", &self.room)
            .field("token", &"<secret>")
            .field("projector_id", &self.projector_id)
            .field("kind", &self.kind)
            .field("rule", &self.rule)
            .field("start", &self.start)
            .field("state_file", &self.state_file)
            .finish()
    }
}

/// Runs one node agent until `cancel`. When the camera agent goes away the display keeps its last
/// values (the lights stay on) and the agent reconnects with exponential backoff and jitter,
/// resuming from the values it shows; the backoff starts afresh after every session in which it
/// was admitted. A refusal that retrying cannot fix ends it with an error.
///
/// An endpoint written by [`crate::discovery::mdns_endpoint`] is found over mDNS instead: each
/// candidate advertising the room is tried in turn, and one that refuses the node or cannot be
/// reached is skipped (not fatal) while the search goes on.
pub async fn run(
    config: NodeConfig,
    display: impl Display,
    cancel: CancellationToken,
) -> Result<(), AgentError> {
    run_tls(config, None, display, cancel).await
}

/// [`run`], over TLS when `tls` is given: the camera agent's certificate is verified against
/// the room CA and must carry its name (`tls.camera_name`, else the endpoint's host, or the
/// room's name for a camera agent found over mDNS) before anything is sent.
pub async fn run_tls(
    config: NodeConfig,
    tls: Option<ClientTls>,
    display: impl Display,
    cancel: CancellationToken,
) -> Result<(), AgentError> {
    match crate::discovery::parse_mdns_endpoint(&config.endpoint) {
        Some((room, mdns, within)) => {
            let find = move |skip: &[String]| {
                crate::discovery::find_camera_except(&room, &mdns, within, skip)
                    .inspect_err(|e| tracing::warn!(error = %e, "no camera agent candidate"))
                    .ok()
            };
            let link = Link {
                name: tls.as_ref().map(|_| config.room.clone()),
                tls,
            };
            candidates(config, link, find, display, cancel).await
        }
        None => {
            let link = Link { tls, name: None };
            let endpoint = endpoint(&config.endpoint, &link)?;
            let target = Target::Fixed(Box::new(endpoint));
            sessions(&config, &link, target, display, cancel).await
        }
    }
}

/// Connects to the camera agent at `address` as a node agent does (plaintext, or TLS with
/// `tls`), for a tool or a test that speaks to it itself (`roomlight check`): the channel, or
/// the failure, said as a plaintext/TLS mismatch when it most likely is one.
pub async fn connect(
    address: &str,
    tls: Option<&ClientTls>,
) -> Result<tonic::transport::Channel, AgentError> {
    let link = Link {
        tls: tls.cloned(),
        name: None,
    };
    let endpoint = endpoint(address, &link)?;
    endpoint
        .connect()
        .await
        .map_err(|e| session::mismatch(&endpoint, e.into()))
}

/// How the node agent reaches a camera agent: plaintext, or TLS with the name a camera agent
/// must carry when the endpoint's host is not it (found over mDNS: the room's name).
#[derive(Debug, Clone, Default)]
struct Link {
    tls: Option<ClientTls>,
    name: Option<String>,
}

/// Runs one node agent whose camera agent is one of the candidates `find` returns (it blocks
/// while it searches, and returns `None` when it found none but those it is asked to skip): a
/// candidate that refuses the node or cannot be reached before it was admitted is skipped, and
/// the next one tried; once all were skipped the list starts afresh. The camera agent that
/// admitted it is reconnected to as long as it can be reached.
pub async fn run_with_candidates(
    config: NodeConfig,
    find: impl FnMut(&[String]) -> Option<String> + Send + 'static,
    display: impl Display,
    cancel: CancellationToken,
) -> Result<(), AgentError> {
    candidates(config, Link::default(), find, display, cancel).await
}

async fn candidates(
    config: NodeConfig,
    link: Link,
    find: impl FnMut(&[String]) -> Option<String> + Send + 'static,
    display: impl Display,
    cancel: CancellationToken,
) -> Result<(), AgentError> {
    let find = std::sync::Arc::new(std::sync::Mutex::new(find));
    sessions(
        &config,
        &link,
        Target::Candidates(Box::new(move |skip: Vec<String>| {
            let find = find.clone();
            tokio::task::spawn_blocking(move || {
                let mut find = find
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                find(&skip)
            })
        })),
        display,
        cancel,
    )
    .await
}

/// A search for a candidate, off the runtime's threads.
type Search = Box<dyn FnMut(Vec<String>) -> tokio::task::JoinHandle<Option<String>> + Send>;

/// Where the camera agent is.
enum Target {
    Fixed(Box<tonic::transport::Endpoint>),
    Candidates(Search),
}

/// Candidates skipped at most at once (the oldest is tried again first).
const MAX_SKIPPED: usize = 16;

/// What to connect to next.
enum Next {
    /// This endpoint (found over mDNS: its address).
    Try(Option<String>, Box<tonic::transport::Endpoint>),
    /// No candidate now: wait the backoff and look again.
    Wait,
    /// Cancelled while searching.
    Stop,
}

/// The fixed endpoint, the candidate that admitted the node last, or a new candidate (one not
/// skipped; when there is none, the skipped ones are tried again after a wait).
async fn next_endpoint(
    link: &Link,
    target: &mut Target,
    current: &mut Option<(String, tonic::transport::Endpoint)>,
    skipped: &mut Vec<String>,
    cancel: &CancellationToken,
) -> Next {
    let search = match (target, &current) {
        (Target::Fixed(endpoint), _) => return Next::Try(None, endpoint.clone()),
        (Target::Candidates(_), Some((address, endpoint))) => {
            return Next::Try(Some(address.clone()), Box::new(endpoint.clone()));
        }
        (Target::Candidates(search), None) => search,
    };
    let found = tokio::select! {
        () = cancel.cancelled() => return Next::Stop,
        found = search(skipped.clone()) => found.ok().flatten(),
    };
    match found.map(|a| endpoint(&a, link).map(|e| (a, e))) {
        Some(Ok((address, endpoint))) => {
            *current = Some((address.clone(), endpoint.clone()));
            Next::Try(Some(address), Box::new(endpoint))
        }
        Some(Err(e)) => {
            tracing::warn!(error = %e, "a candidate's address: skipped");
            Next::Wait
        }
        None => {
            // Every candidate was skipped (or none answered): try them all again.
            skipped.clear();
            Next::Wait
        }
    }
}

/// Relights from the state file, then runs sessions until cancelled (see [`run`]).
async fn sessions(
    config: &NodeConfig,
    link: &Link,
    mut target: Target,
    mut display: impl Display,
    cancel: CancellationToken,
) -> Result<(), AgentError> {
    // Relight at once from the state file, before any camera agent is reachable.
    let mut memory = Memory::relight(
        config.state_file.clone(),
        &mut display,
        &config.projector_id,
    );
    let mut backoff = Backoff::new();
    let mut skipped: Vec<String> = Vec::new();
    let mut current: Option<(String, tonic::transport::Endpoint)> = None;
    loop {
        let (candidate, endpoint) =
            match next_endpoint(link, &mut target, &mut current, &mut skipped, &cancel).await {
                Next::Try(candidate, endpoint) => (candidate, endpoint),
                Next::Wait => {
                    if !backoff.sleep(&cancel).await {
                        return Ok(());
                    }
                    continue;
                }
                Next::Stop => return Ok(()),
            };
        let mut admitted = false;
        let outcome = session::run(
            config,
            &endpoint,
            &mut display,
            &cancel,
            &mut memory,
            &mut admitted,
        )
        .await;
        memory.flush();
        if cancel.is_cancelled() {
            // Stopping: a stream that broke while the goodbye went out is no loss to report.
            return Ok(());
        }
        if admitted {
            // A good session: the next wait starts from the first step, whatever ended it.
            backoff.reset();
        }
        if let Some(address) = candidate.filter(|_| !admitted) {
            // mDNS found it, it did not admit us: whoever it is, try the next candidate.
            let why = outcome
                .as_ref()
                .map_or_else(ToString::to_string, |_| "closed".into());
            tracing::warn!(projector = %config.projector_id, candidate = %address, %why, "candidate did not admit us: skipped");
            if skipped.len() == MAX_SKIPPED {
                skipped.remove(0);
            }
            skipped.push(address);
            current = None;
            if !backoff.sleep(&cancel).await {
                return Ok(());
            }
            continue;
        }
        match outcome {
            Ok(SessionEnd::Cancelled) => return Ok(()),
            Ok(SessionEnd::Closed) => backoff.reset(),
            Err(AgentError::Status(status)) => {
                if Refusal::is_fatal_status(&status) {
                    log_refusal(&config.projector_id, &status, "refused by the camera agent");
                    return Err(AgentError::Status(status));
                }
                log_refusal(&config.projector_id, &status, "session lost");
            }
            Err(e) => tracing::warn!(projector = %config.projector_id, error = %e, "session lost"),
        }
        if !backoff.sleep(&cancel).await {
            return Ok(());
        }
    }
}

/// The camera agent's address, with the connection's keepalive and, over TLS, the room CA
/// (an `http://` address is then reached as `https://`). A malformed address cannot heal by
/// retrying. HTTP/2 pings notice a camera host that vanished without closing the connection
/// (power loss, cable pulled): the session ends and the agent reconnects, and the lights stay on
/// meanwhile.
fn endpoint(address: &str, link: &Link) -> Result<tonic::transport::Endpoint, AgentError> {
    let malformed = |e: &dyn std::fmt::Display| {
        AgentError::Protocol(format!(
            "camera endpoint {address:?}: {e}; expected an address like http://host:port"
        ))
    };
    let uri = match (&link.tls, address.strip_prefix("http://")) {
        (Some(_), Some(rest)) => format!("https://{rest}"),
        _ => address.to_string(),
    };
    let endpoint = tonic::transport::Endpoint::from_shared(uri)
        .map_err(|e| malformed(&e))?
        .connect_timeout(Duration::from_secs(5))
        .http2_keep_alive_interval(Duration::from_secs(5))
        .keep_alive_timeout(Duration::from_secs(10))
        .keep_alive_while_idle(true)
        .tcp_nodelay(true);
    match &link.tls {
        Some(tls) => {
            let name = tls.camera_name.as_deref().or(link.name.as_deref());
            endpoint
                .tls_config(tls.tonic(name))
                .map_err(|e| malformed(&e))
        }
        None => Ok(endpoint),
    }
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
