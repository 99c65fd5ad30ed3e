//! `roomlight bench shading`: per-pixel shading over the wire on the simulated lab (or the
//! small room). The room is brought up over the wire twice (`crate::wire_room`: the camera
//! agent on its camera with a survey, a node agent per luminaire), once with shading off and
//! once with `--passes` passes per preset; every preset is then chosen in turn as an installer
//! would from the console, and once the room has settled on it (after its last pass) the
//! simulator's noiseless truth of what the projectors show is judged against the LEDs: the
//! whole room's ΔE00 (mean and 95th percentile over the pixels luminaires light directly), the
//! charts' ΔE00, the light on the target, and the captures the preset took.

use crate::wire_room::{Judged, Options, WireRoom};
use anyhow::{Context, Result, bail};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Model rounds per capture, as the demo's camera agent runs them: every model round redraws
/// each rendered projector's whole image (2.4 MB over gRPC at the lab's 1024 × 768), and at the
/// deployed default of 100 a capture of the lab took tens of seconds here.
const MODEL_ROUNDS: usize = 5;

/// One preset's outcome in one run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Record {
    pub preset: String,
    pub shading_passes: usize,
    /// The weight of the light on the target in the luminaires' objective.
    pub dark_weight: f64,
    /// Captures from choosing the preset until the room settled after its last pass.
    pub captures: u64,
    pub seconds: f64,
    pub whole_room_de00_mean: f64,
    pub whole_room_de00_p95: f64,
    pub charts_de00: f64,
    pub target_light_share: Option<f64>,
}

