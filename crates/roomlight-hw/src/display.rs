//! `WindowDisplay`: roomlight-agent's `Display` on a real window. Node values are drawn
//! through the assignment the camera agent measured (`Assignment::draw`), calibration patterns
//! through `Pattern::codes`; both give projector codes in [0, 1], which are rounded to 8 bits
//! and shown as they are (the projector's response is already in the codes). `flush` resolves
//! once the frame is on the screen plus `settle_ms`, the projector's own latency. It must not
//! know the wire or rounds.

use crate::HwError;
use crate::frame::Frame;
use crate::output::OutputSelector;
use crate::window::{DisplayState, WindowHandle};
use roomlight_agent::hardware::{Assignment, Display, Pattern};
use roomlight_core::LinearRgb;
use std::time::Duration;
use tokio::sync::{oneshot, watch};

/// How long `flush` waits for a lost display to come back before it gives up on the frame and
/// lets the node answer (logged): a node that stops answering would be dropped by the camera
/// agent, and the display shows the frame as soon as it is back.
const LOST_WAIT: Duration = Duration::from_secs(5);

/// What a window display is configured with.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowSpec {
    /// The X display (`:0`), or `None` for `$DISPLAY`.
    pub x_display: Option<String>,
    pub output: OutputSelector,
    /// How long the projector takes to show a frame the X server has.
    pub settle: Duration,
}

/// What is on the display: node values (drawn through the assignment) or a pattern.
#[derive(Debug, Clone)]
enum Content {
    Values,
    Pattern(Pattern),
}

/// A projector driven through a fullscreen window on one output.
#[derive(Debug)]
pub struct WindowDisplay {
    window: WindowHandle,
    settle: Duration,
    assignment: Option<Assignment>,
    values: Vec<(u32, LinearRgb)>,
    content: Content,
    dirty: bool,
}

impl WindowDisplay {
    /// Opens the window of `spec` (titled with the projector id); black until something is
    /// shown.
    pub fn open(spec: &WindowSpec, projector: &str) -> Result<Self, HwError> {
        let window = WindowHandle::open(
            spec.x_display.as_deref(),
            spec.output.clone(),
            &format!("roomlight {projector}"),
        )?;
        Ok(Self {
            window,
            settle: spec.settle,
            assignment: None,
            values: Vec::new(),
            content: Content::Values,
            dirty: false,
        })
    }

    /// What the display is doing now (showing, or lost and why).
    pub fn state(&self) -> DisplayState {
        self.window.state()
    }

    /// Follows the state as it changes.
    pub fn watch(&self) -> watch::Receiver<DisplayState> {
        self.window.watch()
    }

    /// The output's name.
    pub fn output_name(&self) -> &str {
        &self.window.output().name
    }

    /// Shows a frame of the output's size as it is (the identify pattern, an image).
    pub async fn show_frame(&mut self, frame: Frame) {
        self.present(frame).await;
    }

    fn size(&self) -> (u32, u32) {
        let o = self.window.output();
        (o.width, o.height)
    }

    /// The frame of what is shown now; black where nothing is assigned.
    fn render(&self) -> Frame {
        let (w, h) = self.size();
        let codes = match &self.content {
            Content::Pattern(p) => match p.codes(w, h) {
                Ok(codes) => codes,
                Err(e) => {
                    tracing::warn!(output = %self.output_name(), error = %e, "pattern refused: black");
                    return Frame::black(w, h);
                }
            },
            Content::Values => match &self.assignment {
                Some(a) if (a.width, a.height) == (w, h) => a.draw(&self.values),
                Some(a) => {
                    tracing::warn!(
                        output = %self.output_name(),
                        "an assignment for {}x{} on a {w}x{h} output: black",
                        a.width,
                        a.height
                    );
                    return Frame::black(w, h);
                }
                None => return Frame::black(w, h),
            },
        };
        Frame::from_codes(w, h, &codes).unwrap_or_else(|_| Frame::black(w, h))
    }

    async fn present(&mut self, frame: Frame) {
        let (tx, rx) = oneshot::channel();
        self.window.show(frame, Some(tx));
        match tokio::time::timeout(LOST_WAIT, rx).await {
            Ok(Ok(())) => tokio::time::sleep(self.settle).await,
            _ => tracing::warn!(
                output = %self.output_name(),
                state = ?self.state(),
                "frame not presented within {LOST_WAIT:?}: it is shown when the display is back"
            ),
        }
    }
}

impl Display for WindowDisplay {
    fn show(&mut self, node: u32, value: LinearRgb) {
        match self.values.iter_mut().find(|(n, _)| *n == node) {
            Some((_, v)) => *v = value,
            None => self.values.push((node, value)),
        }
        self.content = Content::Values;
        self.dirty = true;
    }

    fn show_pattern(&mut self, pattern: Pattern) -> bool {
        self.content = Content::Pattern(pattern);
        self.dirty = true;
        true
    }

    fn assign(&mut self, assignment: &Assignment) {
        self.assignment = Some(assignment.clone());
        self.dirty = true;
    }

    fn resolution(&self) -> Option<(u32, u32)> {
        Some(self.size())
    }

    async fn flush(&mut self) {
        if !std::mem::take(&mut self.dirty) {
            return;
        }
        let frame = self.render();
        self.present(frame).await;
    }
}
