//! `gphoto2[:PORT]`: DSLRs and mirrorless cameras through libgphoto2 (cargo feature `gphoto2`).
//! Opening sets the session's shutter speed, ISO and aperture to the camera's nearest offered
//! value, reads each back, and asks for JPEG; a capture takes one photograph, downloads it,
//! decodes it through the bounded decoder and checks its EXIF against what was asked. The
//! camera is driven through the small `Tether` trait (libgphoto2 in `ffi`, a fake in tests) on
//! a thread of its own, so that a capture hung inside the library still ends at its deadline.
//! It must not know radiometry.

#[cfg(feature = "gphoto2")]
pub mod ffi;

use crate::Backend;
use crate::error::CameraError;
use crate::exif::{ExpectExif, TOLERANCE};
use crate::frame::{Frame, decode_file};
use crate::spec::{CameraConfig, Gphoto2Settings};
use std::sync::mpsc;
use std::time::Instant;

/// One of the camera's config widgets: its value and, for menus, the values it offers.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Widget {
    pub value: String,
    pub choices: Vec<String>,
}

/// What the backend needs of a camera: libgphoto2's, or a fake.
pub trait Tether: Send {
    /// The widget called `name`; `Ok(None)` when the camera has none by that name.
    fn widget(&mut self, name: &str) -> Result<Option<Widget>, String>;
    /// Writes a widget's value to the camera.
    fn set(&mut self, name: &str, value: &str) -> Result<(), String>;
    /// Takes one photograph; its file name and bytes, downloaded (and removed from the card).
    fn capture(&mut self) -> Result<(String, Vec<u8>), String>;
}

/// The widget names cameras use for each setting, most common first (Canon, Nikon, Sony and
/// Fuji drivers of libgphoto2 differ).
const SHUTTER: [&str; 3] = ["shutterspeed", "shutterspeed2", "exposuretime"];
const ISO: [&str; 2] = ["iso", "isospeed"];
const APERTURE: [&str; 2] = ["aperture", "f-number"];
const FORMAT: [&str; 2] = ["imageformat", "imagequality"];

/// A shutter speed as cameras write it ("1/30", "0.5", "2s", "30"); `None` for "bulb",
/// "auto" and the like.
pub fn parse_shutter(text: &str) -> Option<f64> {
    let t = text.trim().trim_end_matches('s').trim();
    let value = match t.split_once('/') {
        Some((n, d)) => n.trim().parse::<f64>().ok()? / d.trim().parse::<f64>().ok()?,
        None => t.parse().ok()?,
    };
    (value.is_finite() && value > 0.0).then_some(value)
}

/// An f-number as cameras write it ("f/8", "f8", "5.6"); `None` for "implicit auto" and such.
pub fn parse_aperture(text: &str) -> Option<f64> {
    let t = text
        .trim()
        .trim_start_matches(['f', 'F'])
        .trim_start_matches('/');
    t.trim()
        .parse()
        .ok()
        .filter(|f: &f64| f.is_finite() && *f > 0.0)
}

/// An ISO as cameras write it ("100", "ISO 100"); `None` for "Auto".
pub fn parse_iso(text: &str) -> Option<f64> {
    let t = text.trim().trim_start_matches("ISO").trim();
    t.parse::<u32>().ok().filter(|&i| i > 0).map(f64::from)
}

/// What one setting is called, how its values read, and the value asked.
struct Ask {
    setting: &'static str,
    names: &'static [&'static str],
    parse: fn(&str) -> Option<f64>,
    asked: f64,
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= TOLERANCE * a.abs().max(b.abs())
}

