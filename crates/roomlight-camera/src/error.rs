//! The one error type of this crate: every variant names the camera (its spec string) or the
//! file, so that a log line or a CLI exit says which device failed and how. It must not know
//! the agents' error types (the adapter maps these to them).

use std::path::PathBuf;
use std::time::Duration;

/// Why a capture, or opening a camera, failed.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// No image within the capture's timeout.
    #[error("camera {camera}: no image within {after:?}")]
    Timeout { camera: String, after: Duration },
    /// The device or folder went away (unplugged, deleted, permission lost).
    #[error("camera {camera}: gone: {reason}")]
    Gone { camera: String, reason: String },
    /// A control did not take the value asked for (auto exposure still on, say).
    #[error("camera {camera}: control {control} refused: asked {asked}, reads back {got}")]
    Refused {
        camera: String,
        control: String,
        asked: i64,
        got: i64,
    },
    /// A shot whose EXIF disagrees with what was asked (or lacks the tag).
    #[error("camera {camera}: EXIF {tag}: asked {asked}, got {got}")]
    Exif {
        camera: String,
        tag: String,
        asked: String,
        got: String,
    },
    /// A camera setting (gphoto2's shutter speed, ISO, aperture) that did not take, or whose
    /// value the camera does not offer.
    #[error("camera {camera}: setting {setting}: asked {asked}, got {got}")]
    Setting {
        camera: String,
        setting: String,
        asked: String,
        got: String,
    },
    /// An image file that cannot be decoded, or that is larger than allowed.
    #[error("image {path}: {reason}")]
    Decode { path: PathBuf, reason: String },
    /// The capture command ran but failed.
    #[error("camera {camera}: the command {status}; its stderr ends: {stderr_tail}")]
    Command {
        camera: String,
        status: String,
        stderr_tail: String,
    },
    /// A spec or config that names no camera this build can drive.
    #[error("camera spec {spec:?}: {reason}")]
    Spec { spec: String, reason: String },
    /// A frame the radiometry cannot use (a dark frame of another size, a bad response).
    #[error("camera {camera}: {reason}")]
    Radiometry { camera: String, reason: String },
    /// An I/O error outside a device's own failure (a temp dir, a stderr file).
    #[error("camera {camera}: {context}: {source}")]
    Io {
        camera: String,
        context: String,
        #[source]
        source: std::io::Error,
    },
}

impl CameraError {
    pub(crate) fn io(camera: &str, context: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io {
            camera: camera.to_string(),
            context: context.into(),
            source,
        }
    }
}
