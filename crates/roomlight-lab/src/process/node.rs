//! `roomlight node` on simulated hardware: the projector a node agent drives — the synthetic
//! room's node values, or a rendered room's projector drawing its nodes' weights.

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
}

/// Connects the display at `hardware` and runs the node agent until `cancel`.
pub async fn run_node(
    config: NodeConfig,
    hardware: &str,
    display: &NodeDisplay,
    cancel: CancellationToken,
) -> Result<()> {
    let display = connect(hardware, display, &config.projector_id, &cancel).await?;
    node::run(config, display, cancel).await?;
    Ok(())
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
