//! `roomlight bench calib`: structured light on the simulated lab, measured against the
//! simulator's true correspondence, and the cost of decoding. Timings are printed, not asserted.

use anyhow::{Context, Result};
use roomlight_calib::charts::{PatchStatus, sample_charts};
use roomlight_calib::graycode::{
    Coding, Correspondence, DecodeConfig, Manifest, SECOND_PASS_LONGEST, decode, decode_where,
    group_disjoint, second_pass,
};
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::nodes::{
    NodeConfig, add_claim, partition_of_unity, projector_weights, segment, segment_beside,
};
use roomlight_sim::scene::{ProjectorKind, ProjectorRole};
use roomlight_sim::{CameraNoise, Capture, Frame, ProjectorImage, Room, scenes};
use std::time::Instant;

/// A camera pixel belongs to a projector's footprint when that projector at white raises it by
/// this share of its brightest pixel. Inter-reflected light stays below it in the lab.
const FOOTPRINT_SHARE: f32 = 0.1;
/// The same for a defocused projector: its blur's tail carries plain Gray code's coarse stripes
/// (which inter-reflection does not average away) well below a tenth of its peak. At 0.1 the
/// lab grouped floor-right with the large aperture, and 0.32% of floor-right's decoded pixels
/// came out off by more than 2 (none coded alone).
const FOOTPRINT_SHARE_DEFOCUSED: f32 = 0.01;

fn shoot_preset(room: &Room, preset: Option<usize>) -> Result<LinearImage> {
    let frames = vec![Frame::Black; room.projectors().len()];
    Ok(image(
        &CameraNoise::with_seed(room, 99).expose(&room.render(&frames, preset)?),
    ))
}

fn image(c: &Capture) -> LinearImage {
    LinearImage {
        width: c.width,
        height: c.height,
        pixels: c.pixels.clone(),
    }
}

/// Accuracy of one decoded projector: (camera pixels it reaches, share within ±1, share of the
/// decoded pixels off by more than 2).
fn accuracy(truth: &[Option<u32>], decoded: &Correspondence, width: u32) -> (usize, f64, f64) {
    accuracy_where(truth, decoded, width, |_| true)
}

/// [`accuracy`] over the reached pixels that `count` accepts.
fn accuracy_where(
    truth: &[Option<u32>],
    decoded: &Correspondence,
    width: u32,
    count: impl Fn(usize) -> bool,
) -> (usize, f64, f64) {
    let off = |t: u32, (x, y): (u32, u32)| {
        (i64::from(x) - i64::from(t % width))
            .abs()
            .max((i64::from(y) - i64::from(t / width)).abs())
    };
    let (mut reached, mut close, mut n, mut far) = (0usize, 0usize, 0usize, 0usize);
    for (i, (t, d)) in truth.iter().zip(&decoded.map).enumerate() {
        if let Some(t) = t
            && count(i)
        {
            reached += 1;
            close += usize::from(d.is_some_and(|d| off(*t, d) <= 1));
        }
        if let Some(d) = d {
            n += 1;
            far += usize::from(t.is_none_or(|t| off(t, *d) > 2));
        }
    }
    (
        reached,
        close as f64 / reached.max(1) as f64,
        far as f64 / n.max(1) as f64,
    )
}

/// Projector `k`'s direct signal per camera pixel (its direct light at white × the albedo
/// there) and its typical level (99th percentile over the pixels it lights).
fn direct_signal(room: &Room, k: usize) -> (Vec<f32>, f32) {
    let factor: Vec<f32> = room
        .direct_factor(k)
        .iter()
        .zip(room.pixel_albedo())
        .map(|(f, a)| f * (a[0] + a[1] + a[2]) as f32 / 3.0)
        .collect();
    let mut lit: Vec<f32> = factor.iter().copied().filter(|f| *f > 0.0).collect();
    lit.sort_by(f32::total_cmp);
    let typical = lit.get(lit.len() * 99 / 100).copied().unwrap_or(0.0);
    (factor, typical)
}

