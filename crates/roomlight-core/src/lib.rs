//! roomlight-core: the mathematics of replacing room lights with projectors (Takeuchi et al.,
//! IEEE TVCG 2024; the project's reading in DESIGN.md §2–§3).
//!
//! - [`model`]: the forward model `y = P x + d` with sparse, validated attenuation columns.
//! - [`rules`]: one node's update (paper's fixed step, per-node safe step, momentum).
//! - [`aggregator`]: the camera's side (measured and predicted errors, `G`, restarts).
//! - [`conventional`]: the conventional start of DESIGN §3.1.
//! - [`optimum`]: the exact bounded least-squares optimum, the yardstick.
//! - [`metrics`]: `G`, CIEDE2000, RMS and ANSI contrast.
//! - [`round`]: the round controller: when to capture and when to run model rounds, restarts,
//!   the settle rule; live projectors and their readiness, what a round waits for, calibration
//!   retries. A state machine; time is passed in.
//! - [`closed_loop`]: an in-memory plant and loop to compare rules without a network, driving
//!   the same round controller as the camera agent.
//! - [`synthetic`]: synthetic rooms for benchmarks and tests.
//!
//! Pure: no I/O, no async, no clocks. Randomness only from explicit seeds.

pub mod aggregator;
pub mod closed_loop;
pub mod colorchecker;
pub mod conventional;
pub mod metrics;
pub mod model;
pub mod optimum;
pub mod rgb;
pub mod round;
pub mod rules;
pub mod synthetic;

pub use model::{AttenuationColumn, ModelError, PatchId, Problem};
pub use rgb::LinearRgb;
pub use rules::{NodeState, StepRule};
