//! The large aperture's footprint by light-weighted centroids (issue 21, item 7), measured
//! against the simulator's true correspondence: `roomlight bench calib` prints the share of
//! blocks whose centroid lies within ±1 camera pixel of where their sharp image lands.

use anyhow::Result;
use roomlight_calib::centroid::{
    Spot, block_centres, local_floor, merge_spots, noise_sigma, spots, spots_over,
};
use roomlight_sim::{CameraNoise, Capture, Frame, ProjectorImage, Room};
use std::time::Instant;

/// Projector pixels per block whose centroid the large aperture's measure finds.
const CENTROID_BLOCK: u32 = 16;
/// Blocks shown at once are this many blocks apart (in x and y), so that their blurs do not
/// meet.
const CENTROID_SPACING: u32 = 6;
/// Fewest camera pixels a block's sharp image covers for its centroid to be checked.
const CENTROID_MIN_PIXELS: usize = 16;

/// The large aperture `k`'s footprint measured by light-weighted centroids (issue 21, item
/// 7): lattices of `CENTROID_BLOCK`-pixel blocks, `CENTROID_SPACING` blocks apart, each
/// photographed (LEDs off, camera noise) minus a black photograph; every spot of light found
/// has its centroid compared with where the block's sharp image lands by the simulator's true
/// correspondence (the mean of the camera pixels it lights through the lens centre). A block
/// counts where its sharp image covers at least `CENTROID_MIN_PIXELS` camera pixels; its error
/// is the distance to the nearest spot's centroid (none: a miss). Spots are found twice: above
/// a floor per neighbourhood ([`local_floor`]: a share of the brightest light within
/// `CENTROID_WINDOW` pixels, at least some noise deviations), and above one floor for the
/// capture (a share of its 99.9th percentile), the measure before, printed beside it. Then the
/// blocks are sorted by their sharp image ([`pieces`]): whole, measured against spots of at
/// least `CENTROID_SMALL` pixels merged within `CENTROID_MERGE` ([`merge_spots`]); or split
/// over surfaces at different depths (their light-weighted centroid is no single point), each
/// piece against its nearest spot, the block within the bar only if every piece is. Every block
/// is counted in one of the two. With `ROOMLIGHT_DIAG` set, the misses are counted by kind and
/// a sample of blocks printed.
pub(super) fn centroids(room: &Room, k: usize) -> Result<()> {
    let t = Instant::now();
    let p = &room.projectors()[k];
    let (pw, ph) = (p.pinhole.width, p.pinhole.height);
    let cw = room.camera().width as usize;
    let truth = room.true_correspondence(k);
    let centres = block_centres(&truth, cw, (pw, ph), CENTROID_BLOCK);
    let (bw, bh) = (pw.div_ceil(CENTROID_BLOCK), ph.div_ceil(CENTROID_BLOCK));
    let pieces = pieces(room, k, &truth);
    let n = room.projectors().len();
    let mut noise = CameraNoise::with_seed(room, 31);
    let green = |c: &Capture| c.pixels.iter().map(|v| v[1]).collect::<Vec<f32>>();
    let black = green(&noise.expose(&room.render(&vec![Frame::Black; n], None)?));
    let mut errors: Vec<f64> = Vec::new();
    let mut errors_global: Vec<f64> = Vec::new();
    // Blocks whose sharp image is one piece: the nearest spot, and the nearest merged spot.
    let mut whole: Vec<f64> = Vec::new();
    let mut whole_merged: Vec<f64> = Vec::new();
    let mut whole_small: Vec<f64> = Vec::new();
    let mut whole_small_merged: Vec<f64> = Vec::new();
    // Blocks split over surfaces: each piece's error (nearest spot), the worst piece per block.
    let mut piece_errors: Vec<f64> = Vec::new();
    let mut split_worst: Vec<f64> = Vec::new();
    let mut split_dark = 0usize;
    let diag = std::env::var_os("ROOMLIGHT_DIAG").is_some();
    let mut samples = Vec::new();
    let mut frames = 0usize;
    for (oy, ox) in (0..CENTROID_SPACING).flat_map(|y| (0..CENTROID_SPACING).map(move |x| (y, x))) {
        let shown: Vec<usize> = (oy..bh)
            .step_by(CENTROID_SPACING as usize)
            .flat_map(|by| {
                (ox..bw)
                    .step_by(CENTROID_SPACING as usize)
                    .map(move |bx| (by * bw + bx) as usize)
            })
            .collect();
        let mut pixels = vec![[0.0f32; 3]; (pw * ph) as usize];
        for &b in &shown {
            let (bx, by) = (b as u32 % bw, b as u32 / bw);
            for y in by * CENTROID_BLOCK..((by + 1) * CENTROID_BLOCK).min(ph) {
                for x in bx * CENTROID_BLOCK..((bx + 1) * CENTROID_BLOCK).min(pw) {
                    pixels[(y * pw + x) as usize] = [1.0; 3];
                }
            }
        }
        let mut all = vec![Frame::Black; n];
        all[k] = Frame::Linear(ProjectorImage {
            width: pw,
            height: ph,
            pixels,
        });
        let lit = green(&noise.expose(&room.render(&all, None)?));
        frames += 1;
        let diff: Vec<f32> = lit.iter().zip(&black).map(|(l, b)| l - b).collect();
        let mut sorted = diff.clone();
        sorted.sort_by(f32::total_cmp);
        let top = sorted[sorted.len() * 999 / 1000];
        let global = spots(&diff, cw, CENTROID_FLOOR * top, CENTROID_MIN_PIXELS)?;
        let floor = local_floor(
            &diff,
            cw,
            CENTROID_WINDOW,
            CENTROID_SHARE,
            CENTROID_NOISE * noise_sigma(&diff),
        )?;
        let found = spots_over(&diff, cw, &floor, CENTROID_MIN_PIXELS)?;
        let merged = merge_spots(&found, CENTROID_MERGE);
        let small = spots_over(&diff, cw, &floor, CENTROID_SMALL)?;
        let small_merged = merge_spots(&small, CENTROID_MERGE);
        for &b in &shown {
            let Some((c, count)) = centres[b] else {
                continue;
            };
            if count < CENTROID_MIN_PIXELS {
                continue;
            }
            let nearest = |found: &[Spot]| nearest_to(found, c);
            let err = nearest(&found);
            errors.push(err);
            errors_global.push(nearest(&global));
            let big: Vec<&([f64; 2], usize)> =
                pieces[b].iter().filter(|p| p.1 >= CENTROID_PIECE).collect();
            if big.len() <= 1 {
                whole.push(err);
                whole_merged.push(nearest(&merged));
                whole_small.push(nearest(&small));
                whole_small_merged.push(nearest(&small_merged));
            } else {
                let mut worst = 0.0f64;
                for (pc, _) in big {
                    let e = nearest_to(&small, *pc);
                    piece_errors.push(e);
                    worst = worst.max(e);
                }
                split_worst.push(worst);
                if err > 1.0 && diff[(c[1] as usize) * cw + c[0] as usize] < 0.05 * top {
                    split_dark += 1;
                }
            }
            if diag {
                let nearest = found.iter().min_by(|a, b| {
                    let d =
                        |s: &&Spot| (s.centroid[0] - c[0]).powi(2) + (s.centroid[1] - c[1]).powi(2);
                    d(a).total_cmp(&d(b))
                });
                let at = diff[(c[1] as usize) * cw + c[0] as usize] / top;
                samples.push((err, b, c, count, at, nearest.copied()));
            }
        }
    }
    if diag {
        let misses: Vec<_> = samples.iter().filter(|s| s.0 > 1.0).collect();
        let far = misses.iter().filter(|s| s.0 > 10.0).count();
        let dark = misses.iter().filter(|s| s.4 < 0.05).count();
        println!(
            "  misses (> 1 px) {}: {far} off by > 10 px (no spot of their own: split at an edge, or under a brighter neighbour's floor), {dark} with under 5% of the top light at their sharp centre (blocks split over surfaces: counted below)",
            misses.len()
        );
        samples.sort_by(|a, b| a.0.total_cmp(&b.0));
        let n = samples.len();
        for (err, b, c, count, at, nearest) in samples.iter().step_by((n / 40).max(1)) {
            println!(
                "  block {b}: sharp at ({:.1}, {:.1}) over {count} px, light there {:.3} of the top; nearest spot {:?}: {err:.2} px",
                c[0], c[1], at, nearest
            );
        }
    }
    println!(
        "{:<18} light-weighted centroids of {}x{} blocks ({frames} captures, {:.1} s): {} blocks seen; floor per neighbourhood: {}; one floor for the capture: {}",
        p.name,
        CENTROID_BLOCK,
        CENTROID_BLOCK,
        t.elapsed().as_secs_f64(),
        errors.len(),
        summary(&errors),
        summary(&errors_global),
    );
    let m = errors.len().max(1) as f64;
    let within = |e: &[f64]| e.iter().filter(|e| **e <= 1.0).count();
    println!(
        "{:<18} by the sharp image's shape (the true correspondence's camera pixels of a block, in pieces split where 8-neighbours differ in depth from the projector by over {:.0}% or do not touch; pieces under {CENTROID_PIECE} px ignored): {} blocks whole ({:.2}%), {} split ({:.2}%; {split_dark} of them missed with under 5% of the top light at their mean)",
        "",
        100.0 * DEPTH_JUMP,
        whole.len(),
        100.0 * whole.len() as f64 / m,
        split_worst.len(),
        100.0 * split_worst.len() as f64 / m,
    );
    println!(
        "{:<18} whole blocks, spots of at least {CENTROID_MIN_PIXELS} px: nearest spot: {}; nearest of the spots merged within {CENTROID_MERGE} px: {}",
        "",
        summary(&whole),
        summary(&whole_merged),
    );
    println!(
        "{:<18} whole blocks, spots of at least {CENTROID_SMALL} px: nearest spot: {}; nearest of the spots merged within {CENTROID_MERGE} px: {}",
        "",
        summary(&whole_small),
        summary(&whole_small_merged),
    );
    println!(
        "{:<18} split blocks, each piece against the nearest spot: {} pieces, {}; blocks with every piece within ±1 px: {} of {}",
        "",
        piece_errors.len(),
        summary(&piece_errors),
        within(&split_worst),
        split_worst.len(),
    );
    println!(
        "{:<18} all {} blocks, whole ones by spots of at least {CENTROID_SMALL} px merged within {CENTROID_MERGE} px and split ones by their worst piece: {:.2}% within ±1 camera px (the whole-block measure above: {:.2}%)",
        "",
        errors.len(),
        100.0 * (within(&whole_small_merged) + within(&split_worst)) as f64 / m,
        100.0 * within(&errors) as f64 / m,
    );
    Ok(())
}

