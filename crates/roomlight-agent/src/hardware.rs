//! What agents drive: a `Display` per node agent and a `Camera` for the camera agent. The
//! in-process `VirtualRoom` adapter wraps the core's plant so that the real agents run against a
//! simulated room without a network between them and the "hardware".

use roomlight_core::LinearRgb;
use roomlight_core::closed_loop::Plant;
use std::sync::{Arc, Mutex, PoisonError};

/// A whole-frame calibration pattern (DESIGN §4), in projector codes: what the camera agent
/// asks a node agent to show while it calibrates the projector over the wire.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pattern {
    /// Every pixel at this code per channel, in [0, 1].
    Uniform([f32; 3]),
    /// A structured-light pattern of the projector's own resolution.
    Structured {
        pattern: roomlight_calib::graycode::Pattern,
        coding: roomlight_calib::graycode::Coding,
    },
}

/// How a projector draws its nodes, as the camera agent measured it: each node's feathered
/// weights (row-major pixels, increasing, weights in (0, 1]) and the projector's response.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Assignment {
    pub width: u32,
    pub height: u32,
    pub response: roomlight_calib::response::Response,
    /// `(node id, [(pixel, weight)])`.
    pub nodes: Vec<(u32, Vec<(u32, f32)>)>,
}

impl Assignment {
    /// Refuses weights outside the frame, unsorted pixels, weights outside (0, 1] and a
    /// response that is not finite and positive; `what` names the sender in the message.
    pub fn validate(&self, what: &str) -> Result<(), crate::AgentError> {
        let bad = |problem: String| Err(crate::AgentError::Protocol(format!("{what}: {problem}")));
        let pixels = u64::from(self.width) * u64::from(self.height);
        if pixels == 0 || pixels > 1 << 26 {
            return bad(format!(
                "a {}×{} projector; expected 1 to 2^26 pixels",
                self.width, self.height
            ));
        }
        if self
            .response
            .gamma
            .iter()
            .any(|g| !(g.is_finite() && *g > 0.0))
        {
            return bad(format!(
                "response exponents {:?}; expected finite and positive",
                self.response.gamma
            ));
        }
        for (node, weights) in &self.nodes {
            if weights.windows(2).any(|w| w[1].0 <= w[0].0) {
                return bad(format!("node {node}: pixels not increasing"));
            }
            if weights.last().is_some_and(|(i, _)| u64::from(*i) >= pixels) {
                return bad(format!(
                    "node {node}: a pixel outside the {}×{} frame",
                    self.width, self.height
                ));
            }
            if weights.iter().any(|(_, w)| !(*w > 0.0 && *w <= 1.0)) {
                return bad(format!("node {node}: a weight outside (0, 1]"));
            }
        }
        Ok(())
    }
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

    /// Takes the nodes' weights and the response measured over the wire (node values shown
    /// afterwards are drawn with them). Displays that draw no pixels ignore it.
    fn assign(&mut self, assignment: &Assignment) {
        let _ = assignment;
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
}

/// Measures the chart patches (linear camera values, one per patch).
pub trait Camera: Send + 'static {
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
