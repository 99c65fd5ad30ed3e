//! Fewer structured-light captures (hand-written): the projectors' Gray-code patterns are laid
//! into up to three *lanes*, one per colour channel of an RGB camera, so that one capture
//! carries three patterns (each drawn in its channel only, decoded from that channel), and the
//! white and black a decoder needs are the captures the procedure took before (the dark capture
//! and each projector's white) instead of two more per projector. Groups of projectors whose
//! footprints do not overlap still share a pattern slot. A pattern and its inverse always share
//! a channel, so light reflected between surfaces still cancels in their difference.
//!
//! A projector whose patterns lie in one channel decodes as before from that channel; the lab's
//! simulated projectors and camera do not mix primaries, a real projector's mixing (a channel's
//! light seen in another camera channel) shows as a small common term in a pattern and its
//! inverse and is measured by the calibration's accuracy figures, not assumed away here.

use crate::graycode::{DecodeConfig, Pattern};
use crate::image_io::LinearImage;
use std::collections::HashMap;

/// One step of a group's pattern stream: group `group` shows its members' bit pattern `step`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Item {
    pub group: usize,
    pub step: usize,
}

/// Where every step of every group's stream is shown: `lanes[c][j]`, channel `c` (or the whole
/// frame with one lane) of capture `j`.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Schedule {
    pub lanes: Vec<Vec<Item>>,
    /// Lanes are colour channels (else one lane, whole frames).
    pub colour: bool,
}

impl Schedule {
    /// Streams of `lengths` steps (even: patterns come in pairs with their inverses), in one
    /// lane, or with `colour` in three: whole streams to the shortest lane first (longest
    /// first), then pairs moved from the end of the longest lane to the shortest until they
    /// differ by at most one pair (a single projector spreads over the three channels).
    pub fn new(lengths: &[usize], colour: bool) -> Self {
        let stream = |g: usize| (0..lengths[g]).map(move |step| Item { group: g, step });
        if !colour {
            return Self {
                lanes: vec![(0..lengths.len()).flat_map(stream).collect()],
                colour,
            };
        }
        let mut order: Vec<usize> = (0..lengths.len()).collect();
        order.sort_by_key(|&g| std::cmp::Reverse(lengths[g]));
        let mut lanes: Vec<Vec<Item>> = vec![Vec::new(); 3];
        for g in order {
            let shortest = (0..3).min_by_key(|&c| lanes[c].len()).unwrap_or(0);
            lanes[shortest].extend(stream(g));
        }
        loop {
            let longest = (0..3).max_by_key(|&c| lanes[c].len()).unwrap_or(0);
            let shortest = (0..3).min_by_key(|&c| lanes[c].len()).unwrap_or(0);
            if lanes[longest].len() <= lanes[shortest].len() + 2 || lanes[longest].len() < 2 {
                break;
            }
            let at = lanes[longest].len() - 2;
            let pair: Vec<Item> = lanes[longest].drain(at..).collect();
            lanes[shortest].extend(pair);
        }
        Self { lanes, colour }
    }

    /// Captures the schedule takes.
    pub fn captures(&self) -> usize {
        self.lanes.iter().map(Vec::len).max().unwrap_or(0)
    }

    /// Where each `(group, step)` is shown: capture and channel (`None`: the whole frame).
    pub fn places(&self) -> HashMap<(usize, usize), (usize, Option<usize>)> {
        let mut out = HashMap::new();
        for (c, lane) in self.lanes.iter().enumerate() {
            for (j, item) in lane.iter().enumerate() {
                out.insert((item.group, item.step), (j, self.colour.then_some(c)));
            }
        }
        out
    }

    /// What capture `j` shows in each lane.
    pub fn at(&self, j: usize) -> Vec<Option<Item>> {
        self.lanes.iter().map(|lane| lane.get(j).copied()).collect()
    }
}

/// The bit patterns of a manifest in display order (white and black left out: the procedure's
/// dark and white captures stand for them).
pub(super) fn bit_patterns(manifest: &crate::graycode::Manifest) -> Vec<Pattern> {
    manifest
        .patterns
        .iter()
        .map(|f| f.pattern)
        .filter(|p| matches!(p, Pattern::Bit { .. }))
        .collect()
}

