//! The processes of an installation as the binary runs them: `roomlight sim`, `calibrate`,
//! `camera`, `node`, `optimum` — their arguments, the runtime, logs and stop signals; what they
//! do is roomlight-lab's `process`. Each server prints `listening on ADDR` once it serves, logs
//! with tracing (RUST_LOG), and stops cleanly on Ctrl-C or SIGTERM (nodes say goodbye and
//! flush their state file).

use crate::config::{self, CameraLocation};
use anyhow::{Context, Result, bail};
use roomlight_agent::discovery;
use roomlight_lab::process::{self, CalibrateOptions, SimRoom, SyntheticSim};
use std::io::Write;
use std::path::{Path, PathBuf};
use tokio_util::sync::CancellationToken;

#[derive(Debug, clap::Args)]
pub struct SimArgs {
    /// Nodes of the synthetic room.
    #[arg(long, default_value_t = 12)]
    synthetic: usize,
    /// Projectors (node agents) the nodes are split among.
    #[arg(long, default_value_t = 3)]
    projectors: usize,
    /// Seed of the room and of the camera noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The synthetic room's camera noise, in multiples of the patch noise (0: noiseless; a
    /// rendered room has its scene's).
    #[arg(long, default_value_t = 0.0)]
    noise: f64,
    /// Address to serve on (port 0: any free port, printed).
    #[arg(long, default_value = "127.0.0.1:50050")]
    listen: String,
    /// Where to write the synthetic room's model (the stand-in for calibration) for the
    /// camera agent. Required for a synthetic room.
    #[arg(long)]
    model_out: Option<PathBuf>,
    /// Serve a rendered room instead (the `RenderedRoom` service: projector images in, camera
    /// images out, LED presets): `default` (the embedded lab), `small`, or a scene TOML file.
    #[arg(long, conflicts_with_all = ["synthetic", "projectors", "model_out", "noise"])]
    scene: Option<String>,
    /// With --scene: the camera's resolution instead of the scene's, as WIDTHxHEIGHT.
    #[arg(long, requires = "scene")]
    camera: Option<String>,
    /// With --scene: PROJECTOR's frames are the screen region WxH+X+Y (its node agent's
    /// window), never ShowImage; a photograph goes to --photos per `.wanted` request of the
    /// `folder:` camera there. Once per projector shown.
    #[arg(long, requires_all = ["scene", "photos"], value_name = "PROJECTOR=WxH+X+Y")]
    grab: Vec<String>,
    /// With --grab: the camera's folder.
    #[arg(long, requires = "grab")]
    photos: Option<PathBuf>,
    /// With --grab: the X display (default: $DISPLAY).
    #[arg(long, requires = "grab")]
    x_display: Option<String>,
}

/// `roomlight calibrate`: calibrates a simulated room (in one process, through captures only)
/// and writes what the processes of a rendered room need.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// `default` (the embedded lab), `small`, or a scene TOML file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// The camera's resolution instead of the scene's, as WIDTHxHEIGHT.
    #[arg(long)]
    camera: Option<String>,
    /// The LED preset whose light the projectors reproduce (default: the first).
    #[arg(long)]
    preset: Option<String>,
    /// Seed of the camera noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Folder for model.json, charts.json and one frame-PROJECTOR.json per luminaire (with
    /// --survey-only: survey.json).
    #[arg(long)]
    out: PathBuf,
    /// Write only survey.json, what an installer configures once for calibration over the wire
    /// (chart corners, patch sampling, the target's camera mask), and calibrate nothing: the
    /// camera agent then calibrates each projector through its node agent as it joins.
    #[arg(long)]
    survey_only: bool,
}

/// Binds `listen`, prints where it serves, and runs `serve` until Ctrl-C or SIGTERM.
fn serve_until_stopped<Fut>(
    name: &str,
    listen: &str,
    serve: impl FnOnce(tokio::net::TcpListener, CancellationToken) -> Fut,
) -> Result<()>
where
    Fut: Future<Output = Result<()>>,
{
    runtime()?.block_on(async {
        let listener = tokio::net::TcpListener::bind(listen)
            .await
            .with_context(|| format!("binding {listen}"))?;
        announce(name, listener.local_addr()?);
        let cancel = CancellationToken::new();
        stop_on_signals(cancel.clone());
        serve(listener, cancel).await
    })
}

fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the runtime")
}

/// Logs to stderr, filtered by `RUST_LOG` (default: warnings), for every command: the agents'
/// warnings show in a bench or the demo as they do in a camera or node agent. Colours only on a
/// terminal: a file, a pipe or journald gets plain text.
///
/// Warnings and errors are also kept for the installer's console (its "last warnings"),
/// whatever `RUST_LOG` says.
pub(crate) fn init_logs() {
    use std::io::IsTerminal as _;
    use tracing_subscriber::prelude::*;
    let log = tracing_subscriber::fmt::layer()
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .with_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        );
    let kept = roomlight_console::warnings::Layer
        .with_filter(tracing_subscriber::filter::LevelFilter::WARN);
    let _ = tracing_subscriber::registry()
        .with(log)
        .with(kept)
        .try_init();
}

/// Cancels `token` on Ctrl-C or SIGTERM.
fn stop_on_signals(token: CancellationToken) {
    tokio::spawn(async move {
        let ctrl_c = tokio::signal::ctrl_c();
        #[cfg(unix)]
        {
            if let Ok(mut term) =
                tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
            {
                tokio::select! {
                    _ = ctrl_c => {}
                    _ = term.recv() => {}
                }
            } else {
                let _ = ctrl_c.await;
            }
        }
        #[cfg(not(unix))]
        let _ = ctrl_c.await;
        token.cancel();
    });
}

