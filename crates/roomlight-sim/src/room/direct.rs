//! Direct light on the probes for a set of frames: each projector's light per pixel computed once
//! per render and shared by every probe set (camera pixels, elements, chart patches), the probes
//! split over the cores. Every probe sums its terms in the same order as one loop over the
//! projectors, their entries and their boxes, then the LED panels, would: the result is the
//! same to the bit on any number of threads.

use super::{Frame, Probes, ProjectorMap, Room, SummedArea};
use crate::optics::Projector;
use rayon::prelude::*;
use roomlight_core::LinearRgb;

/// Probes a task of the parallel loops handles at least.
const CHUNK: usize = 4096;

impl Room {
    /// Direct irradiance on every probe of each set, for these frames and LED preset.
    pub(super) fn direct_sets(
        &self,
        sets: &[&Probes],
        frames: &[Frame],
        preset: Option<usize>,
    ) -> Vec<Vec<LinearRgb>> {
        let mut out: Vec<Vec<LinearRgb>> = sets
            .iter()
            .map(|p| vec![LinearRgb::ZERO; p.albedo.len()])
            .collect();
        for (k, (frame, projector)) in frames.iter().zip(&self.projectors).enumerate() {
            match frame {
                Frame::Black | Frame::Uniform(_) => {
                    let code = match frame {
                        Frame::Uniform(c) => *c,
                        _ => [0.0; 3],
                    };
                    let light = projector.light(code);
                    for (e, set) in out.iter_mut().zip(sets) {
                        add_weighted(e, &set.projectors[k].white, light);
                    }
                }
                Frame::Image(img) | Frame::Linear(img) => {
                    let linear = matches!(frame, Frame::Linear(_));
                    let mut light = self.buffers.take(img.pixels.len());
                    pixel_light(projector, &img.pixels, linear, &mut light);
                    let maps: Vec<&ProjectorMap> = sets.iter().map(|s| &s.projectors[k]).collect();
                    for (e, map) in out.iter_mut().zip(&maps) {
                        add_entries(e, &map.entries, |&px| light[px as usize]);
                    }
                    // Then the boxes, over the light summed in place: each set still takes its
                    // entries before its boxes, as one loop over the sets would.
                    if maps.iter().any(|m| !m.boxes.is_empty()) {
                        let table = SummedArea::in_place(img.width, light);
                        for (e, map) in out.iter_mut().zip(&maps) {
                            add_entries(e, &map.boxes, |b| table.mean(*b));
                        }
                        light = table.into_buffer();
                    }
                    self.buffers.give(light);
                }
            }
        }
        if let Some(p) = preset {
            let spec = &self.scene.presets[p];
            for name in &spec.lights {
                let Some(l) = self.lights.iter().position(|l| &l.name == name) else {
                    continue;
                };
                let light = &self.lights[l];
                let rgb = spec
                    .cct_k
                    .map_or(light.rgb, crate::optics::cct_to_linear_rgb)
                    * (light.intensity * spec.intensity);
                for (e, set) in out.iter_mut().zip(sets) {
                    add_weighted(e, &set.lights[l], rgb);
                }
            }
        }
        out
    }
}

/// `e_i += light · w_i` where `w_i > 0`.
fn add_weighted(e: &mut [LinearRgb], weights: &[f32], light: LinearRgb) {
    e.par_iter_mut()
        .with_min_len(CHUNK)
        .zip(weights.par_iter())
        .for_each(|(ei, &w)| {
            if w > 0.0 {
                *ei += light * f64::from(w);
            }
        });
}

/// The light of every pixel of a frame (codes, or linear shares) into `out` (as long as the
/// frame). Neighbouring pixels often share a code (a pattern's stripes, a node's flat inside),
/// so each task keeps its last one.
fn pixel_light(projector: &Projector, pixels: &[[f32; 3]], linear: bool, out: &mut [LinearRgb]) {
    let light = |c: [f32; 3]| {
        if linear {
            projector.light_linear(c)
        } else {
            projector.light(c)
        }
    };
    out.par_chunks_mut(CHUNK)
        .zip(pixels.par_chunks(CHUNK))
        .for_each(|(out, chunk)| {
            // Equal bits, equal light (a NaN code never reaches here: frames are checked). The
            // last code's bits and light are kept apart, not as an `Option` of both, which was
            // compared through memory right after being stored.
            let (mut seen, mut last_bits, mut last_light) = (false, [0u32; 3], LinearRgb::ZERO);
            for (o, &c) in out.iter_mut().zip(chunk) {
                let bits = c.map(f32::to_bits);
                if !seen || bits != last_bits {
                    (seen, last_bits, last_light) = (true, bits, light(c));
                }
                *o = last_light;
            }
        });
}

/// `e[probe] += value(item) · factor` for every `(probe, item, factor)`, in the order given for
/// each probe. The transport lists its entries by probe, so the probes are split into ranges
/// over the cores; a list out of that order is summed in one loop.
fn add_entries<T: Sync>(
    e: &mut [LinearRgb],
    items: &[(u32, T, f32)],
    value: impl Fn(&T) -> LinearRgb + Sync,
) {
    if !items.is_sorted_by_key(|i| i.0) {
        for (probe, item, f) in items {
            e[*probe as usize] += value(item) * f64::from(*f);
        }
        return;
    }
    e.par_chunks_mut(CHUNK).enumerate().for_each(|(c, chunk)| {
        let lo = (c * CHUNK) as u32;
        let hi = lo + chunk.len() as u32;
        let a = items.partition_point(|i| i.0 < lo);
        let b = items.partition_point(|i| i.0 < hi);
        for (probe, item, f) in &items[a..b] {
            chunk[(probe - lo) as usize] += value(item) * f64::from(*f);
        }
    });
}
