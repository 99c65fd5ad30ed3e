//! `roomlight bench calib`: structured light on the simulated lab, measured against the
//! simulator's true correspondence, and the cost of decoding. Timings are printed, not asserted.
//! Structured light runs through the one calibration procedure ([`roomlight_calib::procedure`])
//! on the simulated room as a rig; this module only measures what it decoded.

mod area;
mod bringup;
mod partition;

use crate::pipeline::{self, SimRig};
use anyhow::{Context, Result};
use roomlight_calib::charts::{ChartCorners, PatchStatus, sample_charts};
use roomlight_calib::graycode::{Correspondence, DecodeConfig, Manifest, decode};
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::nodes::{NodeConfig, Segmentation, segment};
use roomlight_calib::procedure::{
    Decoded, Event, Procedure, Settings, Stage, coding, coding_groups,
};
use roomlight_calib::rig::{Rig, block_on};
use roomlight_sim::scene::{ProjectorKind, ProjectorRole};
use roomlight_sim::{CameraNoise, Capture, Frame, ProjectorImage, Room, scenes};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

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

/// Accuracy of one decoded projector coded over cells with `tolerance`
/// (`Manifest::tolerance`: 1 for cells of one): (camera pixels it reaches, share within
/// ±tolerance, share of the decoded pixels off by more than tolerance + 1).
fn accuracy(
    truth: &[Option<u32>],
    decoded: &Correspondence,
    (width, tolerance): (u32, u32),
) -> (usize, f64, f64) {
    accuracy_where(truth, decoded, (width, tolerance), |_| true)
}

