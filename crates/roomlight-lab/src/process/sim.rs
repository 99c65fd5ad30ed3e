//! `roomlight sim`: the simulated hardware as a process — a synthetic room served as
//! `VirtualHardware` (its model written as the stand-in for calibration), or the rendered room
//! served as `RenderedRoom`, its frames from `ShowImage` or, in grab mode, from the screen
//! (`photos`).

use super::files::{ModelFile, load_scene, write_json};
use super::photos::{GrabMode, shoot_on_request};
use crate::rendered::Rendered;
use anyhow::{Context, Result, bail};
use roomlight_agent::hardware::VirtualRoom;
use roomlight_agent::remote::serve_hardware;
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_sim::Room;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use tokio_util::sync::CancellationToken;

/// A synthetic room split among projectors.
#[derive(Debug, Clone)]
pub struct SyntheticSim {
    /// Nodes of the room.
    pub nodes: usize,
    /// Projectors (node agents) the nodes are split among, in order.
    pub projectors: usize,
    /// Seed of the room and of the camera noise.
    pub seed: u64,
    /// Camera noise, in multiples of the patch noise (0: noiseless).
    pub noise: f64,
    /// Where the room's model goes, for the camera agent.
    pub model_out: PathBuf,
}

/// Which room the process serves.
#[derive(Debug, Clone)]
pub enum SimRoom {
    Synthetic(SyntheticSim),
    /// A scene by name or file (see `load_scene`), camera noise from `seed`; with `grab`, its
    /// frames from the screen and its photographs written as files.
    Rendered {
        scene: String,
        camera: Option<[u32; 2]>,
        seed: u64,
        grab: Option<GrabMode>,
    },
}

/// A room built and ready to serve (building a rendered room takes a while; its files are
/// written before anything listens).
#[derive(Debug)]
pub enum PreparedSim {
    Synthetic(VirtualRoom),
    Rendered {
        room: Arc<Room>,
        seed: u64,
        /// Grab mode with each projector's region, checked against the room.
        grab: Option<(GrabMode, Vec<Option<roomlight_hw::Geometry>>)>,
    },
}

/// Builds the room; a synthetic room's model file is written here.
pub fn prepare_sim(which: &SimRoom) -> Result<PreparedSim> {
    match which {
        SimRoom::Rendered {
            scene,
            camera,
            seed,
            grab,
        } => {
            let room = Room::build(load_scene(scene, *camera)?)
                .with_context(|| format!("building the room of {scene}"))?;
            let grab = match grab {
                Some(g) => Some((g.clone(), g.regions_of(&room)?)),
                None => None,
            };
            Ok(PreparedSim::Rendered {
                room: Arc::new(room),
                seed: *seed,
                grab,
            })
        }
        SimRoom::Synthetic(s) => synthetic(s).map(PreparedSim::Synthetic),
    }
}

fn synthetic(s: &SyntheticSim) -> Result<VirtualRoom> {
    if s.projectors == 0 || s.nodes < s.projectors {
        bail!(
            "{} projectors for {} nodes: expected between 1 and the number of nodes",
            s.projectors,
            s.nodes
        );
    }
    let problem = synthetic_room(&SyntheticConfig::new(s.nodes, s.seed))?.problem;
    let per = s.nodes.div_ceil(s.projectors);
    let owners: HashMap<String, Vec<u32>> = (0..s.projectors)
        .map(|p| {
            (
                format!("p{p}"),
                ((p * per) as u32..((p + 1) * per).min(s.nodes) as u32).collect(),
            )
        })
        .filter(|(_, nodes): &(String, Vec<u32>)| !nodes.is_empty())
        .collect();
    let model = ModelFile {
        problem: problem.clone(),
        owners,
        start: None,
        patches: None,
        dark_target_weight: None,
    };
    write_json(&s.model_out, &model)?;
    let plant = Plant::new(
        problem,
        PlantConfig {
            noise_scale: s.noise,
            seed: s.seed,
            ..PlantConfig::default()
        },
    )?;
    Ok(VirtualRoom::new(plant))
}

impl PreparedSim {
    /// Serves the room on `listener` until `cancel`.
    pub async fn serve(
        self,
        listener: tokio::net::TcpListener,
        cancel: CancellationToken,
    ) -> Result<()> {
        match self {
            Self::Synthetic(room) => Ok(serve_hardware(room, listener, cancel).await?),
            Self::Rendered {
                room,
                seed,
                grab: None,
            } => crate::rendered::serve(room, seed, listener, cancel).await,
            Self::Rendered {
                room,
                seed,
                grab: Some((grab, regions)),
            } => {
                let rendered = Rendered::new(room, seed, true);
                // Ends both the service and the shooter: a sim that cannot grab serves nothing.
                let stop = cancel.child_token();
                let mut shooter = {
                    let (rendered, stop) = (rendered.clone(), stop.clone());
                    tokio::task::spawn_blocking(move || {
                        shoot_on_request(&rendered, &grab, &regions, &stop)
                    })
                };
                let served = crate::rendered::serve_rendered(rendered, listener, stop.clone());
                tokio::pin!(served);
                let (served, shot) = tokio::select! {
                    r = &mut served => {
                        stop.cancel();
                        (r, shooter.await)
                    }
                    r = &mut shooter => {
                        stop.cancel();
                        (served.await, r)
                    }
                };
                shot.context("the grab task")??;
                served
            }
        }
    }
}