/// Channel `c` of `capture` in the units of the whole image (the sum of the channels, what
/// the decoder reads): each pixel's rise above `dark` in that channel scaled by how much more
/// the projector's `white` raises the whole pixel than that channel, spread over the three
/// channels. A pixel the channel barely sees (under 2% of the pixel's rise) shows its dark
/// level: no pattern there, so the decoder leaves it unknown. A clipped channel stays clipped
/// (`saturation` in every channel). (Scaling each pair by its own sum instead, which makes
/// pattern + inverse − white − black vanish, blinds the decoder's per-pixel noise estimate:
/// the small room's left projector fell from 99.86% to 97.06% within ±1.)
pub(super) fn channel_image(
    capture: &LinearImage,
    c: usize,
    white: &LinearImage,
    dark: &LinearImage,
    saturation: f32,
) -> LinearImage {
    let pixels = capture
        .pixels
        .iter()
        .zip(&white.pixels)
        .zip(&dark.pixels)
        .map(|((v, w), d)| {
            if v[c] >= saturation {
                return [saturation; 3];
            }
            let dark_sum = d[0] + d[1] + d[2];
            let rise_sum = (w[0] + w[1] + w[2]) - dark_sum;
            let rise = w[c] - d[c];
            let value = if rise > 0.02 * rise_sum && rise > 0.0 {
                dark_sum + (v[c] - d[c]) * rise_sum / rise
            } else {
                dark_sum
            };
            [value / 3.0; 3]
        })
        .collect();
    LinearImage {
        width: capture.width,
        height: capture.height,
        pixels,
    }
}

/// The decoder for patterns read from one channel: about a third of the signal, with the
/// channel's noise spread over the three as one (√3 times the whole pixel's).
pub(super) fn channel_decoder(config: DecodeConfig) -> DecodeConfig {
    DecodeConfig {
        noise_floor: config.noise_floor * 3f32.sqrt(),
        shot_noise: config.shot_noise * 3f32.sqrt(),
        ..config
    }
}

/// The white of a group coded together: `dark` plus every member's rise over it.
pub(super) fn group_white(dark: &LinearImage, whites: &[&LinearImage]) -> LinearImage {
    if let [one] = whites {
        return (*one).clone();
    }
    let mut out = dark.clone();
    for w in whites {
        for ((o, wp), d) in out.pixels.iter_mut().zip(&w.pixels).zip(&dark.pixels) {
            for c in 0..3 {
                o[c] += wp[c] - d[c];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn three_lanes_take_a_third_and_keep_pairs_in_one_channel() {
        let s = Schedule::new(&[40, 40, 40, 40, 40, 38], true);
        assert_eq!(s.captures(), 80);
        let one = Schedule::new(&[40], true);
        assert_eq!(one.captures(), 14);
        let places = one.places();
        for step in (0..40).step_by(2) {
            assert_eq!(places[&(0, step)].1, places[&(0, step + 1)].1);
        }
        assert_eq!(places.len(), 40);
        let flat = Schedule::new(&[40, 38], false);
        assert_eq!(flat.captures(), 78);
        assert_eq!(flat.places()[&(1, 0)], (40, None));
    }

    #[test]
    fn a_channel_reads_in_the_units_of_the_whole_pixel() {
        let img = |p: [f32; 3]| LinearImage {
            width: 1,
            height: 1,
            pixels: vec![p],
        };
        let (dark, white) = (img([0.01; 3]), img([0.31, 0.21, 0.11]));
        // Half of the red rise: half of the whole rise.
        let half = channel_image(&img([0.16, 0.5, 0.5]), 0, &white, &dark, 1.0);
        let sum: f32 = half.pixels[0].iter().sum();
        assert!((sum - (0.03 + 0.3)).abs() < 1e-5, "{sum}");
        let clipped = channel_image(&img([1.0, 0.0, 0.0]), 0, &white, &dark, 1.0);
        assert!(clipped.pixels[0].iter().all(|v| (v - 1.0).abs() < 1e-6));
    }
}
