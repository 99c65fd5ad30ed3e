//! What per-pixel shading needs, kept beside the model file (`<model_out>.shading`), so that a
//! camera agent restarted mid-show shades again without calibrating anew: the dark room, the
//! LEDs' light of the last preset chosen, and each standard projector's decode. They are
//! camera-sized images and maps (tens of megabytes for the lab), not model data, so they stay
//! out of the JSON model file; encoded with postcard (serde), written whole to a temporary
//! file and renamed, off the runtime. What is read back is checked against the camera's size
//! and the projectors the resumed model knows; anything else is refused, naming the file and
//! what was expected, and the agent starts without it, as before this file existed.

use roomlight_calib::graycode::Correspondence;
use roomlight_calib::image_io::LinearImage;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The format's version; another one is refused.
const VERSION: u32 = 1;

/// The largest projector side a stored decode may name.
const MAX_PROJECTOR_SIDE: u32 = 16_384;

/// The largest file read (a 4K camera with six projectors' decodes is some 650 MB).
const MAX_BYTES: u64 = 2 << 30;

/// The file beside `model_out`.
pub(crate) fn path(model_out: &Path) -> PathBuf {
    model_out.with_extension("shading")
}

/// The file beside `model_out` that counts the passes sent on the stored inputs: written after
/// each pass, removed before the inputs are written again (a new target, a calibration: the
/// passes start over). A restarted agent goes on from it; without it (or unreadable) it counts
/// none done, and passes the node agents' kept gains already carry only step them again
/// towards the ratios they reached, which costs captures, not light.
pub(crate) fn passes_path(model_out: &Path) -> PathBuf {
    model_out.with_extension("shading-passes")
}

/// What [`passes_path`] holds.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Passes {
    passes: usize,
}

/// Writes that `passes` passes were sent (through a temporary file renamed over it).
pub(crate) fn write_passes(model_out: &Path, passes: usize) -> Result<(), String> {
    let path = passes_path(model_out);
    let tmp = path.with_extension("shading-passes.tmp");
    let text = serde_json::to_string(&Passes { passes }).map_err(|e| e.to_string())?;
    std::fs::write(&tmp, text).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, &path).map_err(|e| format!("{}: {e}", path.display()))
}

/// Removes the pass count (none written is fine).
pub(crate) fn forget_passes(model_out: &Path) -> Result<(), String> {
    let path = passes_path(model_out);
    match std::fs::remove_file(&path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            Err(format!("{}: {e}", path.display()))
        }
        _ => Ok(()),
    }
}

/// The passes sent, as written, at most `max`: `Ok(None)` without a file; an error naming the
/// file for one that is not a count (over 64 bytes, not JSON, a count above `max`).
pub(crate) fn read_passes(model_out: &Path, max: usize) -> Result<Option<usize>, String> {
    let path = passes_path(model_out);
    let at = path.display();
    let bytes = match std::fs::read(&path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("{at}: {e}")),
    };
    if bytes.len() > 64 {
        return Err(format!(
            "{at}: {} bytes, expected a pass count",
            bytes.len()
        ));
    }
    let Passes { passes } = serde_json::from_slice(&bytes)
        .map_err(|e| format!("{at}: expected {{\"passes\": N}} ({e})"))?;
    if passes > max {
        return Err(format!("{at}: {passes} passes, expected at most {max}"));
    }
    Ok(Some(passes))
}

/// The stored inputs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Stored {
    version: u32,
    /// The camera's size.
    pub width: u32,
    pub height: u32,
    /// The room dark, row-major.
    pub dark: Option<Vec<[f32; 3]>>,
    /// The LEDs' light alone (negatives cut), row-major.
    pub leds: Option<Vec<[f32; 3]>>,
    pub decodes: Vec<Decode>,
}

/// One projector's decode: for each camera pixel its `(column, row)` or `None`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Decode {
    pub projector: String,
    pub projector_width: u32,
    pub projector_height: u32,
    pub map: Vec<Option<(u32, u32)>>,
}

impl Decode {
    pub(crate) fn of(projector: &str, corr: &Correspondence) -> Self {
        Self {
            projector: projector.to_string(),
            projector_width: corr.projector_width,
            projector_height: corr.projector_height,
            map: corr.map.clone(),
        }
    }

    /// The decode as shading uses it (the map; no confidence or light kept).
    pub(crate) fn correspondence(&self, width: u32, height: u32) -> Correspondence {
        let n = self.map.len();
        Correspondence {
            width,
            height,
            projector_width: self.projector_width,
            projector_height: self.projector_height,
            map: self.map.clone(),
            confidence: vec![0.0; n],
            direct: vec![0.0; n],
            global: vec![0.0; n],
            reach: 0.0,
        }
    }
}

