//! The `roomlight` command: a thin clap front over the crates.

mod config;
mod procs;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use roomlight_lab::bench;
use roomlight_lab::demo::{self, DemoOptions};
use std::path::PathBuf;

#[derive(Debug, Parser)]
#[command(
    name = "roomlight",
    version,
    about = "Projection mapping in a lit room: projectors replace the room lights"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The whole method on the embedded lab: calibration from simulated captures, then the real
    /// agents over loopback gRPC lighting every LED preset, per-pixel shading passes after each
    /// (in process), a projector leaving and another joining, the projection-mapping target's
    /// contrast; an HTML report against the exact optimum (`--synthetic`: the update rules
    /// compared on a synthetic room).
    Demo(DemoArgs),
    /// The simulated hardware as a process: a synthetic room served as `VirtualHardware`, or
    /// (`--scene`) the rendered room served as `RenderedRoom`.
    Sim(procs::SimArgs),
    /// Calibrates a simulated room and writes the files the processes of a rendered room need
    /// (the camera agent's model and charts, each node agent's frame).
    Calibrate(procs::CalibrateArgs),
    /// The camera agent of a room, and its installer's web console (`console` in its config).
    /// Its rounds are summarised on stdout, at most a line a second, with a line at once when
    /// the projectors live or calibrated change.
    Camera {
        /// Its TOML config (see deploy/camera.toml).
        #[arg(long)]
        config: PathBuf,
        /// Load and check the config, print what would run, and exit.
        #[arg(long)]
        check: bool,
        /// One stdout line per round instead of the summary, for tools that follow the rounds:
        /// `round R captures C objective G live L calibrated H averaged K`.
        #[arg(long)]
        status_lines: bool,
    },
    /// A node agent (one per projector).
    Node {
        /// Its TOML config (see deploy/node.toml).
        #[arg(long)]
        config: PathBuf,
        /// Load and check the config, print what would run, and exit.
        #[arg(long)]
        check: bool,
    },
    /// The pre-flight of one PC: a camera agent's or node agent's config checked against the
    /// room (camera agent found and accepting, display, camera, files); a checklist, and a
    /// non-zero exit naming the first item that failed.
    Check {
        /// A camera agent's config (it has `listen`) or a node agent's.
        #[arg(long)]
        config: PathBuf,
    },
    /// Prints a model file's size and its optimum G* (to read the camera agent's objective
    /// against), e.g. the `model_out` of a room calibrated over the wire.
    Optimum {
        /// A model file (`roomlight calibrate`, `roomlight sim --model-out`, or a camera
        /// agent's `model_out`).
        #[arg(long)]
        model: PathBuf,
    },
    /// Gray-code structured light for real photographs.
    Graycode {
        #[command(subcommand)]
        which: roomlight_lab::commands::GraycodeCommand,
    },
    /// The room's TLS certificates: its CA (`init`), a certificate per camera agent or node.
    Certs {
        #[command(subcommand)]
        which: roomlight_lab::commands::CertsCommand,
    },
    /// Benchmarks: speed against error. Without a subcommand: the whole evidence — the core,
    /// the default room's presets, the hard cases, a thousand-node room and sparsity (a table,
    /// `--json`, an HTML page with `--out`), scaling over loopback, calibration and the
    /// simulator — and with `--out DIR` every bench's tables in DIR/results.md.
    Bench(BenchArgs),
    /// Real hardware: the outputs a projector can be on, an image or the identify pattern on one;
    /// the cameras, one capture, a camera's response curve.
    Hw(HwArgs),
    /// A room of processes for thousands of rounds with kills, restarts, additions and a
    /// misbehaving peer (issue 20): memory, descriptors, logs, final excess; fails naming why.
    Soak(roomlight_lab::soak::SoakArgs),
}

#[derive(Debug, clap::Args)]
struct HwArgs {
    /// The X display (default: $DISPLAY).
    #[arg(long, global = true)]
    x_display: Option<String>,
    #[command(subcommand)]
    which: HwCommand,
}

