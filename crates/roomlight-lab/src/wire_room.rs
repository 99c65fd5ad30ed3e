//! A simulated room run over the wire in one process, as a real room runs: the rendered room
//! served on loopback (whole projector images in, noisy camera images out, LEDs switched by
//! name), the camera agent on its camera with a survey (the room's black and first preset
//! measured through the charts, the projection-mapping target masked) and the room's LEDs, and
//! a node agent per luminaire projector drawing into the rendered projectors. Nothing is
//! calibrated beforehand: the camera agent brings the room up over the wire.
//!
//! What it adds to the agents is the judge: the simulator's noiseless truth of what the
//! projectors show, against the LEDs' light ([`WireRoom::judge`]). `roomlight bench shading`
//! and the integration tests drive it.
//!
//! A run is the same at a fixed seed on every run and machine: each capture is held until the
//! driver has handled the camera agent's last status ([`crate::pipeline::gate`]), so a preset
//! is chosen, and the room judged, exactly after the rounds of the capture whose status asked
//! for it ([`WireRoom::until`], [`WireRoom::preset`]).

use crate::dark_target::target_light;
use crate::pipeline::gate::Gate;
use crate::pipeline::{chart_corners, image, sample_config};
use crate::rendered::{self, Rendered, RenderedCamera, rendered_display};
use crate::whole_room::{Reach, ReachMap, delta_e_map, luminaires, map_image, white_luminance};
use anyhow::{Context, Result, bail, ensure};
use roomlight_agent::AgentError;
use roomlight_agent::camera::{
    self, CameraConfig, Control, Extras, Lights, RoomModel, RoomStatus, Survey, SurveyPhotographs,
};
use roomlight_agent::node::{self, NodeConfig};
use roomlight_calib::charts::{PatchStatus, sample_charts};
use roomlight_calib::image_io::LinearImage;
use roomlight_core::metrics::patch_delta_e;
use roomlight_core::{LinearRgb, StepRule};
use roomlight_proto::v1;
use roomlight_sim::scene::{ProjectorKind, ProjectorRole};
use roomlight_sim::{Capture, Frame, Room};
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio_util::sync::{CancellationToken, DropGuard};

/// How the camera agent runs.
#[derive(Debug, Clone, Copy)]
pub struct Options {
    /// Per-pixel shading passes per target (`CameraConfig::shading_passes`).
    pub shading_passes: usize,
    /// Model rounds per capture.
    pub model_rounds: usize,
    /// The rendered room's camera noise.
    pub seed: u64,
    /// The camera agent gets the survey's photographs (dark, LEDs): shading follows the
    /// bring-up. Without, it waits for a preset chosen from the console.
    pub survey_photographs: bool,
    /// The camera agent writes its model file (and the shading's inputs beside it) into a
    /// temporary folder, so that it can be restarted from them ([`WireRoom::restart_camera`]).
    pub model_file: bool,
    /// The weight of the light on the target in the luminaires' objective (`Survey::new`;
    /// 0: the charts alone).
    pub dark_weight: f64,
}

/// What starting (or restarting) the camera agent takes.
struct CameraSetup {
    client: rendered::Client,
    corners: Vec<roomlight_calib::charts::ChartCorners>,
    sample: roomlight_calib::charts::SampleConfig,
    config: CameraConfig,
    lights: Arc<RoomLights>,
    survey: Survey,
    /// Where node agents reach it.
    at: std::net::SocketAddr,
    /// Holds the model file.
    _folder: Option<tempfile::TempDir>,
}

impl CameraSetup {
    /// Starts the camera agent on `listener` (bound to `self.at`) with `model` and `patches`
    /// until `cancel`; its captures held by a new gate.
    fn start(
        &self,
        listener: tokio::net::TcpListener,
        model: RoomModel,
        patches: Vec<usize>,
        preset: Option<String>,
        photographs: Option<SurveyPhotographs>,
        cancel: CancellationToken,
    ) -> (camera::Served, Arc<Gate>) {
        let gate = Arc::new(Gate::new());
        let camera = RenderedCamera::new(
            self.client.clone(),
            self.corners.clone(),
            patches,
            self.sample,
        )
        .with_gate(gate.clone());
        let extras = Extras {
            lights: Some(self.lights.clone()),
            preset,
            photographs,
        };
        let served = camera::serve_room(
            self.config.clone(),
            model,
            camera,
            listener,
            None,
            extras,
            cancel,
        );
        gate.follow(served.status.clone());
        (served, gate)
    }
}