impl Stored {
    pub(crate) fn new(
        (width, height): (u32, u32),
        dark: Option<&LinearImage>,
        leds: Option<&LinearImage>,
        decodes: Vec<Decode>,
    ) -> Self {
        Self {
            version: VERSION,
            width,
            height,
            dark: dark.map(|i| i.pixels.clone()),
            leds: leds.map(|i| i.pixels.clone()),
            decodes,
        }
    }

    /// Writes `self` to `path` (through a temporary file renamed over it); the bytes written.
    pub(crate) fn write(&self, path: &Path) -> Result<usize, String> {
        let bytes = postcard::to_stdvec(self).map_err(|e| format!("encoding: {e}"))?;
        let tmp = path.with_extension("shading.tmp");
        std::fs::write(&tmp, &bytes).map_err(|e| format!("{}: {e}", tmp.display()))?;
        std::fs::rename(&tmp, path).map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(bytes.len())
    }

    /// Reads `path` for a camera of `size`. Decodes of projectors `known` does not accept are
    /// dropped (named in the returned notes); anything else out of shape refuses the file.
    pub(crate) fn read(
        path: &Path,
        size: (u32, u32),
        known: impl Fn(&str) -> bool,
    ) -> Result<(Self, Vec<String>), String> {
        let at = path.display();
        let len = std::fs::metadata(path)
            .map_err(|e| format!("{at}: {e}"))?
            .len();
        if len > MAX_BYTES {
            return Err(format!("{at}: {len} bytes, expected at most {MAX_BYTES}"));
        }
        let bytes = std::fs::read(path).map_err(|e| format!("{at}: {e}"))?;
        let stored: Self = postcard::from_bytes(&bytes)
            .map_err(|e| format!("{at}: not a shading file of this version ({e})"))?;
        stored
            .checked(size, known)
            .map_err(|e| format!("{at}: {e}"))
    }

    fn checked(
        mut self,
        (width, height): (u32, u32),
        known: impl Fn(&str) -> bool,
    ) -> Result<(Self, Vec<String>), String> {
        if self.version != VERSION {
            return Err(format!("version {}, expected {VERSION}", self.version));
        }
        if (self.width, self.height) != (width, height) {
            return Err(format!(
                "for a {}×{} camera, this one is {width}×{height}",
                self.width, self.height
            ));
        }
        let pixels = width as usize * height as usize;
        for (what, image) in [("dark", &self.dark), ("leds", &self.leds)] {
            if let Some(p) = image {
                if p.len() != pixels {
                    return Err(format!("{what}: {} pixels, expected {pixels}", p.len()));
                }
                if let Some(i) = p.iter().position(|v| v.iter().any(|c| !c.is_finite())) {
                    return Err(format!("{what}: pixel {i} is not finite"));
                }
            }
        }
        let mut notes = Vec::new();
        let mut decodes = Vec::new();
        for d in std::mem::take(&mut self.decodes) {
            let (pw, ph) = (d.projector_width, d.projector_height);
            if !(1..=MAX_PROJECTOR_SIDE).contains(&pw) || !(1..=MAX_PROJECTOR_SIDE).contains(&ph) {
                return Err(format!(
                    "decode of {:?}: a {pw}×{ph} projector, expected sides 1 to {MAX_PROJECTOR_SIDE}",
                    d.projector
                ));
            }
            if d.map.len() != pixels {
                return Err(format!(
                    "decode of {:?}: {} camera pixels, expected {pixels}",
                    d.projector,
                    d.map.len()
                ));
            }
            if let Some(i) = d
                .map
                .iter()
                .position(|m| m.is_some_and(|(c, r)| c >= pw || r >= ph))
            {
                return Err(format!(
                    "decode of {:?}: camera pixel {i} lands outside its {pw}×{ph} pixels",
                    d.projector
                ));
            }
            if known(&d.projector) {
                decodes.push(d);
            } else {
                notes.push(format!(
                    "decode of {:?} dropped: the model has no such projector",
                    d.projector
                ));
            }
        }
        self.decodes = decodes;
        Ok((self, notes))
    }

