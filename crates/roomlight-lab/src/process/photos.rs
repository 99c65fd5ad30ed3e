//! `roomlight sim --scene S --grab P=WxH+X+Y … --photos DIR`: the rendered room fed by the
//! screen. Each projector's frame is a grab of a region of an X display (its node agent's
//! window), never a `ShowImage` call, and the camera is a folder: when the `folder:DIR` camera
//! is armed it writes `DIR/.wanted` (roomlight-camera's folder backend), and for each new
//! number this grabs every region, renders the room from those 8-bit codes (the simulator's
//! projector model applies, as for any frame) and writes the photograph into `DIR` as a 16-bit
//! linear PNG, which the folder backend reads as linear light. This proves that what a node
//! puts in its window is what the room receives.
//!
//! It must not know the agents or the wire: it reads the screen and writes files.

use crate::rendered::Rendered;
use anyhow::{Context, Result, bail};
use roomlight_camera::folder::wanted;
use roomlight_hw::Geometry;
use roomlight_hw::grab::Grabber;
use roomlight_sim::{Frame, ProjectorImage, Room};
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// How often `.wanted` is read: small beside a capture's render, and a file read is cheap.
const POLL: Duration = Duration::from_millis(5);

/// Where the frames come from and where the photographs go.
#[derive(Debug, Clone)]
pub struct GrabMode {
    /// The X display (`:7`), or `None` for `$DISPLAY`.
    pub x_display: Option<String>,
    /// Projector name and the screen region its window covers, the projector's resolution.
    pub regions: Vec<(String, Geometry)>,
    /// The `folder:` camera's folder.
    pub photos: PathBuf,
}

impl GrabMode {
    /// The region of each of `room`'s projectors (`None`: no window, black); an unknown
    /// projector, one named twice, or a region that is not the projector's resolution is
    /// refused.
    pub(super) fn regions_of(&self, room: &Room) -> Result<Vec<Option<Geometry>>> {
        let projectors = &room.scene().projectors;
        let mut out = vec![None; projectors.len()];
        for (name, g) in &self.regions {
            let Some(k) = projectors.iter().position(|p| &p.name == name) else {
                bail!(
                    "--grab {name}={g}: no projector {name:?} (the room has {})",
                    projectors
                        .iter()
                        .map(|p| p.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            };
            let [w, h] = projectors[k].resolution;
            if (g.width, g.height) != (w, h) {
                bail!("--grab {name}={g}: the projector is {w}x{h}, pixel for pixel");
            }
            if out[k].replace(*g).is_some() {
                bail!("--grab {name}: given twice");
            }
        }
        if !self.photos.is_dir() {
            bail!("--photos {}: not a folder", self.photos.display());
        }
        Ok(out)
    }
}

/// Shoots one photograph per new `.wanted` number until `cancel`; a failed shot is logged and
/// the next request tried (the camera agent times out and asks again).
pub(super) fn shoot_on_request(
    rendered: &Rendered,
    grab: &GrabMode,
    regions: &[Option<Geometry>],
    cancel: &CancellationToken,
) -> Result<()> {
    let grabber = Grabber::connect(grab.x_display.as_deref())
        .with_context(|| format!("grab mode: X display {:?}", grab.x_display))?;
    // A request left from an earlier run is not this run's: its frames are gone.
    let mut last = wanted(&grab.photos);
    let mut previous: Option<PathBuf> = None;
    while !cancel.is_cancelled() {
        let now = wanted(&grab.photos);
        if now <= last {
            std::thread::sleep(POLL);
            continue;
        }
        last = now;
        // The camera asks again: it has read the photograph before, or given up on it.
        if let Some(old) = previous.take() {
            let _ = std::fs::remove_file(old);
        }
        match shoot(rendered, &grabber, regions, &grab.photos, now) {
            Ok(path) => previous = Some(path),
            Err(e) => tracing::warn!(request = now, "grab mode: no photograph: {e:#}"),
        }
    }
    Ok(())
}

/// Grabs every region, renders the room from them and writes `photo-N.png` (16-bit linear),
/// renamed into place so that the folder camera never reads half a file.
fn shoot(
    rendered: &Rendered,
    grabber: &Grabber,
    regions: &[Option<Geometry>],
    dir: &Path,
    n: u64,
) -> Result<PathBuf> {
    let frames = regions
        .iter()
        .map(|region| match region {
            None => Ok(Frame::Black),
            Some(g) => {
                let rgb = grabber.grab(*g).with_context(|| format!("grabbing {g}"))?;
                Ok(Frame::Image(ProjectorImage {
                    width: g.width,
                    height: g.height,
                    pixels: rgb
                        .pixels()
                        .map(|p| p.0.map(|v| f32::from(v) / 255.0))
                        .collect(),
                }))
            }
        })
        .collect::<Result<Vec<_>>>()?;
    let capture = rendered.photograph(frames).context("rendering")?;
    let values: Vec<u16> = capture
        .pixels
        .iter()
        .flatten()
        .map(|v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16)
        .collect();
    let image = image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::from_raw(
        capture.width,
        capture.height,
        values,
    )
    .context("a capture of the wrong size")?;
    let path = dir.join(format!("photo-{n:06}.png"));
    let part = dir.join(format!(".photo-{n:06}.png.part"));
    // Fast and unfiltered: a noisy photograph barely compresses, and encoding it well took
    // longer than rendering it.
    let file = std::fs::File::create(&part)
        .map(std::io::BufWriter::new)
        .with_context(|| format!("creating {}", part.display()))?;
    let encoder = image::codecs::png::PngEncoder::new_with_quality(
        file,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::NoFilter,
    );
    image
        .write_with_encoder(encoder)
        .with_context(|| format!("writing {}", part.display()))?;
    std::fs::rename(&part, &path).with_context(|| format!("renaming to {}", path.display()))?;
    Ok(path)
}
