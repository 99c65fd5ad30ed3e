//! The console's pictures, as PNG: the latest photograph scaled down (off the round loop, once
//! per photograph, whoever asks), coverage and attenuation maps over the camera view, and
//! projector frame thumbnails. Rendering runs on the blocking pool, at most [`AT_ONCE`] at a
//! time: a browser asking for thousands of images waits its turn and slows nothing else.

use crate::Console;
use roomlight_agent::camera::Photo;
use roomlight_calib::charts::{COLUMNS, ChartCorners, ROWS};
use roomlight_calib::image_io::LinearImage;
use std::io::Cursor;
use std::sync::{Arc, Mutex, PoisonError};
use tokio::sync::{Semaphore, watch};
use tokio_util::sync::CancellationToken;

/// Pictures are at most this wide.
pub const MAX_WIDTH: u32 = 640;
/// Renderings at once.
pub const AT_ONCE: usize = 2;

/// The latest photograph, scaled and encoded.
#[derive(Debug, Clone)]
pub struct Encoded {
    pub seq: u64,
    /// The photograph's full size.
    pub width: u32,
    pub height: u32,
    pub png: Arc<Vec<u8>>,
}

/// The latest photograph's PNG and the renderings' permits.
#[derive(Debug)]
pub struct Images {
    photos: watch::Receiver<Option<Photo>>,
    latest: Mutex<Option<Encoded>>,
    pub permits: Semaphore,
}

impl Images {
    pub fn new(photos: watch::Receiver<Option<Photo>>) -> Self {
        Self {
            photos,
            latest: Mutex::new(None),
            permits: Semaphore::new(AT_ONCE),
        }
    }

    /// The latest photograph encoded.
    pub fn latest(&self) -> Option<Encoded> {
        self.latest
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }
}

/// Encodes each photograph the agent publishes (the newest only: one that arrives while the
/// last is being encoded replaces it).
pub async fn follow(console: Arc<Console>, cancel: CancellationToken) {
    let mut photos = console.images.photos.clone();
    loop {
        tokio::select! {
            changed = photos.changed() => if changed.is_err() { return },
            () = cancel.cancelled() => return,
        }
        let Some(photo) = photos.borrow_and_update().clone() else {
            continue;
        };
        let (seq, width, height) = (photo.seq, photo.image.width, photo.image.height);
        let png = tokio::task::spawn_blocking(move || photograph_png(&photo.image)).await;
        match png {
            Ok(Ok(png)) => {
                *console
                    .images
                    .latest
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner) = Some(Encoded {
                    seq,
                    width,
                    height,
                    png: Arc::new(png),
                });
            }
            Ok(Err(e)) => {
                tracing::warn!(error = %e, "console: the photograph could not be encoded")
            }
            Err(e) => tracing::warn!(error = %e, "console: encoding the photograph failed"),
        }
    }
}

/// The factor a `width`-wide picture is divided by to fit [`MAX_WIDTH`] (1 when it fits).
fn factor(width: u32) -> u32 {
    width.div_ceil(MAX_WIDTH).max(1)
}

/// Box-filters `pixels` (`width × height`, row-major) down by `k` (each output pixel the mean
/// of the `k × k` block it covers, partial blocks at the edges included).
fn shrink(width: u32, height: u32, pixels: &[[f32; 3]], k: u32) -> (u32, u32, Vec<[f32; 3]>) {
    let (w, h) = (width.div_ceil(k), height.div_ceil(k));
    let mut sum = vec![[0f32; 3]; (w * h) as usize];
    let mut count = vec![0u32; (w * h) as usize];
    for (i, p) in pixels.iter().enumerate() {
        let (x, y) = (i as u32 % width, i as u32 / width);
        let o = ((y / k) * w + x / k) as usize;
        if let (Some(s), Some(c)) = (sum.get_mut(o), count.get_mut(o)) {
            for ch in 0..3 {
                s[ch] += p[ch];
            }
            *c += 1;
        }
    }
    let out = sum
        .into_iter()
        .zip(count)
        // Every output pixel covers at least one input pixel; 0 only for an empty image.
        .map(|(s, c)| s.map(|v| if c == 0 { 0.0 } else { v / c as f32 }))
        .collect();
    (w, h, out)
}

/// The sRGB transfer curve of a linear value in [0, 1].
fn srgb(v: f32) -> u8 {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let e = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (e * 255.0).round() as u8
}

