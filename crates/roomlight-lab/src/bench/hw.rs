//! `roomlight bench hw`: what real hardware costs a round. (a) Display latency: a frame shown
//! in a window (roomlight-hw) until its pixels are seen in a grab of the root window, under a
//! private Xvfb when `$DISPLAY` is unset. (b) Capture latency of every camera backend available
//! here: a folder fed by a writer thread, a command running a tiny program, and V4L2 / gphoto2
//! only where a device answers ("no device" otherwise). (c) The wall-clock time to 1 % excess
//! of the simulated lab for two camera models, from the room bench's measured captures to 1 %
//! and round cost. Timings are printed and written, never asserted. It must not know how a
//! window or a camera works inside: it drives them through their crates' public API.

use super::results::{self, Section, Stamp};
use anyhow::{Context, Result, anyhow};
use roomlight_camera::folder::FolderBackend;
use roomlight_camera::spec::{CameraConfig, CameraSpec, Gphoto2Settings, V4l2Controls};
use roomlight_camera::{Backend, open_backend};
use roomlight_hw::grab::Grabber;
use roomlight_hw::xvfb::Xvfb;
use roomlight_hw::{Geometry, OutputSelector};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// `roomlight bench hw [--quick] [--out DIR] [--frames N]`.
#[derive(Debug, Clone, clap::Args)]
pub struct HwArgs {
    /// Few frames and captures, the small room for the time to 1 % (seconds, for tests).
    #[arg(long)]
    pub quick: bool,
    /// Write a `hw` section to DIR/results.md.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Frames shown, and captures per backend (default 60, or 8 with --quick).
    #[arg(long)]
    pub frames: Option<usize>,
}

/// The video camera model: 30 frames per second, and the frame in flight when the projector
/// changed is discarded, so a capture costs one frame period after the display settled.
const VIDEO_CAPTURE_S: f64 = 1.0 / 30.0;
/// The DSLR model: 9 s per shot, the paper's rig (shutter, mirror, download, write).
const DSLR_CAPTURE_S: f64 = 9.0;
/// Longest wait for one frame to appear, or one capture.
const DEADLINE: Duration = Duration::from_secs(10);

/// Median and 90th percentile (nearest rank) of samples in milliseconds; NaN for none.
fn median_p90(samples: &mut [f64]) -> (f64, f64) {
    samples.sort_by(f64::total_cmp);
    let at = |q: f64| {
        let k = ((q * samples.len() as f64).ceil() as usize).clamp(1, samples.len().max(1));
        samples.get(k - 1).copied().unwrap_or(f64::NAN)
    };
    (at(0.5), at(0.9))
}

/// One row of the latency table: a measurement, or why it was skipped.
#[derive(Debug, Clone)]
struct Latency {
    what: String,
    result: Result<Vec<f64>, String>,
}

impl Latency {
    fn row(&self) -> String {
        match &self.result {
            Ok(samples) => {
                let (median, p90) = median_p90(&mut samples.clone());
                format!(
                    "| {} | {median:.2} | {p90:.2} | {} |",
                    self.what,
                    samples.len()
                )
            }
            Err(why) => format!("| {} | - | - | {why} |", self.what),
        }
    }
}