fn announce(what: &str, addr: std::net::SocketAddr) {
    println!("{what} listening on {addr}");
    let _ = std::io::stdout().flush();
}

/// `WIDTHxHEIGHT`, both positive.
fn resolution(size: Option<&str>) -> Result<Option<[u32; 2]>> {
    let Some(size) = size else { return Ok(None) };
    let parsed = size
        .split_once('x')
        .and_then(|(w, h)| Some([w.parse::<u32>().ok()?, h.parse::<u32>().ok()?]))
        .filter(|[w, h]| *w > 0 && *h > 0);
    match parsed {
        Some(r) => Ok(Some(r)),
        None => bail!("--camera {size:?}: expected WIDTHxHEIGHT, e.g. 640x480"),
    }
}

pub fn calibrate(args: &CalibrateArgs) -> Result<()> {
    process::calibrate_to_files(&CalibrateOptions {
        scene: args.scene.clone(),
        camera: resolution(args.camera.as_deref())?,
        preset: args.preset.clone(),
        seed: args.seed,
        out: args.out.clone(),
        survey_only: args.survey_only,
    })
}

pub fn sim(args: &SimArgs) -> Result<()> {
    let room = match &args.scene {
        Some(scene) => SimRoom::Rendered {
            scene: scene.clone(),
            camera: resolution(args.camera.as_deref())?,
            seed: args.seed,
            grab: grab_mode(args)?,
        },
        None => {
            let Some(model_out) = &args.model_out else {
                bail!("--model-out FILE is required for a synthetic room (or give --scene)");
            };
            SimRoom::Synthetic(SyntheticSim {
                nodes: args.synthetic,
                projectors: args.projectors,
                seed: args.seed,
                noise: args.noise,
                model_out: model_out.clone(),
            })
        }
    };
    let prepared = process::prepare_sim(&room)?;
    serve_until_stopped("sim", &args.listen, |listener, cancel| {
        prepared.serve(listener, cancel)
    })
}

fn grab_mode(args: &SimArgs) -> Result<Option<process::GrabMode>> {
    let Some(photos) = &args.photos else {
        return Ok(None);
    };
    let regions = args.grab.iter().map(|g| {
        let (p, region) = g.split_once('=').context("expected PROJECTOR=WxH+X+Y")?;
        Ok((p.to_string(), region.parse()?))
    });
    Ok(Some(process::GrabMode {
        x_display: args.x_display.clone(),
        regions: regions
            .collect::<Result<_>>()
            .with_context(|| format!("--grab {:?}", args.grab))?,
        photos: photos.clone(),
    }))
}

/// `roomlight optimum`: nodes, patches (and those left out), G* and G with every node black.
pub fn optimum(path: &Path) -> Result<()> {
    println!("{}", process::optimum_summary(path)?);
    Ok(())
}

/// With `check`: the config loaded, checked and printed, nothing run. `status_lines`: one
/// stdout line per round rather than the summary.
pub fn camera(path: &Path, check: bool, status_lines: bool) -> Result<()> {
    let mut process = config::load_camera(path)?;
    if status_lines {
        process.status_lines = process::StatusLines::EveryRound;
    }
    if check {
        println!("{process:#?}");
        return Ok(());
    }
    runtime()?.block_on(async {
        let cancel = CancellationToken::new();
        stop_on_signals(cancel.clone());
        process::serve_camera(process, |addr| announce("camera", addr), cancel).await
    })
}

/// `roomlight check --config FILE`: a camera agent's config (it has `listen`) or a node's.
pub fn check(path: &Path) -> Result<()> {
    let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
    let table = text.parse::<toml::Table>();
    let list = if table.is_ok_and(|t| t.contains_key("listen")) {
        runtime()?.block_on(process::check_camera(&config::load_camera(path)?))
    } else {
        let n = config::load_node(path)?;
        let camera = match &n.camera {
            CameraLocation::Address(a) => process::CameraAt::Address(a.clone()),
            CameraLocation::Mdns(r) => {
                process::CameraAt::Mdns(r.clone(), n.mdns.clone(), n.mdns_wait)
            }
        };
        let agent = n.agent_config(String::new());
        runtime()?.block_on(process::check_node(
            &agent,
            n.tls.as_ref(),
            &camera,
            &n.hardware,
            &n.display,
        ))
    };
    print!("{list}");
    if let Some(failed) = list.first_failure() {
        bail!("{}: {failed}", path.display());
    }
    println!("{}: every check passed", path.display());
    Ok(())
}

pub fn node(path: &Path, check: bool) -> Result<()> {
    let setup = config::load_node(path)?;
    if check {
        println!("{setup:#?}");
        return Ok(());
    }
    let endpoint = match &setup.camera {
        CameraLocation::Address(address) => address.clone(),
        // The node agent tries each candidate advertising the room, skipping any that refuses it.
        CameraLocation::Mdns(room) => discovery::mdns_endpoint(room, &setup.mdns, setup.mdns_wait),
    };
    let agent = setup.agent_config(endpoint);
    runtime()?.block_on(async {
        let cancel = CancellationToken::new();
        stop_on_signals(cancel.clone());
        process::run_node(
            agent,
            setup.tls.clone(),
            &setup.hardware,
            &setup.display,
            cancel,
        )
        .await
        .with_context(|| format!("the node agent of {}", path.display()))
    })
}
