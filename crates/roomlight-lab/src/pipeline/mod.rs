//! The whole method on a simulated room, as the system does it: structured light, projector
//! responses, nodes and feathering, Hadamard attenuation and the LED target measured from noisy
//! captures through the charts, then the real agents over loopback gRPC. The simulator is touched
//! only through captures, except the target mask, which a real room configures by hand. Node
//! values become projector codes through the measured responses (the simulator keeps its own
//! gamma hidden), and every capture during the rounds is rendered, exposed with camera noise and
//! sampled through the charts exactly as in calibration. The truth for the metrics is what a
//! noiseless camera samples the same way: the simulator's own patch averages differ from that
//! sampling by enough to hold a loop fed with them 4–37% above the optimum.

mod calibration;
pub mod gate;
mod model;
mod rig;
mod run;
mod sim_hw;
mod truth;

pub use calibration::*;
pub use model::*;
pub use rig::{SimRig, projector};
pub use run::*;
use sim_hw::*;
pub use truth::*;

use anyhow::{Context, Result};
use roomlight_calib::charts::{ChartCorners, SampleConfig};
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::procedure::Setup;
use roomlight_core::LinearRgb;
use roomlight_sim::Room;

pub(crate) fn image(c: &roomlight_sim::Capture) -> LinearImage {
    LinearImage {
        width: c.width,
        height: c.height,
        pixels: c.pixels.clone(),
    }
}

/// The charts' corners in the camera image, as configured for a real room (here from the
/// simulator's camera model); a chart out of view is an error, not skipped.
pub fn chart_corners(room: &Room) -> Result<Vec<ChartCorners>> {
    room.chart_corners_px()
        .into_iter()
        .zip(&room.scene().charts)
        .map(|(c, spec)| {
            c.map(|corners| ChartCorners {
                name: spec.name.clone(),
                corners,
            })
            .with_context(|| format!("chart {} is not in the camera's view", spec.name))
        })
        .collect()
}

/// Patches per colour chart.
const PATCHES_PER_CHART: usize = roomlight_calib::charts::COLUMNS * roomlight_calib::charts::ROWS;

/// How the charts are sampled: the simulated camera's saturation (with a margin) and noise.
pub fn sample_config(room: &Room) -> SampleConfig {
    let c = &room.scene().camera;
    SampleConfig {
        saturation: (0.98 * c.saturation) as f32,
        read_noise: c.read_noise as f32,
        shot_noise: c.shot_noise as f32,
        ..SampleConfig::default()
    }
}

/// Every room patch of a capture (the charts', then the target's and the walls'), as
/// calibration samples them.
fn sample(capture: &roomlight_sim::Capture, setup: &Setup) -> Result<Vec<LinearRgb>> {
    Ok(setup
        .sample_room(&image(capture))?
        .iter()
        .map(|p| p.mean)
        .collect())
}
