//! What an operator (the installer's console) sees of a running camera agent beyond its
//! [`RoomStatus`](super::RoomStatus), and what it may ask of it: pause and resume the rounds,
//! measure projectors again, reproduce another LED preset, show a projector's identify pattern,
//! photograph the room now. Requests travel on a bounded channel to the round loop, which
//! carries them out between two rounds (never inside one) and answers each on its own oneshot;
//! what the console reads (photographs, coverage, attenuation, frames) is published or copied
//! under short read locks, so serving it costs the rounds nothing but those copies.

use super::Shared;
use roomlight_calib::image_io::LinearImage;
use roomlight_core::LinearRgb;
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{mpsc, oneshot, watch};

/// What the console follows beyond the rounds: published on its own watch whenever it
/// changes (the projectors at most five times a second).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Overview {
    /// The rounds are paused by the console (the projectors keep their light).
    pub paused: bool,
    /// Times the target changed (another LED preset measured): each restarts the rounds.
    pub restarts: u64,
    /// The LED preset reproduced, when known.
    pub preset: Option<String>,
    /// The attached projectors, by id.
    pub projectors: Vec<ProjectorStatus>,
    /// The calibration running now.
    pub calibrating: Option<CalibrationProgress>,
    /// Each projector's last calibration (or failed attempt), by id.
    pub calibrations: Vec<CalibrationResult>,
}

/// A projector as the console lists it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProjectorStatus {
    pub id: String,
    pub state: ProjectorState,
    /// Nodes it owns in the model (none before its calibration over the wire).
    pub nodes: usize,
    /// The last frame (round or pattern sequence number) its node agent acknowledged.
    pub shown: Option<u64>,
    /// Its resolution, as its Hello said.
    pub width: u32,
    pub height: u32,
}

/// Where a projector is in its life.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProjectorState {
    /// Admitted; it has shown nothing yet.
    Connecting,
    /// Waiting for its calibration (another runs, or its retry is not due).
    Waiting,
    /// Being measured now.
    Calibrating,
    /// In the rounds.
    Live,
    /// Left out of the last round: it had not shown its frame by the deadline.
    Late,
    /// Its node agent says its display is lost.
    DisplayLost,
}

impl ProjectorState {
    /// The state's name on the console.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Connecting => "connecting",
            Self::Waiting => "waiting",
            Self::Calibrating => "calibrating",
            Self::Live => "live",
            Self::Late => "late",
            Self::DisplayLost => "display lost",
        }
    }
}

/// A calibration running now.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CalibrationProgress {
    /// The projectors measured together.
    pub projectors: Vec<String>,
    /// The step running (`Dark`, `StructuredLight`, `Attenuation`, `Hot`…).
    pub stage: String,
    /// Captures taken so far.
    pub done: usize,
    /// Captures the steps begun so far plan, a lower bound of the total until the last step.
    pub expected: usize,
}

/// A projector's last calibration, as the console shows it.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationResult {
    pub projector: String,
    /// The share of camera pixels its structured light decoded (`None`: only its attenuation
    /// was measured, hot).
    pub decoded: Option<f64>,
    /// Its nodes.
    pub nodes: usize,
    /// Captures its calibration took (shared with the projectors measured with it).
    pub captures: usize,
    /// The round count when it ended.
    pub at_round: u64,
    /// What went wrong or looked doubtful (it failed, a second pass was needed…).
    pub warnings: Vec<String>,
}

/// The latest photograph of the room, whole (the console scales it down off the round loop).
#[derive(Debug, Clone)]
pub struct Photo {
    /// Counts photographs published since the agent started.
    pub seq: u64,
    pub image: Arc<LinearImage>,
}

/// Switches the room's LEDs, for measuring an LED preset's light (`None`: off). The lab's
/// rendered room and the manual `lights` of a physical room implement it.
pub trait Lights: Send + Sync + 'static {
    /// The presets the room's LEDs can show.
    fn presets(&self) -> Vec<String>;

    /// Switches to `preset` (`None`: every LED off); an error says why it could not.
    fn switch(
        &self,
        preset: Option<String>,
    ) -> Pin<Box<dyn Future<Output = Result<(), String>> + Send + '_>>;
}

