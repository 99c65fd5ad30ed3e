//! roomlight-proto: the generated wire types of `proto/roomlight/v1` and the conversions between
//! them and the domain types of roomlight-core, validated on the way in.

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

pub mod convert;

/// The protocol version this build speaks.
pub const PROTOCOL_VERSION: u32 = 1;