/// The rendered room's LEDs, switched through its camera's client.
#[derive(Clone)]
struct RoomLights {
    camera: RenderedCamera,
    presets: Vec<String>,
}

impl Lights for RoomLights {
    fn presets(&self) -> Vec<String> {
        self.presets.clone()
    }

    fn switch(
        &self,
        preset: Option<String>,
    ) -> Pin<Box<dyn Future<Output = Result<(), String>> + Send + '_>> {
        Box::pin(async move {
            self.camera
                .set_lights(preset.as_deref().unwrap_or(""))
                .await
                .map_err(|e| e.to_string())
        })
    }
}

/// The room running over the wire; dropping it stops every agent, [`WireRoom::stop`] also
/// joins them.
pub struct WireRoom {
    pub room: Arc<Room>,
    rendered: Rendered,
    /// The camera agent's status; read it through [`WireRoom::until`], which lets each
    /// capture go once its status is handled.
    status: watch::Receiver<RoomStatus>,
    /// The console's requests; a preset through [`WireRoom::preset`], which holds the gate.
    control: Control,
    gate: Arc<Gate>,
    agent: JoinHandle<Result<(), AgentError>>,
    /// Stops the camera agent alone.
    camera: CancellationToken,
    setup: CameraSetup,
    nodes: Vec<JoinHandle<Result<(), AgentError>>>,
    /// Stops the agents.
    agents: CancellationToken,
    /// Stops everything (the rendered room too) when dropped.
    guard: DropGuard,
}

impl std::fmt::Debug for WireRoom {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WireRoom")
            .field("room", &self.room.scene().name)
            .field("status", &*self.status.borrow())
            .finish_non_exhaustive()
    }
}

/// The camera agent's model before any projector, as `roomlight camera` with a survey measures
/// it: the room's black (LEDs off) and target (its first preset) through the charts (and with
/// `dark_weight` > 0 the target's patches, kept at the black level with that weight,
/// [`Survey::model`]), the patches both measure, and the target's camera pixels masked; and
/// the two photographs.
pub async fn survey_model(
    room: &Room,
    camera: &RenderedCamera,
    dark_weight: f64,
) -> Result<(RoomModel, Vec<usize>, SurveyPhotographs)> {
    let corners = chart_corners(room)?;
    let sample = sample_config(room);
    let Some(preset) = room.scene().presets.first().map(|p| p.name.clone()) else {
        bail!("{}: no LED preset to reproduce", room.scene().name);
    };
    let photograph = async |lights: &str| -> Result<LinearImage> {
        camera.set_lights(lights).await?;
        Ok(camera.image().await?)
    };
    let dark = photograph("").await?;
    let leds = photograph(&preset).await?;
    camera.set_lights("").await?;
    let [w, h] = room.scene().camera.resolution;
    let survey = Survey::new(
        corners,
        sample,
        room.pixels().iter().map(|p| p.target).collect(),
        (w, h),
        dark_weight,
    )?;
    let (black, lit) = (survey.sample(&dark)?, survey.sample(&leds)?);
    let (problem, survey) = survey.model(&black, &lit)?;
    let patches = survey.patches.clone();
    let model = RoomModel {
        problem,
        owners: Default::default(),
        start: None,
        hot: Default::default(),
        survey: Some(survey),
    };
    Ok((model, patches, SurveyPhotographs { dark, leds }))
}

