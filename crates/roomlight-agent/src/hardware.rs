//! What agents drive: a `Display` per node agent and a `Camera` for the camera agent, and what
//! travels to them (calibration patterns with their masks, assignments). The in-process
//! `VirtualRoom` adapter wraps the core's plant so that the real agents run against a simulated
//! room without a network between them and the "hardware". It must not know the wire or the
//! agents' sessions.

use roomlight_core::LinearRgb;
use roomlight_core::closed_loop::Plant;
use std::sync::{Arc, Mutex, PoisonError};

/// What a calibration pattern shows where it is shown, in projector codes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fill {
    /// Every pixel at this code per channel, in [0, 1].
    Uniform([f32; 3]),
    /// A structured-light pattern of the projector's own resolution, over code cells of
    /// `cell × cell` pixels, its stripes white or in one primary.
    Structured {
        pattern: roomlight_calib::graycode::Pattern,
        coding: roomlight_calib::graycode::Coding,
        cell: u32,
        primary: Option<roomlight_calib::graycode::Primary>,
    },
}

/// A whole-frame calibration pattern (DESIGN §4): what the camera agent asks a node agent to
/// show while it calibrates the projector over the wire. A second structured-light pass shows
/// its patterns only where the first left camera pixels unknown (`mask`), so that the bright
/// surfaces whose reflections hid their code stay black.
#[derive(Debug, Clone, PartialEq)]
pub struct Pattern {
    pub fill: Fill,
    /// Where the fill is shown (row-major projector pixels; black where false); `None`:
    /// everywhere.
    pub mask: Option<Arc<[bool]>>,
}

impl Pattern {
    /// `fill` on every pixel.
    pub fn everywhere(fill: Fill) -> Self {
        Self { fill, mask: None }
    }

    /// The codes of a `width`×`height` projector showing it, the mask applied (black where it
    /// is false). Every display that draws pixels draws through this, so a masked pattern is
    /// masked on all of them. Refused: a mask of another size, a structured pattern the
    /// projector's size cannot code.
    pub fn codes(&self, width: u32, height: u32) -> Result<Vec<[f32; 3]>, crate::AgentError> {
        let n = width as usize * height as usize;
        let refused = |e: String| crate::AgentError::Protocol(format!("pattern: {e}"));
        let mut codes = match self.fill {
            Fill::Uniform(code) => vec![code; n],
            Fill::Structured {
                pattern,
                coding,
                cell,
                primary,
            } => {
                let manifest =
                    roomlight_calib::graycode::Manifest::with_cell(width, height, coding, cell)
                        .map_err(|e| refused(e.to_string()))?;
                check_gray_bit(&manifest, pattern).map_err(refused)?;
                let mut codes = manifest.pattern_image(pattern).pixels;
                if let Some(primary) = primary {
                    primary.tint(&mut codes);
                }
                codes
            }
        };
        if let Some(mask) = &self.mask {
            if mask.len() != n {
                return Err(refused(format!(
                    "a mask of {} pixels for a {width}×{height} projector",
                    mask.len()
                )));
            }
            for (c, &shown) in codes.iter_mut().zip(mask.iter()) {
                if !shown {
                    *c = [0.0; 3];
                }
            }
        }
        Ok(codes)
    }
}

/// How a projector draws its nodes, as the camera agent measured it: the calibration rig's
/// own type, so that what the procedure assigns is what a node agent draws.
pub use roomlight_calib::rig::Assignment;
pub use roomlight_calib::shading::Gains;

/// A Gray bit must be one of the projector's: bit `b` of an axis of `bits` bits (a bit beyond
/// them has no stripes to draw, and roomlight-calib's coder assumes it never comes).
pub fn check_gray_bit(
    manifest: &roomlight_calib::graycode::Manifest,
    pattern: roomlight_calib::graycode::Pattern,
) -> Result<(), String> {
    use roomlight_calib::graycode::{Axis, Pattern as Gray};
    let Gray::Bit { axis, bit, .. } = pattern else {
        return Ok(());
    };
    let bits = match axis {
        Axis::Column => manifest.column_bits,
        Axis::Row => manifest.row_bits,
    };
    if bit >= bits {
        return Err(format!(
            "Gray bit {bit} of the {axis:?} axis: a {}×{} projector has {bits}",
            manifest.width, manifest.height
        ));
    }
    Ok(())
}

/// Refuses weights outside the frame, unsorted pixels, weights outside (0, 1] and a response
/// that is not finite and positive; `what` names the sender in the message.
pub fn validate_assignment(a: &Assignment, what: &str) -> Result<(), crate::AgentError> {
    let bad = |problem: String| Err(crate::AgentError::Protocol(format!("{what}: {problem}")));
    let pixels = u64::from(a.width) * u64::from(a.height);
    if pixels == 0 || pixels > 1 << 26 {
        return bad(format!(
            "a {}×{} projector; expected 1 to 2^26 pixels",
            a.width, a.height
        ));
    }
    if a.response
        .gamma
        .iter()
        .any(|g| !(g.is_finite() && *g > 0.0))
    {
        return bad(format!(
            "response exponents {:?}; expected finite and positive",
            a.response.gamma
        ));
    }
    for (node, weights) in &a.nodes {
        if weights.windows(2).any(|w| w[1].0 <= w[0].0) {
            return bad(format!("node {node}: pixels not increasing"));
        }
        if weights.last().is_some_and(|(i, _)| u64::from(*i) >= pixels) {
            return bad(format!(
                "node {node}: a pixel outside the {}×{} frame",
                a.width, a.height
            ));
        }
        if weights.iter().any(|(_, w)| !(*w > 0.0 && *w <= 1.0)) {
            return bad(format!("node {node}: a weight outside (0, 1]"));
        }
    }
    Ok(())
}