pub fn run(quick: bool) -> Result<()> {
    let scene = if quick {
        // The small room's own camera (256×192) sees a chart patch as a few pixels: too few to
        // sample. The quick bench uses the same 640×480 camera as `bench room --quick`.
        let mut small = scenes::small()?;
        small.camera.resolution = [640, 480];
        small
    } else {
        scenes::lab()?
    };
    let t0 = Instant::now();
    let room = Room::build(scene).context("building the room")?;
    println!(
        "{}: room built in {:.1} s",
        room.scene().name,
        t0.elapsed().as_secs_f64()
    );
    let n = room.projectors().len();
    let mut noise = CameraNoise::new(&room);
    let mut shoot = |frames: &[Frame]| -> Result<LinearImage> {
        Ok(image(&noise.expose(&room.render(frames, None)?)))
    };
    // Footprints: one white capture per projector and one black (N + 1 captures).
    let black = shoot(&vec![Frame::Black; n])?.intensity();
    let mut footprints = Vec::with_capacity(n);
    let mut gains: Vec<Vec<f32>> = Vec::with_capacity(n);
    for k in 0..n {
        let share = if room.projectors()[k].kind == ProjectorKind::LargeAperture {
            FOOTPRINT_SHARE_DEFOCUSED
        } else {
            FOOTPRINT_SHARE
        };
        let mut frames = vec![Frame::Black; n];
        frames[k] = Frame::Uniform([1.0; 3]);
        let white = shoot(&frames)?.intensity();
        gains.push(white.iter().zip(&black).map(|(w, b)| w - b).collect());
        let peak = white
            .iter()
            .zip(&black)
            .map(|(w, b)| w - b)
            .fold(0.0f32, f32::max);
        footprints.push(
            white
                .iter()
                .zip(&black)
                .map(|(w, b)| w - b > share * peak)
                .collect::<Vec<bool>>(),
        );
    }
    let groups = group_disjoint(&footprints);
    // Defocused projectors blur the fine XOR stripes away: they get plain Gray code.
    let manifests: Vec<Manifest> = room
        .projectors()
        .iter()
        .map(|p| {
            let coding = if p.kind == ProjectorKind::LargeAperture {
                Coding::Gray
            } else {
                Coding::Xor04
            };
            Manifest::with_coding(p.pinhole.width, p.pinhole.height, coding)
        })
        .collect::<Result<_, _>>()?;
    let alone: usize = manifests.iter().map(|m| m.patterns.len()).sum();
    let grouped: usize = n
        + 1
        + groups
            .iter()
            .map(|g| {
                g.iter()
                    .map(|&k| manifests[k].patterns.len())
                    .max()
                    .unwrap_or(0)
            })
            .sum::<usize>();
    println!(
        "structured light: {alone} captures one projector at a time; {grouped} with simultaneous coding of non-overlapping projectors ({} groups: {:?}, including {} footprint captures)",
        groups.len(),
        groups
            .iter()
            .map(|g| g
                .iter()
                .map(|&k| room.projectors()[k].name.as_str())
                .collect::<Vec<_>>())
            .collect::<Vec<_>>(),
        n + 1
    );
    println!(
        "{:<18} {:>9} {:>12} {:>14} {:>10}   within ±1 where its direct light is ≥ 2% of its typical",
        "projector", "reached", "within ±1", "off by > 2", "decoded",
    );
    let config = DecodeConfig::default();
    let mut decode_secs = Vec::new();
    let mut decoded_all: Vec<Option<Correspondence>> = vec![None; n];

    // Every group, then each member of a shared group alone (as `roomlight calibrate` codes
    // them): what coding at the same time costs in accuracy.
    let alone_runs: Vec<Vec<usize>> = groups
        .iter()
        .filter(|g| g.len() > 1)
        .flatten()
        .map(|&k| vec![k])
        .collect();
    for (run, group) in groups.iter().chain(&alone_runs).enumerate() {
        let alone = run >= groups.len();
        let longest = group
            .iter()
            .map(|&k| manifests[k].patterns.len())
            .max()
            .unwrap_or(0);
        // Slot j of the group: every member shows its own pattern j (black once it has no more).
        let mut captures = Vec::with_capacity(longest);
        for j in 0..longest {
            let frames: Vec<Frame> = (0..n)
                .map(
                    |k| match (group.contains(&k), manifests[k].patterns.get(j)) {
                        (true, Some(p)) => {
                            let img = manifests[k].pattern_image(p.pattern);
                            Frame::Image(ProjectorImage {
                                width: img.width,
                                height: img.height,
                                pixels: img.pixels,
                            })
                        }
                        _ => Frame::Black,
                    },
                )
                .collect();
            captures.push(shoot(&frames)?);
        }
        for &k in group {
            let m = &manifests[k];
            // In a group, a pixel belongs to the member whose white light raises it most.
            let ours: Option<Vec<bool>> = (group.len() > 1).then(|| {
                (0..gains[k].len())
                    .map(|i| !group.iter().any(|&o| o != k && gains[o][i] > gains[k][i]))
                    .collect()
            });
            let t = Instant::now();
            let cfg = if room.projectors()[k].kind == ProjectorKind::LargeAperture {
                DecodeConfig::strict()
            } else {
                config
            };
            let decoded = decode_where(m, &cfg, ours.as_deref(), |f| {
                let j = m
                    .patterns
                    .iter()
                    .position(|p| p.file == f.file)
                    .unwrap_or(0);
                Ok(&captures[j])
            })?;
            decode_secs.push(t.elapsed().as_secs_f64());
            let truth = room.true_correspondence(k);
            let (reached, close, far) = accuracy(&truth, &decoded, m.width);
            // Of the decoded pixels off by more than 2, the share the simulator says this
            // projector does not reach directly at all (a defocused projector's blur reaches
            // beyond its pinhole footprint).
            let decoded_n = decoded.map.iter().filter(|d| d.is_some()).count();
            let outside = truth
                .iter()
                .zip(&decoded.map)
                .filter(|(t, d)| t.is_none() && d.is_some())
                .count() as f64
                / decoded_n.max(1) as f64;
            // The same, leaving out pixels where the projector's direct signal (light × albedo:
            // grazing surfaces, black chart frames) is under 2% of its typical (99th percentile)
            // level: there the direct light cannot be told from noise and global light, and
            // unknown is the right answer.
            let (factor, typical) = direct_signal(&room, k);
            let (reached_lit, close_lit, _) =
                accuracy_where(&truth, &decoded, m.width, |i| factor[i] >= 0.02 * typical);
            if let Some(dir) = std::env::var_os("ROOMLIGHT_DIAG") {
                let dir = std::path::PathBuf::from(dir);
                std::fs::create_dir_all(&dir)?;
                let w = decoded.width;
                let data: Vec<u8> = (0..truth.len())
                    .flat_map(|i| match (truth[i], decoded.map[i]) {
                        (Some(_), None) => [255u8, 0, 0],
                        (Some(_), Some(_)) => [0, 160, 0],
                        (None, Some(_)) => [0, 0, 255],
                        (None, None) => [(decoded.global[i] * 100.0).min(255.0) as u8; 3],
                    })
                    .collect();
                if let Some(img) = image::RgbImage::from_raw(w, decoded.height, data) {
                    img.save(dir.join(format!("decode-{}.png", room.projectors()[k].name)))?;
                }
                let unknown: Vec<usize> = (0..truth.len())
                    .filter(|&i| truth[i].is_some() && decoded.map[i].is_none())
                    .collect();
                let global_dominates = unknown
                    .iter()
                    .filter(|&&i| decoded.direct[i] < decoded.global[i])
                    .count();
                let mut ld: Vec<f32> = unknown.iter().map(|&i| decoded.direct[i]).collect();
                ld.sort_by(f32::total_cmp);
                let mut ok: Vec<f32> = (0..truth.len())
                    .filter(|&i| decoded.map[i].is_some())
                    .map(|i| decoded.direct[i])
                    .collect();
                ok.sort_by(f32::total_cmp);
                println!(
                    "  unknown {} ({} with Lg > Ld), median Ld unknown {:.4}, median Ld decoded {:.4}",
                    unknown.len(),
                    global_dominates,
                    ld.get(ld.len() / 2).copied().unwrap_or(0.0),
                    ok.get(ok.len() / 2).copied().unwrap_or(0.0)
                );
            }
            let p = &room.projectors()[k];
            let kind = if p.kind == ProjectorKind::LargeAperture {
                " (large aperture: defocused)"
            } else {
                ""
            };
            println!(
                "{:<18} {:>9} {:>11.2}% {:>13.3}% {:>9.1}% {:>12.2}% of {:>7}{kind}",
                if alone {
                    format!("{} alone", p.name)
                } else {
                    p.name.clone()
                },
                reached,
                100.0 * close,
                100.0 * far,
                100.0 * decoded.decoded_share(),
                100.0 * close_lit,
                reached_lit
            );
            if far > 0.0 {
                println!(
                    "{:<18} of the decoded pixels, {:.3}% lie where the simulator has no direct correspondence for it",
                    "",
                    100.0 * outside
                );
            }
            decoded_all[k] = Some(decoded);
        }
    }
    // Second pass (one projector at a time, as `roomlight calibrate` does) where the first
    // left enough reached pixels unknown.
    let mut second_captures = 0usize;
    let saturation = room.scene().camera.saturation as f32;
    for k in 0..n {
        if room.projectors()[k].kind != ProjectorKind::Standard {
            continue;
        }
        let Some(first) = decoded_all[k].as_mut() else {
            continue;
        };
        let m = &manifests[k];
        let name = &room.projectors()[k].name;
        let left = first
            .reached_unknown(&config)
            .iter()
            .filter(|u| **u)
            .count();
        let decoded_before = first.map.iter().filter(|d| d.is_some()).count();
        let t = Instant::now();
        let done = second_pass(
            m,
            &config,
            first,
            saturation,
            SECOND_PASS_LONGEST,
            |img, exposure| -> Result<LinearImage> {
                let mut frames = vec![Frame::Black; n];
                frames[k] = Frame::Image(ProjectorImage {
                    width: img.width,
                    height: img.height,
                    pixels: img.pixels.clone(),
                });
                Ok(image(&noise.expose_longer(
                    &room.render(&frames, None)?,
                    f64::from(exposure),
                )))
            },
        )?;
        let Some(done) = done else {
            println!(
                "{name:<18} second pass: not needed ({left} reached pixels unknown, {:.2}% of {decoded_before} decoded)",
                100.0 * left as f64 / decoded_before.max(1) as f64
            );
            continue;
        };
        second_captures += done.captures;
        let truth = room.true_correspondence(k);
        let (reached, close, far) = accuracy(&truth, first, m.width);
        // How much direct light the pixels still unknown get.
        let (factor, typical) = direct_signal(&room, k);
        let mut missed: Vec<f32> = (0..truth.len())
            .filter(|&i| truth[i].is_some() && first.map[i].is_none())
            .map(|i| factor[i] / typical.max(f32::MIN_POSITIVE))
            .collect();
        missed.sort_by(f32::total_cmp);
        let under = |share: f32| missed.iter().filter(|m| **m < share).count();
        println!(
            "{:<18} {:>9} {:>11.2}% {:>13.3}% {:>9.1}%   second pass: {left} reached pixels unknown ({:.2}% of {decoded_before}), {:.1}% of the frame shown, exposure ×{:.1}, {} captures, {} pixels added, {:.2} s with rendering",
            format!("{name} +2nd"),
            reached,
            100.0 * close,
            100.0 * far,
            100.0 * first.decoded_share(),
            100.0 * left as f64 / decoded_before.max(1) as f64,
            100.0 * done.shown,
            done.exposure,
            done.captures,
            done.taken,
            t.elapsed().as_secs_f64()
        );
        println!(
            "{:<18} still unknown: {} reached pixels; their direct light is a median {:.2}% of its typical, under 0.5% on {}, under 1% on {}, under 2% on {}",
            "",
            missed.len(),
            100.0 * missed.get(missed.len() / 2).copied().unwrap_or(0.0),
            under(0.005),
            under(0.01),
            under(0.02)
        );
    }
    println!(
        "second pass: {second_captures} more captures ({} in all one projector at a time)",
        alone + second_captures
    );
    // Charts and nodes on the same room.
    let charts = crate::pipeline::chart_corners(&room)?;
    let preset = room
        .scene()
        .presets
        .first()
        .map(|p| room.preset(&p.name))
        .transpose()?;
    let lit = shoot_preset(&room, preset)?;
    let t = Instant::now();
    let samples = sample_charts(&lit, &charts, &crate::pipeline::sample_config(&room))?;
    let elapsed = t.elapsed();
    let count = |status: PatchStatus| samples.iter().filter(|s| s.status == status).count();
    println!(
        "chart sampling: {} charts, {} of {} patches usable ({} saturated, {} out of the image, {} too small, {} crossed by an edge), {:.1} ms",
        charts.len(),
        count(PatchStatus::Ok),
        samples.len(),
        count(PatchStatus::Saturated),
        count(PatchStatus::OutOfImage),
        count(PatchStatus::TooFewPixels),
        count(PatchStatus::NonUniform),
        elapsed.as_secs_f64() * 1e3
    );
    let luminaires: Vec<usize> = (0..n)
        .filter(|&k| {
            room.scene().projectors[k].role == ProjectorRole::Luminaire
                && room.projectors()[k].kind == ProjectorKind::Standard
        })
        .collect();
    let corr: Vec<Correspondence> = luminaires
        .iter()
        .filter_map(|&k| decoded_all[k].clone())
        .collect();
    let mask: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let t = Instant::now();
    let seg = segment(&corr, &charts, Some(&mask), &NodeConfig::default())?;
    println!(
        "segmentation and feathering of {} standard luminaires: {} nodes in {:.2} s",
        corr.len(),
        seg.nodes.len(),
        t.elapsed().as_secs_f64()
    );
    // Partition of unity on the surface points, through the simulator's true correspondence,
    // away from the target (its margin is black): segmented together, and one after the other
    // as projectors joining a lit room over the wire are.
    let truth: Vec<Vec<Option<u32>>> = luminaires
        .iter()
        .filter(|&&k| decoded_all[k].is_some())
        .map(|&k| room.true_correspondence(k))
        .collect();
    let (cw, ch) = (room.camera().width as usize, room.camera().height as usize);
    let away = roomlight_calib::nodes::dilate(&mask, cw, ch, 8);
    let weights: Vec<Vec<f32>> = (0..corr.len())
        .map(|k| projector_weights(&seg.nodes, k))
        .collect();
    println!(
        "  partition of unity, segmented together: {}",
        partition_of_unity(&truth, &weights, &seg.excluded, &away)
    );
    let mut claimed = vec![0.0f32; cw * ch];
    let (mut weights, mut dark) = (Vec::new(), Vec::new());
    for c in &corr {
        let one = segment_beside(
            std::slice::from_ref(c),
            &charts,
            Some(&mask),
            &NodeConfig::default(),
            Some(&claimed),
        );
        // A projector that lights no chart alone: no nodes, no light.
        let Ok(one) = one else {
            weights.push(Vec::new());
            dark.push(Vec::new());
            continue;
        };
        add_claim(&mut claimed, &one.claims[0]);
        weights.push(projector_weights(&one.nodes, 0));
        dark.extend(one.excluded);
    }
    println!(
        "  partition of unity, one after the other: {}",
        partition_of_unity(&truth, &weights, &dark, &away)
    );
    // Luminaire light on the target against a patch on the desk beside it.
    let desk = room.scene().charts.iter().position(|c| c.name == "desk");
    if let Some(desk) = desk {
        let centre = room.geometry().charts[desk].center.to_array();
        let (mut on_target, mut on_desk) = (0.0, 0.0);
        for (slot, &k) in luminaires.iter().enumerate() {
            let p = &room.projectors()[k].pinhole;
            let mut pixels = vec![[0.0f32; 3]; (p.width * p.height) as usize];
            for node in seg.nodes.iter().filter(|nd| nd.projector == slot) {
                for (px, w) in pixels.iter_mut().zip(&node.weights) {
                    px.iter_mut().for_each(|c| *c += w);
                }
            }
            let frame = Frame::Linear(ProjectorImage {
                width: p.width,
                height: p.height,
                pixels,
            });
            on_target += room.target_irradiance(k, &frame)?[1];
            on_desk += room.direct_irradiance_at(k, &frame, centre, [0.0, 0.0, 1.0])?[1];
        }
        println!(
            "standard luminaires at full white: direct light on the target is {:.2}% of the desk chart's",
            100.0 * on_target / on_desk.max(1e-12)
        );
    }
    let mut d = decode_secs.clone();
    d.sort_by(f64::total_cmp);
    println!(
        "decode per projector: median {:.2} s",
        d.get(d.len() / 2).copied().unwrap_or(0.0)
    );
    // Decode speed at the reference size: a 1920×1080 projector from 1280×960 captures.
    let big = Manifest::new(1920, 1080)?;
    let caps: Vec<LinearImage> = big
        .patterns
        .iter()
        .map(|p| {
            let src = big.pattern_values(p.pattern);
            LinearImage {
                width: 1280,
                height: 960,
                pixels: (0..1280 * 960u32)
                    .map(|i| {
                        let (x, y) = (i % 1280 * 1920 / 1280, i / 1280 * 1080 / 960);
                        [0.05 + 0.8 * src[(y * 1920 + x) as usize]; 3]
                    })
                    .collect(),
            }
        })
        .collect();
    let t = Instant::now();
    let decoded = decode(&big, &config, |f| {
        Ok(&caps[big
            .patterns
            .iter()
            .position(|p| p.file == f.file)
            .unwrap_or(0)])
    })?;
    println!(
        "decode of a 1920x1080 pattern set ({} captures of 1280x960): {:.2} s, {:.1}% decoded",
        big.patterns.len(),
        t.elapsed().as_secs_f64(),
        100.0 * decoded.decoded_share()
    );
    Ok(())
}
