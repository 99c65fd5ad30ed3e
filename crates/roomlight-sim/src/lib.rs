//! roomlight-sim: the simulated room that stands in for the projectors, the LED lights and the
//! camera in tests, the demo and the benchmarks (DESIGN §7, §5).
//!
//! - [`scene`]: the TOML scene file and its validation.
//! - [`geometry`]: faces, radiosity elements, charts, parry3d colliders in a BVH.
//! - [`optics`]: pinhole and thin-lens projectors, LED panels, the fisheye camera.
//! - [`radiosity`]: inter-reflection on coarse elements.
//! - [`room`]: precomputed transport, `render`, camera noise, and ground truth.
//! - [`scenes`]: the embedded rooms.
//!
//! It must not be used by the calibration or agents except through captures: the real system
//! never sees simulator internals.

pub mod geometry;
pub mod optics;
pub mod radiosity;
pub mod room;
pub mod scene;
pub mod scenes;

pub use room::{
    CameraNoise, Capture, Frame, NodeBasis, NodeRegion, PixelSubset, ProjectorImage, Room, SimError,
};
pub use scene::Scene;
