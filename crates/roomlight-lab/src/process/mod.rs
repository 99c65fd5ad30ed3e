//! The processes of a simulated installation once their options are known: what `roomlight
//! calibrate`, `sim`, `camera` and `node` do, and the files they hand each other (model, charts,
//! survey, frames).
//!
//! It must not know the command line, config files or the process itself: the binary parses
//! and validates, owns the runtime, logs and stop signals, and passes a cancellation token.

mod calibrate;
mod camera;
mod check;
mod files;
mod lights;
mod node;
mod photos;
mod sim;
mod status;
mod survey;
mod systemd;

pub use calibrate::{CalibrateOptions, calibrate_to_files};
pub use camera::{CameraHardware, CameraProcess, CameraSource, ConsoleProcess, serve_camera};
pub use check::{CameraAt, Checklist, check_camera, check_node};
pub use files::{
    ChartsFile, MAX_CHARTS, ModelFile, SurveyFile, load_model, load_scene, load_survey,
    optimum_summary,
};
pub use lights::{LightsSpec, ManualLights};
pub use node::{NodeDisplay, run_node};
pub use photos::GrabMode;
pub use sim::{PreparedSim, SimRoom, SyntheticSim, prepare_sim};
pub use status::{Round, StatusLine, StatusLines, StatusPrinter};
