//! What per-pixel, per-channel projector light could reach over the whole room, from the
//! simulator's truth: every luminaire's pixels free in `[0, 1]` (those landing on the target
//! kept black), stepped multiplicatively towards the LEDs' noiseless render through each
//! projector's true correspondence, with inter-reflection. Not the system (it reads ground
//! truth the system never has); the ceiling that `roomlight_calib::shading` aims at, quoted in
//! docs/results.md.
//!
//! Then what holds the last pass's tail (pixels above ΔE00 8) back: how many are too dim, and
//! how many of those every projector pixel that sees them already gives full light in some
//! channel (only light bounced from elsewhere could raise them); and a bound per pixel alone,
//! the LEDs' light clamped per channel between the dark room and every driven pixel at full
//! light (pixels left above 8 by it cannot be matched whatever the others do).
//!
//! With `closest`, a pixel short of headroom in a channel steps to the closest colour it can
//! still give (`roomlight_calib::shading::closest_within`, as the node agents step their
//! blocks) instead of by each channel's own ratio.
//!
//! `cargo run --release -p roomlight-lab --example per_pixel_ceiling [lab|small] [passes] [closest]`

use anyhow::{Context, Result};
use roomlight_lab::whole_room::{
    Reach, ReachMap, WholeRoom, delta_e_map, luminaires, white_luminance,
};
use roomlight_sim::{Frame, NodeRegion, ProjectorImage, Room};

/// Each pass moves a pixel by this power of its camera pixels' mean log ratio.
const RATE: f64 = 0.8;
/// Projector pixels no camera pixel sees take their block's mean ratio.
const BLOCK: u32 = 8;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let scene = match args.get(1).map(String::as_str) {
        Some("small") => roomlight_sim::scenes::small()?,
        _ => roomlight_sim::scenes::lab()?,
    };
    let passes: usize = match args.get(2) {
        Some(p) => p.parse().context("passes: expected a count")?,
        None => 10,
    };
    // `closest`: a pixel short of headroom in a channel takes the closest colour in ΔE00
    // within it (`shading::closest_within`) instead of each channel's own ratio.
    let closest = args.get(3).is_some_and(|a| a == "closest");
    let room = Room::build(scene)?;
    let n = room.projectors().len();
    let luminaires = luminaires(&room);
    let size = |k: usize| {
        let p = &room.projectors()[k].pinhole;
        (p.width, p.height)
    };
    let corr: Vec<Vec<Option<u32>>> = (0..n).map(|k| room.true_correspondence(k)).collect();
    let pixels = room.pixels();
    // Driven: every luminaire pixel but those that land on the target.
    let mut driven: Vec<Vec<bool>> = (0..n)
        .map(|k| {
            let (w, h) = size(k);
            vec![luminaires.contains(&k); (w * h) as usize]
        })
        .collect();
    for &k in &luminaires {
        for (c, p) in corr[k].iter().enumerate() {
            if let Some(p) = p.filter(|_| pixels[c].target) {
                driven[k][p as usize] = false;
            }
        }
    }
    let regions: Vec<NodeRegion> = luminaires
        .iter()
        .map(|&k| NodeRegion {
            projector: k,
            weights: driven[k].iter().map(|d| f32::from(u8::from(*d))).collect(),
        })
        .collect();
    let reach = ReachMap::new(&room, &regions)?;
    let surface: Vec<bool> = reach.reach.iter().map(|r| *r != Reach::NoSurface).collect();
    let black = vec![Frame::Black; n];
    let dark = room.render(&black, None)?;
    for (preset, spec) in room.scene().presets.iter().enumerate() {
        let reference = room.render(&black, Some(preset))?;
        let white = white_luminance(&reference, &surface)?;
        let mut light: Vec<Vec<[f32; 3]>> = (0..n)
            .map(|k| {
                driven[k]
                    .iter()
                    .map(|d| [if *d { 0.3 } else { 0.0 }; 3])
                    .collect()
            })
            .collect();
        let mut path = Vec::new();
        let mut last = None;
        for pass in 0..=passes {
            let frames: Vec<Frame> = (0..n)
                .map(|k| {
                    let (width, height) = size(k);
                    Frame::Linear(ProjectorImage {
                        width,
                        height,
                        pixels: light[k].clone(),
                    })
                })
                .collect();
            let lit = room.render(&frames, None)?;
            let whole = WholeRoom::measure(&delta_e_map(&reference, &lit, white)?, &reach, white)?;
            path.push(format!("{:.2} / {:.2}", whole.de00_mean, whole.de00_p95));
            if pass == passes {
                last = Some(lit);
                break;
            }
            for &k in &luminaires {
                step(
                    &mut light[k],
                    &driven[k],
                    size(k),
                    &corr[k],
                    closest.then_some(white),
                    |c| {
                        (!pixels[c].target).then(|| {
                            let above = |im: &roomlight_sim::Capture| -> [f64; 3] {
                                std::array::from_fn(|i| {
                                    f64::from(im.pixels[c][i] - dark.pixels[c][i]).max(1e-6)
                                })
                            };
                            (above(&reference), above(&lit))
                        })
                    },
                );
            }
        }
        println!(
            "{}: whole room ΔE00 mean / p95 pass by pass: {}",
            spec.name,
            path.join(" → ")
        );
        if let Some(lit) = last {
            let de = delta_e_map(&reference, &lit, white)?;
            let at_full = at_full_light(&luminaires, &corr, &light, de.len());
            let luminance = |p: &[f32; 3]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
            let tail: Vec<usize> = (0..de.len())
                .filter(|&i| reach.reach[i] == Reach::Reached && de[i] > 8.0)
                .collect();
            let dim: Vec<&usize> = tail
                .iter()
                .filter(|&&i| luminance(&lit.pixels[i]) < luminance(&reference.pixels[i]))
                .collect();
            let full = dim.iter().filter(|&&&i| at_full[i]).count();
            println!(
                "  after the last pass {} reached pixels above 8: {} too dim, {full} of them seen only at full light in some channel",
                tail.len(),
                dim.len()
            );
        }
        let bound = clamped_to_full_light(&room, &driven, &reference, &dark)?;
        let de = delta_e_map(&reference, &bound, white)?;
        let reached = (0..de.len()).filter(|&i| reach.reach[i] == Reach::Reached);
        let (count, over) = reached.fold((0, 0), |(n, o), i| (n + 1, o + usize::from(de[i] > 8.0)));
        println!(
            "  each pixel alone, every driven pixel at full light: {over} of {count} reached pixels above 8 ({:.2}%)",
            100.0 * over as f64 / f64::from(count.max(1))
        );
    }
    Ok(())
}

