//! Rendering only some of the camera's pixels: a run of the agents reads nothing of a capture
//! but its chart patches, and the camera pixels are most of a render's cost (on the lab, a full
//! render 0.72 s against 0.27 s for the elements, the inter-reflection and the patches alone;
//! release, 2026-11-27).
//!
//! A subset keeps, for each of its pixels, the camera probe's own transport entries in their
//! original order, so each of its pixels gets the same value, to the bit, as in a full render.

use super::capture::Capture;
use super::{Frame, Probes, ProjectorMap, Room, SimError, to_f32};

/// Some of the camera's pixels, with their share of the camera's light transport.
#[derive(Debug, Clone)]
pub struct PixelSubset {
    /// Row-major camera pixel indices, ascending, each once.
    pixels: Vec<u32>,
    probes: Probes,
}

impl PixelSubset {
    /// The pixels, ascending.
    pub fn pixels(&self) -> &[u32] {
        &self.pixels
    }
}

impl Room {
    /// The camera pixels `pixels` (row-major indices, in any order, repeats ignored), ready to
    /// render alone. Refused if one lies outside the camera image.
    pub fn pixel_subset(
        &self,
        pixels: impl IntoIterator<Item = u32>,
    ) -> Result<PixelSubset, SimError> {
        let count = self.pixels.len();
        let mut pixels: Vec<u32> = pixels.into_iter().collect();
        if let Some(&bad) = pixels.iter().find(|&&p| p as usize >= count) {
            return Err(SimError::PixelOutside { pixel: bad, count });
        }
        pixels.sort_unstable();
        pixels.dedup();
        // Camera probe → its index in the subset.
        let mut index = vec![u32::MAX; count];
        for (i, &p) in pixels.iter().enumerate() {
            index[p as usize] = i as u32;
        }
        let all = &self.camera_probes;
        let projectors = all
            .projectors
            .iter()
            .map(|map| ProjectorMap {
                entries: keep(&map.entries, &index),
                boxes: keep(&map.boxes, &index),
                white: pixels.iter().map(|&p| map.white[p as usize]).collect(),
            })
            .collect();
        let probes = Probes {
            albedo: pixels.iter().map(|&p| all.albedo[p as usize]).collect(),
            interp: pixels.iter().map(|&p| all.interp[p as usize]).collect(),
            projectors,
            lights: all
                .lights
                .iter()
                .map(|l| pixels.iter().map(|&p| l[p as usize]).collect())
                .collect(),
        };
        Ok(PixelSubset { pixels, probes })
    }

    /// The noiseless capture of these frames and LED preset on the subset's pixels, zero on
    /// every other pixel: on the subset, the same values as [`Room::render`] to the bit.
    pub fn render_subset(
        &self,
        subset: &PixelSubset,
        frames: &[Frame],
        preset: Option<usize>,
    ) -> Result<Capture, SimError> {
        self.check_frames(frames)?;
        let (elements, direct) = self.direct_with_elements(&[&subset.probes], frames, preset);
        let indirect = self.indirect(&elements);
        let values = to_f32(self.values(&subset.probes, &direct[0], &indirect));
        let mut pixels = vec![[0.0f32; 3]; self.pixels.len()];
        for (&p, v) in subset.pixels.iter().zip(values) {
            pixels[p as usize] = v;
        }
        Ok(Capture {
            width: self.camera.width,
            height: self.camera.height,
            pixels,
        })
    }
}

/// The entries of the subset's probes, renumbered (`index`: camera probe → subset index, or
/// `u32::MAX` when left out), in their order.
fn keep<T: Copy>(list: &[(u32, T, f32)], index: &[u32]) -> Vec<(u32, T, f32)> {
    list.iter()
        .filter_map(|&(probe, item, f)| {
            let i = *index.get(probe as usize)?;
            (i != u32::MAX).then_some((i, item, f))
        })
        .collect()
}