/// (a) Frames of alternating colours shown on a window covering a 320×240 output; the time
/// from `show` until a grab of the output's centre has the new colour.
fn display_latency(frames: usize) -> Result<Vec<f64>> {
    let region = Geometry {
        width: 320,
        height: 240,
        x: 0,
        y: 0,
    };
    // A private server unless the session has one: the bench must not paint over a desktop
    // by accident, and CI has none.
    let (private, display, selector) = match std::env::var("DISPLAY") {
        Ok(d) if !d.is_empty() => (None, d, OutputSelector::Index(0)),
        _ => {
            let x = Xvfb::start(region.width, region.height).map_err(|e| anyhow!("{e}"))?;
            x.add_output("bench", region)
                .map_err(|e| anyhow!("adding an output: {e}"))?;
            let d = x.display().to_string();
            (Some(x), d, OutputSelector::Name("bench".into()))
        }
    };
    let window = roomlight_hw::window::WindowHandle::open(Some(&display), selector, "bench hw")
        .map_err(|e| anyhow!("opening the window: {e}"))?;
    let out = window.output().geometry();
    let grabber = Grabber::connect(Some(&display)).map_err(|e| anyhow!("{e}"))?;
    let centre = Geometry {
        width: 8,
        height: 8,
        x: out.x + out.width as i32 / 2 - 4,
        y: out.y + out.height as i32 / 2 - 4,
    };
    let mut samples = Vec::with_capacity(frames);
    for k in 0..frames + 1 {
        // Colours that differ from the previous frame's in every channel.
        let c = if k % 2 == 0 {
            [200, 40, 120]
        } else {
            [30, 220, 60]
        };
        let frame = roomlight_hw::Frame::new(
            out.width,
            out.height,
            vec![c; (out.width * out.height) as usize],
        )
        .map_err(|e| anyhow!("{e}"))?;
        let t0 = Instant::now();
        window.show(frame, None);
        loop {
            let seen = grabber.grab(centre).map_err(|e| anyhow!("{e}"))?;
            if seen.pixels().all(|p| p.0 == c) {
                break;
            }
            if t0.elapsed() > DEADLINE {
                return Err(anyhow!("frame {k} not on the screen after {DEADLINE:?}"));
            }
        }
        // The first frame also maps the window: not a frame's latency.
        if k > 0 {
            samples.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    drop(window);
    drop(private);
    Ok(samples)
}

/// A 1280×720 8-bit PNG, a small camera's frame, as bytes.
fn test_image() -> Result<Vec<u8>> {
    let image = image::RgbImage::from_fn(1280, 720, |x, y| {
        image::Rgb([(x % 256) as u8, (y % 256) as u8, ((x + y) % 256) as u8])
    });
    let mut png = Vec::new();
    image
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .context("encoding the test image")?;
    Ok(png)
}

/// (b) The folder backend: a writer thread renames a complete file into the folder after the
/// capture was armed; the time from the rename to the decoded frame (the folder's `settle_ms`,
/// 200 ms by default, included: a file must stop growing before it counts).
fn folder_latency(captures: usize, png: &[u8]) -> Result<Vec<f64>> {
    let dir = tempfile::tempdir().context("a temp dir")?;
    let config = CameraConfig::new(CameraSpec::Folder(dir.path().to_path_buf()));
    let backend = FolderBackend::new(
        dir.path().to_path_buf(),
        Duration::from_millis(config.settle_ms),
        config.max_pixels,
    );
    let mut samples = Vec::with_capacity(captures);
    for k in 0..captures {
        let armed = backend.arm().map_err(|e| anyhow!("{e}"))?;
        let (staging, target) = (
            dir.path().join(format!(".shot-{k}.part")),
            dir.path().join(format!("shot-{k}.png")),
        );
        std::fs::write(&staging, png).context("writing a shot")?;
        let writer =
            std::thread::spawn(move || std::fs::rename(&staging, &target).map(|()| Instant::now()));
        let frame = armed.wait(Instant::now() + DEADLINE);
        let done = Instant::now();
        let written = writer
            .join()
            .map_err(|_| anyhow!("the writer thread panicked"))?
            .context("renaming a shot into place")?;
        frame.map_err(|e| anyhow!("{e}"))?;
        samples.push(done.saturating_duration_since(written).as_secs_f64() * 1e3);
    }
    Ok(samples)
}

/// (b) Any backend opened from a config: the time of each whole capture.
fn capture_latency(config: &CameraConfig, captures: usize) -> Result<Vec<f64>, String> {
    let mut backend: Box<dyn Backend> = open_backend(config).map_err(|e| e.to_string())?;
    (0..captures)
        .map(|_| {
            let t0 = Instant::now();
            backend
                .capture(t0 + DEADLINE)
                .map(|_| t0.elapsed().as_secs_f64() * 1e3)
                .map_err(|e| e.to_string())
        })
        .collect()
}

/// (b) Every backend: folder and command always; the first V4L2 device and a gphoto2 camera
/// only when one is there.
fn capture_rows(captures: usize) -> Result<Vec<Latency>> {
    let png = test_image()?;
    let dir = tempfile::tempdir().context("a temp dir")?;
    let source = dir.path().join("source.png");
    std::fs::write(&source, &png).context("writing the test image")?;
    let mut rows = vec![
        Latency {
            what: "capture: folder (1280×720 PNG renamed in → frame, settle 200 ms)".into(),
            result: folder_latency(captures, &png).map_err(|e| format!("{e:#}")),
        },
        Latency {
            what: "capture: command (`cp` of a 1280×720 PNG → frame)".into(),
            result: capture_latency(
                &CameraConfig::new(CameraSpec::Command(format!(
                    "cp '{}' {{out}}",
                    source.display()
                ))),
                captures,
            ),
        },
    ];
    let v4l2 = std::fs::read_dir("/dev")
        .into_iter()
        .flatten()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("video"))
        })
        .min();
    rows.push(Latency {
        what: "capture: v4l2".into(),
        result: match v4l2 {
            None => Err("no device".into()),
            Some(path) => {
                let mut config = CameraConfig::new(CameraSpec::V4l2(path));
                config.v4l2 = Some(V4l2Controls {
                    exposure_100us: 100,
                    gain: None,
                    white_balance_k: None,
                    size: [1280, 720],
                });
                capture_latency(&config, captures)
            }
        },
    });
    rows.push(Latency {
        what: "capture: gphoto2".into(),
        result: match "gphoto2".parse::<CameraSpec>() {
            Err(_) => Err("no device (built without the gphoto2 feature)".into()),
            Ok(spec) => {
                let mut config = CameraConfig::new(spec);
                config.gphoto2 = Some(Gphoto2Settings {
                    exposure_s: 1.0 / 30.0,
                    iso: 100,
                    f_number: None,
                });
                match open_backend(&config) {
                    Err(e) => Err(format!("no device ({e})")),
                    Ok(_) => capture_latency(&config, captures.min(3)),
                }
            }
        },
    });
    Ok(rows)
}