/// What a console asks of the round loop.
#[derive(Debug)]
pub(super) enum Request {
    Pause(bool),
    /// Measure these projectors again (`None`: every attached one); answers the ids queued.
    Calibrate(
        Option<String>,
        oneshot::Sender<Result<Vec<String>, Refused>>,
    ),
    /// Reproduce this LED preset from now on.
    Preset(String, oneshot::Sender<Result<(), Refused>>),
    /// A photograph now; answers its sequence number and full size.
    Photograph(oneshot::Sender<Result<(u64, u32, u32), Refused>>),
}

/// Why a request was not carried out.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    #[error("no projector {0:?} is attached")]
    UnknownProjector(String),
    #[error("the room has no LED preset {0:?} (it has: {1})")]
    UnknownPreset(String, String),
    #[error("this camera agent cannot switch the room's LEDs")]
    NoLights,
    #[error("the camera: {0}")]
    Camera(String),
    #[error("the LEDs: {0}")]
    Lights(String),
    #[error("{0}")]
    Model(String),
    #[error("the camera agent is stopping")]
    Stopping,
    #[error("too many requests are waiting; try again")]
    Busy,
}

/// A handle on a running camera agent for its console: cheap to clone; every call is bounded
/// (a full request queue is refused, never waited on).
#[derive(Clone)]
pub struct Control {
    pub(super) shared: Arc<Shared>,
    pub(super) requests: mpsc::Sender<Request>,
    pub(super) photos: watch::Receiver<Option<Photo>>,
    pub(super) overview: watch::Receiver<Overview>,
}

impl std::fmt::Debug for Control {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Control").finish_non_exhaustive()
    }
}

/// How long a request may wait for the round loop: a round and its model rounds, and a
/// calibration's or a preset's captures, end well within it.
const ANSWER_WITHIN: Duration = Duration::from_secs(600);

impl Control {
    async fn ask<T>(
        &self,
        make: impl FnOnce(oneshot::Sender<Result<T, Refused>>) -> Request,
    ) -> Result<T, Refused> {
        let (tx, rx) = oneshot::channel();
        self.requests.try_send(make(tx)).map_err(|e| match e {
            mpsc::error::TrySendError::Full(_) => Refused::Busy,
            mpsc::error::TrySendError::Closed(_) => Refused::Stopping,
        })?;
        match tokio::time::timeout(ANSWER_WITHIN, rx).await {
            Ok(Ok(answer)) => answer,
            Ok(Err(_)) | Err(_) => Err(Refused::Stopping),
        }
    }

    /// Stops the rounds after the current one (`true`; the projectors keep their light) or
    /// lets them go on.
    pub fn pause(&self, paused: bool) -> Result<(), Refused> {
        self.shared.overview.send_if_modified(|s| {
            let changed = s.paused != paused;
            s.paused = paused;
            changed
        });
        self.requests
            .try_send(Request::Pause(paused))
            .map_err(|e| match e {
                mpsc::error::TrySendError::Full(_) => Refused::Busy,
                mpsc::error::TrySendError::Closed(_) => Refused::Stopping,
            })
    }

    /// Queues projector `projector` (`None`: every attached one) to be measured again; returns
    /// the projectors queued.
    pub async fn calibrate(&self, projector: Option<String>) -> Result<Vec<String>, Refused> {
        self.ask(|tx| Request::Calibrate(projector, tx)).await
    }

    /// Measures the LEDs' light under `preset` and makes it the target; the rounds restart.
    pub async fn preset(&self, preset: String) -> Result<(), Refused> {
        self.ask(|tx| Request::Preset(preset, tx)).await
    }

    /// Photographs the room between two rounds; returns the photograph's sequence number and
    /// size once [`Control::photos`] holds it.
    pub async fn photograph(&self) -> Result<(u64, u32, u32), Refused> {
        self.ask(Request::Photograph).await
    }

    /// Shows the identify pattern on `projector` for `seconds`, then its light again.
    pub fn identify(&self, projector: &str, seconds: u32) -> Result<(), Refused> {
        let outbox = self.shared.registry.lock().outbox(projector);
        let Some((tx, _)) = outbox else {
            return Err(Refused::UnknownProjector(projector.to_string()));
        };
        let body =
            roomlight_proto::v1::room_message::Body::Identify(roomlight_proto::v1::Identify {
                seconds: seconds.clamp(1, 60),
            });
        if self.shared.offer(projector, &tx, vec![body]) {
            Ok(())
        } else {
            Err(Refused::UnknownProjector(projector.to_string()))
        }
    }