/// Runs the bench; the records of both runs (shading off first).
pub fn run(
    quick: bool,
    passes: usize,
    dark_weight: f64,
    only: &[String],
    maps: Option<&Path>,
    json: Option<&Path>,
) -> Result<Vec<Record>> {
    let scene = if quick {
        let mut s = roomlight_sim::scenes::small()?;
        s.camera.resolution = [640, 480];
        s
    } else {
        roomlight_sim::scenes::lab()?
    };
    let name = scene.name.clone();
    if let Some(unknown) = only
        .iter()
        .find(|p| !scene.presets.iter().any(|q| &&q.name == p))
    {
        let known: Vec<&str> = scene.presets.iter().map(|p| p.name.as_str()).collect();
        bail!("--preset {unknown:?}: the {name} room's presets are {known:?}");
    }
    if let Some(dir) = maps {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let room = Arc::new(
        roomlight_sim::Room::build(scene).with_context(|| format!("building the {name} room"))?,
    );
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    let mut records = Vec::new();
    for shading_passes in [0, passes] {
        let started = Instant::now();
        let run = runtime.block_on(presets(
            room.clone(),
            Run {
                shading_passes,
                dark_weight,
                only,
                maps,
            },
        ))?;
        eprintln!(
            "{name}, {shading_passes} shading passes: brought up and every preset run in {:.0} s",
            started.elapsed().as_secs_f64()
        );
        records.extend(run);
    }
    print(&name, &records, passes, dark_weight);
    if let Some(path) = json {
        std::fs::write(path, serde_json::to_string_pretty(&records)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(records)
}

/// One bring-up's settings.
struct Run<'a> {
    shading_passes: usize,
    dark_weight: f64,
    /// Only these presets (all when empty), each still judged against its own LEDs.
    only: &'a [String],
    /// Where to write each preset's ΔE00 map, `<preset>-<passes>.png`, and each projector's
    /// frame, `<preset>-<passes>-<projector>.png`.
    maps: Option<&'a Path>,
}

/// Brings `room` up over the wire and runs every preset (or those `run` names).
async fn presets(room: Arc<roomlight_sim::Room>, run: Run<'_>) -> Result<Vec<Record>> {
    let Run {
        shading_passes,
        dark_weight,
        only,
        maps,
    } = run;
    let options = Options {
        shading_passes,
        model_rounds: MODEL_ROUNDS,
        seed: 1,
        // Each preset is chosen as an installer would, the first too.
        survey_photographs: false,
        // What a restarted camera agent would resume from, measured.
        model_file: true,
        dark_weight,
    };
    let names: Vec<String> = room
        .scene()
        .presets
        .iter()
        .map(|p| p.name.clone())
        .collect();
    let luminaires = crate::whole_room::luminaires(&room).len() as u64;
    let projectors: Vec<String> = room
        .scene()
        .projectors
        .iter()
        .map(|p| p.name.clone())
        .collect();
    let mut wire = WireRoom::start(room, options).await?;
    let up = wire
        .until(Duration::from_secs(3600), "the bring-up", |s| {
            s.calibrated_hot >= luminaires
        })
        .await?;
    eprintln!(
        "brought up over the wire in {} captures ({} projectors)",
        up.captures, up.calibrated_hot
    );
    let mut records = Vec::new();
    for (index, preset) in names.iter().enumerate() {
        if !only.is_empty() && !only.contains(preset) {
            continue;
        }
        let at = wire.status().captures;
        let started = Instant::now();
        wire.preset(preset).await?;
        let settled = wire
            .until(Duration::from_secs(1800), preset, |s| {
                s.settled && s.shading_passes == shading_passes && s.captures > at + 2
            })
            .await?;
        let judged: Judged = match maps {
            Some(dir) => {
                let (judged, map) = wire.judge_map(index)?;
                // What each projector shows: its codes, as it receives them.
                for (name, frame) in projectors.iter().zip(wire.frames()) {
                    if let roomlight_sim::Frame::Image(im) = frame {
                        let img = image::RgbImage::from_fn(im.width, im.height, |x, y| {
                            let p = im.pixels[(y * im.width + x) as usize];
                            image::Rgb(p.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8))
                        });
                        let path = dir.join(format!("{preset}-{shading_passes}-{name}.png"));
                        img.save(&path)
                            .with_context(|| format!("writing {}", path.display()))?;
                    }
                }
                let path = dir.join(format!("{preset}-{shading_passes}.png"));
                map.save(&path)
                    .with_context(|| format!("writing {}", path.display()))?;
                judged
            }
            None => wire.judge(index)?,
        };
        eprintln!(
            "  {preset}: settled after {} passes, {} captures, {:.0} s: whole room ΔE00 {:.2} / p95 {:.2}",
            settled.shading_passes,
            settled.captures - at,
            started.elapsed().as_secs_f64(),
            judged.de00_mean,
            judged.de00_p95
        );
        records.push(Record {
            preset: preset.clone(),
            shading_passes,
            dark_weight,
            captures: settled.captures - at,
            seconds: started.elapsed().as_secs_f64(),
            whole_room_de00_mean: judged.de00_mean,
            whole_room_de00_p95: judged.de00_p95,
            charts_de00: judged.charts_de00,
            target_light_share: judged.target_share,
        });
    }
    if let Some(model) = wire.model_file() {
        let size = |p: &Path| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
        eprintln!(
            "the camera agent's model file {} bytes, the shading's inputs beside it {} bytes",
            size(model),
            size(&model.with_extension("shading"))
        );
    }
    wire.stop().await?;
    Ok(records)
}

fn print(room: &str, records: &[Record], passes: usize, dark_weight: f64) {
    println!(
        "per-pixel shading over the wire on the {room} room ({passes} passes per preset, dark target weight {dark_weight})"
    );
    println!(
        "{:<10} {:>6} {:>9} {:>8} {:>13} {:>12} {:>9} {:>9}",
        "preset", "passes", "captures", "seconds", "room ΔE00", "room p95", "charts", "target"
    );
    for r in records {
        println!(
            "{:<10} {:>6} {:>9} {:>8.1} {:>13.2} {:>12.2} {:>9.2} {:>9}",
            r.preset,
            r.shading_passes,
            r.captures,
            r.seconds,
            r.whole_room_de00_mean,
            r.whole_room_de00_p95,
            r.charts_de00,
            r.target_light_share
                .map_or("—".to_string(), |s| format!("{:.0}%", 100.0 * s))
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_preset_is_refused_by_name_before_the_room_is_built() {
        let dir = tempfile::tempdir().expect("temp dir");
        let maps = dir.path().join("maps");
        let err = run(true, 1, 0.0, &["dusk".into()], Some(&maps), None)
            .expect_err("no preset is called dusk");
        let text = format!("{err:#}");
        assert!(text.contains("\"dusk\""), "{text}");
        assert!(text.contains("[\"on\"]"), "names the known presets: {text}");
        assert!(!maps.exists(), "nothing written for a refused run");
    }
}
