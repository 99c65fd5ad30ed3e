//! roomlight-agent: the camera agent and the node agents of DESIGN §6.
//!
//! - [`hardware`]: the `Display` and `Camera` traits and an in-process virtual room for tests.
//! - [`camera`]: the camera agent: `service` (the `Room.Attach` handshake and each peer's
//!   reader), `registry` (live peers, admission, removal on drop), `rounds` (wait for
//!   acknowledgements, capture, send each node its errors, collect), `calibration` (over the
//!   wire and hot) and `model` (the live model and its file).
//! - [`node`]: a node agent: owns its nodes' values, updates them from the errors it receives,
//!   drives its display, acknowledges frames and reports contributions.
//!
//! - [`discovery`]: the camera agent advertised over mDNS, and node agents finding it.
//! - [`tls`]: the room's certificates, a config's TLS files, the plaintext rule.
//! - `throttle`: repeated warnings logged at a limited rate (a flood must not fill the disk).
//!
//! Measured and model rounds run over gRPC with joins (a projector not yet measured is
//! calibrated hot) and leaves, reconnection and state files; calibration of a whole room over
//! the wire comes next.

pub mod camera;
pub mod discovery;
pub mod hardware;
pub mod node;
pub mod remote;
mod throttle;
pub mod tls;

/// What went wrong in an agent.
#[derive(Debug, thiserror::Error)]
pub enum AgentError {
    /// The transport failed (connect, serve).
    #[error("transport: {0}")]
    Transport(#[from] tonic::transport::Error),
    /// The peer refused us or sent something invalid.
    #[error("peer: {0}")]
    Status(#[from] tonic::Status),
    /// The model handed to the agent is inconsistent.
    #[error("model: {0}")]
    Model(#[from] roomlight_core::ModelError),
    /// A protocol rule was broken.
    #[error("protocol: {0}")]
    Protocol(String),
}