/// (c) One rule's time to 1 % for both camera models.
#[derive(Debug, Clone)]
struct TimeTo1 {
    rule: String,
    captures: Option<u64>,
    budget: u64,
    round_ms: f64,
}

/// The room bench's first preset through the agents (the small room with `--quick`, else the
/// lab): its captures to 1 % and round cost per rule.
fn time_to_1pct(quick: bool) -> Result<(String, Vec<TimeTo1>)> {
    let scene = if quick {
        roomlight_sim::scenes::small()?
    } else {
        roomlight_sim::scenes::lab()?
    };
    let preset = scene
        .presets
        .first()
        .map(|p| p.name.clone())
        .context("the room has no preset")?;
    let case = format!("{}/{preset}", scene.name);
    let outcome = super::room::measure(&super::room::Plan {
        quick,
        presets: true,
        hard: false,
        scaling: false,
        repeats: 1,
        seed: 1,
        json: None,
        out: None,
        case: Some(case.clone()),
    })?;
    let rows = outcome
        .records
        .iter()
        .map(|r| TimeTo1 {
            rule: r.rule.clone(),
            captures: r.captures_to_1pct,
            budget: r.captures,
            round_ms: r.compute_us_per_round / 1e3 + r.message_ms_per_round,
        })
        .collect();
    Ok((case, rows))
}

/// Runs the three parts, prints the tables, and with `--out` writes the `hw` section.
pub fn run(args: &HwArgs) -> Result<()> {
    let stamp = Stamp::now();
    let t0 = Instant::now();
    let frames = args
        .frames
        .unwrap_or(if args.quick { 8 } else { 60 })
        .max(1);
    let display = Latency {
        what: "display: show → pixels in a root-window grab".into(),
        result: display_latency(frames).map_err(|e| format!("{e:#}")),
    };
    let mut latencies = vec![display.clone()];
    latencies.extend(capture_rows(frames)?);
    let mut body = String::from(
        "Latency (ms; median and 90th percentile over the samples):\n\n\
         | measure | median ms | p90 ms | samples |\n| --- | --- | --- | --- |\n",
    );
    for l in &latencies {
        let _ = writeln!(body, "{}", l.row());
    }
    let display_ms = match &display.result {
        Ok(s) => median_p90(&mut s.clone()).0,
        Err(_) => 0.0,
    };
    let (case, rules) = time_to_1pct(args.quick)?;
    let _ = write!(
        body,
        "\nWall-clock time to 1 % excess on {case} (one run, seed 1), per rule: \
         T = N × (t_capture + t_display + t_round), N the captures to 1 % measured through the \
         agents, t_display = {display_ms:.2} ms (the median above), t_round the rule's measured \
         compute and messages per round; t_capture = {:.1} ms for a 30 fps video camera (one \
         frame of latency), {DSLR_CAPTURE_S:.0} s for a DSLR (the paper's rig):\n\n\
         | rule | captures to 1 % | t_round ms | video 30 fps s | DSLR 9 s/shot s |\n\
         | --- | --- | --- | --- | --- |\n",
        VIDEO_CAPTURE_S * 1e3
    );
    for r in &rules {
        match r.captures {
            Some(n) => {
                let per = |capture_s: f64| n as f64 * (capture_s + (display_ms + r.round_ms) / 1e3);
                let _ = writeln!(
                    body,
                    "| {} | {n} | {:.2} | {:.2} | {:.1} |",
                    r.rule,
                    r.round_ms,
                    per(VIDEO_CAPTURE_S),
                    per(DSLR_CAPTURE_S)
                );
            }
            None => {
                let _ = writeln!(
                    body,
                    "| {} | not reached in {} | {:.2} | - | - |",
                    r.rule, r.budget, r.round_ms
                );
            }
        }
    }
    println!("{body}");
    if let Some(dir) = &args.out {
        let command = std::iter::once("roomlight".to_string())
            .chain(std::env::args().skip(1))
            .collect::<Vec<_>>()
            .join(" ");
        let section = Section {
            bench: "hw".into(),
            command: command.clone(),
            stamp,
            seconds: t0.elapsed().as_secs_f64(),
            body,
        };
        results::write(dir, &command, &[section])?;
        println!("results: {}", dir.join("results.md").display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_nearest_rank() {
        let mut v: Vec<f64> = (1..=10).map(f64::from).collect();
        assert_eq!(median_p90(&mut v), (5.0, 9.0));
        let (m, p) = median_p90(&mut []);
        assert!(m.is_nan() && p.is_nan());
        assert_eq!(median_p90(&mut [3.0]), (3.0, 3.0));
    }
}