/// An 8-bit RGB PNG of `pixels` (channels in [0, 1], encoded with `encode`).
fn png(w: u32, h: u32, pixels: &[[f32; 3]], encode: impl Fn(f32) -> u8) -> Result<Vec<u8>, String> {
    let data: Vec<u8> = pixels.iter().flat_map(|p| p.map(&encode)).collect();
    let image = image::RgbImage::from_raw(w, h, data)
        .ok_or_else(|| format!("{w}×{h}: the pixels do not fill it"))?;
    let mut out = Cursor::new(Vec::new());
    image
        .write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| e.to_string())?;
    Ok(out.into_inner())
}

/// A photograph for viewing: scaled down, exposed so that its 99th percentile is white (at
/// most 16 times brighter: a dark room stays dark), sRGB-encoded.
pub fn photograph_png(image: &LinearImage) -> Result<Vec<u8>, String> {
    let k = factor(image.width);
    let (w, h, pixels) = shrink(image.width, image.height, &image.pixels, k);
    let mut peaks: Vec<f32> = pixels
        .iter()
        .map(|p| p[0].max(p[1]).max(p[2]))
        .filter(|v| v.is_finite())
        .collect();
    let p99 = if peaks.is_empty() {
        1.0
    } else {
        let i = (peaks.len() - 1) * 99 / 100;
        *peaks.select_nth_unstable_by(i, f32::total_cmp).1
    };
    // A black image (p99 = 0) is shown at the largest gain.
    let gain = if p99 > 0.0 {
        (1.0 / p99).min(16.0)
    } else {
        16.0
    };
    png(w, h, &pixels, |v| srgb(v * gain))
}

/// A coverage map: each camera pixel's share of a projector's light (white = 1), over a dim
/// copy of the photograph when one of the same size is given.
pub fn coverage_png(
    width: u32,
    height: u32,
    share: &[f32],
    under: Option<&LinearImage>,
) -> Result<Vec<u8>, String> {
    let under = under.filter(|i| (i.width, i.height) == (width, height));
    let pixels: Vec<[f32; 3]> = share
        .iter()
        .enumerate()
        .map(|(i, &s)| {
            let s = if s.is_finite() {
                s.clamp(0.0, 1.0)
            } else {
                0.0
            };
            let base = under
                .and_then(|u| u.pixels.get(i))
                .map_or(0.0, |p| (p[0] + p[1] + p[2]) / 3.0 * 0.3);
            [s.max(base), s.max(base), base + s * (1.0 - base) * 0.4]
        })
        .collect();
    let (w, h, pixels) = shrink(width, height, &pixels, factor(width));
    png(w, h, &pixels, srgb)
}

/// Where a chart's patch (column `c`, row `r`) is: its centre by bilinear interpolation of
/// the chart's corners, and its half-size in pixels.
fn patch_centre(chart: &ChartCorners, c: usize, r: usize) -> ([f64; 2], f64) {
    let [tl, tr, br, bl] = chart.corners;
    let u = (c as f64 + 0.5) / COLUMNS as f64;
    let v = (r as f64 + 0.5) / ROWS as f64;
    let lerp =
        |a: [f64; 2], b: [f64; 2], t: f64| [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t];
    let top = lerp(tl, tr, u);
    let bottom = lerp(bl, br, u);
    let centre = lerp(top, bottom, v);
    let dist = |a: [f64; 2], b: [f64; 2]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    let side = (dist(tl, tr) / COLUMNS as f64).min(dist(tl, bl) / ROWS as f64);
    (centre, 0.4 * side)
}

/// An attenuation map: each chart patch filled with the projector's attenuation there
/// (normalised to its brightest patch), over a dim photograph of the same size if given.
pub fn attenuation_png(
    width: u32,
    height: u32,
    charts: &[ChartCorners],
    patches: &[(usize, roomlight_core::LinearRgb)],
    under: Option<&LinearImage>,
) -> Result<Vec<u8>, String> {
    let under = under.filter(|i| (i.width, i.height) == (width, height));
    let mut pixels: Vec<[f32; 3]> = match under {
        Some(u) => u.pixels.iter().map(|p| p.map(|v| v * 0.2)).collect(),
        None => vec![[0.0; 3]; (width as usize) * (height as usize)],
    };
    let peak = patches
        .iter()
        .map(|(_, p)| p.0.iter().copied().fold(0.0, f64::max))
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    let per = COLUMNS * ROWS;
    for &(room, p) in patches {
        let Some(chart) = charts.get(room / per) else {
            continue;
        };
        let (c, r) = ((room % per) % COLUMNS, (room % per) / COLUMNS);
        let ([cx, cy], half) = patch_centre(chart, c, r);
        // No light at all: the patch stays as it is (0 / 0 is not drawn).
        let colour = if peak > 0.0 {
            p.0.map(|v| (v / peak).clamp(0.0, 1.0) as f32)
        } else {
            continue;
        };
        let (x0, x1) = (
            (cx - half).floor().max(0.0),
            (cx + half).ceil().min(f64::from(width)),
        );
        let (y0, y1) = (
            (cy - half).floor().max(0.0),
            (cy + half).ceil().min(f64::from(height)),
        );
        for y in (y0 as u32)..(y1 as u32) {
            for x in (x0 as u32)..(x1 as u32) {
                if let Some(px) = pixels.get_mut((y * width + x) as usize) {
                    *px = colour;
                }
            }
        }
    }
    let (w, h, pixels) = shrink(width, height, &pixels, factor(width));
    png(w, h, &pixels, srgb)
}