/// Shows node values (linear light) on a projector.
pub trait Display: Send + 'static {
    /// Shows `value` on node `node` (a global node id).
    fn show(&mut self, node: u32, value: LinearRgb);

    /// Shows a whole-frame calibration pattern until the next value or pattern; false when
    /// this display cannot (it only shows node values).
    fn show_pattern(&mut self, pattern: Pattern) -> bool {
        let _ = pattern;
        false
    }

    /// Shows the identify pattern naming `projector` (`on`) until called again with `on`
    /// false, then what it showed before; false when this display cannot (it draws no pixels).
    fn identify(&mut self, projector: &str, on: bool) -> bool {
        let _ = (projector, on);
        false
    }

    /// Takes the nodes' weights and the response measured over the wire (node values shown
    /// afterwards are drawn with them). Displays that draw no pixels ignore it.
    fn assign(&mut self, assignment: &Assignment) {
        let _ = assignment;
    }

    /// Draws node values with per-pixel shading `gains` from now on (`None`: without), as
    /// [`Assignment::draw_shaded`] does; redraws what it shows. Displays that draw no pixels
    /// ignore it.
    fn shade(&mut self, gains: Option<&Gains>) {
        let _ = gains;
    }

    /// The projector's resolution, when the display knows it (sent in Hello).
    fn resolution(&self) -> Option<(u32, u32)> {
        None
    }

    /// Resolves once everything shown so far is on the display: a node agent acknowledges a
    /// frame only after this, so the camera never captures a frame that is still on its way.
    /// Displays that show synchronously need nothing more.
    fn flush(&mut self) -> impl Future<Output = ()> + Send {
        std::future::ready(())
    }

    /// Follows the display's state (showing, or lost and why), for the node agent to tell the
    /// camera agent; `None` for displays without such a state (the simulator's).
    fn state_feed(&self) -> Option<DisplayFeed> {
        None
    }
}

/// What a display says of itself: showing on its output, or lost (unplugged, window closed)
/// and why. Strings are the display's own words; the wire bounds them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DisplayReport {
    Showing { output: String },
    Lost { output: String, reason: String },
}

impl DisplayReport {
    /// Its output's name.
    pub fn output(&self) -> &str {
        match self {
            Self::Showing { output } | Self::Lost { output, .. } => output,
        }
    }
}

/// A display's state as it changes: any `watch` channel of the display's own state type,
/// described as a [`DisplayReport`] (so the agent needs no display crate's types).
pub struct DisplayFeed(Box<dyn Feed>);

impl std::fmt::Debug for DisplayFeed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("DisplayFeed").finish_non_exhaustive()
    }
}

trait Feed: Send {
    fn now(&mut self) -> DisplayReport;
    fn changed(&mut self) -> std::pin::Pin<Box<dyn Future<Output = bool> + Send + '_>>;
}

/// How a display's own state reads as a report.
type Describe<T> = Box<dyn Fn(&T) -> DisplayReport + Send>;

struct WatchFeed<T> {
    rx: tokio::sync::watch::Receiver<T>,
    describe: Describe<T>,
}

impl<T: Send + Sync> Feed for WatchFeed<T> {
    fn now(&mut self) -> DisplayReport {
        (self.describe)(&self.rx.borrow_and_update())
    }

    fn changed(&mut self) -> std::pin::Pin<Box<dyn Future<Output = bool> + Send + '_>> {
        Box::pin(async { self.rx.changed().await.is_ok() })
    }
}

impl DisplayFeed {
    /// Follows `rx`, each state described by `describe`.
    pub fn from_watch<T: Send + Sync + 'static>(
        rx: tokio::sync::watch::Receiver<T>,
        describe: impl Fn(&T) -> DisplayReport + Send + 'static,
    ) -> Self {
        Self(Box::new(WatchFeed {
            rx,
            describe: Box::new(describe),
        }))
    }

    /// The state now.
    pub fn now(&mut self) -> DisplayReport {
        self.0.now()
    }

    /// The next state that differs from the last one returned (a loss whose reason changes
    /// between retries counts as a change); `None` once the display has gone for good.
    pub async fn next(&mut self, last: &DisplayReport) -> Option<DisplayReport> {
        loop {
            if !self.0.changed().await {
                return None;
            }
            let now = self.0.now();
            if &now != last {
                return Some(now);
            }
        }
    }
}

