//! `v4l2:/dev/videoN`: USB and industrial video cameras through linuxvideo (pure Rust: no
//! libv4l, no libclang). Opening sets manual exposure, gain and white balance and reads each
//! back; a control that did not take (auto exposure still on) refuses the camera with the
//! control's name. A capture first drains every frame already queued (exposed before it was
//! asked) and discards the one in flight, then waits for the next with `poll` up to the
//! deadline. Pixel formats: YUYV, RGB3, GREY and MJPG. It must not know radiometry. The control
//! checks and the format conversions are plain functions, tested without a device.

use crate::Backend;
use crate::error::CameraError;
use crate::frame::{Frame, Samples};
use crate::spec::V4l2Controls;
use linuxvideo::controls::Cid;
use linuxvideo::format::{PixFormat, PixelFormat};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use std::os::fd::AsFd;
use std::path::PathBuf;
use std::time::Instant;

/// V4L2's `V4L2_EXPOSURE_MANUAL` for `exposure_auto`.
const EXPOSURE_MANUAL: i64 = 1;
/// 8-bit greyscale (linuxvideo names no constant for it).
const GREY: PixelFormat = PixelFormat::from_fourcc(*b"GREY");

/// Reads and writes a device's controls; the device, or a recorded fake in tests.
pub trait Controls {
    fn write(&mut self, cid: Cid, value: i64) -> std::io::Result<()>;
    fn read(&self, cid: Cid) -> std::io::Result<i64>;
}

impl Controls for linuxvideo::Device {
    fn write(&mut self, cid: Cid, value: i64) -> std::io::Result<()> {
        let v = i32::try_from(value)
            .map_err(|_| std::io::Error::other(format!("{value} outside i32")))?;
        self.write_control_raw(cid, v)
    }
    fn read(&self, cid: Cid) -> std::io::Result<i64> {
        self.read_control_raw(cid).map(i64::from)
    }
}

/// The controls to write, in order (automatics off first, else the manual values are
/// ignored), each named as V4L2 names it.
pub fn plan(controls: &V4l2Controls) -> Vec<(&'static str, Cid, i64)> {
    let mut plan = vec![
        ("exposure_auto", Cid::EXPOSURE_AUTO, EXPOSURE_MANUAL),
        (
            "exposure_absolute",
            Cid::EXPOSURE_ABSOLUTE,
            controls.exposure_100us,
        ),
    ];
    if let Some(g) = controls.gain {
        plan.push(("autogain", Cid::AUTOGAIN, 0));
        plan.push(("gain", Cid::GAIN, g));
    }
    if let Some(k) = controls.white_balance_k {
        plan.push(("white_balance_temperature_auto", Cid::AUTO_WHITE_BALANCE, 0));
        plan.push((
            "white_balance_temperature",
            Cid::WHITE_BALANCE_TEMPERATURE,
            k,
        ));
    }
    plan
}

/// Writes every planned control and reads it back; the first that reads back otherwise
/// refuses the camera, named.
pub fn apply_controls(
    device: &mut impl Controls,
    controls: &V4l2Controls,
    camera: &str,
) -> Result<(), CameraError> {
    for (name, cid, value) in plan(controls) {
        let refused = |got: i64| CameraError::Refused {
            camera: camera.to_string(),
            control: name.to_string(),
            asked: value,
            got,
        };
        if let Err(e) = device.write(cid, value) {
            tracing::warn!(camera, control = name, "writing failed: {e}");
        }
        let got = device.read(cid).map_err(|e| CameraError::Gone {
            camera: camera.to_string(),
            reason: format!("reading {name}: {e}"),
        })?;
        if got != value {
            return Err(refused(got));
        }
    }
    Ok(())
}

/// The pixel formats [`convert`] knows.
pub const SUPPORTED: [PixelFormat; 4] = [
    PixelFormat::YUYV,
    PixelFormat::RGB3,
    GREY,
    PixelFormat::MJPG,
];

/// One buffer of a `format` frame as 8-bit RGB; `None` for a buffer of the wrong length or an
/// unsupported format. YUYV is BT.601 limited range, as UVC cameras send it.
pub fn convert(format: PixelFormat, width: u32, height: u32, data: &[u8]) -> Option<Vec<[u8; 3]>> {
    let n = width as usize * height as usize;
    if format == PixelFormat::RGB3 {
        (data.len() >= n * 3).then(|| {
            data[..n * 3]
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect()
        })
    } else if format == GREY {
        (data.len() >= n).then(|| data[..n].iter().map(|&g| [g; 3]).collect())
    } else if format == PixelFormat::YUYV {
        if data.len() < n * 2 || !width.is_multiple_of(2) {
            return None;
        }
        let rgb = |y: u8, u: u8, v: u8| {
            let c = 1.164 * (f32::from(y) - 16.0);
            let d = f32::from(u) - 128.0;
            let e = f32::from(v) - 128.0;
            let q = |x: f32| x.round().clamp(0.0, 255.0) as u8;
            [
                q(c + 1.596 * e),
                q(c - 0.392 * d - 0.813 * e),
                q(c + 2.017 * d),
            ]
        };
        Some(
            data[..n * 2]
                .chunks_exact(4)
                .flat_map(|m| [rgb(m[0], m[1], m[3]), rgb(m[2], m[1], m[3])])
                .collect(),
        )
    } else if format == PixelFormat::MJPG {
        let image = image::load_from_memory_with_format(data, image::ImageFormat::Jpeg).ok()?;
        ((image.width(), image.height()) == (width, height))
            .then(|| image.to_rgb8().pixels().map(|p| p.0).collect())
    } else {
        None
    }
}

