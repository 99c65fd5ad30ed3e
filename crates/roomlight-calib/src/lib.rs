//! roomlight-calib: what the real system does to captures (DESIGN §4, §5). Everything here takes
//! images and configs, never simulator internals, so it works on real photographs.
//!
//! - [`image_io`]: linear images, PNG input with the encodings cameras deliver.
//! - [`graycode`]: Gray-code patterns and robust decoding.
//! - [`charts`]: homography, patch sampling with noise and saturation.
//! - [`response`]: gray-ramp response fit and its inverse.
//! - [`attenuation`]: black offset, attenuation (one at a time, Hadamard), `s`, hot calibration.
//! - [`nodes`]: nodes per chart region, feathering, target exclusion.
//! - [`cone`]: the large aperture's cone mask and the ring handed to the texture projector.
//! - [`rig`]: the [`rig::Rig`] trait, what differs between the callers of calibration (which
//!   projectors are live, show frames on them, capture).
//! - [`shading`]: per-pixel, per-channel gains that make each luminaire follow the room's
//!   reference photograph beyond the charts.
//! - [`procedure`]: the one calibration procedure, written against a rig: bring-up of a dark
//!   room, a projector joining a lit one.
//!
//! It must not know processes, networks, async runtimes or the simulator (a dev-dependency
//! for the tests only).

pub mod attenuation;
mod blocks;
pub mod centroid;
pub mod charts;
pub mod cone;
pub mod graycode;
pub mod image_io;
pub mod nodes;
pub mod procedure;
pub mod response;
pub mod rig;
pub mod shading;
pub mod shared_ramp;

/// What went wrong, naming the file or field and what was expected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibError {
    /// A file is missing, unreadable, or not what was promised.
    #[error("{file}: {problem}")]
    File { file: String, problem: String },
    /// A parameter or configuration field is out of range.
    #[error("{field}: {problem}")]
    Invalid {
        field: &'static str,
        problem: String,
    },
}
