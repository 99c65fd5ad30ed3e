//! roomlight's real displays: fullscreen windows on chosen outputs, adapted to roomlight-agent's
//! `Display` trait, and grabs of the screen. It must not know the wire, rounds or the
//! calibration procedure: it shows what it is given and reports what the devices do. Cameras
//! are roomlight-camera's (docs/architecture.md).
//!
//! - [`output`]: the X screen's outputs (RandR monitors), chosen by name, index or geometry.
//! - [`window`]: a borderless, cursor-less window covering one output, on a thread of its own,
//!   re-opened with backoff when it or its output goes away ([`DisplayState`]).
//! - [`display`]: [`WindowDisplay`], the agents' `Display` on such a window.
//! - [`frame`], [`identify`], [`font`]: 8-bit frames, the identify pattern and its font.
//! - [`grab`]: what is on a region of the screen, read back (tests, the simulator chain).
//! - [`xvfb`]: a virtual X server with outputs on regions of its screen, for tests.
//! - [`cli`]: the bodies of `roomlight hw …`.
//!
//! Displays are X11 through x11rb, a pure-Rust client: nothing to install at build time and no
//! C library at run time. Not winit + softbuffer: winit allows one event loop per process and
//! opens only `$DISPLAY` (a test cannot point it at its own Xvfb without `set_var`, which is
//! unsafe in Rust 2024 and the workspace denies unsafe code), and an X11 window pixel for pixel
//! needs none of its machinery. Wayland sessions run these windows through XWayland.

pub mod cli;
pub mod display;
pub mod font;
pub mod frame;
pub mod grab;
pub mod identify;
pub mod output;
pub mod window;
mod x11;
pub mod xvfb;

pub use display::{WindowDisplay, WindowSpec};
pub use frame::Frame;
pub use output::{Geometry, Output, OutputSelector};
pub use window::DisplayState;

/// What went wrong with a device.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HwError {
    /// No X server at that display.
    #[error("cannot connect to X display {display:?}: {reason}")]
    Connect { display: String, reason: String },
    /// The server cannot show what roomlight draws.
    #[error("unsupported display: {0}")]
    Unsupported(String),
    /// An output selector that is not one.
    #[error("output selector {0}")]
    Selector(String),
    /// No output matches.
    #[error("no output matches {wanted}; there are: {there}")]
    NoSuchOutput { wanted: String, there: String },
    /// Something of the wrong size.
    #[error("{what}; expected {}x{}", expected.0, expected.1)]
    Size { what: String, expected: (u32, u32) },
    /// A request to the server failed.
    #[error("{0}")]
    Request(String),
    /// A window or its output went away.
    #[error("{0}")]
    Lost(String),
    /// The virtual X server could not be started.
    #[error("{0}")]
    Xvfb(String),
}