/// A projector frame's thumbnail: codes in [0, 1] shown as they are (they are what the
/// projector receives), scaled to at most 160 pixels wide; a strip of swatches when the frame
/// is one pixel per node.
pub fn frame_png(width: u32, height: u32, pixels: &[[f32; 3]]) -> Result<Vec<u8>, String> {
    if height == 1 {
        // One swatch of 16×16 per node.
        let side = 16u32;
        let w = (width * side).max(1);
        let mut out = vec![[0f32; 3]; (w * side) as usize];
        for (i, p) in out.iter_mut().enumerate() {
            let node = (i as u32 % w) / side;
            if let Some(v) = pixels.get(node as usize) {
                // Values are linear: shown through the sRGB curve.
                *p = *v;
            }
        }
        return png(w, side, &out, srgb);
    }
    let k = width.div_ceil(160).max(1);
    let (w, h, pixels) = shrink(width, height, pixels, k);
    png(w, h, &pixels, |v| {
        let v = if v.is_finite() {
            v.clamp(0.0, 1.0)
        } else {
            0.0
        };
        (v * 255.0).round() as u8
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode(png: &[u8]) -> image::RgbImage {
        image::load_from_memory(png).expect("a PNG").to_rgb8()
    }

    /// A 1280-wide photograph comes out 640 wide, its mean kept by the box filter, exposed to
    /// its 99th percentile; a black or non-finite image encodes without a panic.
    #[test]
    fn photographs_are_scaled_and_exposed() {
        let mut image = LinearImage::new(1280, 10);
        for (i, p) in image.pixels.iter_mut().enumerate() {
            *p = if i % 2 == 0 { [0.5; 3] } else { [0.0; 3] };
        }
        let out = decode(&photograph_png(&image).expect("encoded"));
        assert_eq!(out.dimensions(), (640, 5));
        // Each 2×2 block averages 0.25; the 99th percentile is 0.25, so it is shown white.
        assert_eq!(out.get_pixel(10, 2).0, [255, 255, 255]);
        let mut dark = LinearImage::new(3, 2);
        dark.pixels[0] = [f32::NAN, f32::INFINITY, -1.0];
        let out = decode(&photograph_png(&dark).expect("encoded"));
        assert_eq!(out.get_pixel(0, 0).0, [0, 0, 0]);
    }

    /// A patch of a chart is filled where the chart's geometry puts it, in proportion to the
    /// brightest; an unlit projector leaves the map black.
    #[test]
    fn attenuation_fills_the_patches() {
        let chart = ChartCorners {
            name: "A".into(),
            corners: [[0.0, 0.0], [60.0, 0.0], [60.0, 40.0], [0.0, 40.0]],
        };
        let bright = roomlight_core::LinearRgb([1.0, 0.0, 0.0]);
        let half = roomlight_core::LinearRgb([0.0, 0.5, 0.0]);
        let png = attenuation_png(
            64,
            48,
            std::slice::from_ref(&chart),
            &[(0, bright), (23, half)],
            None,
        )
        .expect("encoded");
        let out = decode(&png);
        // Patch 0's centre is (5, 5); patch 23 (column 5, row 3) is at (55, 35).
        assert_eq!(out.get_pixel(5, 5).0, [255, 0, 0]);
        assert_eq!(out.get_pixel(55, 35).0[1], srgb(0.5));
        assert_eq!(out.get_pixel(30, 20).0, [0, 0, 0]);
        let none = attenuation_png(
            64,
            48,
            &[chart],
            &[(0, roomlight_core::LinearRgb::ZERO)],
            None,
        )
        .expect("encoded");
        assert!(decode(&none).pixels().all(|p| p.0 == [0, 0, 0]));
    }
}
