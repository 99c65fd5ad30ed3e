//! A frame as a display shows it: 8-bit RGB, row-major, of the output's size. Projector codes
//! (linear values in [0, 1] that already include the projector's response, as
//! `Pattern::codes` and `Assignment::draw` give them) become 8 bits by rounding, with no
//! further curve: the code is what drives the projector. It must not know windows.

use crate::HwError;
use std::sync::Arc;

/// One frame of `width`×`height` 8-bit RGB pixels.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub rgb: Arc<[[u8; 3]]>,
}

impl Frame {
    /// `rgb` as a frame; refused when it is not `width`×`height` pixels.
    pub fn new(width: u32, height: u32, rgb: Vec<[u8; 3]>) -> Result<Self, HwError> {
        if rgb.len() != width as usize * height as usize {
            return Err(HwError::Size {
                what: format!("{} pixels", rgb.len()),
                expected: (width, height),
            });
        }
        Ok(Self {
            width,
            height,
            rgb: rgb.into(),
        })
    }

    /// Every pixel black.
    pub fn black(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            rgb: vec![[0; 3]; width as usize * height as usize].into(),
        }
    }

    /// Projector codes in [0, 1] as a frame (see the module doc).
    pub fn from_codes(width: u32, height: u32, codes: &[[f32; 3]]) -> Result<Self, HwError> {
        Self::new(
            width,
            height,
            codes.iter().map(|c| c.map(to_8bit)).collect(),
        )
    }

    /// An image file's pixels as a frame of its own size.
    pub fn from_image(image: &image::RgbImage) -> Self {
        Self {
            width: image.width(),
            height: image.height(),
            rgb: image.pixels().map(|p| p.0).collect::<Vec<_>>().into(),
        }
    }
}

/// A projector code in [0, 1] as 8 bits: rounded to the nearest of 256 levels; out of range
/// clamped, NaN black.
pub fn to_8bit(code: f32) -> u8 {
    if code.is_nan() {
        return 0;
    }
    (code.clamp(0.0, 1.0) * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_to_the_nearest_level() {
        assert_eq!(to_8bit(0.0), 0);
        assert_eq!(to_8bit(1.0), 255);
        assert_eq!(to_8bit(0.5), 128);
        assert_eq!(to_8bit(127.4 / 255.0), 127);
        assert_eq!(to_8bit(-0.2), 0);
        assert_eq!(to_8bit(3.0), 255);
        assert_eq!(to_8bit(f32::NAN), 0);
    }

    #[test]
    fn a_frame_of_the_wrong_size_is_refused() {
        assert!(Frame::new(2, 2, vec![[0; 3]; 3]).is_err());
        assert!(Frame::from_codes(2, 1, &[[0.0; 3]; 2]).is_ok());
    }
}
