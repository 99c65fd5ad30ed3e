//! What the camera delivers: a linear capture, and writing it as PNG for people to look at.

use super::SimError;
use std::path::Path;

/// A camera capture: linear RGB values (f32), row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Capture {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear camera values.
    pub pixels: Vec<[f32; 3]>,
}

/// How to write a capture as PNG.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PngEncoding {
    /// 8-bit sRGB-encoded (for viewing).
    Srgb8,
    /// 16-bit sRGB-encoded.
    Srgb16,
    /// 16-bit linear (values as measured).
    Linear16,
}

impl PngEncoding {
    /// A file-name suffix that says the encoding.
    pub fn suffix(self) -> &'static str {
        match self {
            Self::Srgb8 => "srgb8",
            Self::Srgb16 => "srgb16",
            Self::Linear16 => "linear16",
        }
    }
}

fn srgb_encode(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

impl Capture {
    /// Writes the capture, values divided by `white` (so `white` maps to full scale), clipped.
    pub fn save_png(&self, path: &Path, encoding: PngEncoding, white: f32) -> Result<(), SimError> {
        let scale = if white > 0.0 { 1.0 / white } else { 1.0 };
        let io = |e: image::ImageError| SimError::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        };
        let encode = |v: f32| {
            let v = (v * scale).clamp(0.0, 1.0);
            match encoding {
                PngEncoding::Linear16 => v,
                _ => srgb_encode(v),
            }
        };
        match encoding {
            PngEncoding::Srgb8 => {
                let data: Vec<u8> = self
                    .pixels
                    .iter()
                    .flat_map(|p| p.map(|v| (encode(v) * 255.0).round() as u8))
                    .collect();
                image::RgbImage::from_raw(self.width, self.height, data)
                    .ok_or_else(|| SimError::Io {
                        path: path.display().to_string(),
                        message: "buffer size".into(),
                    })?
                    .save(path)
                    .map_err(io)
            }
            PngEncoding::Srgb16 | PngEncoding::Linear16 => {
                let data: Vec<u16> = self
                    .pixels
                    .iter()
                    .flat_map(|p| p.map(|v| (encode(v) * 65535.0).round() as u16))
                    .collect();
                image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::from_raw(
                    self.width,
                    self.height,
                    data,
                )
                .ok_or_else(|| SimError::Io {
                    path: path.display().to_string(),
                    message: "buffer size".into(),
                })?
                .save(path)
                .map_err(io)
            }
        }
    }

    /// Luminance of every pixel.
    pub fn luminance(&self) -> Vec<f32> {
        self.pixels
            .iter()
            .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
            .collect()
    }
}