/// Sets one setting to the offered choice nearest to what was asked (within 3 %) and reads it
/// back; the widget's name is returned. A camera lacking the widget, not offering the value, or
/// reading back another is refused naming the setting, asked and got.
fn apply_one(t: &mut dyn Tether, camera: &str, ask: &Ask) -> Result<&'static str, CameraError> {
    let refuse = |got: String| CameraError::Setting {
        camera: camera.to_string(),
        setting: ask.setting.to_string(),
        asked: ask.asked.to_string(),
        got,
    };
    let mut found = None;
    for &name in ask.names {
        if let Some(w) = t
            .widget(name)
            .map_err(|e| refuse(format!("unreadable: {e}")))?
        {
            found = Some((name, w));
            break;
        }
    }
    let (name, widget) = found.ok_or_else(|| {
        refuse(format!(
            "no such control (looked for {}); is the camera in manual (M) mode?",
            ask.names.join(", ")
        ))
    })?;
    let choice = widget
        .choices
        .iter()
        .filter_map(|c| (ask.parse)(c).map(|v| (c, v)))
        .filter(|&(_, v)| close(ask.asked, v))
        .min_by(|a, b| (a.1 - ask.asked).abs().total_cmp(&(b.1 - ask.asked).abs()))
        .map(|(c, _)| c.clone());
    let choice = match (choice, widget.choices.is_empty()) {
        (Some(c), _) => c,
        // A text or range widget: the value as the camera writes it.
        (None, true) => ask.asked.to_string(),
        (None, false) => {
            return Err(refuse(format!(
                "not offered ({name} offers {})",
                widget.choices.join(", ")
            )));
        }
    };
    t.set(name, &choice)
        .map_err(|e| refuse(format!("{name} = {choice:?} not written: {e}")))?;
    let back = t
        .widget(name)
        .map_err(|e| refuse(format!("unreadable after writing: {e}")))?
        .map(|w| w.value)
        .unwrap_or_default();
    match (ask.parse)(&back) {
        Some(v) if close(ask.asked, v) => Ok(name),
        _ => Err(refuse(format!("{name} reads back {back:?}"))),
    }
}

/// Sets the session's settings (shutter, ISO, then aperture) and asks for JPEG where the
/// camera has an image-format menu with a JPEG-only choice. RAW is not decoded in this build:
/// a RAW-only camera's shots fail to decode, naming the file.
pub fn apply_settings(
    t: &mut dyn Tether,
    camera: &str,
    settings: &Gphoto2Settings,
) -> Result<(), CameraError> {
    let mut asks = vec![
        Ask {
            setting: "shutter speed",
            names: &SHUTTER,
            parse: parse_shutter,
            asked: settings.exposure_s,
        },
        Ask {
            setting: "ISO",
            names: &ISO,
            parse: parse_iso,
            asked: f64::from(settings.iso),
        },
    ];
    if let Some(f) = settings.f_number {
        asks.push(Ask {
            setting: "aperture",
            names: &APERTURE,
            parse: parse_aperture,
            asked: f,
        });
    }
    for ask in &asks {
        apply_one(t, camera, ask)?;
    }
    for name in FORMAT {
        let Ok(Some(w)) = t.widget(name) else {
            continue;
        };
        let jpeg_only = |c: &&String| {
            let c = c.to_ascii_uppercase();
            (c.contains("JPEG") || c.contains("JPG") || c.contains("FINE"))
                && !c.contains("RAW")
                && !c.contains('+')
        };
        if let Some(choice) = w.choices.iter().find(jpeg_only)
            && &w.value != choice
        {
            t.set(name, choice).map_err(|e| CameraError::Setting {
                camera: camera.to_string(),
                setting: "image format".into(),
                asked: choice.clone(),
                got: format!("not written: {e}"),
            })?;
        }
        break;
    }
    Ok(())
}

/// What the camera's thread answers: the shot's file name and bytes.
type Download = Result<(String, Vec<u8>), String>;
/// A request to the camera's thread, answered on its own channel.
type Reply = mpsc::Sender<Download>;

/// A DSLR on its own thread: captures are requests, answered with the downloaded file.
#[derive(Debug)]
pub struct Gphoto2Backend {
    name: String,
    expect: ExpectExif,
    max_pixels: u64,
    requests: mpsc::Sender<Reply>,
    /// The reply of a capture that timed out: its photograph is stale and is discarded.
    late: Option<mpsc::Receiver<Download>>,
    dir: tempfile::TempDir,
}