/// A V4L2 camera streaming with manual controls.
pub struct V4l2Backend {
    name: String,
    stream: linuxvideo::stream::ReadStream,
    /// Width, height and pixel format as negotiated.
    format: (u32, u32, PixelFormat),
    exposure_s: f64,
}

impl V4l2Backend {
    /// Opens the device, applies and checks the controls, negotiates a format the converter
    /// knows and starts streaming.
    pub fn open(path: PathBuf, controls: &V4l2Controls) -> Result<Self, CameraError> {
        let name = format!("v4l2:{}", path.display());
        let gone = |what: &str, e: std::io::Error| CameraError::Gone {
            camera: name.clone(),
            reason: format!("{what}: {e}"),
        };
        let mut device = linuxvideo::Device::open(&path).map_err(|e| gone("opening", e))?;
        apply_controls(&mut device, controls, &name)?;
        let exposure = device
            .read(Cid::EXPOSURE_ABSOLUTE)
            .map_err(|e| gone("reading exposure_absolute", e))?;
        let [w, h] = controls.size;
        let capture = device
            .video_capture(PixFormat::new(w, h, PixelFormat::YUYV))
            .map_err(|e| gone("setting the format", e))?;
        let negotiated = capture.format();
        let format = (
            negotiated.width(),
            negotiated.height(),
            negotiated.pixel_format(),
        );
        if !SUPPORTED.contains(&format.2) {
            return Err(CameraError::Spec {
                spec: name,
                reason: format!("pixel format {} not supported", format.2),
            });
        }
        let stream = capture.into_stream().map_err(|e| gone("streaming", e))?;
        Ok(Self {
            name,
            stream,
            format,
            exposure_s: exposure as f64 * 1e-4,
        })
    }

    fn ready(&self, deadline: Instant) -> Result<bool, CameraError> {
        let left = deadline.saturating_duration_since(Instant::now());
        let ms = u16::try_from(left.as_millis()).unwrap_or(u16::MAX);
        let mut fds = [PollFd::new(self.stream.as_fd(), PollFlags::POLLIN)];
        poll(&mut fds, PollTimeout::from(ms))
            .map_err(|e| CameraError::Gone {
                camera: self.name.clone(),
                reason: format!("poll: {e}"),
            })
            .map(|n| n > 0)
    }
}

impl std::fmt::Debug for V4l2Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("V4l2Backend")
            .field("name", &self.name)
            .field("format", &self.format)
            .finish_non_exhaustive()
    }
}

impl Backend for V4l2Backend {
    fn name(&self) -> &str {
        &self.name
    }

    fn capture(&mut self, deadline: Instant) -> Result<Frame, CameraError> {
        let started = Instant::now();
        let gone = |e: std::io::Error| CameraError::Gone {
            camera: self.name.clone(),
            reason: e.to_string(),
        };
        // Frames already filled were exposed before this capture was asked: the projectors
        // may not have shown the new frame yet. linuxvideo gives no buffer timestamps, so the
        // frame being exposed at the request is discarded too: the first frame dequeued after
        // the drain, whatever its content (one frame of latency, as a video camera has).
        while !self.stream.will_block().map_err(gone)? {
            self.stream.dequeue(|_| Ok(())).map_err(gone)?;
        }
        let mut in_flight = true;
        loop {
            if !self.ready(deadline)? {
                if Instant::now() >= deadline {
                    return Err(CameraError::Timeout {
                        camera: self.name.clone(),
                        after: started.elapsed(),
                    });
                }
                continue;
            }
            let (w, h, f) = self.format;
            let pixels = self
                .stream
                .dequeue(|buf| Ok((!buf.is_error()).then(|| convert(f, w, h, &buf)).flatten()))
                .map_err(gone)?;
            if std::mem::take(&mut in_flight) {
                continue;
            }
            if let Some(pixels) = pixels {
                return Ok(Frame {
                    width: w,
                    height: h,
                    samples: Samples::Rgb8(pixels),
                    exposure_s: Some(self.exposure_s),
                    shot: None,
                });
            }
        }
    }
}

/// The V4L2 capture devices present (`/dev/video*` that open and can capture).
pub fn list() -> Vec<String> {
    let Ok(devices) = linuxvideo::list() else {
        return Vec::new();
    };
    devices
        .filter_map(Result::ok)
        .filter_map(|d| {
            let caps = d.capabilities().ok()?;
            let path = d.path().ok()?;
            Some(format!(
                "v4l2:{}  {} ({})",
                path.display(),
                caps.card(),
                caps.driver()
            ))
        })
        .collect()
}