/// The share of `errors` within ±1 and ±2 camera pixels, their median and 99th percentile.
fn summary(errors: &[f64]) -> String {
    // No block: shares of 0.
    let m = errors.len().max(1) as f64;
    let share = |bar: f64| 100.0 * errors.iter().filter(|e| **e <= bar).count() as f64 / m;
    let mut sorted = errors.to_vec();
    sorted.sort_by(f64::total_cmp);
    format!(
        "{:.2}% within ±1 camera px, {:.2}% within ±2, median {:.2} px, 99th percentile {:.2} px",
        share(1.0),
        share(2.0),
        sorted.get(sorted.len() / 2).copied().unwrap_or(0.0),
        sorted.get(sorted.len() * 99 / 100).copied().unwrap_or(0.0),
    )
}

/// A spot's floor, as a share of the brightest light in the capture (its 99.9th percentile).
const CENTROID_FLOOR: f32 = 0.05;

/// The window (camera pixels each way) whose brightest light sets a pixel's floor. Measured
/// on the lab (2026-11-28, 01:45-01:58 UTC; share 0.2, 8σ unless said): ±1 px on 82.16% of the
/// blocks at 8, 81.93% at 12 and 15, 80.14% at 20, 75.98% at 30, 73.96% at 45; 83.35% at 12
/// with a share of 0.1 and 6σ. A wider window lets an in-focus block on the desk raise the
/// floor over a defocused one on the floor beside it.
const CENTROID_WINDOW: usize = 12;
/// A pixel's floor as a share of the brightest light in its window (0.35: 74.08%, 0.2: 75.98%,
/// 0.1: 76.22% at a window of 30).
const CENTROID_SHARE: f32 = 0.1;
/// The least floor, in standard deviations of the capture's noise.
const CENTROID_NOISE: f32 = 6.0;