/// Measures the chart patches (linear camera values, one per patch).
pub trait Camera: Send + 'static {
    /// Its name in logs and the status (e.g. its spec, `v4l2:/dev/video0`).
    fn name(&self) -> &str {
        "camera"
    }

    /// How long one capture (of the normal exposure) may take before the camera agent abandons
    /// it as hung. A camera with a timeout of its own should make this a little longer than
    /// that one, so its own, more precise error is the one logged. By default a minute.
    fn capture_timeout(&self) -> std::time::Duration {
        std::time::Duration::from_secs(60)
    }

    /// One capture of every patch.
    fn capture(&mut self)
    -> impl Future<Output = Result<Vec<LinearRgb>, crate::AgentError>> + Send;

    /// One whole linear image, for calibration over the wire (structured light, responses);
    /// cameras that deliver only patches refuse.
    fn capture_image(
        &mut self,
    ) -> impl Future<Output = Result<roomlight_calib::image_io::LinearImage, crate::AgentError>> + Send
    {
        std::future::ready(Err(crate::AgentError::Protocol(
            "this camera delivers chart patches only, not images".into(),
        )))
    }

    /// What calibration plans with: the level at which a pixel saturates and the longest
    /// exposure [`Self::capture_image_exposed`] takes. By default one exposure and an unknown
    /// saturation, so a second structured-light pass keeps the normal exposure.
    fn limits(&self) -> roomlight_calib::rig::CameraLimits {
        roomlight_calib::rig::CameraLimits {
            saturation: f32::NAN,
            longest_exposure: 1.0,
        }
    }

    /// One whole linear image exposed `exposure` times as long as normal (at most the
    /// [`Self::limits`]' longest), in the units of a normal one; by default the camera's one
    /// exposure.
    fn capture_image_exposed(
        &mut self,
        exposure: f32,
    ) -> impl Future<Output = Result<roomlight_calib::image_io::LinearImage, crate::AgentError>> + Send
    {
        let _ = exposure;
        self.capture_image()
    }
}

#[derive(Debug)]
struct Shared {
    plant: Plant,
    shown: Vec<LinearRgb>,
    lit: Vec<bool>,
    captures: usize,
}

/// A simulated room shared by the virtual displays and the virtual camera.
#[derive(Debug, Clone)]
pub struct VirtualRoom(Arc<Mutex<Shared>>);

impl VirtualRoom {
    /// Every node starts dark until its display shows something.
    pub fn new(plant: Plant) -> Self {
        let n = plant.truth().nodes();
        Self(Arc::new(Mutex::new(Shared {
            plant,
            shown: vec![LinearRgb::ZERO; n],
            lit: vec![true; n],
            captures: 0,
        })))
    }

    fn with<T>(&self, f: impl FnOnce(&mut Shared) -> T) -> T {
        // A panic elsewhere must not take the room down: use the data as it is.
        let mut guard = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        f(&mut guard)
    }

    /// A display for a projector.
    pub fn display(&self) -> VirtualDisplay {
        VirtualDisplay(self.clone())
    }

    /// The camera.
    pub fn camera(&self) -> VirtualCamera {
        VirtualCamera(self.clone())
    }

    /// Switches nodes off for good (a projector unplugged).
    pub fn unplug(&self, nodes: &[u32]) {
        self.with(|s| {
            for &n in nodes {
                if let Some(l) = s.lit.get_mut(n as usize) {
                    *l = false;
                }
            }
        });
    }

    /// The values every node shows now (dark for unplugged nodes).
    pub fn shown(&self) -> Vec<LinearRgb> {
        self.with(|s| {
            s.shown
                .iter()
                .zip(&s.lit)
                .map(|(v, &l)| if l { *v } else { LinearRgb::ZERO })
                .collect()
        })
    }

    /// The true `G` of what the room shows now.
    pub fn true_objective(&self) -> f64 {
        let shown = self.shown();
        self.with(|s| s.plant.truth().objective(&shown))
    }

    /// Captures taken so far.
    pub fn captures(&self) -> usize {
        self.with(|s| s.captures)
    }
}

/// A projector's display in the virtual room.
#[derive(Debug, Clone)]
pub struct VirtualDisplay(VirtualRoom);

impl Display for VirtualDisplay {
    fn show(&mut self, node: u32, value: LinearRgb) {
        self.0.with(|s| {
            if let Some(v) = s.shown.get_mut(node as usize) {
                *v = value.clamp_unit();
            }
        });
    }
}

/// The virtual room's camera.
#[derive(Debug, Clone)]
pub struct VirtualCamera(VirtualRoom);

impl VirtualCamera {
    /// One capture, at once.
    pub fn capture_now(&self) -> Vec<LinearRgb> {
        let shown = self.0.shown();
        self.0.with(|s| {
            s.captures += 1;
            let k = s.captures;
            s.plant.capture(&shown, k)
        })
    }
}

impl Camera for VirtualCamera {
    fn capture(
        &mut self,
    ) -> impl Future<Output = Result<Vec<LinearRgb>, crate::AgentError>> + Send {
        std::future::ready(Ok(self.capture_now()))
    }
}
