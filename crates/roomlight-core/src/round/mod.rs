//! The round controller (DESIGN §3.4, §3.6, §6): which projectors and nodes are live and
//! calibrated and what each shows, what a round waits for (acknowledgements of a frame,
//! contributions with a deadline), when to capture and when to run a model round instead, the
//! restart flag, when the room has settled, and when to try a failed calibration again.
//!
//! - [`Controller`]: the sequence of rounds — after each capture `k` model rounds, then a
//!   capture; each round's errors (measured, or predicted from the contributions), its `G` and
//!   restart flag (`G` rose, or the live projectors changed); the settle rule. The camera
//!   agent's round loop and the in-memory closed loop both drive it.
//! - [`Projectors`]: the live projectors, their readiness and node owners (the camera agent).
//! - [`Collection`]: the contributions one round waits for, until a deadline.
//! - [`Settle`] and [`Backoff`]: the settle rule and calibration retries.
//!
//! A pure state machine: no I/O, no async, no clocks. Time is a `Duration` since an epoch the
//! caller chooses, passed in with every call that needs it. It knows nothing of messages,
//! streams or cameras: the camera agent and the in-memory loop drive it.

mod backoff;
mod collection;
mod controller;
mod projectors;

pub use backoff::Backoff;
pub use collection::{Collection, Received};
pub use controller::{
    AVERAGE_CAPTURES, Controller, INNOVATION_SIGMAS, MODEL_ERROR_LIMIT, Next, STALE_CAPTURES,
    Settle, objective_noise,
};
pub use projectors::{Projector, Projectors};
