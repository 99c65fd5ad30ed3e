//! Linear RGB images and PNG input/output with the encodings real cameras deliver; files too
//! large to decode are refused from their header.

use crate::CalibError;
use std::path::Path;

/// A linear RGB image (f32), row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width · height` linear RGB values.
    pub pixels: Vec<[f32; 3]>,
}

/// How the values in a PNG file are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// sRGB transfer curve (ordinary photographs).
    Srgb,
    /// Linear values (RAW-derived or linear sensor output).
    Linear,
}

/// Bit depth a set of captures is promised to have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Depth {
    /// 8 bits per channel.
    Eight,
    /// 16 bits per channel.
    Sixteen,
    /// Either.
    Any,
}

/// The largest side of a capture or pattern file read (a 100-megapixel camera's is 11 648).
pub const MAX_LOAD_SIDE: u32 = 12_000;
/// The most a read file may take decoded: its linear copy at 12 bytes per pixel (1.5 GiB, a
/// 100-megapixel photograph); a 20 000² file would take 4.8 GB.
pub const MAX_LOAD_BYTES: u64 = 3 << 29;

fn srgb_decode(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

fn srgb_encode(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

impl LinearImage {
    /// A black image.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            pixels: vec![[0.0; 3]; (width * height) as usize],
        }
    }

    /// Reads a PNG, decoding its transfer curve; refuses a depth other than the promised one,
    /// and an image beyond [`MAX_LOAD_SIDE`] per side or [`MAX_LOAD_BYTES`] to decode, from its
    /// header, before anything is allocated.
    pub fn load_png(path: &Path, encoding: Encoding, depth: Depth) -> Result<Self, CalibError> {
        let file = path.display().to_string();
        let failed = |e: &dyn std::fmt::Display| CalibError::File {
            file: file.clone(),
            problem: e.to_string(),
        };
        let open = || {
            image::ImageReader::open(path)
                .and_then(image::ImageReader::with_guessed_format)
                .map_err(|e| failed(&e))
        };
        let (w, h) = open()?.into_dimensions().map_err(|e| failed(&e))?;
        // The decoded image is 4 bytes per channel and a linear copy 12 bytes per pixel.
        if w > MAX_LOAD_SIDE
            || h > MAX_LOAD_SIDE
            || 12 * u64::from(w) * u64::from(h) > MAX_LOAD_BYTES
        {
            return Err(CalibError::File {
                file,
                problem: format!(
                    "is {w}x{h}, larger than the cap of {MAX_LOAD_SIDE} per side and {} MB \
                     decoded",
                    MAX_LOAD_BYTES >> 20
                ),
            });
        }
        let mut reader = open()?;
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MAX_LOAD_SIDE);
        limits.max_image_height = Some(MAX_LOAD_SIDE);
        limits.max_alloc = Some(MAX_LOAD_BYTES);
        reader.limits(limits);
        let img = reader.decode().map_err(|e| failed(&e))?;
        let sixteen = matches!(
            img.color(),
            image::ColorType::Rgb16
                | image::ColorType::Rgba16
                | image::ColorType::L16
                | image::ColorType::La16
        );
        match (depth, sixteen) {
            (Depth::Sixteen, false) => {
                return Err(CalibError::File {
                    file,
                    problem: format!("is {:?}, expected 16 bits per channel", img.color()),
                });
            }
            (Depth::Eight, true) => {
                return Err(CalibError::File {
                    file,
                    problem: format!("is {:?}, expected 8 bits per channel", img.color()),
                });
            }
            _ => {}
        }
        let rgb = img.to_rgb32f();
        let decode = |v: f32| match encoding {
            Encoding::Srgb => srgb_decode(v),
            Encoding::Linear => v,
        };
        Ok(Self {
            width: rgb.width(),
            height: rgb.height(),
            pixels: rgb
                .pixels()
                .map(|p| [decode(p[0]), decode(p[1]), decode(p[2])])
                .collect(),
        })
    }

    /// Writes a PNG: 8-bit sRGB-encoded (for patterns and viewing) with values clipped to [0, 1].
    pub fn save_png_srgb8(&self, path: &Path) -> Result<(), CalibError> {
        let data: Vec<u8> = self
            .pixels
            .iter()
            .flat_map(|p| p.map(|v| (srgb_encode(v.clamp(0.0, 1.0)) * 255.0).round() as u8))
            .collect();
        let file = path.display().to_string();
        image::RgbImage::from_raw(self.width, self.height, data)
            .ok_or_else(|| CalibError::File {
                file: file.clone(),
                problem: "buffer size does not match".into(),
            })?
            .save(path)
            .map_err(|e| CalibError::File {
                file,
                problem: e.to_string(),
            })
    }

    /// Sum of the three channels of every pixel (the signal used for decoding).
    pub fn intensity(&self) -> Vec<f32> {
        self.pixels.iter().map(|p| p[0] + p[1] + p[2]).collect()
    }

    /// Checks that the image is `width × height`; `what` names it in the error.
    pub fn expect_size(&self, width: u32, height: u32, what: &str) -> Result<(), CalibError> {
        if self.width == width
            && self.height == height
            && self.pixels.len() == (width * height) as usize
        {
            Ok(())
        } else {
            Err(CalibError::File {
                file: what.to_string(),
                problem: format!(
                    "is {}x{}, expected {width}x{height}",
                    self.width, self.height
                ),
            })
        }
    }
}
