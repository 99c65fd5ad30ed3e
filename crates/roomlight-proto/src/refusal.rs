//! Why a camera agent refuses or drops a node agent: one [`Refusal`] enum, and the one table that
//! maps each reason to its gRPC code, its message and whether the node gives up or retries.
//!
//! The camera agent turns a refusal into a [`tonic::Status`] ([`Refusal::to_status`]); the node
//! agent reads it back ([`Refusal::from_status`]), so both sides log the same reason in the same
//! words. The reason and its fields travel in the status's metadata (`roomlight-refusal` and one
//! binary entry per field), so the message text is for people and never parsed.
//!
//! This module knows nothing of registries, rounds or sessions: it is the contract at the
//! boundary, not the policy of when to refuse.

use tonic::metadata::{AsciiMetadataValue, BinaryMetadataValue, MetadataKey, MetadataMap};
use tonic::{Code, Status};

/// Metadata entry that names the refusal (its key in the table).
const KIND: &str = "roomlight-refusal";

/// One line of the table: what a refusal is called on the wire, its gRPC code, and whether
/// retrying cannot fix it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Row {
    /// The refusal's name on the wire (the `roomlight-refusal` metadata entry).
    pub key: &'static str,
    /// The gRPC status code it is sent with.
    pub code: Code,
    /// True when retrying cannot fix it: the node agent stops instead of reconnecting.
    pub fatal: bool,
}