    /// The stored image `pixels` as a camera-sized image.
    pub(crate) fn image(&self, pixels: &Option<Vec<[f32; 3]>>) -> Option<LinearImage> {
        pixels.as_ref().map(|p| LinearImage {
            width: self.width,
            height: self.height,
            pixels: p.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stored() -> Stored {
        let image = |v: f32| LinearImage {
            width: 4,
            height: 3,
            pixels: (0..12).map(|i| [v * i as f32, v, 0.5]).collect(),
        };
        let corr = Correspondence {
            width: 4,
            height: 3,
            projector_width: 8,
            projector_height: 6,
            map: (0..12)
                .map(|i| (i % 3 != 0).then_some((i % 8, i / 4)))
                .collect(),
            confidence: vec![1.0; 12],
            direct: vec![0.2; 12],
            global: vec![0.1; 12],
            reach: 0.01,
        };
        Stored::new(
            (4, 3),
            Some(&image(0.01)),
            Some(&image(0.2)),
            vec![Decode::of("left", &corr), Decode::of("right", &corr)],
        )
    }

    #[test]
    fn what_is_written_is_read_back_for_the_same_camera_and_projectors() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = path(&dir.path().join("model.json"));
        assert_eq!(
            file.file_name().and_then(|n| n.to_str()),
            Some("model.shading")
        );
        let s = stored();
        s.write(&file).expect("written");
        let (back, notes) = Stored::read(&file, (4, 3), |_| true).expect("read");
        assert_eq!(back, s);
        assert!(notes.is_empty());
        let corr = back.decodes[0].correspondence(4, 3);
        assert_eq!(corr.map, s.decodes[0].map);
        assert_eq!((corr.projector_width, corr.projector_height), (8, 6));
        assert_eq!(
            back.image(&back.leds).expect("leds").pixels,
            s.leds.clone().expect("leds")
        );
        // A projector the model does not know loses its decode, the rest is kept.
        let (back, notes) = Stored::read(&file, (4, 3), |p| p == "left").expect("read");
        assert_eq!(back.decodes.len(), 1);
        assert!(notes[0].contains("\"right\""), "{notes:?}");
    }

    #[test]
    fn the_pass_count_is_kept_forgotten_and_checked() {
        let dir = tempfile::tempdir().expect("temp dir");
        let model = dir.path().join("model.json");
        assert_eq!(read_passes(&model, 10), Ok(None));
        write_passes(&model, 3).expect("written");
        assert_eq!(read_passes(&model, 10), Ok(Some(3)));
        let e = read_passes(&model, 2).expect_err("above the configured passes");
        assert!(
            e.contains("model.shading-passes") && e.contains("at most 2"),
            "{e}"
        );
        forget_passes(&model).expect("forgotten");
        assert_eq!(read_passes(&model, 10), Ok(None));
        forget_passes(&model).expect("none to forget is fine");
        for bad in [
            "",
            "3",
            "{\"passes\": -1}",
            "{\"passes\": 1, \"x\": 2}",
            &"9".repeat(100),
        ] {
            std::fs::write(passes_path(&model), bad).expect("written");
            let e = read_passes(&model, 10).expect_err(bad);
            assert!(e.contains("model.shading-passes"), "{e}");
        }
    }

    #[test]
    fn a_file_out_of_shape_is_refused_naming_the_file_and_what_was_expected() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join("model.shading");
        stored().write(&file).expect("written");
        let e = Stored::read(&file, (640, 480), |_| true).expect_err("another camera");
        assert!(e.contains("model.shading") && e.contains("640×480"), "{e}");

        let mut s = stored();
        s.decodes[0].map[1] = Some((8, 0));
        s.write(&file).expect("written");
        let e = Stored::read(&file, (4, 3), |_| true).expect_err("off the projector");
        assert!(
            e.contains("\"left\"") && e.contains("outside its 8×6"),
            "{e}"
        );

        let mut s = stored();
        if let Some(d) = s.dark.as_mut() {
            d[5][1] = f32::NAN;
        }
        s.write(&file).expect("written");
        let e = Stored::read(&file, (4, 3), |_| true).expect_err("NaN");
        assert!(e.contains("dark: pixel 5 is not finite"), "{e}");

        let mut s = stored();
        s.leds = Some(vec![[0.0; 3]; 5]);
        s.write(&file).expect("written");
        let e = Stored::read(&file, (4, 3), |_| true).expect_err("short");
        assert!(e.contains("leds: 5 pixels, expected 12"), "{e}");

        // Bytes that are not a shading file, cut short or empty: an error, never a panic.
        let bytes = postcard::to_stdvec(&stored()).expect("encoded");
        for cut in [0, 1, 7, bytes.len() / 2, bytes.len() - 1] {
            std::fs::write(&file, &bytes[..cut]).expect("written");
            let e = Stored::read(&file, (4, 3), |_| true).expect_err("cut short");
            assert!(e.contains("not a shading file"), "{cut}: {e}");
        }
        let e =
            Stored::read(&dir.path().join("absent.shading"), (4, 3), |_| true).expect_err("absent");
        assert!(e.contains("absent.shading"), "{e}");
    }
}
