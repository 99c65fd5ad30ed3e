//! roomlight-proto: the generated wire types of `proto/roomlight/v1`, the conversions between
//! them and the domain types of roomlight-core (validated on the way in), and the one table of
//! refusals and their gRPC statuses. It knows the contract, not the agents that speak it.

/// Generated code of `roomlight.v1`.
#[allow(
    missing_docs,
    missing_debug_implementations,
    unused_qualifications,
    clippy::all
)]
pub mod v1 {
    tonic::include_proto!("roomlight.v1");
}

pub mod bounds;
pub mod convert;
#[cfg(test)]
mod fuzz;
#[cfg(any(test, feature = "fuzzing"))]
pub mod mutate;
pub mod refusal;

/// The protocol version this build speaks. 3: a node's errors travel without their patch ids
/// (the node knows its support) and its contribution as its change of value `Δx_n` (the camera
/// agent holds `p_n`); 2: `Errors` and `Contribution` carry every node of the node agent's
/// projector, one message per node agent per round (1: one per node).
pub const PROTOCOL_VERSION: u32 = 3;
