//! `roomlight bench sim`: what the simulated room costs. Timings are printed, never asserted.

use anyhow::{Context, Result};
use roomlight_sim::room::PngEncoding;
use roomlight_sim::{Frame, NodeBasis, NodeRegion, Room, Scene, scenes};
use std::path::Path;
use std::time::Instant;

fn median_ms(mut f: impl FnMut() -> Result<()>, runs: usize) -> Result<(f64, f64, f64)> {
    let mut t = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t0 = Instant::now();
        f()?;
        t.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    t.sort_by(f64::total_cmp);
    Ok((t[t.len() / 2], t[0], t[t.len() - 1]))
}

/// The room, its precomputation's seconds and how far the resident set's peak rose meanwhile
/// (MB, see `bench::memory`).
fn build(scene: Scene) -> Result<(Room, f64, Option<f64>)> {
    let t0 = Instant::now();
    let (room, mb) = super::memory::peak_growth(|| Room::build(scene));
    let room = room.context("building the room")?;
    Ok((room, t0.elapsed().as_secs_f64(), mb))
}

/// Four nodes per projector: its image split into quadrants.
fn quadrants(room: &Room) -> Vec<NodeRegion> {
    let mut nodes = Vec::new();
    for (k, p) in room.projectors().iter().enumerate() {
        let (w, h) = (p.pinhole.width, p.pinhole.height);
        for q in 0..4u32 {
            let weights = (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    f32::from(u8::from((x * 2 / w) + 2 * (y * 2 / h) == q))
                })
                .collect();
            nodes.push(NodeRegion {
                projector: k,
                weights,
            });
        }
    }
    nodes
}

/// Precomputation, capture times (uniform frames, full images, through a node basis), and with
/// `out` the LED presets and each projector alone as pictures.
pub fn run(quick: bool, out: Option<&Path>) -> Result<()> {
    let scene = if quick {
        scenes::small()?
    } else {
        scenes::lab()?
    };
    let name = scene.name.clone();
    let (room, secs, mb) = build(scene.clone())?;
    let (w, h) = (room.camera().width, room.camera().height);
    println!(
        "{name}: precomputation {secs:.2} s (geometry, {} radiosity elements, form factors, {w}x{h} camera pixels, 3 probe sets), peak resident growth {}",
        room.geometry().elements.len(),
        super::memory::mb(mb)
    );
    let n = room.projectors().len();
    let preset = room.scene().presets.first().map(|p| p.name.clone());
    let preset = preset.map(|p| room.preset(&p)).transpose()?;
    let white = vec![Frame::Uniform([1.0; 3]); n];
    let (med, lo, hi) = median_ms(
        || room.render(&white, preset).map(|_| ()).map_err(Into::into),
        7,
    )?;
    println!(
        "  capture {w}x{h} with inter-reflection (uniform frames, LEDs on): median {med:.1} ms (min {lo:.1}, max {hi:.1})"
    );
    let images = checker_frames(&room);
    let (med, lo, hi) = median_ms(
        || room.render(&images, preset).map(|_| ()).map_err(Into::into),
        7,
    )?;
    println!(
        "  capture {w}x{h} with every projector showing a full image: median {med:.1} ms (min {lo:.1}, max {hi:.1})"
    );
    basis_timings(&room, preset)?;
    // The reference size: the same room seen by a 640x480 camera.
    if !quick {
        let mut small_cam = scene;
        small_cam.camera.resolution = [640, 480];
        let (room640, secs, mb) = build(small_cam)?;
        let (med, lo, hi) = median_ms(
            || {
                room640
                    .render(&white, preset)
                    .map(|_| ())
                    .map_err(Into::into)
            },
            7,
        )?;
        println!(
            "{name} at 640x480: precomputation {secs:.2} s, peak resident growth {}; capture with inter-reflection: median {med:.1} ms (min {lo:.1}, max {hi:.1})",
            super::memory::mb(mb)
        );
    }
    if let Some(dir) = out {
        write_pictures(&room, dir)?;
    }
    Ok(())
}

/// Every projector showing a full-resolution checkerboard (16-pixel squares).
fn checker_frames(room: &Room) -> Vec<Frame> {
    room.projectors()
        .iter()
        .map(|p| {
            let (pw, ph) = (p.pinhole.width, p.pinhole.height);
            Frame::Image(roomlight_sim::ProjectorImage {
                width: pw,
                height: ph,
                pixels: (0..pw * ph)
                    .map(|i| {
                        if (i % pw / 16 + i / pw / 16) % 2 == 0 {
                            [1.0; 3]
                        } else {
                            [0.2; 3]
                        }
                    })
                    .collect(),
            })
        })
        .collect()
}

/// The node basis of four quadrants per projector: its build, a capture and the chart patches
/// through it.
fn basis_timings(room: &Room, preset: Option<usize>) -> Result<()> {
    let (w, h) = (room.camera().width, room.camera().height);
    let t0 = Instant::now();
    let nodes = quadrants(room);
    let basis = NodeBasis::new(room, &nodes, preset)?;
    println!(
        "  node basis of {} nodes: built in {:.2} s",
        nodes.len(),
        t0.elapsed().as_secs_f64()
    );
    let x = vec![roomlight_core::LinearRgb::splat(0.5); nodes.len()];
    let (med, _, _) = median_ms(
        || {
            std::hint::black_box(basis.capture(&x));
            Ok(())
        },
        7,
    )?;
    println!("  uniform-node capture {w}x{h} through the basis: median {med:.1} ms");
    let (med, _, _) = median_ms(
        || {
            std::hint::black_box(basis.patch_values(&x));
            Ok(())
        },
        7,
    )?;
    println!(
        "  uniform-node chart patches ({}) through the basis: median {:.3} ms",
        room.patches(),
        med
    );
    Ok(())
}

/// The LED presets and each projector alone at full white, as sRGB PNGs in `dir`.
fn write_pictures(room: &Room, dir: &Path) -> Result<()> {
    let n = room.projectors().len();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (k, p) in room.scene().presets.iter().enumerate() {
        let cap = room.render(&vec![Frame::Black; n], Some(k))?;
        cap.save_png(
            &dir.join(format!(
                "led-{}.{}.png",
                p.name,
                PngEncoding::Srgb8.suffix()
            )),
            PngEncoding::Srgb8,
            1.0,
        )?;
    }
    for (k, p) in room.projectors().iter().enumerate() {
        let mut frames = vec![Frame::Black; n];
        frames[k] = Frame::Uniform([1.0; 3]);
        room.render(&frames, None)?.save_png(
            &dir.join(format!(
                "projector-{}.{}.png",
                p.name,
                PngEncoding::Srgb8.suffix()
            )),
            PngEncoding::Srgb8,
            1.0,
        )?;
    }
    println!("  pictures in {}", dir.display());
    Ok(())
}
