//! Which camera and how it is treated: the `CameraSpec` parsed from `folder:DIR`,
//! `command:CMD`, `v4l2:/dev/videoN` or `gphoto2[:PORT]`, and the typed `CameraConfig` the
//! camera agent's config holds (spec, timeout, response, masks, dark frame, V4L2 controls,
//! gphoto2 settings, the EXIF a folder/command camera's shots must carry). It must not open
//! devices.

use crate::error::CameraError;
use crate::exif::ExpectExif;
use crate::radiometry::Response;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Duration;

/// A camera, as written on the command line and in configs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CameraSpec {
    /// The next new image file in this folder.
    Folder(PathBuf),
    /// A shell command writing an image to `{out}`.
    Command(String),
    /// A V4L2 video device.
    V4l2(PathBuf),
    /// A DSLR through libgphoto2 (cargo feature `gphoto2`), optionally at a port.
    Gphoto2(Option<String>),
}

impl FromStr for CameraSpec {
    type Err = CameraError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = |reason: &str| CameraError::Spec {
            spec: s.to_string(),
            reason: reason.to_string(),
        };
        let (kind, rest) = match s.split_once(':') {
            Some((k, r)) => (k, Some(r)),
            None => (s, None),
        };
        let nonempty = |what: &str| match rest {
            Some(r) if !r.is_empty() => Ok(r.to_string()),
            _ => Err(bad(&format!("expected {kind}:{what}"))),
        };
        match kind {
            "folder" => Ok(Self::Folder(nonempty("DIR")?.into())),
            "command" => {
                let cmd = nonempty("CMD")?;
                if !cmd.contains("{out}") {
                    return Err(bad("the command must write its image to {out}"));
                }
                Ok(Self::Command(cmd))
            }
            "v4l2" => Ok(Self::V4l2(nonempty("/dev/videoN")?.into())),
            "gphoto2" => {
                if !cfg!(feature = "gphoto2") {
                    return Err(bad(
                        "gphoto2 cameras need roomlight built with the cargo feature `gphoto2` \
                         (not available in this build)",
                    ));
                }
                Ok(Self::Gphoto2(
                    rest.filter(|r| !r.is_empty()).map(String::from),
                ))
            }
            _ => Err(bad(
                "expected folder:DIR, command:CMD, v4l2:/dev/videoN or gphoto2[:PORT]",
            )),
        }
    }
}

impl fmt::Display for CameraSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Folder(d) => write!(f, "folder:{}", d.display()),
            Self::Command(c) => write!(f, "command:{c}"),
            Self::V4l2(d) => write!(f, "v4l2:{}", d.display()),
            Self::Gphoto2(None) => write!(f, "gphoto2"),
            Self::Gphoto2(Some(p)) => write!(f, "gphoto2:{p}"),
        }
    }
}

impl Serialize for CameraSpec {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for CameraSpec {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// Manual V4L2 controls, in the device's own units; each is written and read back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct V4l2Controls {
    /// Exposure time in units of 100 µs (V4L2's `exposure_absolute`).
    pub exposure_100us: i64,
    /// Analogue gain; `None`: left as it is.
    #[serde(default)]
    pub gain: Option<i64>,
    /// White balance temperature in kelvin; `None`: left as it is (auto white balance off).
    #[serde(default)]
    pub white_balance_k: Option<i64>,
    /// Requested frame size (the driver may pick another; the one it picked is used).
    #[serde(default = "default_size")]
    pub size: [u32; 2],
}

fn default_size() -> [u32; 2] {
    [1280, 720]
}

/// A DSLR's settings for a session (`gphoto2:` cameras): each is set to the camera's nearest
/// offered value (within 3 %), read back, and checked in every shot's EXIF.
/// `gphoto2 = { exposure_s = 0.0333, iso = 100, f_number = 8.0 }`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gphoto2Settings {
    /// Shutter speed in seconds.
    pub exposure_s: f64,
    pub iso: u32,
    /// `None`: a lens without electronic aperture (left as it is, not checked).
    #[serde(default)]
    pub f_number: Option<f64>,
}

impl Gphoto2Settings {
    /// What every shot's EXIF must say.
    pub fn expected(&self) -> ExpectExif {
        ExpectExif {
            exposure_s: Some(self.exposure_s),
            iso: Some(self.iso),
            f_number: self.f_number,
        }
    }
}

