//! What agents drive: a `Display` per node agent and a `Camera` for the camera agent. The
//! in-process `VirtualRoom` adapter wraps the core's plant so that the real agents run against a
//! simulated room without a network between them and the "hardware".

use roomlight_core::LinearRgb;
use roomlight_core::closed_loop::Plant;
use std::sync::{Arc, Mutex, PoisonError};

/// Shows node values (linear light) on a projector.
pub trait Display: Send + 'static {
    /// Shows `value` on node `node` (a global node id).
    fn show(&mut self, node: u32, value: LinearRgb);

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