impl WireRoom {
    /// Serves `room` and starts the camera agent and a node agent per luminaire, together.
    pub async fn start(room: Arc<Room>, options: Options) -> Result<Self> {
        // The rendered room stops after the agents (their displays' last frames land).
        let served = CancellationToken::new();
        let cancel = served.child_token();
        let guard = served.clone().drop_guard();
        let hardware = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let hardware_at = format!("http://{}", hardware.local_addr()?);
        let rendered = Rendered::new(room.clone(), options.seed, false);
        tokio::spawn(rendered::serve_rendered(rendered.clone(), hardware, served));
        let client = rendered::connect(hardware_at).await?;
        let corners = chart_corners(&room)?;
        let sample = sample_config(&room);
        let probe = RenderedCamera::new(client.clone(), corners.clone(), Vec::new(), sample);
        let (model, patches, photographs) =
            survey_model(&room, &probe, options.dark_weight).await?;
        let folder = if options.model_file {
            Some(tempfile::tempdir().context("a folder for the model file")?)
        } else {
            None
        };
        let config = CameraConfig {
            room: room.scene().name.clone(),
            token: "wire-room".into(),
            heartbeat: Duration::from_millis(200),
            deadline: Duration::from_secs(10),
            model_rounds: options.model_rounds,
            calibration_epoch: 1,
            stale_frames: 0,
            model_out: folder.as_ref().map(|f| f.path().join("model.json")),
            primaries: true,
            shading_passes: options.shading_passes,
        };
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let at = listener.local_addr()?;
        let endpoint = format!("http://{at}");
        let Some(survey) = model.survey.clone() else {
            bail!("the survey's model has no survey");
        };
        let setup = CameraSetup {
            client: client.clone(),
            corners,
            sample,
            config,
            lights: Arc::new(RoomLights {
                camera: probe,
                presets: room
                    .scene()
                    .presets
                    .iter()
                    .map(|p| p.name.clone())
                    .collect(),
            }),
            survey,
            at,
            _folder: folder,
        };
        let camera_cancel = cancel.child_token();
        let (
            camera::Served {
                status,
                control,
                handle,
            },
            gate,
        ) = setup.start(
            listener,
            model,
            patches,
            room.scene().presets.first().map(|p| p.name.clone()),
            options.survey_photographs.then_some(photographs),
            camera_cancel.clone(),
        );
        let mut nodes = Vec::new();
        for p in room
            .scene()
            .projectors
            .iter()
            .filter(|p| p.role == ProjectorRole::Luminaire)
        {
            let [w, h] = p.resolution;
            let display =
                rendered_display(client.clone(), p.name.clone(), (w, h), None, cancel.clone());
            let config = NodeConfig {
                endpoint: endpoint.clone(),
                room: room.scene().name.clone(),
                token: "wire-room".into(),
                projector_id: p.name.clone(),
                kind: match p.kind {
                    ProjectorKind::LargeAperture => v1::ProjectorKind::LargeAperture,
                    _ => v1::ProjectorKind::Standard,
                },
                rule: StepRule::Momentum { theta: 1.0 },
                start: LinearRgb::splat(0.5),
                state_file: None,
            };
            nodes.push(tokio::spawn(node::run(config, display, cancel.clone())));
        }
        Ok(Self {
            room,
            rendered,
            status,
            control,
            gate,
            agent: handle,
            camera: camera_cancel,
            setup,
            nodes,
            agents: cancel,
            guard,
        })
    }

    /// The first status for which `done` holds, within `limit`, once the camera agent holds
    /// its next capture (what the projectors show is then final, and the status is the
    /// driver's to act on); an error naming `what` and the last status otherwise. Every
    /// status before it is handled (its next capture goes); that one is not, until the next
    /// call ([`WireRoom::until`], [`WireRoom::preset`], [`WireRoom::stop`]).
    pub async fn until(
        &mut self,
        limit: Duration,
        what: &str,
        done: impl Fn(&RoomStatus) -> bool,
    ) -> Result<RoomStatus> {
        let started = tokio::time::Instant::now();
        let status = &mut self.status;
        let gate = &self.gate;
        let waited = tokio::time::timeout(limit, async {
            loop {
                let now = status.borrow_and_update().clone();
                if done(&now) {
                    return Ok(now);
                }
                gate.handled(now.captures);
                if status.changed().await.is_err() {
                    bail!("the camera agent stopped before {what}");
                }
            }
        })
        .await;
        let found = match waited {
            Ok(status) => status?,
            Err(_) => bail!(
                "{what}: not within {limit:?}; last status {:?}",
                self.status.borrow()
            ),
        };
        let left = limit.saturating_sub(started.elapsed());
        self.gate
            .held(found.captures, left)
            .await
            .with_context(|| format!("after {what}"))?;
        Ok(found)
    }