impl Gphoto2Backend {
    /// Applies the settings on the caller's thread (an error refuses the camera), then moves
    /// the camera to a thread of its own.
    pub fn new(
        name: String,
        mut tether: Box<dyn Tether>,
        settings: &Gphoto2Settings,
        max_pixels: u64,
    ) -> Result<Self, CameraError> {
        apply_settings(tether.as_mut(), &name, settings)?;
        let dir = tempfile::Builder::new()
            .prefix("roomlight-gphoto2-")
            .tempdir()
            .map_err(|e| CameraError::io(&name, "creating a temp dir", e))?;
        let (requests, inbox) = mpsc::channel::<Reply>();
        std::thread::Builder::new()
            .name("gphoto2".into())
            .spawn(move || {
                // Ends when the backend (the only sender) is dropped.
                for reply in inbox {
                    let _ = reply.send(tether.capture());
                }
            })
            .map_err(|e| CameraError::io(&name, "starting the camera thread", e))?;
        Ok(Self {
            name,
            expect: settings.expected(),
            max_pixels,
            requests,
            late: None,
            dir,
        })
    }
}

impl Backend for Gphoto2Backend {
    fn name(&self) -> &str {
        &self.name
    }

    fn capture(&mut self, deadline: Instant) -> Result<Frame, CameraError> {
        let started = Instant::now();
        let timeout = |this: &Self| CameraError::Timeout {
            camera: this.name.clone(),
            after: started.elapsed(),
        };
        // A shot that came too late for the last capture was exposed before this one was
        // asked: wait it out and drop it, within this capture's deadline.
        if let Some(late) = self.late.take() {
            match late.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    self.late = Some(late);
                    return Err(timeout(self));
                }
                Ok(_) | Err(mpsc::RecvTimeoutError::Disconnected) => {}
            }
        }
        let (reply, answer) = mpsc::channel();
        self.requests.send(reply).map_err(|_| CameraError::Gone {
            camera: self.name.clone(),
            reason: "the camera thread ended".into(),
        })?;
        let (file, bytes) =
            match answer.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                Ok(result) => result.map_err(|reason| CameraError::Gone {
                    camera: self.name.clone(),
                    reason,
                })?,
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    self.late = Some(answer);
                    return Err(timeout(self));
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    return Err(CameraError::Gone {
                        camera: self.name.clone(),
                        reason: "the camera thread ended".into(),
                    });
                }
            };
        // The camera's own name keeps its extension, which the decoder's format guess uses.
        let base = std::path::Path::new(&file)
            .file_name()
            .map_or_else(|| "shot.jpg".into(), |n| n.to_string_lossy().into_owned());
        let path = self.dir.path().join(base);
        std::fs::write(&path, &bytes)
            .map_err(|e| CameraError::io(&self.name, "writing the downloaded shot", e))?;
        let frame = decode_file(&path, self.max_pixels);
        let _ = std::fs::remove_file(&path);
        let frame = frame?;
        self.expect.check(&self.name, frame.shot.as_ref())?;
        Ok(frame)
    }
}

/// Opens `gphoto2[:PORT]` with the config's settings (libgphoto2 in builds with the feature).
pub fn open(port: Option<&str>, config: &CameraConfig) -> Result<Box<dyn Backend>, CameraError> {
    let name = config.spec.to_string();
    let settings = config.gphoto2.ok_or_else(|| CameraError::Spec {
        spec: name.clone(),
        reason: "a gphoto2 camera needs gphoto2 = { exposure_s = ..., iso = ... }".into(),
    })?;
    #[cfg(feature = "gphoto2")]
    {
        let tether = ffi::Libgphoto2::open(port).map_err(|reason| CameraError::Gone {
            camera: name.clone(),
            reason,
        })?;
        Ok(Box::new(Gphoto2Backend::new(
            name,
            Box::new(tether),
            &settings,
            config.max_pixels,
        )?))
    }
    #[cfg(not(feature = "gphoto2"))]
    {
        let _ = (port, settings);
        Err(CameraError::Spec {
            spec: name,
            reason: "gphoto2 cameras need roomlight built with the cargo feature `gphoto2`".into(),
        })
    }
}
