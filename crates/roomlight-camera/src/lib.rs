//! roomlight's real cameras. This crate owns the camera backends (a folder that receives
//! photographs, a command that writes one, a V4L2 video device, a DSLR through libgphoto2
//! with each shot's EXIF checked), the spec and config that
//! choose one, and the radiometry that turns what they deliver into linear light (response
//! curves, saturation and under-exposure masks, dark frames). It must not know rounds, the
//! wire, or the calibration procedure: the camera agent drives it through
//! `roomlight_agent::hardware::Camera`.

pub mod adapter;
pub mod cli;
pub mod command;
mod dng;
pub mod error;
pub mod exif;
pub mod folder;
pub mod frame;
pub mod gphoto2;
pub mod radiometry;
pub mod spec;
pub mod v4l2;

pub use adapter::{Charts, HwCamera};
pub use error::CameraError;
pub use frame::{Frame, Samples};
pub use radiometry::{Linearized, Radiometry, Response, calibrate_response};
pub use spec::{CameraConfig, CameraSpec, Gphoto2Settings, V4l2Controls};

use std::time::{Duration, Instant};

/// A camera backend: one blocking capture at a time, each bounded by a deadline.
pub trait Backend: Send {
    /// The camera's spec string, used in every error and log line.
    fn name(&self) -> &str;

    /// The next frame exposed after this call, with the exposure actually used; a
    /// `CameraError::Timeout` naming the camera when none comes before `deadline`.
    fn capture(&mut self, deadline: Instant) -> Result<Frame, CameraError>;
}

/// Opens the backend a config names; with `expect_exif`, every shot's EXIF is checked.
pub fn open_backend(config: &CameraConfig) -> Result<Box<dyn Backend>, CameraError> {
    let backend = open_unchecked(config)?;
    Ok(match config.expect_exif {
        Some(expect) => Box::new(exif::Checked::new(backend, expect)),
        None => backend,
    })
}

fn open_unchecked(config: &CameraConfig) -> Result<Box<dyn Backend>, CameraError> {
    Ok(match &config.spec {
        CameraSpec::Folder(dir) => Box::new(folder::FolderBackend::new(
            dir.clone(),
            Duration::from_millis(config.settle_ms),
            config.max_pixels,
        )),
        CameraSpec::Command(cmd) => Box::new(command::CommandBackend::new(
            cmd.clone(),
            config.max_pixels,
        )?),
        CameraSpec::V4l2(path) => {
            let controls = config.v4l2.as_ref().ok_or_else(|| CameraError::Spec {
                spec: config.spec.to_string(),
                reason: "a v4l2 camera needs its manual controls".into(),
            })?;
            Box::new(v4l2::V4l2Backend::open(path.clone(), controls)?)
        }
        CameraSpec::Gphoto2(port) => gphoto2::open(port.as_deref(), config)?,
    })
}
