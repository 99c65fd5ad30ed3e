//! The bodies of `roomlight hw cameras` and `roomlight hw capture`, as plain functions the
//! binary dispatches to. It must not parse arguments.

use crate::error::CameraError;
use crate::frame::save_png;
use crate::spec::{CameraConfig, CameraSpec};
use crate::{Backend, open_backend};
use std::path::Path;
use std::time::{Duration, Instant};

/// What `roomlight hw capture` did.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    pub camera: String,
    pub width: u32,
    pub height: u32,
    /// 8 or 16.
    pub bits: u8,
    /// The exposure actually used, when the camera reports it.
    pub exposure_s: Option<f64>,
    pub elapsed: Duration,
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {}×{} {}-bit in {:.2} s, exposure ",
            self.camera,
            self.width,
            self.height,
            self.bits,
            self.elapsed.as_secs_f64()
        )?;
        match self.exposure_s {
            Some(t) => write!(f, "{t} s"),
            None => write!(f, "not reported by this camera"),
        }
    }
}

/// `roomlight hw cameras`: one line per camera found (V4L2 devices), and the backends that
/// need no discovery.
pub fn cameras() -> Result<String, CameraError> {
    let mut lines = crate::v4l2::list();
    if lines.is_empty() {
        lines.push("no V4L2 capture devices".into());
    }
    lines.push("folder:DIR      the next new image file written to DIR".into());
    lines.push("command:CMD     a program writing an image to {out}".into());
    lines.push(if cfg!(feature = "gphoto2") {
        "gphoto2[:PORT]  a DSLR through libgphoto2".into()
    } else {
        "gphoto2[:PORT]  not in this build (cargo feature gphoto2)".into()
    });
    Ok(lines.join("\n"))
}

/// `roomlight hw capture --camera SPEC --out FILE.png [--timeout-s N]`: one capture written
/// as PNG, as the camera delivered it (8-bit codes or 16-bit linear). A timeout is an error
/// naming the camera (the binary exits non-zero). `v4l2:` cameras need their controls, so
/// take a `CameraConfig`: see [`capture_config`].
pub fn capture(spec: &str, out: &Path, timeout: Duration) -> Result<Report, CameraError> {
    let spec: CameraSpec = spec.parse()?;
    let mut config = CameraConfig::new(spec);
    config.timeout_s = timeout.as_secs_f64();
    capture_config(&config, out)
}

/// One capture of a configured camera, written to `out`.
pub fn capture_config(config: &CameraConfig, out: &Path) -> Result<Report, CameraError> {
    config.validate()?;
    let started = Instant::now();
    let mut backend: Box<dyn Backend> = open_backend(config)?;
    let frame = backend.capture(started + config.timeout())?;
    save_png(&frame, out)?;
    Ok(Report {
        camera: backend.name().to_string(),
        width: frame.width,
        height: frame.height,
        bits: match frame.samples {
            crate::frame::Samples::Rgb8(_) => 8,
            crate::frame::Samples::Rgb16(_) => 16,
        },
        exposure_s: frame.exposure_s,
        elapsed: started.elapsed(),
    })
}

/// `roomlight hw calibrate-response IMAGE=SECONDS...`: the camera's 8-bit response measured from
/// images of one static scene at several exposures (`calibrate_response`, 100 pixels sampled,
/// smoothness 10), returned as the line to put in the camera config:
/// `response = { table = [...] }`. Each image is decoded through the bounded decoder.
pub fn calibrate_response(
    shots: &[(std::path::PathBuf, f64)],
    max_pixels: u64,
) -> Result<String, CameraError> {
    let frames = shots
        .iter()
        .map(|(path, t)| Ok((crate::frame::decode_file(path, max_pixels)?, *t)))
        .collect::<Result<Vec<_>, CameraError>>()?;
    let refs: Vec<_> = frames.iter().map(|(f, t)| (f, *t)).collect();
    let response = crate::radiometry::calibrate_response(&refs, 100, 10.0).map_err(|reason| {
        CameraError::Radiometry {
            camera: "calibrate-response".into(),
            reason,
        }
    })?;
    let table = match &response {
        crate::radiometry::Response::Table(t) => t.clone(),
        other => other.table().to_vec(),
    };
    let values: Vec<String> = table.iter().map(|v| format!("{v:.6}")).collect();
    Ok(format!("response = {{ table = [{}] }}", values.join(", ")))
}
