//! The report's PNG files, with chunks that say what their numbers mean: linear 16-bit images
//! scaled so that nothing clips (the largest value at code 65535), the scale in a tEXt chunk,
//! gAMA 1.0 and cHRM with the sRGB primaries and D65; sRGB-encoded 8-bit images with an sRGB
//! chunk (and its gAMA/cHRM fallbacks).

use anyhow::{Context, Result, bail, ensure};
use roomlight_sim::Capture;
use std::io::BufWriter;
use std::path::Path;

/// tEXt keyword of a linear PNG's scale: linear camera value = code × this number.
pub const SCALE_KEYWORD: &str = "roomlight linear value per code";

/// The sRGB (Rec. 709) primaries and D65 white, the camera RGB the metrics assume.
fn srgb_chromaticities() -> png::SourceChromaticities {
    png::SourceChromaticities::new((0.3127, 0.3290), (0.64, 0.33), (0.30, 0.60), (0.15, 0.06))
}

fn encoder<'a>(
    path: &Path,
    width: u32,
    height: u32,
) -> Result<png::Encoder<'a, BufWriter<std::fs::File>>> {
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut e = png::Encoder::new(BufWriter::new(file), width, height);
    e.set_color(png::ColorType::Rgb);
    // fdeflate's fast mode: the demo writes about a hundred images, and the default (balanced,
    // miniz) took about 6 s of the full demo's CPU (perf, 2026-11-28).
    e.set_compression(png::Compression::Fast);
    Ok(e)
}

/// Writes `capture` as linear 16-bit RGB with its largest value at 65535 (negative values, which
/// a noiseless render does not have, at 0). Returns the scale (linear value per code), also in
/// the file's tEXt chunk [`SCALE_KEYWORD`]. An all-black capture gets scale 1/65535.
pub fn write_linear16(path: &Path, capture: &Capture) -> Result<f64> {
    ensure!(
        capture.pixels.len() == (capture.width * capture.height) as usize,
        "{}: {} pixels for {}×{}",
        path.display(),
        capture.pixels.len(),
        capture.width,
        capture.height
    );
    let mut top = 0.0f64;
    for (i, p) in capture.pixels.iter().enumerate() {
        if p.iter().any(|v| !v.is_finite()) {
            bail!("{}: pixel {i} is not finite: {p:?}", path.display());
        }
        top = p.iter().fold(top, |m, v| m.max(f64::from(*v)));
    }
    // All black: any positive scale keeps the codes at 0.
    let scale = if top > 0.0 {
        top / 65535.0
    } else {
        1.0 / 65535.0
    };
    let mut e = encoder(path, capture.width, capture.height)?;
    e.set_depth(png::BitDepth::Sixteen);
    e.set_source_gamma(png::ScaledFloat::new(1.0));
    e.set_source_chromaticities(srgb_chromaticities());
    e.add_text_chunk(SCALE_KEYWORD.into(), format!("{scale:e}"))?;
    e.add_text_chunk(
        "Description".into(),
        format!(
            "linear camera RGB (sRGB primaries, D65): value = code x {scale:e}; code 65535 = {top:e}, nothing clipped"
        ),
    )?;
    let data: Vec<u8> = capture
        .pixels
        .iter()
        .flatten()
        .flat_map(|v| {
            let code = (f64::from(*v).max(0.0) / scale).round().min(65535.0) as u16;
            code.to_be_bytes()
        })
        .collect();
    e.write_header()?
        .write_image_data(&data)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(scale)
}

/// What a linear PNG says about itself.
#[derive(Debug, Clone)]
pub struct LinearPng {
    /// The values, code × scale.
    pub capture: Capture,
    pub scale: f64,
    /// The gAMA chunk's value, and whether the cHRM chunk holds the sRGB primaries and D65.
    pub gamma: Option<f32>,
    pub chromaticities: bool,
}