/// Distance from `point` to the nearest spot's centroid (infinite when there is none).
fn nearest_to(spots: &[Spot], point: [f64; 2]) -> f64 {
    spots
        .iter()
        .map(|s| ((s.centroid[0] - point[0]).powi(2) + (s.centroid[1] - point[1]).powi(2)).sqrt())
        .fold(f64::INFINITY, f64::min)
}

/// Spots closer than this (camera pixels, centroid to centroid) are merged into one: more than
/// a footprint's pieces lie apart, less than footprints shown together do.
const CENTROID_MERGE: f64 = 16.0;
/// Fewest camera pixels of a spot in the measure that merges spots (an in-focus block's spot
/// above its floor can be smaller than `CENTROID_MIN_PIXELS`).
const CENTROID_SMALL: usize = 4;
/// Fewest camera pixels of a piece of a block's sharp image for the piece to count.
const CENTROID_PIECE: usize = 8;
/// Neighbouring camera pixels whose depths from the projector differ by more than this share lie
/// on different surfaces.
const DEPTH_JUMP: f32 = 0.03;

/// For every block (row-major over the projector, `CENTROID_BLOCK` pixels), the pieces of its
/// sharp image in the camera: the camera pixels that `truth` maps into the block, grouped into
/// 8-connected sets whose neighbours differ in depth from projector `k` by at most
/// `DEPTH_JUMP`; each piece as its mean centre and its pixels, largest first.
fn pieces(room: &Room, k: usize, truth: &[Option<u32>]) -> Vec<Vec<([f64; 2], usize)>> {
    let p = &room.projectors()[k].pinhole;
    let cw = room.camera().width as usize;
    let ch = truth.len() / cw.max(1);
    let bw = p.width.div_ceil(CENTROID_BLOCK);
    let bh = p.height.div_ceil(CENTROID_BLOCK);
    let (o, f) = (p.position.to_array(), p.forward.to_array());
    let block = |i: usize| {
        truth[i].map(|t| (t / p.width / CENTROID_BLOCK) * bw + (t % p.width) / CENTROID_BLOCK)
    };
    let depth: Vec<f32> = room
        .pixels()
        .iter()
        .map(|info| {
            info.point
                .map_or(0.0, |q| (0..3).map(|a| (q[a] - o[a]) * f[a]).sum::<f32>())
        })
        .collect();
    let mut out = vec![Vec::new(); (bw * bh) as usize];
    let mut seen = vec![false; truth.len()];
    let mut stack = Vec::new();
    for start in 0..truth.len() {
        let Some(b) = block(start) else { continue };
        if seen[start] {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let (mut sx, mut sy, mut n) = (0.0f64, 0.0f64, 0usize);
        while let Some(i) = stack.pop() {
            let (x, y) = (i % cw, i / cw);
            sx += x as f64 + 0.5;
            sy += y as f64 + 0.5;
            n += 1;
            for ny in y.saturating_sub(1)..(y + 2).min(ch) {
                for nx in x.saturating_sub(1)..(x + 2).min(cw) {
                    let j = ny * cw + nx;
                    if !seen[j]
                        && block(j) == Some(b)
                        && (depth[j] - depth[i]).abs() <= DEPTH_JUMP * depth[i].abs()
                    {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        out[b as usize].push(([sx / n as f64, sy / n as f64], n));
    }
    for v in &mut out {
        v.sort_by_key(|p| std::cmp::Reverse(p.1));
    }
    out
}