#[derive(Debug, Subcommand)]
enum HwCommand {
    /// One line per output: its name, then resolution and position.
    Displays,
    /// Shows an image on an output until SIGINT or SIGTERM.
    Show {
        /// The output: a name (`HDMI-1`), an index, or a geometry `WxH+X+Y`.
        #[arg(long)]
        output: roomlight_hw::OutputSelector,
        /// A PNG of the output's size.
        file: PathBuf,
        /// Scale an image of another size to the output instead of refusing it.
        #[arg(long)]
        scale: bool,
    },
    /// The identify pattern (projector id, output, resolution, grid, corner marks) on an
    /// output, or on every output, until SIGINT or SIGTERM.
    Identify {
        /// The output: a name (`HDMI-1`), an index, or a geometry `WxH+X+Y` (default: every
        /// output).
        #[arg(long)]
        output: Option<roomlight_hw::OutputSelector>,
        /// The projector id shown.
        #[arg(long, default_value = "unnamed")]
        projector: String,
    },
    /// One line per camera found (V4L2 devices), and the backends that need no discovery.
    Cameras,
    /// One capture written as PNG, with the exposure actually used; exits non-zero naming the
    /// camera when it times out.
    Capture {
        /// `folder:DIR`, `command:CMD` (`{out}` is the file to write), `v4l2:/dev/videoN` or
        /// `gphoto2[:PORT]`, with default settings.
        #[arg(long, required_unless_present = "config", conflicts_with = "config")]
        camera: Option<String>,
        /// A camera agent's config: its camera with every setting (exposure, controls, EXIF).
        #[arg(long)]
        config: Option<PathBuf>,
        /// The PNG file to write.
        #[arg(long)]
        out: PathBuf,
        /// With --camera (a config has its own `timeout_s`).
        #[arg(long, default_value_t = 10.0, conflicts_with = "config")]
        timeout_s: f64,
    },
    /// A camera's response curve from photographs of a static scene at several exposures
    /// (`IMAGE=SECONDS` each); prints the `response` line for the camera config.
    CalibrateResponse {
        #[arg(required = true, value_parser = shot)]
        shots: Vec<(PathBuf, f64)>,
    },
}

/// `IMAGE=SECONDS`, the exposure finite and positive.
fn shot(s: &str) -> Result<(PathBuf, f64), String> {
    let (path, t) = s.rsplit_once('=').ok_or("expected IMAGE=SECONDS")?;
    match t.parse::<f64>() {
        Ok(t) if t.is_finite() && t > 0.0 => Ok((PathBuf::from(path), t)),
        _ => Err(format!(
            "{t:?}: expected an exposure in seconds, above zero"
        )),
    }
}

/// Options of the demo.
#[derive(Debug, clap::Args)]
struct DemoArgs {
    /// The small test room (its camera at 640x480) and 15 captures per preset instead of 30;
    /// with --synthetic, 25 nodes instead of 100 (seconds, for tests).
    #[arg(long)]
    quick: bool,
    /// The synthetic-room comparison of update rules instead of the simulated lab.
    #[arg(long)]
    synthetic: bool,
    /// Seed of the synthetic room and the camera noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Where the report goes.
    #[arg(long, default_value = "roomlight-report")]
    out: PathBuf,
    /// Weigh the walls beyond the charts into the rounds' model: each wall tile's squared error
    /// at this weight, a chart patch's at 1 (0: the charts alone; 0.25 is what docs/results.md
    /// measured).
    #[arg(long, default_value_t = 0.0, value_parser = weight)]
    wall_weight: f64,
    /// Weigh the light on the projection-mapping target into every preset's rounds at this
    /// weight (each target patch's squared light against a chart patch's 1), instead of the
    /// weight each preset asks for in the scene (`dark_weight`; 0 when left out).
    #[arg(long, value_parser = weight)]
    dark_weight: Option<f64>,
    /// Shape every luminaire node to the first LED preset's falloff, photographed once with the
    /// projectors dark (one more capture), instead of driving its region evenly.
    #[arg(long)]
    shaped_nodes: bool,
    /// Calibrate with one group of projectors coded at a time in white, instead of up to three
    /// at once, each in its own primary (more captures, fuller decodes; `bench calib --white`).
    #[arg(long)]
    white: bool,
}

