//! What a backend delivers (`Frame`: the camera's own codes, 8- or 16-bit RGB, with the
//! exposure actually used) and the one bounded decoder every image from outside goes through:
//! its size is checked from the header, before any pixel is decoded. It must not know response
//! curves (radiometry.rs turns frames into linear light).

use crate::error::CameraError;
use crate::exif::Shot;
use image::ImageDecoder as _;
use std::path::Path;

/// A frame's samples, row-major RGB.
#[derive(Debug, Clone, PartialEq)]
pub enum Samples {
    /// 8-bit codes through the camera's response (sRGB/JPEG/video).
    Rgb8(Vec<[u8; 3]>),
    /// 16-bit values, linear as they are (16-bit PNG, RAW developed linear).
    Rgb16(Vec<[u16; 3]>),
}

/// One capture as the camera delivered it.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub samples: Samples,
    /// The exposure actually used in seconds, when the camera reports it.
    pub exposure_s: Option<f64>,
    /// What the image file's EXIF says it was taken with (files only).
    pub shot: Option<Shot>,
}

impl Frame {
    /// An 8-bit frame, checked to be `width · height` pixels.
    pub fn rgb8(width: u32, height: u32, pixels: Vec<[u8; 3]>) -> Option<Self> {
        (pixels.len() == width as usize * height as usize).then_some(Self {
            width,
            height,
            samples: Samples::Rgb8(pixels),
            exposure_s: None,
            shot: None,
        })
    }
}

/// Decodes an image file (PNG, JPEG, TIFF, or a RAW shot as DNG) into a frame, refusing it
/// before decoding when it has more than `max_pixels` pixels; every error names the file. The
/// EXIF, when the file has some, gives the shot's settings and the exposure used; EXIF that
/// does not parse is an error.
pub fn decode_file(path: &Path, max_pixels: u64) -> Result<Frame, CameraError> {
    let data = read_bounded(path, max_pixels)?;
    decode_bytes(path, data, max_pixels)
}

/// Decodes an image file's bytes as [`decode_file`] does (`path` only names it in errors): the
/// one entry for whatever a camera delivered, fuzzed in tests/integration/raw/fuzz.rs.
pub fn decode_bytes(path: &Path, data: Vec<u8>, max_pixels: u64) -> Result<Frame, CameraError> {
    let bad = |reason: String| CameraError::Decode {
        path: path.to_path_buf(),
        reason,
    };
    if crate::dng::is_dng(&data) {
        let frame = crate::dng::decode(path, &data, max_pixels)?;
        // A DNG is itself the TIFF structure EXIF is read from; TIFF/EP keeps the settings in
        // its first directory instead of an EXIF one.
        let ep = crate::dng::tiff_ep_shot(&data);
        let exif = Shot::from_tiff(data).map_err(bad)?;
        let shot = Shot {
            exposure_s: exif.exposure_s.or(ep.exposure_s),
            iso: exif.iso.or(ep.iso),
            f_number: exif.f_number.or(ep.f_number),
        };
        return Ok(Frame {
            exposure_s: shot.exposure_s,
            shot: Some(shot),
            ..frame
        });
    }
    if let Some(reason) = crate::dng::foreign_raw(&data) {
        return Err(bad(reason));
    }
    let open = || {
        image::ImageReader::new(std::io::Cursor::new(&data))
            .with_guessed_format()
            .map_err(|e| bad(format!("cannot read: {e}")))
    };
    let (width, height) = open()?
        .into_dimensions()
        .map_err(|e| bad(format!("no image header: {e}")))?;
    let pixels = u64::from(width) * u64::from(height);
    if pixels > max_pixels {
        return Err(bad(format!(
            "{width}×{height} = {pixels} pixels, more than the {max_pixels} allowed; refused \
             before decoding"
        )));
    }
    let mut reader = open()?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(width);
    limits.max_image_height = Some(height);
    // RGBA16 is the widest layout a decoder allocates, plus the conversion's copy.
    limits.max_alloc = Some(pixels.saturating_mul(16).max(1 << 20));
    reader.limits(limits);
    let mut decoder = reader
        .into_decoder()
        .map_err(|e| bad(format!("cannot decode: {e}")))?;
    let shot = decoder
        .exif_metadata()
        .map_err(|e| bad(format!("cannot read its EXIF: {e}")))?
        .map(Shot::from_tiff)
        .transpose()
        .map_err(bad)?;
    let image = image::DynamicImage::from_decoder(decoder)
        .map_err(|e| bad(format!("cannot decode: {e}")))?;
    let samples = if image.color().bytes_per_pixel() / image.color().channel_count() >= 2 {
        Samples::Rgb16(image.to_rgb16().pixels().map(|p| p.0).collect())
    } else {
        Samples::Rgb8(image.to_rgb8().pixels().map(|p| p.0).collect())
    };
    Ok(Frame {
        width,
        height,
        samples,
        exposure_s: shot.and_then(|s| s.exposure_s),
        shot,
    })
}

/// Reads a whole image file, refusing one larger than an uncompressed image of `max_pixels`
/// pixels could be (16-bit RGBA, or four 16-bit sensor values a pixel, plus 16 MiB of
/// metadata and previews) before reading it.
fn read_bounded(path: &Path, max_pixels: u64) -> Result<Vec<u8>, CameraError> {
    let bad = |reason: String| CameraError::Decode {
        path: path.to_path_buf(),
        reason,
    };
    let cap = max_pixels.saturating_mul(8).saturating_add(16 << 20);
    let file = std::fs::File::open(path).map_err(|e| bad(format!("cannot open: {e}")))?;
    let len = file
        .metadata()
        .map_err(|e| bad(format!("cannot read: {e}")))?
        .len();
    if len > cap {
        return Err(bad(format!(
            "{len} bytes, more than the {cap} an image of {max_pixels} pixels may take; refused \
             before reading"
        )));
    }
    let mut data = Vec::with_capacity(len as usize);
    // Bounded again while reading: the file may grow after its size was read.
    std::io::Read::read_to_end(&mut std::io::Read::take(file, cap), &mut data)
        .map_err(|e| bad(format!("cannot read: {e}")))?;
    Ok(data)
}

/// Writes a frame as PNG (8- or 16-bit as it came), for `roomlight hw capture`.
pub fn save_png(frame: &Frame, path: &Path) -> Result<(), CameraError> {
    let bad = |e: image::ImageError| CameraError::Decode {
        path: path.to_path_buf(),
        reason: format!("cannot write: {e}"),
    };
    match &frame.samples {
        Samples::Rgb8(p) => {
            let raw = p.iter().flatten().copied().collect();
            image::RgbImage::from_raw(frame.width, frame.height, raw)
                .map(|i| i.save(path).map_err(bad))
        }
        Samples::Rgb16(p) => {
            let raw = p.iter().flatten().copied().collect();
            image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::from_raw(
                frame.width,
                frame.height,
                raw,
            )
            .map(|i| i.save(path).map_err(bad))
        }
    }
    .unwrap_or_else(|| {
        Err(CameraError::Decode {
            path: path.to_path_buf(),
            reason: "a frame whose pixels do not fill it".into(),
        })
    })
}
