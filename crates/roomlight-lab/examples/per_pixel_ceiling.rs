//! What per-pixel, per-channel projector light could reach over the whole room, from the
//! simulator's truth: every luminaire's pixels free in `[0, 1]` (those landing on the target
//! kept black), stepped multiplicatively towards the LEDs' noiseless render through each
//! projector's true correspondence, with inter-reflection. Not the system (it reads ground
//! truth the system never has); the ceiling that `roomlight_calib::shading` aims at, quoted in
//! docs/results.md.
//!
//! `cargo run --release -p roomlight-lab --example per_pixel_ceiling [lab|small] [passes]`

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
                break;
            }
            for &k in &luminaires {
                step(&mut light[k], &driven[k], size(k), &corr[k], |c| {
                    (!pixels[c].target).then(|| {
                        std::array::from_fn(|i| {
                            let want = f64::from(reference.pixels[c][i] - dark.pixels[c][i]);
                            let got = f64::from(lit.pixels[c][i] - dark.pixels[c][i]);
                            // Both floored above zero: a log of their ratio.
                            (want.max(1e-6) / got.max(1e-6)).ln()
                        })
                    })
                });
            }
        }
        println!(
            "{}: whole room ΔE00 mean / p95 pass by pass: {}",
            spec.name,
            path.join(" → ")
        );
    }
    Ok(())
}

/// One pass on one projector's light: each pixel by the mean log ratio of the camera pixels
/// that see it (`ratio(c)`, `None`: left out), else its block's.
fn step(
    light: &mut [[f32; 3]],
    driven: &[bool],
    (w, h): (u32, u32),
    corr: &[Option<u32>],
    ratio: impl Fn(usize) -> Option<[f64; 3]>,
) {
    let mut sums = vec![([0.0f64; 3], 0u32); light.len()];
    for (c, p) in corr.iter().enumerate() {
        let (Some(p), Some(r)) = (p, ratio(c)) else {
            continue;
        };
        let s = &mut sums[*p as usize];
        (0..3).for_each(|i| s.0[i] += r[i]);
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
        let s = if sums[i].1 > 0 {
            sums[i]
        } else {
            blocks[block(i)]
        };
        if !driven[i] || s.1 == 0 {
            continue;
        }
        for (v, sum) in v.iter_mut().zip(s.0) {
            let g = (sum / f64::from(s.1) * RATE).exp();
            *v = (f64::from(*v) * g).clamp(0.0, 1.0) as f32;
        }
    }
}