/// Reads a file [`write_linear16`] wrote back into linear values.
pub fn read_linear16(path: &Path) -> Result<LinearPng> {
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .with_context(|| format!("reading {}", path.display()))?;
    let info = reader.info();
    ensure!(
        info.color_type == png::ColorType::Rgb && info.bit_depth == png::BitDepth::Sixteen,
        "{}: {:?} {:?}, expected 16-bit RGB",
        path.display(),
        info.color_type,
        info.bit_depth
    );
    let scale: f64 = info
        .uncompressed_latin1_text
        .iter()
        .find(|t| t.keyword == SCALE_KEYWORD)
        .with_context(|| format!("{}: no {SCALE_KEYWORD:?} text chunk", path.display()))?
        .text
        .parse()
        .with_context(|| format!("{}: the scale is not a number", path.display()))?;
    ensure!(
        scale.is_finite() && scale > 0.0,
        "{}: scale {scale}, expected > 0",
        path.display()
    );
    let (width, height) = (info.width, info.height);
    let gamma = info.gama_chunk.map(|g| g.into_value());
    let chromaticities = info.chrm_chunk == Some(srgb_chromaticities());
    let mut buf = vec![0; reader.output_buffer_size().context("image too large")?];
    reader
        .next_frame(&mut buf)
        .with_context(|| format!("decoding {}", path.display()))?;
    let pixels = buf
        .chunks_exact(6)
        .map(|c| {
            std::array::from_fn(|k| {
                (f64::from(u16::from_be_bytes([c[2 * k], c[2 * k + 1]])) * scale) as f32
            })
        })
        .collect();
    Ok(LinearPng {
        capture: Capture {
            width,
            height,
            pixels,
        },
        scale,
        gamma,
        chromaticities,
    })
}

fn srgb_encode(v: f64) -> f64 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Writes an 8-bit sRGB-encoded image (already encoded: pictures, maps) with an sRGB chunk.
pub fn write_srgb8_image(path: &Path, image: &image::RgbImage) -> Result<()> {
    let mut e = encoder(path, image.width(), image.height())?;
    e.set_depth(png::BitDepth::Eight);
    e.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    e.write_header()?
        .write_image_data(image.as_raw())
        .with_context(|| format!("writing {}", path.display()))
}

/// `capture` for viewing: values divided by `white` (white and above at full scale, clipped),
/// sRGB-encoded to 8 bits. A `white` ≤ 0 counts as 1.
pub fn srgb8(capture: &Capture, white: f32) -> Result<image::RgbImage> {
    let scale = if white > 0.0 {
        1.0 / f64::from(white)
    } else {
        1.0
    };
    let data: Vec<u8> = capture
        .pixels
        .iter()
        .flatten()
        .map(|v| (srgb_encode((f64::from(*v) * scale).clamp(0.0, 1.0)) * 255.0).round() as u8)
        .collect();
    image::RgbImage::from_raw(capture.width, capture.height, data).with_context(|| {
        format!(
            "a {}×{} capture with {} pixels",
            capture.width,
            capture.height,
            capture.pixels.len()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_png_round_trips_without_clipping_and_says_what_it_holds() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("a.linear16.png");
        // Values well above 1 (an LED highlight), a dark one and zero.
        let pixels = vec![
            [3.5, 1.0, 0.25],
            [0.001, 0.0, 2.0],
            [0.0; 3],
            [1.75, 3.5, 0.5],
        ];
        let capture = Capture {
            width: 2,
            height: 2,
            pixels,
        };
        let scale = write_linear16(&path, &capture).expect("write");
        assert!((scale - 3.5 / 65535.0).abs() < 1e-15);
        let back = read_linear16(&path).expect("read");
        assert!((back.scale - scale).abs() <= 1e-6 * scale);
        assert_eq!(back.gamma, Some(1.0));
        assert!(back.chromaticities);
        for (a, b) in capture
            .pixels
            .iter()
            .flatten()
            .zip(back.capture.pixels.iter().flatten())
        {
            // Within half a code step: no value clipped.
            assert!(
                (a - b).abs() <= (0.5 * scale) as f32 + 1e-7,
                "{a} against {b}"
            );
        }
        assert!(
            (back.capture.pixels[0][0] - 3.5).abs() < 1e-6,
            "the largest value at code 65535"
        );
    }

    #[test]
    fn srgb_png_carries_the_srgb_chunk_and_bad_input_is_an_error() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("a.png");
        let capture = Capture {
            width: 2,
            height: 1,
            pixels: vec![[0.5, 1.0, 2.0], [0.0, 0.0, 0.0]],
        };
        let img = srgb8(&capture, 1.0).expect("encode");
        assert_eq!(img.get_pixel(0, 0).0, [188, 255, 255]);
        write_srgb8_image(&path, &img).expect("write");
        let file = std::fs::File::open(&path).expect("open");
        let reader = png::Decoder::new(std::io::BufReader::new(file))
            .read_info()
            .expect("read");
        assert_eq!(
            reader.info().srgb,
            Some(png::SrgbRenderingIntent::Perceptual)
        );
        let bad = Capture {
            width: 2,
            height: 1,
            pixels: vec![[f32::NAN, 0.0, 0.0], [0.0; 3]],
        };
        assert!(write_linear16(&dir.path().join("b.png"), &bad).is_err());
        let short = Capture {
            width: 3,
            height: 1,
            pixels: vec![[0.0; 3]],
        };
        assert!(srgb8(&short, 1.0).is_err());
        assert!(write_linear16(&dir.path().join("c.png"), &short).is_err());
    }
}
