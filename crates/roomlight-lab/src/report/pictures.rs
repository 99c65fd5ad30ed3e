//! One preset's pictures for the report: the room under the LEDs, at the conventional start and
//! with the result (tone-mapped sRGB for viewing, linear 16-bit beside them, never clipped), the
//! whole-room ΔE00 map with its colour bar, and full-resolution crops where the map is worst.

use super::png::{srgb8, write_linear16, write_srgb8_image};
use crate::pipeline;
use crate::whole_room::{
    ReachMap, WholeRoom, delta_e_map, map_image, white_luminance, worst_window,
};
use anyhow::{Context, Result};
use roomlight_sim::{Frame, Room};
use std::path::Path;

/// What [`preset_pictures`] wrote and measured.
#[derive(Debug, Clone)]
pub struct PresetPictures {
    /// Tone-mapped sRGB pictures: under the LEDs, at the conventional start, with the result.
    pub pictures: [String; 3],
    /// The ΔE00 map of the result against the LEDs, with its colour bar.
    pub de00_map: String,
    /// Crops at the camera's full resolution where the map is worst: LEDs, result, map.
    pub crops: [String; 3],
    /// The crops' window in the camera image: x, y, width, height.
    pub crop: (u32, u32, u32, u32),
    /// The linear 16-bit PNGs and their scales (linear camera value per code).
    pub linear: Vec<(String, f64)>,
    /// The whole-room figures.
    pub whole_room: WholeRoom,
}

/// A file name for a preset: letters and digits kept, everything else a dash.
pub fn slug(name: &str) -> String {
    name.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect()
}

/// Renders the room under the LEDs, at the conventional start and with the result (noiseless,
/// the same exposure for the three), writes them and the whole-room map, and measures it.
#[allow(clippy::too_many_arguments)]
pub fn preset_pictures(
    room: &Room,
    cal: &pipeline::Calibrated,
    model: &pipeline::Model,
    result: &pipeline::RunResult,
    reach: &ReachMap,
    preset: usize,
    name: &str,
    dir: &Path,
) -> Result<PresetPictures> {
    let dark = vec![Frame::Black; room.projectors().len()];
    let frames = pipeline::FrameBuilder::new(room, &cal.regions, cal.responses.clone())?;
    let captures = [
        room.render(&dark, Some(preset))?,
        room.render(&frames.frames(&model.conventional), None)?,
        room.render(&frames.frames(&result.x), None)?,
    ];
    // Exposure of the viewing pictures: the target's 99th percentile channel value at full scale.
    let mut levels: Vec<f64> = captures[0]
        .pixels
        .iter()
        .map(|p| f64::from(p.iter().copied().fold(0.0, f32::max)))
        .collect();
    let white = crate::whole_room::nearest_rank(&mut levels, 0.99)
        .filter(|w| *w > 0.0)
        .unwrap_or(1.0) as f32;
    let slug = slug(name);
    let mut pictures = Vec::new();
    let mut linear = Vec::new();
    let mut viewed = Vec::new();
    for (capture, what) in captures.iter().zip(["target", "conventional", "result"]) {
        let file = format!("{slug}-{what}.png");
        let img = srgb8(capture, white)?;
        write_srgb8_image(&dir.join(&file), &img)?;
        let lin = format!("{slug}-{what}.linear16.png");
        let scale = write_linear16(&dir.join(&lin), capture)?;
        linear.push((lin, scale));
        pictures.push(file);
        viewed.push(img);
    }
    strip(dir, &slug, &viewed)?;
    // The whole room: ΔE00 of the result against the LEDs, white from the LED reference.
    let surface: Vec<bool> = reach
        .reach
        .iter()
        .map(|r| *r != crate::whole_room::Reach::NoSurface)
        .collect();
    let white_l = white_luminance(&captures[0], &surface)?;
    let de = delta_e_map(&captures[0], &captures[2], white_l)?;
    let whole_room = WholeRoom::measure(&de, reach, white_l)
        .with_context(|| format!("the whole room under {name}"))?;
    let map = map_image(&de, reach)?;
    let de00_map = format!("{slug}-de00-map.png");
    write_srgb8_image(&dir.join(&de00_map), &map)?;
    let crop = worst_window(&de, reach, reach.width / 4, reach.height / 4);
    let (x, y, w, h) = crop;
    let mut crops = Vec::new();
    for (img, what) in [
        (&viewed[0], "target"),
        (&viewed[2], "result"),
        (&map, "de00"),
    ] {
        let file = format!("{slug}-crop-{what}.png");
        let part = image::imageops::crop_imm(img, x, y, w, h).to_image();
        write_srgb8_image(&dir.join(&file), &part)?;
        crops.push(file);
    }
    let [a, b, c] = <[String; 3]>::try_from(pictures).map_err(|_| anyhow::anyhow!("3 pictures"))?;
    let [d, e, f] = <[String; 3]>::try_from(crops).map_err(|_| anyhow::anyhow!("3 crops"))?;
    Ok(PresetPictures {
        pictures: [a, b, c],
        de00_map,
        crops: [d, e, f],
        crop,
        linear,
        whole_room,
    })
}

/// The three pictures side by side, small: the headline picture for a README.
fn strip(dir: &Path, slug: &str, viewed: &[image::RgbImage]) -> Result<()> {
    let thumbs: Vec<image::RgbImage> = viewed
        .iter()
        .map(|img| image::imageops::thumbnail(img, 320, 240))
        .collect();
    let (w, h) = thumbs
        .iter()
        .fold((0, 0), |(w, h), t| (w + t.width(), h.max(t.height())));
    let mut strip = image::RgbImage::new(w, h);
    let mut x = 0;
    for t in &thumbs {
        image::imageops::replace(&mut strip, t, i64::from(x), 0);
        x += t.width();
    }
    write_srgb8_image(&dir.join(format!("{slug}-strip.png")), &strip)
}