/// Defines [`Refusal`] and [`Refusal::TABLE`] from one list, so that a variant, its message, its
/// code, its wire name and its fatality cannot drift apart. Every field must print with
/// `Display` and read back with `FromStr` (it travels as UTF-8 text in binary metadata).
macro_rules! refusals {
    ($(
        $(#[doc = $doc:literal])*
        $variant:ident $({ $($field:ident : $ty:ty),* $(,)? })?
            => $key:literal, $code:ident, fatal: $fatal:literal, $message:literal;
    )*) => {
        /// Everything a camera agent refuses a node agent for, at the handshake or later.
        #[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
        pub enum Refusal {
            $(
                $(#[doc = $doc])*
                #[error($message)]
                $variant $({ $($field: $ty),* })?,
            )*
        }

        impl Refusal {
            /// Every refusal's wire name, code and fatality, in declaration order.
            pub const TABLE: &'static [Row] = &[
                $(Row { key: $key, code: Code::$code, fatal: $fatal },)*
            ];

            /// This refusal's line of [`Refusal::TABLE`].
            pub fn row(&self) -> Row {
                match self {
                    $(Self::$variant { .. } => Row { key: $key, code: Code::$code, fatal: $fatal },)*
                }
            }

            /// The fields, each under its own binary metadata key.
            fn fields(&self, metadata: &mut MetadataMap) {
                match self {
                    $(
                        #[allow(unused_variables)]
                        Self::$variant $({ $($field),* })? => {
                            $($(
                                metadata.insert_bin(
                                    MetadataKey::from_static(
                                        concat!("roomlight-refusal-", stringify!($field), "-bin"),
                                    ),
                                    BinaryMetadataValue::from_bytes($field.to_string().as_bytes()),
                                );
                            )*)?
                        }
                    )*
                }
            }

            /// The refusal named `key`, its fields read from `metadata`; `None` when the name is
            /// unknown or a field is missing or unreadable.
            fn from_fields(key: &str, metadata: &MetadataMap) -> Option<Self> {
                match key {
                    $(
                        $key => Some(Self::$variant $({ $(
                            $field: field(
                                metadata,
                                concat!("roomlight-refusal-", stringify!($field), "-bin"),
                            )?
                        ),* })?),
                    )*
                    _ => None,
                }
            }
        }
    };
}

refusals! {
    /// The node speaks another protocol version.
    ProtocolVersion { got: u32, speaks: u32 }
        => "protocol-version", FailedPrecondition, fatal: true,
        "protocol version {got}, this camera agent speaks {speaks}";
    /// The node asked for another room than this camera agent's.
    OtherRoom { asked: String, room: String }
        => "other-room", FailedPrecondition, fatal: true,
        "room {asked:?}, this is room {room:?}";
    /// The room token does not match.
    WrongToken
        => "wrong-token", Unauthenticated, fatal: true,
        "wrong room token";
    /// The projector is not in the room's calibration and the room cannot calibrate it.
    UnknownProjector { projector: String, room: String }
        => "unknown-projector", NotFound, fatal: true,
        "projector {projector:?} is not calibrated in room {room:?}";
    /// The projector is not calibrated yet and its Hello gives no resolution to calibrate it.
    NoResolution { projector: String, room: String }
        => "no-resolution", FailedPrecondition, fatal: true,
        "projector {projector:?} is not calibrated in room {room:?}, and its Hello gives no resolution to calibrate it with (a display that draws pixels does)";
    /// Another stream of the same projector is alive; a reconnecting node is admitted once the
    /// old stream has ended or missed its heartbeats, so it retries.
    AlreadyAttached { projector: String, room: String }
        => "already-attached", AlreadyExists, fatal: false,
        "projector {projector:?} is already attached to room {room:?}";
    /// No Hello arrived within the deadline.
    NoHello
        => "no-hello", DeadlineExceeded, fatal: false,
        "no Hello within the deadline";
    /// The stream's first message was something else than Hello.
    FirstNotHello
        => "first-not-hello", InvalidArgument, fatal: true,
        "the first message must be Hello";
    /// The stream ended before its Hello.
    EndedBeforeHello
        => "ended-before-hello", InvalidArgument, fatal: true,
        "the stream ended before Hello";
    /// The node's stream closed while the camera agent was sending the handshake.
    LeftDuringHandshake
        => "left-during-handshake", Unavailable, fatal: false,
        "the node left during the handshake";
    /// mTLS: the node's client certificate (verified against the room CA) is not valid for the
    /// projector its Hello names.
    CertificateName { projector: String, certificate: String }
        => "certificate-name", PermissionDenied, fatal: true,
        "projector {projector:?}: the client certificate is for {certificate}, not this projector";
    /// The node read too slowly: its queue of messages filled up and it was dropped, so that
    /// the room does not wait for it. It reconnects and starts from what it shows.
    Lagging { queue: usize }
        => "lagging", ResourceExhausted, fatal: false,
        "lagging: {queue} messages waiting unread; dropped so the room goes on";
    /// The node sent a message the camera agent cannot read.
    Malformed { what: String }
        => "malformed", InvalidArgument, fatal: true,
        "malformed message: {what}";
    /// The camera agent is stopping; a node reconnects to the next one.
    ShuttingDown
        => "shutting-down", Unavailable, fatal: false,
        "the camera agent is shutting down";
}

/// Reads one field back from its binary metadata entry.
fn field<T: std::str::FromStr>(metadata: &MetadataMap, key: &'static str) -> Option<T> {
    let bytes = metadata.get_bin(key)?.to_bytes().ok()?;
    std::str::from_utf8(&bytes).ok()?.parse().ok()
}

impl Refusal {
    /// The gRPC status the camera agent answers with: the table's code, this refusal's message,
    /// and its name and fields in the metadata.
    pub fn to_status(&self) -> Status {
        let row = self.row();
        let mut metadata = MetadataMap::new();
        metadata.insert(KIND, AsciiMetadataValue::from_static(row.key));
        self.fields(&mut metadata);
        Status::with_metadata(row.code, self.to_string(), metadata)
    }

    /// The refusal a status carries; `None` for any other status (a transport error, a peer of
    /// an older build, a proxy), or one whose code does not match the table.
    pub fn from_status(status: &Status) -> Option<Self> {
        let key = status.metadata().get(KIND)?.to_str().ok()?;
        let refusal = Self::from_fields(key, status.metadata())?;
        (refusal.row().code == status.code()).then_some(refusal)
    }

    /// True when retrying cannot fix it (wrong token, room or version, unknown projector, a
    /// malformed message): the node agent stops with an error instead of reconnecting.
    pub fn is_fatal(&self) -> bool {
        self.row().fatal
    }

    /// Whether a status ends a node agent: by its refusal when it carries one, otherwise by its
    /// code as the table would decide it (the table gives each code one fatality, so a peer
    /// that sends only codes is judged the same way).
    pub fn is_fatal_status(status: &Status) -> bool {
        match Self::from_status(status) {
            Some(refusal) => refusal.is_fatal(),
            None => Self::TABLE
                .iter()
                .any(|row| row.code == status.code() && row.fatal),
        }
    }
}

impl From<Refusal> for Status {
    fn from(refusal: Refusal) -> Self {
        refusal.to_status()
    }
}