/// The camera agent's camera, as its config file holds it:
/// `camera = { spec = "v4l2:/dev/video0", timeout_s = 5, response = "srgb" }`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraConfig {
    pub spec: CameraSpec,
    /// Longest wait for one capture.
    #[serde(default = "default_timeout_s")]
    pub timeout_s: f64,
    /// How 8-bit codes map to linear light (16-bit images are linear as they are).
    #[serde(default)]
    pub response: Response,
    /// 8-bit codes at or above this are saturated and masked.
    #[serde(default = "default_saturated")]
    pub saturated_code: u8,
    /// 8-bit codes at or below this are under-exposed and masked (0: only clipped black).
    #[serde(default)]
    pub underexposed_code: u8,
    /// A linear 16-bit PNG of the camera with the lens capped, subtracted from every capture.
    #[serde(default)]
    pub dark_frame: Option<PathBuf>,
    /// Largest image accepted from outside, in pixels, checked before decoding.
    #[serde(default = "default_max_pixels")]
    pub max_pixels: u64,
    /// For `v4l2:` cameras: the manual controls (required there, refused elsewhere).
    #[serde(default)]
    pub v4l2: Option<V4l2Controls>,
    /// For `folder:` cameras: how long a new file's size must stay the same before it counts.
    #[serde(default = "default_settle_ms")]
    pub settle_ms: u64,
    /// For `gphoto2:` cameras: shutter, ISO and aperture (required there, refused elsewhere).
    #[serde(default)]
    pub gphoto2: Option<Gphoto2Settings>,
    /// For `folder:` and `command:` cameras (a tethered DSLR writing files): what every shot's
    /// EXIF must say; a shot that disagrees is refused naming the tag.
    #[serde(default)]
    pub expect_exif: Option<ExpectExif>,
}

fn default_timeout_s() -> f64 {
    10.0
}
fn default_saturated() -> u8 {
    250
}
/// The largest image a camera may deliver, in pixels, unless its config says otherwise.
pub const MAX_PIXELS: u64 = 64 << 20;

fn default_max_pixels() -> u64 {
    MAX_PIXELS
}
fn default_settle_ms() -> u64 {
    200
}

impl CameraConfig {
    /// A config with every default for `spec`.
    pub fn new(spec: CameraSpec) -> Self {
        Self {
            spec,
            timeout_s: default_timeout_s(),
            response: Response::default(),
            saturated_code: default_saturated(),
            underexposed_code: 0,
            dark_frame: None,
            max_pixels: default_max_pixels(),
            v4l2: None,
            settle_ms: default_settle_ms(),
            gphoto2: None,
            expect_exif: None,
        }
    }

    /// Checks ranges once, at load; the field is named in the error.
    pub fn validate(&self) -> Result<(), CameraError> {
        let bad = |reason: String| CameraError::Spec {
            spec: self.spec.to_string(),
            reason,
        };
        if !(self.timeout_s.is_finite() && self.timeout_s > 0.0 && self.timeout_s <= 3600.0) {
            return Err(bad(format!(
                "timeout_s = {}; expected (0, 3600]",
                self.timeout_s
            )));
        }
        if self.underexposed_code >= self.saturated_code {
            return Err(bad(format!(
                "underexposed_code = {} is not below saturated_code = {}",
                self.underexposed_code, self.saturated_code
            )));
        }
        if self.max_pixels == 0 {
            return Err(bad("max_pixels = 0".into()));
        }
        self.response.validate().map_err(bad)?;
        if let Some(expect) = &self.expect_exif {
            expect.validate().map_err(bad)?;
            if !matches!(self.spec, CameraSpec::Folder(_) | CameraSpec::Command(_)) {
                return Err(bad(
                    "expect_exif is for folder: and command: cameras (gphoto2 checks its own \
                     settings; video frames have no EXIF)"
                        .into(),
                ));
            }
        }
        match (&self.spec, &self.gphoto2) {
            (CameraSpec::Gphoto2(_), None) => {
                return Err(bad(
                    "a gphoto2 camera needs gphoto2 = { exposure_s = ..., iso = ... }: its \
                     settings are set and checked per session"
                        .into(),
                ));
            }
            (CameraSpec::Gphoto2(_), Some(g)) => g.expected().validate().map_err(bad)?,
            (_, Some(_)) => {
                return Err(bad(
                    "gphoto2 settings given for a camera that is not gphoto2".into(),
                ));
            }
            (_, None) => {}
        }
        match (&self.spec, &self.v4l2) {
            (CameraSpec::V4l2(_), None) => Err(bad(
                "a v4l2 camera needs v4l2 = { exposure_100us = ... }: auto exposure is refused"
                    .into(),
            )),
            (CameraSpec::V4l2(_), Some(_)) | (_, None) => Ok(()),
            (_, Some(_)) => Err(bad(
                "v4l2 controls given for a camera that is not v4l2".into()
            )),
        }
    }

    /// The capture timeout.
    pub fn timeout(&self) -> Duration {
        Duration::from_secs_f64(self.timeout_s)
    }
}
