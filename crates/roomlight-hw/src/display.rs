//! `WindowDisplay`: roomlight-agent's `Display` on a real window. Node values are drawn
//! through the assignment the camera agent measured, with the per-pixel shading gains the node
//! agent stepped (`Assignment::draw_shaded`), calibration patterns
//! through `Pattern::codes`; both give projector codes in [0, 1], which are rounded to 8 bits
//! and shown as they are (the projector's response is already in the codes). `flush` resolves
//! once the frame is on the screen plus `settle_ms`, the projector's own latency. Its state
//! (showing, or lost and why) feeds the node agent, which tells the camera agent. It must not
//! know the wire or rounds.

use crate::HwError;
use crate::frame::Frame;
use crate::output::OutputSelector;
use crate::window::{DisplayState, WindowHandle};
use roomlight_agent::hardware::{Assignment, Display, DisplayFeed, DisplayReport, Gains, Pattern};
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
    /// Per-pixel shading gains node values are drawn with.
    gains: Option<Gains>,
    values: Vec<(u32, LinearRgb)>,
    content: Content,
    /// Showing the identify pattern of this projector id, over whatever else.
    identify: Option<String>,
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
            gains: None,
            values: Vec::new(),
            content: Content::Values,
            identify: None,
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
        if let Some(projector) = &self.identify {
            return crate::identify::frame(projector, self.output_name(), w, h);
        }
        let codes = match &self.content {
            Content::Pattern(p) => match p.codes(w, h) {
                Ok(codes) => codes,
                Err(e) => {
                    tracing::warn!(output = %self.output_name(), error = %e, "pattern refused: black");
                    return Frame::black(w, h);
                }
            },
            Content::Values => match &self.assignment {
                Some(a) if (a.width, a.height) == (w, h) => {
                    a.draw_shaded(&self.values, self.gains.as_ref())
                }
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

    fn identify(&mut self, projector: &str, on: bool) -> bool {
        self.identify = on.then(|| projector.to_string());
        self.dirty = true;
        true
    }

    fn assign(&mut self, assignment: &Assignment) {
        self.assignment = Some(assignment.clone());
        self.dirty = true;
    }

    fn shade(&mut self, gains: Option<&Gains>) {
        self.gains = gains.cloned();
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

    fn state_feed(&self) -> Option<DisplayFeed> {
        let opened_on = self.output_name().to_string();
        Some(DisplayFeed::from_watch(self.watch(), move |s| {
            report(s, &opened_on)
        }))
    }
}

/// A window's state as the node agent reports it; a lost window names the output it was
/// opened on.
fn report(state: &DisplayState, opened_on: &str) -> DisplayReport {
    match state {
        DisplayState::Showing { output, .. } => DisplayReport::Showing {
            output: output.name.clone(),
        },
        DisplayState::Lost { reason, .. } => DisplayReport::Lost {
            output: opened_on.to_string(),
            reason: reason.clone(),
        },
    }
}

#[cfg(test)]
mod tests {
    //! A real window under Xvfb driven by a real node agent attached to a camera agent: its
    //! output is removed and added back, and the camera agent's status follows.

    use super::*;
    use crate::Geometry;
    use crate::xvfb::Xvfb;
    use roomlight_agent::camera::{self, CameraConfig, RoomModel, RoomStatus};
    use roomlight_agent::hardware::VirtualRoom;
    use roomlight_agent::node::{self, NodeConfig};
    use roomlight_core::StepRule;
    use roomlight_core::closed_loop::{Plant, PlantConfig};
    use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};

    const A: Geometry = Geometry {
        width: 320,
        height: 240,
        x: 0,
        y: 0,
    };

    async fn wait(
        status: &mut watch::Receiver<RoomStatus>,
        pred: impl Fn(&RoomStatus) -> bool,
    ) -> RoomStatus {
        let within = Duration::from_secs(30);
        let reached = tokio::time::timeout(within, status.wait_for(|s| pred(s)))
            .await
            .is_ok_and(|r| r.is_ok());
        let last = status.borrow().clone();
        assert!(
            reached && pred(&last),
            "not reached within {within:?}: {last:?}"
        );
        last
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn an_output_removed_under_a_node_agent_is_lost_in_the_camera_agents_status_until_back() {
        let x = Xvfb::start(640, 240).unwrap_or_else(|e| panic!("{e}"));
        x.add_output("A", A).expect("output A");
        let spec = WindowSpec {
            x_display: Some(x.display().to_string()),
            output: "A".parse().expect("selector"),
            settle: Duration::from_millis(5),
        };
        let display = WindowDisplay::open(&spec, "p0").expect("window on A");

        let problem = synthetic_room(&SyntheticConfig::new(6, 4))
            .expect("room")
            .problem;
        let room =
            VirtualRoom::new(Plant::new(problem.clone(), PlantConfig::default()).expect("plant"));
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let endpoint = format!("http://{}", listener.local_addr().expect("address"));
        let config = CameraConfig {
            room: "lab".into(),
            token: "t".into(),
            // A node silent for 600 ms is dropped; a lost window holds a frame up to 5 s.
            heartbeat: Duration::from_millis(200),
            deadline: Duration::from_secs(1),
            model_rounds: 0,
            calibration_epoch: 1,
            stale_frames: 0,
            model_out: None,
            primaries: true,
            shading_passes: 0,
        };
        let model = RoomModel {
            problem,
            owners: [("p0".to_string(), (0..6).collect())].into(),
            start: None,
            hot: Default::default(),
            survey: None,
        };
        // Tokens the tasks are never asked to stop by: they are aborted at the end.
        let (mut status, camera) =
            camera::serve(config, model, room.camera(), listener, Default::default());
        let node = tokio::spawn(node::run(
            NodeConfig {
                endpoint,
                room: "lab".into(),
                token: "t".into(),
                projector_id: "p0".into(),
                kind: Default::default(),
                rule: StepRule::Momentum { theta: 1.0 },
                start: LinearRgb::splat(0.5),
                state_file: None,
            },
            display,
            Default::default(),
        ));
        wait(&mut status, |s| s.live_projectors == 1 && s.captures >= 1).await;

        x.remove_output("A").expect("remove A");
        let lost = wait(&mut status, |s| !s.displays_lost.is_empty()).await;
        let entry = &lost.displays_lost[0];
        assert_eq!(
            (entry.projector.as_str(), entry.output.as_str()),
            ("p0", "A")
        );
        assert!(!entry.reason.is_empty());
        // Rounds go on; the projector stays attached while its window is gone.
        let captures = lost.captures;
        let later = wait(&mut status, |s| s.captures >= captures + 2).await;
        assert_eq!(later.live_projectors, 1, "{later:?}");
        assert_eq!(later.displays_lost.len(), 1, "{later:?}");

        x.add_output("A", A).expect("A again");
        let back = wait(&mut status, |s| s.displays_lost.is_empty()).await;
        assert_eq!(back.live_projectors, 1);
        node.abort();
        camera.abort();
    }
}
