//! A node agent (DESIGN §6): one per projector. It owns its nodes' values and attenuation,
//! receives only the errors on its nodes' supports, computes its own steps, drives its display,
//! acknowledges each frame and reports its contribution changes for model rounds.
//!
//! - `session`: one connection to the camera agent, handshake to goodbye.
//! - `state`: what the node remembers across sessions and restarts, and its state file.
//! - `backoff`: how long it waits before reconnecting.
//!
//! This module strings them together: relight from the state file, then sessions until
//! cancelled, reconnecting unless the camera agent's refusal is one retrying cannot fix. It
//! knows nothing of the camera agent's registry or rounds, only the wire contract.

mod backoff;
mod session;
mod state;
mod wire;

pub use state::SavedState;

use crate::AgentError;
use crate::hardware::Display;
use backoff::Backoff;
use roomlight_core::{LinearRgb, StepRule};
use roomlight_proto::refusal::Refusal;
use roomlight_proto::v1;
use session::SessionEnd;
use state::Memory;
use std::path::PathBuf;
use std::time::Duration;
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

/// Runs one node agent until `cancel`. When the camera agent goes away the display keeps its last
/// values (the lights stay on) and the agent reconnects with exponential backoff and jitter,
/// resuming from the values it shows. A refusal that retrying cannot fix ends it with an error.
pub async fn run(
    config: NodeConfig,
    mut display: impl Display,
    cancel: CancellationToken,
) -> Result<(), AgentError> {
    let endpoint = endpoint(&config.endpoint)?;
    // Relight at once from the state file, before any camera agent is reachable.
    let mut memory = Memory::relight(
        config.state_file.clone(),
        &mut display,
        &config.projector_id,
    )?;
    let mut backoff = Backoff::new();
    loop {
        let outcome = session::run(&config, &endpoint, &mut display, &cancel, &mut memory).await;
        memory.flush();
        if cancel.is_cancelled() {
            // Stopping: a stream that broke while the goodbye went out is no loss to report.
            return Ok(());
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

/// The camera agent's address, with the connection's keepalive. A malformed address cannot heal
/// by retrying. HTTP/2 pings notice a camera host that vanished without closing the connection
/// (power loss, cable pulled): the session ends and the agent reconnects, and the lights stay on
/// meanwhile.
fn endpoint(address: &str) -> Result<tonic::transport::Endpoint, AgentError> {
    Ok(tonic::transport::Endpoint::from_shared(address.to_string())
        .map_err(|e| {
            AgentError::Protocol(format!(
                "camera endpoint {address:?}: {e}; expected an address like http://host:port"
            ))
        })?
        .connect_timeout(Duration::from_secs(5))
        .http2_keep_alive_interval(Duration::from_secs(5))
        .keep_alive_timeout(Duration::from_secs(10))
        .keep_alive_while_idle(true)
        .tcp_nodelay(true))
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
