//! `roomlight node`: the projector a node agent drives — the synthetic room's node values, a
//! rendered room's projector drawing its nodes' weights, or a real window on an output
//! (roomlight-hw).

use super::systemd::{ReadyOnShow, with_watchdog};
use anyhow::{Context, Result, bail};
use roomlight_agent::node::{self, NodeConfig};
use roomlight_agent::remote::{QueuedDisplay, remote_display};
use roomlight_proto::v1;
use std::path::PathBuf;
use tokio_util::sync::CancellationToken;

/// What the node agent's projector shows.
#[derive(Debug, Clone)]
pub enum NodeDisplay {
    /// The synthetic room's node values.
    Synthetic,
    /// A rendered room's projector with its frame file (weights and response from
    /// `roomlight calibrate`).
    Frame(PathBuf),
    /// A rendered room's projector calibrated over the wire: it shows the camera agent's
    /// patterns and draws the weights it is sent.
    OverTheWire,
    /// A real projector: a fullscreen window on an output (no simulator).
    Window(roomlight_hw::WindowSpec),
}

/// Backoff between attempts to open a window display at start: from 200 ms, doubling, at
/// most 5 s.
const OPEN_FIRST: std::time::Duration = std::time::Duration::from_millis(200);
const OPEN_MAX: std::time::Duration = std::time::Duration::from_secs(5);

/// Connects the display at `hardware` and runs the node agent until `cancel` (over TLS with
/// `tls`).
pub async fn run_node(
    config: NodeConfig,
    tls: Option<roomlight_agent::tls::ClientTls>,
    hardware: &str,
    display: &NodeDisplay,
    cancel: CancellationToken,
) -> Result<()> {
    let projector = config.projector_id.clone();
    if let NodeDisplay::Window(spec) = display {
        let Some(window) = open_window(spec, &projector, &cancel).await else {
            return Ok(());
        };
        let window = ReadyOnShow::new(window, &projector);
        with_watchdog(node::run_tls(config, tls, window, cancel)).await?;
        return Ok(());
    }
    let display = connect(hardware, display, &projector, &cancel).await?;
    let display = ReadyOnShow::new(display, &projector);
    with_watchdog(node::run_tls(config, tls, display, cancel)).await?;
    Ok(())
}

/// Opens the window display, retrying with backoff (logged) until it opens: a projector
/// switched on after its node agent, or an X session that starts later, is waited for. `None`
/// once cancelled.
async fn open_window(
    spec: &roomlight_hw::WindowSpec,
    projector: &str,
    cancel: &CancellationToken,
) -> Option<roomlight_hw::WindowDisplay> {
    let mut backoff = OPEN_FIRST;
    loop {
        match roomlight_hw::WindowDisplay::open(spec, projector) {
            Ok(window) => {
                tracing::info!(output = %window.output_name(), "window display open");
                return Some(window);
            }
            Err(e) => {
                tracing::warn!(output = %spec.output, error = %e, ?backoff, "window display not available; retrying")
            }
        }
        tokio::select! {
            () = cancel.cancelled() => return None,
            () = tokio::time::sleep(backoff) => {}
        }
        backoff = (backoff * 2).min(OPEN_MAX);
    }
}

async fn connect(
    hardware: &str,
    display: &NodeDisplay,
    projector: &str,
    cancel: &CancellationToken,
) -> Result<QueuedDisplay> {
    let rendered = || async {
        crate::rendered::connect(hardware.to_string())
            .await
            .with_context(|| format!("connecting to the rendered room at {hardware}"))
    };
    match display {
        NodeDisplay::Window(_) => bail!("a window display is opened by run_node"),
        NodeDisplay::Synthetic => remote_display(hardware.to_string(), cancel.clone())
            .await
            .with_context(|| format!("connecting to the display at {hardware}")),
        NodeDisplay::Frame(path) => {
            let spec: crate::rendered::FrameSpec = super::files::read_json(path, "a frame file")?;
            if spec.projector != projector {
                bail!(
                    "{}: drawn for projector {:?}, this node agent is {projector:?}",
                    path.display(),
                    spec.projector,
                );
            }
            let (name, size) = (spec.projector.clone(), (spec.width, spec.height));
            let client = rendered().await?;
            Ok(crate::rendered::rendered_display(
                client,
                name,
                size,
                Some(spec),
                cancel.clone(),
            ))
        }
        NodeDisplay::OverTheWire => {
            let client = rendered().await?;
            // The projector reports its own mode, as a real display does.
            let room = client
                .clone()
                .describe(v1::DescribeRequest {})
                .await
                .context("describing the rendered room")?
                .into_inner();
            let Some(p) = room.projectors.iter().find(|p| p.name == projector) else {
                bail!(
                    "projector {projector:?}: the rendered room has {}",
                    room.projectors
                        .iter()
                        .map(|p| p.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            };
            Ok(crate::rendered::rendered_display(
                client,
                p.name.clone(),
                (p.width, p.height),
                None,
                cancel.clone(),
            ))
        }
    }
}