/// A weight: finite and at least 0.
fn weight(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(w) if w.is_finite() && w >= 0.0 => Ok(w),
        _ => Err(format!("{s:?}: expected a finite weight >= 0")),
    }
}

#[derive(Debug, clap::Args)]
#[command(args_conflicts_with_subcommands = true)]
struct BenchArgs {
    #[command(subcommand)]
    which: Option<BenchCommand>,
    /// The small room, fewer captures, a subset of rules on the hard cases, 100 synthetic
    /// nodes, and every other bench with its own `--quick`.
    #[arg(long)]
    quick: bool,
    /// Runs per case and rule, each with its own camera noise; figures are their medians.
    /// Default: 3, or 1 with --quick.
    #[arg(long)]
    repeats: Option<usize>,
    /// Write one record per case and rule as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write the room's plots (SVG), bench.json and index.html, and results.md (every bench's
    /// tables with date, commit, machine and command), to this folder.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Seed of the camera noise (repeats use the following seeds) and of the core's rooms.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Only the room's cases whose name contains this text (e.g. `stale`, `lab/warm`,
    /// `scaling`); the core, calibration and simulator benches are then skipped.
    #[arg(long)]
    case: Option<String>,
}

#[derive(Debug, Subcommand)]
enum BenchCommand {
    /// The optimisation core on synthetic rooms of 10, 100 and 1000 nodes, and two harder rooms
    /// of 100 (reflective, noisy), every rule from the conventional start.
    Core {
        /// Only the rooms of 10 and 100 nodes, 150 captures per rule instead of 400 (seconds,
        /// for tests).
        #[arg(long)]
        quick: bool,
        /// Write the table as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Seed of the synthetic rooms.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Speed against error on the simulated lab: every preset and rule through the agents.
    Room {
        /// The small test room (its camera at 640x480), one preset, 8 captures per rule (10 with
        /// stale errors), a few rules on the hard cases, 100 synthetic nodes instead of 1000
        /// (seconds).
        #[arg(long)]
        quick: bool,
        /// The hard cases (variants of the room, stale errors, a projector leaving and another
        /// joining, a synthetic room of 1000 nodes) instead of the presets.
        #[arg(long)]
        hard: bool,
        /// Write the records as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Write the plots, bench.json and index.html to this folder.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Runs per case and rule (camera noise seeds from --seed on); figures are medians.
        #[arg(long, default_value_t = 1)]
        repeats: usize,
        /// Seed of the camera noise.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Only the cases whose name contains this text.
        #[arg(long)]
        case: Option<String>,
    },
    /// Calibration on the embedded lab: structured-light accuracy against the simulator's truth,
    /// captures with and without simultaneous coding, decode speed.
    Calib {
        /// The small test room instead of the lab.
        #[arg(long)]
        quick: bool,
        /// Only the large aperture's light-weighted centroids (a minute or two on the lab).
        #[arg(long)]
        area_only: bool,
        /// Code one group of projectors at a time in white, instead of up to three at once,
        /// each in its own primary (more captures, fuller decodes; to compare).
        #[arg(long)]
        white: bool,
    },
    /// Per-pixel shading over the wire on the simulated lab: brought up over the wire with
    /// shading off, then with it, every preset chosen in turn; the whole room's and the charts'
    /// ΔE00 against the LEDs, the light on the target, captures.
    Shading {
        /// The small test room (its camera at 640x480) instead of the lab.
        #[arg(long)]
        quick: bool,
        /// Shading passes per preset in the second run (the camera agent's default).
        #[arg(long, default_value_t = 10)]
        passes: usize,
        /// The weight of the light on the target in the luminaires' objective, against a chart
        /// patch's (the camera agent's `dark_target_weight`; 0: the charts alone).
        #[arg(long, default_value_t = roomlight_agent::camera::DEFAULT_DARK_WEIGHT)]
        dark_weight: f64,
        /// Only this preset (repeatable; all when none is given). A preset starts from the
        /// light the one run before it left, so a preset run alone can differ a little from
        /// the same preset in a full run.
        #[arg(long = "preset", value_name = "NAME")]
        presets: Vec<String>,
        /// Write each preset's whole-room ΔE00 map into this folder, `<preset>-<passes>.png`,
        /// and what each projector shows, `<preset>-<passes>-<projector>.png`.
        #[arg(long, value_name = "DIR")]
        maps: Option<PathBuf>,
        /// Write the records as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    // Its help says the sizes it runs, from the constants it runs them from.
    #[command(about = net_about(), long_about = None)]
    Net {
        #[arg(long, help = net_quick_help())]
        quick: bool,
        /// Write the table (every size, the growth exponents) as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    // Its help says its consoles and phases, from the constants it runs with.
    #[command(about = console_about(), long_about = None)]
    Console {
        /// Nodes of the synthetic room (ten per node agent).
        #[arg(long, default_value_t = 100)]
        nodes: usize,
        #[arg(long, default_value_t = 60, help = console_rounds_help())]
        rounds: usize,
    },
    /// The simulator on the embedded lab: precomputation, capture times, memory.
    Sim {
        /// The small test room instead of the lab.
        #[arg(long)]
        quick: bool,
        /// Also write the captures as PNG (sRGB, 8-bit) to this folder.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Display and capture latency here, and the wall-clock time to 1% for two camera models.
    Hw(bench::hw::HwArgs),
}

/// `bench net`'s help, from the sizes it runs.
fn net_about() -> String {
    format!(
        "The distributed runtime over loopback gRPC: round overhead, bytes and resident memory \
         per node for {} nodes ({} nodes per node agent), and the growth exponents. A size too \
         slow to measure is reported as such.",
        bench::net::said(&bench::net::SIZES),
        bench::net::NODES_PER_AGENT
    )
}

fn net_quick_help() -> String {
    format!("{} nodes only", bench::net::said(&bench::net::QUICK_SIZES))
}

/// `bench console`'s help, from its number of consoles.
fn console_about() -> String {
    format!(
        "What the installer's console costs the rounds: median round time of a synthetic room \
         through the agents alone, with {} consoles open (event streams, the page's polling), \
         and alone again.",
        bench::console::CONSOLES
    )
}

fn console_rounds_help() -> String {
    format!(
        "The fewest rounds timed in each phase (a phase also lasts at least {} s)",
        bench::console::PHASE.as_secs()
    )
}

fn main() -> Result<()> {
    roomlight_lab::heap::limit_arenas();
    let cli = Cli::parse();
    procs::init_logs();
    match cli.command {
        Command::Demo(args) => demo::run(&DemoOptions {
            quick: args.quick,
            synthetic: args.synthetic,
            seed: args.seed,
            out: args.out,
            wall_weight: args.wall_weight,
            dark_weight: args.dark_weight,
            shaped_nodes: args.shaped_nodes,
            primaries: !args.white,
        }),
        Command::Sim(args) => procs::sim(&args),
        Command::Calibrate(args) => procs::calibrate(&args),
        Command::Camera {
            config,
            check,
            status_lines,
        } => procs::camera(&config, check, status_lines),
        Command::Node { config, check } => procs::node(&config, check),
        Command::Check { config } => procs::check(&config),
        Command::Optimum { model } => procs::optimum(&model),
        Command::Graycode { which } => roomlight_lab::commands::graycode(which),
        Command::Certs { which } => roomlight_lab::commands::certs(which),
        Command::Bench(args) => bench(args),
        Command::Hw(args) => hw(args),
        Command::Soak(args) => roomlight_lab::soak::run(&args, &std::env::current_exe()?),
    }
}

fn hw(args: HwArgs) -> Result<()> {
    use roomlight_camera::cli as camera;
    let x = args.x_display.as_deref();
    match args.which {
        HwCommand::Displays => {
            print!("{}", roomlight_hw::cli::displays(x)?);
            Ok(())
        }
        HwCommand::Show {
            output,
            file,
            scale,
        } => roomlight_hw::cli::show(x, &output, &file, scale),
        HwCommand::Identify { output, projector } => {
            roomlight_hw::cli::identify(x, output.as_ref(), &projector)
        }
        HwCommand::Cameras => {
            print!("{}", camera::cameras()?);
            Ok(())
        }
        HwCommand::Capture {
            camera: spec,
            config,
            out,
            timeout_s: t,
        } => {
            let report = match (spec, config) {
                (Some(spec), _) => {
                    if !(t.is_finite() && (0.001..=86_400.0).contains(&t)) {
                        anyhow::bail!("--timeout-s {t}: expected 0.001 to 86400 seconds");
                    }
                    camera::capture(&spec, &out, std::time::Duration::from_secs_f64(t))?
                }
                (None, file) => {
                    let file = file.unwrap_or_default();
                    let process = config::load_camera(&file)?;
                    let roomlight_lab::process::CameraHardware::Real { camera: real, .. } =
                        process.hardware
                    else {
                        anyhow::bail!(
                            "{}: no `camera` to capture with (the simulator's)",
                            file.display()
                        );
                    };
                    camera::capture_config(&real, &out)?
                }
            };
            println!("{report}");
            Ok(())
        }
        HwCommand::CalibrateResponse { shots } => {
            let max = roomlight_camera::spec::MAX_PIXELS;
            println!("{}", camera::calibrate_response(&shots, max)?);
            Ok(())
        }
    }
}

fn bench(args: BenchArgs) -> Result<()> {
    match args.which {
        None => bench::evidence::run(&bench::evidence::Evidence {
            plan: bench::room::Plan {
                quick: args.quick,
                presets: true,
                hard: true,
                scaling: true,
                repeats: args.repeats.unwrap_or(if args.quick { 1 } else { 3 }),
                seed: args.seed,
                json: args.json,
                out: args.out,
                case: args.case,
            },
            exe: std::env::current_exe().context("finding the roomlight binary")?,
            command: typed_command(),
        }),
        Some(BenchCommand::Core { quick, json, seed }) => {
            bench::core::core(quick, json.as_deref(), seed)
        }
        Some(BenchCommand::Room {
            quick,
            hard,
            json,
            out,
            repeats,
            seed,
            case,
        }) => bench::room::run(&bench::room::Plan {
            quick,
            presets: !hard,
            hard,
            scaling: false,
            repeats,
            seed,
            json,
            out,
            case,
        }),
        Some(BenchCommand::Net { quick, json }) => {
            bench::net::run(quick, json.as_deref()).map(|_| ())
        }
        Some(BenchCommand::Calib {
            quick,
            area_only,
            white,
        }) => bench::calib::run(quick, area_only, !white),
        Some(BenchCommand::Shading {
            quick,
            passes,
            dark_weight,
            presets,
            maps,
            json,
        }) => bench::shading::run(
            quick,
            passes,
            dark_weight,
            &presets,
            maps.as_deref(),
            json.as_deref(),
        )
        .map(|_| ()),
        Some(BenchCommand::Console { nodes, rounds }) => {
            bench::console::run(nodes, rounds).map(|_| ())
        }
        Some(BenchCommand::Sim { quick, out }) => bench::sim::run(quick, out.as_deref()),
        Some(BenchCommand::Hw(args)) => bench::hw::run(&args),
    }
}

/// The command line as typed, the program named `roomlight` whatever its path; arguments with
/// spaces quoted.
fn typed_command() -> String {
    std::iter::once("roomlight".to_string())
        .chain(std::env::args().skip(1).map(|a| {
            if a.contains(char::is_whitespace) {
                format!("'{a}'")
            } else {
                a
            }
        }))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::weight;

    #[test]
    fn a_weight_is_finite_and_not_negative() {
        assert_eq!(weight("0.25"), Ok(0.25));
        assert_eq!(weight("0"), Ok(0.0));
        for bad in ["-1", "NaN", "inf", "a lot"] {
            let e = weight(bad).expect_err(bad);
            assert!(e.contains("expected a finite weight >= 0"), "{e}");
        }
    }
}