/// Camera pixels some luminaire pixel at full light (in any channel) lands on.
fn at_full_light(
    luminaires: &[usize],
    corr: &[Vec<Option<u32>>],
    light: &[Vec<[f32; 3]>],
    pixels: usize,
) -> Vec<bool> {
    let mut full = vec![false; pixels];
    for &k in luminaires {
        for (c, p) in corr[k].iter().enumerate() {
            if let Some(p) = p
                && light[k][*p as usize].iter().any(|v| *v >= 0.999)
            {
                full[c] = true;
            }
        }
    }
    full
}

/// The LEDs' light clamped per pixel and channel between the dark room and the room with every
/// driven pixel at full light.
fn clamped_to_full_light(
    room: &Room,
    driven: &[Vec<bool>],
    reference: &roomlight_sim::Capture,
    dark: &roomlight_sim::Capture,
) -> Result<roomlight_sim::Capture> {
    let frames: Vec<Frame> = driven
        .iter()
        .enumerate()
        .map(|(k, d)| {
            let p = &room.projectors()[k].pinhole;
            Frame::Linear(ProjectorImage {
                width: p.width,
                height: p.height,
                pixels: d.iter().map(|d| [f32::from(u8::from(*d)); 3]).collect(),
            })
        })
        .collect();
    let most = room.render(&frames, None)?;
    let mut clamped = reference.clone();
    for ((p, lo), hi) in clamped
        .pixels
        .iter_mut()
        .zip(&dark.pixels)
        .zip(&most.pixels)
    {
        for c in 0..3 {
            p[c] = p[c].clamp(lo[c], hi[c].max(lo[c]));
        }
    }
    Ok(clamped)
}

/// One pass on one projector's light: each pixel by the mean log ratio of the camera pixels
/// that see it (`light(c)`: the LEDs' light and the current one above the dark room; `None`:
/// left out), else its block's. With `closest` (the white's luminance), a pixel seen by camera
/// pixels steps by `shading::closest_within` their summed light and its headroom instead.
fn step(
    light: &mut [[f32; 3]],
    driven: &[bool],
    (w, h): (u32, u32),
    corr: &[Option<u32>],
    closest: Option<f64>,
    seen: impl Fn(usize) -> Option<([f64; 3], [f64; 3])>,
) {
    let mut sums = vec![([0.0f64; 3], 0u32, [0.0f64; 3], [0.0f64; 3]); light.len()];
    for (c, p) in corr.iter().enumerate() {
        let (Some(p), Some((want, got))) = (p, seen(c)) else {
            continue;
        };
        let s = &mut sums[*p as usize];
        (0..3).for_each(|i| {
            s.0[i] += (want[i] / got[i]).ln();
            s.2[i] += want[i];
            s.3[i] += got[i];
        });
        s.1 += 1;
    }
    let across = w.div_ceil(BLOCK);
    let mut blocks = vec![([0.0f64; 3], 0u32); (across * h.div_ceil(BLOCK)) as usize];
    let block = |i: usize| {
        let (x, y) = (i as u32 % w, i as u32 / w);
        ((y / BLOCK) * across + x / BLOCK) as usize
    };
    for (i, s) in sums.iter().enumerate() {
        let b = &mut blocks[block(i)];
        (0..3).for_each(|c| b.0[c] += s.0[c]);
        b.1 += s.1;
    }
    for (i, v) in light.iter_mut().enumerate() {
        if !driven[i] {
            continue;
        }
        let log: [f64; 3] = match (closest, sums[i].1) {
            (Some(white), n) if n > 0 => {
                let (want, got) = (sums[i].2, sums[i].3);
                let most = v.map(|x| 1.0 / f64::from(x).max(1e-6));
                roomlight_calib::shading::closest_within(
                    want.map(|x| x / white / f64::from(n)),
                    got.map(|x| x / white / f64::from(n)),
                    most,
                )
                .map(f64::ln)
            }
            _ => {
                let s = if sums[i].1 > 0 {
                    (sums[i].0, sums[i].1)
                } else {
                    blocks[block(i)]
                };
                if s.1 == 0 {
                    continue;
                }
                s.0.map(|x| x / f64::from(s.1))
            }
        };
        for (v, l) in v.iter_mut().zip(log) {
            let g = (l * RATE).exp();
            *v = (f64::from(*v) * g).clamp(0.0, 1.0) as f32;
        }
    }
}
