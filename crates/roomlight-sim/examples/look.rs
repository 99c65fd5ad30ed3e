//! Renders the lab under each LED preset and with every projector white, into PNGs to look at.
use roomlight_sim::room::PngEncoding;
use roomlight_sim::{Frame, Room, scenes};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::path::PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "/tmp/look".into()),
    );
    std::fs::create_dir_all(&out)?;
    let t = Instant::now();
    let room = Room::build(scenes::lab()?)?;
    println!(
        "build {:.2} s, {} elements",
        t.elapsed().as_secs_f64(),
        room.geometry().elements.len()
    );
    let n = room.projectors().len();
    for preset in ["neutral", "warm", "reading"] {
        let t = Instant::now();
        let cap = room.render(&vec![Frame::Black; n], Some(room.preset(preset)?))?;
        println!("{preset}: {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
        cap.save_png(
            &out.join(format!("led-{preset}.png")),
            PngEncoding::Srgb8,
            1.0,
        )?;
    }
    let mut frames = vec![Frame::Uniform([1.0; 3]); n];
    frames[n - 1] = Frame::Black;
    let t = Instant::now();
    let cap = room.render(&frames, None)?;
    println!(
        "projectors white: {:.1} ms",
        t.elapsed().as_secs_f64() * 1e3
    );
    cap.save_png(&out.join("projectors.png"), PngEncoding::Srgb8, 1.0)?;
    for k in 0..n {
        let mut frames = vec![Frame::Black; n];
        frames[k] = Frame::Uniform([1.0; 3]);
        let cap = room.render(&frames, None)?;
        cap.save_png(
            &out.join(format!("proj-{}.png", room.projectors()[k].name)),
            PngEncoding::Srgb8,
            1.0,
        )?;
    }
    Ok(())
}