    /// Chooses LED preset `preset` from the console, as an installer would, right after the
    /// rounds of the capture [`WireRoom::until`] last returned: it is asked for while that
    /// capture is held, so the camera agent reads it after the capture's rounds. The statuses
    /// meanwhile are handled; returns once the preset's light is measured.
    pub async fn preset(&mut self, preset: &str) -> Result<()> {
        let asked = self.control.preset(preset.to_string());
        tokio::pin!(asked);
        // The request is queued on the first poll (the console's queue is not awaited).
        let answer = tokio::select! {
            biased;
            answer = &mut asked => Some(answer),
            () = std::future::ready(()) => None,
        };
        let answer = match answer {
            Some(answer) => answer,
            // Queued: the held capture goes, and every status until the answer is handled.
            None => loop {
                self.gate.handled(self.status.borrow_and_update().captures);
                tokio::select! {
                    answer = &mut asked => break answer,
                    changed = self.status.changed() => if changed.is_err() {
                        bail!("the camera agent stopped before preset {preset}");
                    },
                }
            },
        };
        answer.map_err(|e| anyhow::anyhow!("preset {preset}: {e}"))
    }

    /// Stops the camera agent and starts it again on the same address from the model file it
    /// wrote (and the shading's inputs beside it), as `roomlight camera` resumes after a
    /// restart: nothing is measured again, the node agents keep their light and reconnect.
    /// Needs [`Options::model_file`].
    pub async fn restart_camera(&mut self) -> Result<()> {
        let Some(path) = self.setup.config.model_out.clone() else {
            bail!("the camera agent keeps no model file (Options::model_file)");
        };
        self.gate.open();
        self.camera.cancel();
        (&mut self.agent).await.context("camera agent task")??;
        let file = crate::process::load_model(&path)?;
        let patches = file
            .patches
            .with_context(|| format!("{}: no patches", path.display()))?;
        let model = RoomModel {
            problem: file.problem,
            owners: file.owners,
            start: file.start,
            hot: Default::default(),
            survey: Some(self.setup.survey.clone().with_patches(patches.clone())),
        };
        // The same address: the node agents reconnect to it.
        let at = self.setup.at;
        let listener = tokio::net::TcpListener::bind(at)
            .await
            .with_context(|| format!("listening on {at} again"))?;
        self.camera = self.agents.child_token();
        let (served, gate) =
            self.setup
                .start(listener, model, patches, None, None, self.camera.clone());
        self.status = served.status;
        self.control = served.control;
        self.agent = served.handle;
        self.gate = gate;
        Ok(())
    }

    /// The camera agent's model file, with [`Options::model_file`].
    pub fn model_file(&self) -> Option<&std::path::Path> {
        self.setup.config.model_out.as_deref()
    }

    /// The camera agent's model now (its patches' targets, black, noise and every node's
    /// column, weighed as it runs them).
    pub fn problem(&self) -> roomlight_core::Problem {
        self.control.problem()
    }

    /// The camera agent's latest status.
    pub fn status(&self) -> RoomStatus {
        self.status.borrow().clone()
    }

    /// What the projectors show now, against LED preset `preset`: see [`Judged`].
    pub fn judge(&self, preset: usize) -> Result<Judged> {
        Ok(judge(&self.room, &self.rendered.frames(), preset)?.0)
    }

    /// What each of the room's projectors shows now, in the room's order.
    pub fn frames(&self) -> Vec<Frame> {
        self.rendered.frames()
    }

    /// [`WireRoom::judge`], with its ΔE00 map ([`crate::whole_room::map_image`]: the target's
    /// pixels shown as undriven, the rest no luminaire lights directly as outside).
    pub fn judge_map(&self, preset: usize) -> Result<(Judged, image::RgbImage)> {
        let (judged, de, reach) = judge(&self.room, &self.rendered.frames(), preset)?;
        Ok((judged, map_image(&de, &reach)?))
    }

