//! What a decode refuses to turn into a map: captures whose white frame is clipped over a large
//! share of the lit pixels (the differences there are the camera's ceiling, not the light),
//! and a projector the camera did not see (cable out, wrong output, patterns below the noise),
//! which would otherwise decode noise into a wrong map. It owns those two decisions and their
//! messages; it must not know how frames are shown or captured.

use super::Correspondence;
use crate::CalibError;

/// Refused as saturated when more than this share of the lit pixels is clipped in the white
/// capture *and* left undecoded. Binary patterns still decode where white clips (pattern and
/// inverse differ all the same: the simulator's calibration clips up to 76% of a texture
/// projector's lit pixels and decodes them all), so clipping alone is no reason to refuse;
/// clipping that cost the code (pattern and inverse both at the ceiling) is.
pub const SATURATED_SHARE: f64 = 0.25;
/// A projector is not seen when fewer camera pixels than this decode…
pub const MIN_SEEN_PIXELS: usize = 16;
/// …or they land on fewer than this share of its pixels (a footprint of a few hundred
/// pixels of a 1024×768 projector is not one to calibrate from).
pub const MIN_SEEN_SHARE: f64 = 0.002;

/// The pixels of white at the camera's ceiling `saturation` in some channel (within one part
/// in a thousand: an 8-bit file's top code is 1 and the next 0.991), from white's brightest
/// channel per pixel (`white_top`, [`super::brightest`]). A ceiling that is not a positive
/// number clips nothing.
pub(super) fn clipped(white_top: &[f32], saturation: f32) -> Vec<bool> {
    let ceiling = saturation * (1.0 - 1e-3);
    white_top
        .iter()
        .map(|&top| saturation > 0.0 && top >= ceiling)
        .collect()
}

/// The pixels (among `ours`, all when `None`) white raises by at least a quarter of what it
/// raises the brightest (the 99th percentile) and at least `reach`: the saturation check's
/// lit pixels. Not the decoder's reached pixels, whose noise test clipping upsets, nor the
/// rest of the room, which reflected light raises a little.
pub(super) fn lit(white: &[f32], black: &[f32], reach: f32, ours: Option<&[bool]>) -> Vec<bool> {
    let raised: Vec<f32> = white.iter().zip(black).map(|(w, b)| w - b).collect();
    let mut sorted: Vec<f32> = raised.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(f32::total_cmp);
    let top = sorted.get(sorted.len() * 99 / 100).copied().unwrap_or(0.0);
    let threshold = (0.25 * top).max(reach);
    raised
        .iter()
        .enumerate()
        // NaN is not lit.
        .map(|(i, &r)| ours.is_none_or(|m| m[i]) && r >= threshold)
        .collect()
}

/// Refuses captures whose white frame is clipped, and the code lost, on more than
/// [`SATURATED_SHARE`] of the pixels `is_lit` marks.
pub(super) fn refuse_saturated<T>(
    clipped: &[bool],
    is_lit: &[bool],
    map: &[Option<T>],
) -> Result<(), CalibError> {
    let (mut lit, mut at_top) = (0usize, 0usize);
    for ((&c, &l), decoded) in clipped.iter().zip(is_lit).zip(map) {
        if l {
            lit += 1;
            at_top += usize::from(c && decoded.is_none());
        }
    }
    // No lit pixel: nothing is saturated (the unseen check speaks for that case).
    let share = at_top as f64 / lit.max(1) as f64;
    if at_top >= MIN_SEEN_PIXELS && share > SATURATED_SHARE {
        return Err(CalibError::Invalid {
            field: "structured-light captures",
            problem: format!(
                "saturated: {:.1}% of the {lit} lit camera pixels are at the camera's largest \
                 value in the white capture and lost their code (at most {:.0}% may); lower the \
                 camera's exposure or the projector's brightness and capture again",
                100.0 * share,
                100.0 * SATURATED_SHARE
            ),
        });
    }
    Ok(())
}

/// Refuses a decode in which the projector was not seen: fewer than [`MIN_SEEN_PIXELS`]
/// camera pixels decoded (among those `ours` marks), or fewer than [`MIN_SEEN_SHARE`] of its
/// pixels among them.
pub(super) fn refuse_unseen(
    corr: &Correspondence,
    ours: Option<&[bool]>,
) -> Result<(), CalibError> {
    let decoded = corr.map.iter().filter(|m| m.is_some()).count();
    let share = corr.seen_share();
    if decoded >= MIN_SEEN_PIXELS && share >= MIN_SEEN_SHARE {
        return Ok(());
    }
    let considered = ours.map_or(corr.map.len(), |m| m.iter().filter(|o| **o).count());
    Err(CalibError::Invalid {
        field: "projector",
        problem: format!(
            "not seen: {decoded} of {considered} camera pixels decoded onto it, {:.2}% of its \
             {}x{} pixels (at least {MIN_SEEN_PIXELS} camera pixels and {:.1}% of its pixels \
             are needed: its patterns did not change the captures beyond their noise); check \
             that it is on, shows the patterns and lights what the camera sees",
            100.0 * share,
            corr.projector_width,
            corr.projector_height,
            100.0 * MIN_SEEN_SHARE
        ),
    })
}

impl Correspondence {
    /// Share of the projector's pixels some camera pixel decoded onto (0 for a projector of
    /// no pixels).
    pub fn seen_share(&self) -> f64 {
        let (pw, ph) = (
            self.projector_width as usize,
            self.projector_height as usize,
        );
        let mut seen = vec![false; pw * ph];
        for &(x, y) in self.map.iter().flatten() {
            if let Some(s) = seen.get_mut(y as usize * pw + x as usize) {
                *s = true;
            }
        }
        seen.iter().filter(|s| **s).count() as f64 / (pw * ph).max(1) as f64
    }
}