/// [`accuracy`] over the pixels that `count` accepts (reached ones for the share within
/// ±tolerance, decoded ones for the share off by more than tolerance + 1).
fn accuracy_where(
    truth: &[Option<u32>],
    decoded: &Correspondence,
    (width, tolerance): (u32, u32),
    count: impl Fn(usize) -> bool,
) -> (usize, f64, f64) {
    let tolerance = i64::from(tolerance);
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
            close += usize::from(d.is_some_and(|d| off(*t, d) <= tolerance));
        }
        if let Some(d) = d
            && count(i)
        {
            n += 1;
            far += usize::from(t.is_none_or(|t| off(t, *d) > tolerance + 1));
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

/// The small room with a 640×480 camera (`quick`) or the lab.
fn scene(quick: bool) -> Result<roomlight_sim::Scene> {
    Ok(if quick {
        // The small room's own camera (256×192) sees a chart patch as a few pixels: too few to
        // sample. The quick bench uses the same 640×480 camera as `bench room --quick`.
        let mut small = scenes::small()?;
        small.camera.resolution = [640, 480];
        small
    } else {
        scenes::lab()?
    })
}

/// The calibration bench on the lab (or the small room, `quick`); `area_only`: only the large
/// aperture's light-weighted centroids; `primaries`: up to three groups coded at once in
/// their primaries ([`Settings::primaries`], the default), else one at a time in white.
pub fn run(quick: bool, area_only: bool, primaries: bool) -> Result<()> {
    let settings = Settings {
        primaries,
        ..Settings::default()
    };
    let t0 = Instant::now();
    let room = Room::build(scene(quick)?).context("building the room")?;
    println!(
        "{}: room built in {:.1} s",
        room.scene().name,
        t0.elapsed().as_secs_f64()
    );
    if area_only {
        for k in 0..room.projectors().len() {
            if room.projectors()[k].kind == ProjectorKind::LargeAperture {
                area::centroids(&room, k)?;
            }
        }
        return Ok(());
    }
    if std::env::var_os("ROOMLIGHT_JOIN_ONLY").is_some() {
        return bringup::hot_join(&room, settings);
    }
    bringup::cold_start(&room, settings)?;
    bringup::hot_join(&room, settings)?;
    let (decoded_all, decode_secs) = structured_light(&room, settings)?;
    for k in 0..room.projectors().len() {
        if room.projectors()[k].kind == ProjectorKind::LargeAperture {
            area::centroids(&room, k)?;
        }
    }
    let charts = pipeline::chart_corners(&room)?;
    chart_sampling(&room, &charts)?;
    let n = room.projectors().len();
    let luminaires: Vec<usize> = (0..n)
        .filter(|&k| {
            room.scene().projectors[k].role == ProjectorRole::Luminaire
                && room.projectors()[k].kind == ProjectorKind::Standard
                && decoded_all[k].is_some()
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
    partition::report(&room, &luminaires, &corr, &seg, &charts, &mask);
    target_light(&room, &luminaires, &seg)?;
    let mut d = decode_secs;
    d.sort_by(f64::total_cmp);
    println!(
        "decode per projector: median {:.2} s",
        d.get(d.len() / 2).copied().unwrap_or(0.0)
    );
    decode_speed()
}

/// The charts sampled under the first LED preset: which patches are usable, and how long
/// sampling takes.
fn chart_sampling(room: &Room, charts: &[ChartCorners]) -> Result<()> {
    let preset = room
        .scene()
        .presets
        .first()
        .map(|p| room.preset(&p.name))
        .transpose()?;
    let lit = shoot_preset(room, preset)?;
    let t = Instant::now();
    let samples = sample_charts(&lit, charts, &pipeline::sample_config(room))?;
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
    Ok(())
}

/// Luminaire light on the target against a patch on the desk beside it, every standard
/// luminaire's nodes at full white.
fn target_light(room: &Room, luminaires: &[usize], seg: &Segmentation) -> Result<()> {
    let Some(desk) = room.scene().charts.iter().position(|c| c.name == "desk") else {
        return Ok(());
    };
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
    Ok(())
}

/// Decode speed at the reference size: a 1920×1080 projector from 1280×960 captures.
fn decode_speed() -> Result<()> {
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
    let decoded = decode(&big, &DecodeConfig::default(), |f| {
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

/// Every projector's structured light through the one calibration procedure on the simulated
/// room (its footprints, the groups coded together, then each member of a shared group alone
/// for comparison, then the second passes), measured against the simulator's truth. Returns
/// each projector's final correspondence and the decode time per projector.
fn structured_light(
    room: &Room,
    settings: Settings,
) -> Result<(Vec<Option<Correspondence>>, Vec<f64>)> {
    let mut noise = CameraNoise::new(room);
    let mut rig = SimRig::new(room, &mut noise);
    let events: Arc<Mutex<Vec<(Instant, Event)>>> = Arc::default();
    let sink = events.clone();
    let mut procedure = Procedure::new(&mut rig, settings, move |e| {
        sink.lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push((Instant::now(), e));
    });
    let live = procedure.rig().projectors();
    let n = live.len();
    // Footprints: one black capture and one white per projector (N + 1 captures; in a
    // calibration they are the ends of the response ramps too).
    let dark = block_on(procedure.dark(&live))?;
    let whites = block_on(procedure.whites(&live))?;
    let groups = coding_groups(&live, &dark, &whites, procedure.settings());
    let before = procedure.captures();
    let mut decoded = block_on(procedure.code(&live, &dark, &whites, None))?;
    let grouped = procedure.captures();
    let alone: usize = decoded.iter().map(|d| d.manifest.patterns.len()).sum();
    let full: usize = live
        .iter()
        .map(|p| Manifest::with_coding(p.width, p.height, coding(p)).map(|m| m.patterns.len()))
        .sum::<Result<_, _>>()?;
    println!(
        "structured light: {alone} captures one projector at a time with its own white and black ({full} with every projector coded at full resolution); {} with non-overlapping projectors coded together, white and black being the footprint captures ({} groups: {:?}), after {before} footprint captures",
        grouped - before,
        groups.len(),
        groups
            .iter()
            .map(|g| g.iter().map(|&k| live[k].id.as_str()).collect::<Vec<_>>())
            .collect::<Vec<_>>(),
    );
    let primaries = events
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .iter()
        .find_map(|(_, e)| match e {
            Event::Primaries { sets } => Some(sets.clone()),
            _ => None,
        });
    if let Some(sets) = primaries {
        println!(
            "  the groups coded in their primaries, up to three at once (each set after a capture of each group at its primary's white): {}",
            sets.iter()
                .map(|set| {
                    let groups: Vec<String> = set
                        .iter()
                        .map(|(primary, ids)| format!("{primary:?} {}", ids.join("+")))
                        .collect();
                    format!("[{}]", groups.join(", "))
                })
                .collect::<Vec<_>>()
                .join(" ")
        );
    }
    println!(
        "code cells (projector pixels a side; \"cell ±1\": placed in the true cell or one beside it, within 2·cell − 1 pixels, ±1 for cells of one; \"beyond\": a pixel further): {}",
        decoded
            .iter()
            .map(|d| format!("{} {}", d.projector.id, d.manifest.cell))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!(
        "{:<18} {:>9} {:>10} {:>10} {:>9} {:>9}   within ±1 where its direct light is ≥ 2% of its typical",
        "projector", "reached", "within ±1", "cell ±1", "beyond", "decoded",
    );
    for d in &decoded {
        report(
            room,
            &d.projector.id,
            &d.corr,
            false,
            d.manifest.tolerance(),
        )?;
    }
    // Each member of a shared group alone (as over the wire before): what coding at the same
    // time costs in accuracy.
    for &k in groups.iter().filter(|g| g.len() > 1).flatten() {
        let one = block_on(procedure.code(
            std::slice::from_ref(&live[k]),
            &dark,
            std::slice::from_ref(&whites[k]),
            None,
        ))?;
        for d in &one {
            report(room, &d.projector.id, &d.corr, true, d.manifest.tolerance())?;
        }
    }
    let decode_secs = decode_times(&events.lock().unwrap_or_else(PoisonError::into_inner));
    // Second pass (one projector at a time) where the first left enough reached pixels unknown.
    let mut second_captures = 0usize;
    for d in &mut decoded {
        if d.projector.kind != roomlight_calib::rig::ProjectorKind::Standard {
            continue;
        }
        second_captures += second_pass(room, &mut procedure, d)?;
    }
    println!(
        "second pass: {second_captures} more captures ({} in all one projector at a time)",
        alone + second_captures
    );
    let mut all = vec![None; n];
    for (k, d) in decoded.into_iter().enumerate() {
        all[k] = Some(d.corr);
    }
    Ok((all, decode_secs))
}

/// Seconds from each group's last structured-light capture to its members' decodes, shared
/// among them: the decode time per projector.
fn decode_times(events: &[(Instant, Event)]) -> Vec<f64> {
    let mut out = Vec::new();
    let mut last_capture = None;
    let mut pending: Vec<Instant> = Vec::new();
    for (at, e) in events {
        match e {
            Event::Captured {
                stage: Stage::StructuredLight,
            } => {
                if let (Some(start), false) = (last_capture, pending.is_empty()) {
                    flush(&mut out, start, &mut pending);
                }
                last_capture = Some(*at);
            }
            Event::Decoded { .. } => pending.push(*at),
            _ => {}
        }
    }
    if let Some(start) = last_capture {
        flush(&mut out, start, &mut pending);
    }
    out
}

fn flush(out: &mut Vec<f64>, start: Instant, pending: &mut Vec<Instant>) {
    if let Some(end) = pending.last() {
        let each = end.duration_since(start).as_secs_f64() / pending.len() as f64;
        out.extend(std::iter::repeat_n(each, pending.len()));
    }
    pending.clear();
}

/// One projector's accuracy line (and, with `ROOMLIGHT_DIAG` set, its diagnostic image).
fn report(
    room: &Room,
    id: &str,
    decoded: &Correspondence,
    alone: bool,
    tolerance: u32,
) -> Result<()> {
    let k = room.projector(id)?;
    let truth = room.true_correspondence(k);
    let width = room.projectors()[k].pinhole.width;
    let (reached, close, _) = accuracy(&truth, decoded, (width, 1));
    let (_, in_cell, far) = accuracy(&truth, decoded, (width, tolerance));
    // Of the decoded pixels off by more than 2, the share the simulator says this projector
    // does not reach directly at all (a defocused projector's blur reaches beyond its pinhole
    // footprint).
    let decoded_n = decoded.map.iter().filter(|d| d.is_some()).count();
    let outside = truth
        .iter()
        .zip(&decoded.map)
        .filter(|(t, d)| t.is_none() && d.is_some())
        .count() as f64
        / decoded_n.max(1) as f64;
    // The same, leaving out pixels where the projector's direct signal (light × albedo:
    // grazing surfaces, black chart frames) is under 2% of its typical (99th percentile)
    // level: there the direct light cannot be told from noise and global light, and unknown is
    // the right answer.
    let (factor, typical) = direct_signal(room, k);
    let (reached_lit, close_lit, _) =
        accuracy_where(&truth, decoded, (width, 1), |i| factor[i] >= 0.02 * typical);
    if let Some(dir) = std::env::var_os("ROOMLIGHT_DIAG") {
        diagnose(room, k, &truth, decoded, std::path::Path::new(&dir))?;
    }
    let p = &room.projectors()[k];
    let kind = if p.kind == ProjectorKind::LargeAperture {
        " (large aperture: defocused)"
    } else {
        ""
    };
    println!(
        "{:<18} {:>9} {:>9.2}% {:>9.2}% {:>8.3}% {:>8.1}% {:>12.2}% of {:>7}{kind}",
        if alone {
            format!("{} alone", p.name)
        } else {
            p.name.clone()
        },
        reached,
        100.0 * close,
        100.0 * in_cell,
        100.0 * far,
        100.0 * decoded.decoded_share(),
        100.0 * close_lit,
        reached_lit
    );
    if p.kind == ProjectorKind::LargeAperture {
        let focus = in_focus(room, k);
        let (sharp, close_sharp, far_sharp) =
            accuracy_where(&truth, decoded, (width, 1), |i| focus[i]);
        println!(
            "{:<18} in focus (its blur within ±1 projector pixel): {sharp} camera pixels ({:.1}% of those it reaches), {:.2}% within ±1, {:.3}% of those decoded off by more than 2",
            "",
            100.0 * sharp as f64 / reached.max(1) as f64,
            100.0 * close_sharp,
            100.0 * far_sharp
        );
    }
    if far > 0.0 {
        println!(
            "{:<18} of the decoded pixels, {:.3}% lie where the simulator has no direct correspondence for it",
            "",
            100.0 * outside
        );
    }
    Ok(())
}

/// Per camera pixel, whether large aperture `k` is in focus there: the display pixels its
/// lens samples send to the surface point the pixel sees (the ray from each lens point through
/// the point came from the display pixel imaged where that ray meets the focus plane, as the
/// simulator renders it) all lie within ±1 of the lens centre's. False where the projector does
/// not reach the pixel's point through its lens centre (visibility is the true
/// correspondence's).
fn in_focus(room: &Room, k: usize) -> Vec<bool> {
    let p = &room.projectors()[k];
    let truth = room.true_correspondence(k);
    let w = p.pinhole.width;
    room.pixels()
        .iter()
        .zip(&truth)
        .map(|(info, t)| {
            let (Some(point), Some(t), Some(focus)) = (info.point, t, p.focus) else {
                return false;
            };
            let point = roomlight_sim::geometry::V3::from_array(point);
            let depth = (point - p.pinhole.position).dot(p.pinhole.forward);
            // Behind the lens (the true correspondence has none there).
            if depth <= 1e-6 {
                return false;
            }
            p.lens.iter().all(|&l| {
                let image = l + (point - l) * (focus / depth);
                p.pinhole
                    .project(image)
                    .and_then(|uv| p.pinhole.pixel(uv))
                    .is_some_and(|px| {
                        let dx = i64::from(px % w) - i64::from(t % w);
                        let dy = i64::from(px / w) - i64::from(t / w);
                        dx.abs().max(dy.abs()) <= 1
                    })
            })
        })
        .collect()
}

/// A diagnostic image of one decode (red: reached but unknown, green: decoded, blue: decoded
/// where the projector does not reach) and where the unknown pixels' light comes from.
fn diagnose(
    room: &Room,
    k: usize,
    truth: &[Option<u32>],
    decoded: &Correspondence,
    dir: &std::path::Path,
) -> Result<()> {
    std::fs::create_dir_all(dir)?;
    let data: Vec<u8> = (0..truth.len())
        .flat_map(|i| match (truth[i], decoded.map[i]) {
            (Some(_), None) => [255u8, 0, 0],
            (Some(_), Some(_)) => [0, 160, 0],
            (None, Some(_)) => [0, 0, 255],
            (None, None) => [(decoded.global[i] * 100.0).min(255.0) as u8; 3],
        })
        .collect();
    if let Some(img) = image::RgbImage::from_raw(decoded.width, decoded.height, data) {
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
    Ok(())
}

/// The procedure's second pass on one standard projector, reported against the truth;
/// returns the captures it took.
fn second_pass(
    room: &Room,
    procedure: &mut Procedure<'_, SimRig<'_>>,
    d: &mut Decoded,
) -> Result<usize> {
    let config = procedure.settings().decode;
    let name = d.projector.id.clone();
    let (first, m) = (&mut d.corr, &d.manifest);
    let left = first
        .reached_unknown(&config)
        .iter()
        .filter(|u| **u)
        .count();
    let decoded_before = first.map.iter().filter(|d| d.is_some()).count();
    let t = Instant::now();
    let Some(done) = block_on(procedure.second_pass(&d.projector, m, first, None))? else {
        println!(
            "{name:<18} second pass: not needed ({left} reached pixels unknown, {:.2}% of {decoded_before} decoded)",
            100.0 * left as f64 / decoded_before.max(1) as f64
        );
        return Ok(0);
    };
    let k = room.projector(&name)?;
    let truth = room.true_correspondence(k);
    let (reached, close, _) = accuracy(&truth, first, (m.width, 1));
    let (_, in_cell, far) = accuracy(&truth, first, (m.width, m.tolerance()));
    // How much direct light the pixels still unknown get.
    let (factor, typical) = direct_signal(room, k);
    let mut missed: Vec<f32> = (0..truth.len())
        .filter(|&i| truth[i].is_some() && first.map[i].is_none())
        .map(|i| factor[i] / typical.max(f32::MIN_POSITIVE))
        .collect();
    missed.sort_by(f32::total_cmp);
    let under = |share: f32| missed.iter().filter(|m| **m < share).count();
    println!(
        "{:<18} {:>9} {:>9.2}% {:>9.2}% {:>8.3}% {:>8.1}%   second pass: {left} reached pixels unknown ({:.2}% of {decoded_before}), {:.1}% of the frame shown, exposure ×{:.1}, {} captures, {} pixels added, {:.2} s with rendering",
        format!("{name} +2nd"),
        reached,
        100.0 * close,
        100.0 * in_cell,
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
    Ok(done.captures)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `in_focus` against the thin lens worked out from the scene's description alone: a lens
    /// point `r` from the centre sends a point at depth `z` to a display pixel
    /// `r·|1 − f/z|·focal/f` pixels from the centre's, `f` the focus distance. Where that is at
    /// most one pixel for the lens's rim the point is in focus; where it is three or more, not.
    #[test]
    fn in_focus_is_where_the_thin_lens_blur_is_under_a_pixel() {
        let room = Room::build(scenes::small().expect("small room")).expect("room");
        let k = room
            .projectors()
            .iter()
            .position(|p| p.kind == ProjectorKind::LargeAperture)
            .expect("a large aperture");
        let spec = &room.scene().projectors[k];
        let v =
            |a: [f64; 3]| roomlight_sim::geometry::V3::from_array(a.map(|x| (x / 1000.0) as f32));
        let (position, look_at) = (v(spec.position_mm), v(spec.look_at_mm));
        let axis = (look_at - position).normalize();
        let focal = 0.5 * f64::from(spec.resolution[0]) / (spec.fov_deg.to_radians() * 0.5).tan();
        let rim = spec.aperture_mm.expect("aperture") / 2000.0;
        let f = spec.focus_mm.expect("focus") / 1000.0;
        let focus = in_focus(&room, k);
        let truth = room.true_correspondence(k);
        let (mut sharp, mut blurred, mut wrong) = (0usize, 0usize, 0usize);
        for ((info, t), inside) in room.pixels().iter().zip(&truth).zip(&focus) {
            let (Some(point), Some(_)) = (info.point, t) else {
                assert!(!inside, "in focus where the projector does not reach");
                continue;
            };
            let z =
                f64::from((roomlight_sim::geometry::V3::from_array(point) - position).dot(axis));
            let blur = rim * (1.0 - f / z).abs() * focal / f;
            if blur <= 1.0 {
                sharp += 1;
                wrong += usize::from(!inside);
            } else if blur >= 3.0 {
                blurred += 1;
                wrong += usize::from(*inside);
            }
        }
        println!("{sharp} pixels sharp, {blurred} blurred by the thin lens, {wrong} disagree");
        assert!(
            sharp > 100 && blurred > 100,
            "{sharp} sharp, {blurred} blurred"
        );
        assert_eq!(wrong, 0);
    }
}