    /// Stops every agent and joins them; an error when one failed.
    pub async fn stop(self) -> Result<()> {
        self.gate.open();
        self.agents.cancel();
        self.agent.await.context("camera agent task")??;
        for n in self.nodes {
            n.await.context("node agent task")??;
        }
        drop(self.guard);
        Ok(())
    }
}

/// The room lit by the projectors against the LEDs, from the simulator's noiseless renders.
#[derive(Debug, Clone, Copy)]
pub struct Judged {
    /// Mean and 95th percentile ΔE00 over the camera pixels some luminaire lights directly
    /// (the simulator's direct factors; the target's pixels left out).
    pub de00_mean: f64,
    pub de00_p95: f64,
    /// Mean ΔE00 over the charts' patches that luminaires light directly all over.
    pub charts_de00: f64,
    /// Light on the target as a share of the LEDs' (`None`: no target, or no LED light on it).
    pub target_share: Option<f64>,
}

/// See [`WireRoom::judge`]; with the ΔE00 map and which pixels it counts.
fn judge(room: &Room, frames: &[Frame], preset: usize) -> Result<(Judged, Vec<f64>, ReachMap)> {
    let black = vec![Frame::Black; room.projectors().len()];
    let truth = room.render(&black, Some(preset))?;
    let lit = room.render(frames, None)?;
    let dark = room.render(&black, None)?;
    let on_target: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let surface: Vec<bool> = room.pixels().iter().map(|p| p.point.is_some()).collect();
    let white = white_luminance(&truth, &surface)?;
    let factors: Vec<&[f32]> = luminaires(room)
        .into_iter()
        .map(|k| room.direct_factor(k))
        .collect();
    let reached =
        |i: usize| !on_target[i] && factors.iter().any(|f| f.get(i).is_some_and(|v| *v > 0.0));
    let de = delta_e_map(&truth, &lit, white)?;
    let mut values: Vec<f64> = de
        .iter()
        .enumerate()
        .filter(|(i, _)| reached(*i))
        .map(|(_, e)| *e)
        .collect();
    ensure!(!values.is_empty(), "no camera pixel is lit by a luminaire");
    values.sort_by(f64::total_cmp);
    let de00_mean = values.iter().sum::<f64>() / values.len() as f64;
    let de00_p95 = values[(values.len() * 95 / 100).min(values.len() - 1)];
    // Each patch's share of directly reached pixels, sampled as the charts are (a patch at
    // half light where reached; sampling refuses saturated ones).
    let corners = chart_corners(room)?;
    let sample = sample_config(room);
    let reach_image = LinearImage {
        width: truth.width,
        height: truth.height,
        pixels: (0..truth.pixels.len())
            .map(|i| [if reached(i) { 0.5 } else { 0.0 }; 3])
            .collect(),
    };
    let direct: Vec<bool> = sample_charts(&reach_image, &corners, &sample)?
        .iter()
        .map(|s| s.status == PatchStatus::Ok && s.mean[0] > 0.495)
        .collect();
    let at = |c: &Capture| -> Result<Vec<LinearRgb>> {
        Ok(sample_charts(&image(c), &corners, &sample)?
            .into_iter()
            .zip(&direct)
            .filter(|(_, d)| **d)
            .map(|(s, _)| s.mean)
            .collect())
    };
    let charts_de00 = patch_delta_e(&at(&truth)?, &at(&lit)?)
        .context("the charts' patches lit directly")?
        .mean;
    let target_share = if on_target.contains(&true) {
        let led_on_target = target_light(&truth, &dark, &on_target)?;
        (led_on_target > 0.0)
            .then(|| target_light(&lit, &dark, &on_target))
            .transpose()?
            .map(|l| l / led_on_target)
    } else {
        None
    };
    let judged = Judged {
        de00_mean,
        de00_p95,
        charts_de00,
        target_share,
    };
    let reach = ReachMap {
        width: truth.width as usize,
        height: truth.height as usize,
        reach: (0..de.len())
            .map(|i| match (reached(i), on_target[i], surface[i]) {
                (true, _, _) => Reach::Reached,
                (false, true, _) => Reach::NoNode,
                (false, false, true) => Reach::Outside,
                (false, false, false) => Reach::NoSurface,
            })
            .collect(),
        lit_by: vec![0; de.len()],
    };
    Ok((judged, de, reach))
}