    /// Projector states, calibration, pause and preset, as they change.
    pub fn overview(&self) -> watch::Receiver<Overview> {
        self.overview.clone()
    }

    /// The latest photograph, as it is published.
    pub fn photos(&self) -> watch::Receiver<Option<Photo>> {
        self.photos.clone()
    }

    /// The model's problem now (a copy: for the console's optimum, computed off the rounds).
    pub fn problem(&self) -> roomlight_core::Problem {
        self.shared.live().problem.clone()
    }

    /// The room's name.
    pub fn room(&self) -> &str {
        &self.shared.config.room
    }

    /// The presets the room's LEDs can show (none when the agent cannot switch them).
    pub fn presets(&self) -> Vec<String> {
        self.shared
            .lights
            .as_ref()
            .map(|l| l.presets())
            .unwrap_or_default()
    }

    /// How dark the luminaires keep the projection-mapping target: the survey's weight and the
    /// model's patches on the target (`None`: no survey).
    pub fn dark_target(&self) -> Option<(f64, usize)> {
        let survey = self.shared.survey.as_ref()?;
        let patches = survey
            .patches
            .iter()
            .filter(|&&r| survey.is_dark(r))
            .count();
        Some((survey.dark_weight(), patches))
    }

    /// Where projector `id`'s light lands in the camera image: its share of each camera pixel
    /// (row-major, the survey's camera), as its segmentation over the wire left it.
    pub fn coverage(&self, id: &str) -> Option<(u32, u32, Vec<f32>)> {
        let survey = self.shared.survey.as_ref()?;
        let (w, h) = (survey.width, survey.height);
        let claim = self.shared.live().claims.get(id)?.clone();
        (claim.len() == w as usize * h as usize).then_some((w, h, claim))
    }

    /// Projector `id`'s attenuation summed over its nodes, at each of the model's patches,
    /// with each patch's room index (chart · 24 + patch); `None` for an unknown projector.
    pub fn attenuation(&self, id: &str) -> Option<Vec<(usize, LinearRgb)>> {
        let live = self.shared.live();
        let nodes = live.owners.get(id)?;
        let mut sum = vec![LinearRgb::ZERO; live.problem.patches()];
        for &n in nodes {
            if let Some(column) = live.problem.columns().get(n as usize) {
                for (i, p) in column.iter() {
                    if let Some(s) = sum.get_mut(i as usize) {
                        *s += p;
                    }
                }
            }
        }
        Some(match &self.shared.survey {
            // The light itself, not the weighed row a dark target patch holds (its scale is
            // never 0: a survey has target patches only at a weight above 0).
            Some(survey) => survey
                .patches
                .iter()
                .zip(sum)
                .map(|(&r, p)| (r, p * (1.0 / survey.scale(r))))
                .collect(),
            None => sum.into_iter().enumerate().collect(),
        })
    }

    /// The frame projector `id` shows now, as the camera agent follows its nodes' values:
    /// with its segmentation over the wire, its codes per pixel (row-major, `width × height`);
    /// without, one pixel per node (its linear value). A node whose value the camera agent has
    /// not seen yet is black.
    pub fn frame(&self, id: &str) -> Option<Frame> {
        let nodes = self.shared.registry.lock().outbox(id)?.1;
        let values: Vec<(u32, LinearRgb)> = {
            let known = self.shared.values();
            nodes
                .iter()
                .filter_map(|n| Some((*n, *known.get(n)?)))
                .collect()
        };
        let live = self.shared.live();
        Some(match live.assignments.get(id) {
            Some(a) => Frame {
                width: a.width,
                height: a.height,
                pixels: a.draw(&values),
            },
            None => Frame {
                width: nodes.len() as u32,
                height: 1,
                pixels: nodes
                    .iter()
                    .map(|n| {
                        let v = values
                            .iter()
                            .find(|(m, _)| m == n)
                            .map_or(LinearRgb::ZERO, |(_, v)| *v);
                        v.0.map(|c| c as f32)
                    })
                    .collect(),
            },
        })
    }
}

/// A projector's frame as the camera agent knows it.
#[derive(Debug, Clone)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// Row-major, `width × height`, each channel in [0, 1].
    pub pixels: Vec<[f32; 3]>,
}
