//! A fullscreen window on one output, owned by a thread of its own that talks to the rest over
//! channels: it opens the window (borderless, cursor-less, exactly the output's rectangle),
//! presents the frames it is sent pixel for pixel, and when the window or the output goes away
//! it says so (`DisplayState::Lost`), logs it with the output's name and opens it again with
//! backoff, showing the last frame. It must not know what the frames mean.
//!
//! The window is override-redirect: no window manager moves, decorates or scales it, so its
//! pixels are the output's pixels. Core X11 drawing has no vsync; a frame counts as presented
//! once the X server has processed it (a round trip after PutImage), and the node's
//! `settle_ms` covers the projector's own latency.

use crate::HwError;
use crate::frame::Frame;
use crate::output::{self, Output, OutputSelector};
use crate::x11::X11;
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tokio::sync::{oneshot, watch};
use x11rb::connection::Connection;
use x11rb::protocol::Event;
use x11rb::protocol::xproto::{
    ConfigureWindowAux, ConnectionExt as _, CreateGCAux, CreateWindowAux, EventMask, ImageFormat,
    PropMode, StackMode, WindowClass,
};
use x11rb::wrapper::ConnectionExt as _;

/// What a display is doing now, for logs and (later) the console.
#[derive(Debug, Clone, PartialEq)]
pub enum DisplayState {
    /// The window is up on `output`; `losses` times it was lost before, the last time for
    /// `last_loss` (a loss shorter than one look at the state still shows here).
    Showing {
        output: Output,
        since: Instant,
        losses: u32,
        last_loss: Option<String>,
    },
    /// The window or its output is gone; it is being opened again with backoff.
    Lost {
        since: Instant,
        reason: String,
        retries: u32,
    },
}

enum Command {
    Show(Frame, Option<oneshot::Sender<()>>),
}

/// The handle of a window thread; dropping every handle closes the window and ends the thread.
#[derive(Debug)]
pub struct WindowHandle {
    tx: mpsc::Sender<Command>,
    state: watch::Receiver<DisplayState>,
    output: Output,
}

/// Backoff between attempts to open a lost window: from 100 ms, doubling, at most 2 s.
const BACKOFF_FIRST: Duration = Duration::from_millis(100);
const BACKOFF_MAX: Duration = Duration::from_secs(2);
/// How often the thread looks for events and checks that its output is still there.
const POLL: Duration = Duration::from_millis(20);
const OUTPUT_CHECK: Duration = Duration::from_millis(500);

impl WindowHandle {
    /// Opens a window on the output `selector` picks on `display` (or `$DISPLAY`); the output
    /// must exist now (later it may come and go). `title` names the window.
    pub fn open(
        display: Option<&str>,
        selector: OutputSelector,
        title: &str,
    ) -> Result<Self, HwError> {
        let x = X11::connect(display)?;
        let outputs = output::list(&x)?;
        let chosen = selector.pick(&outputs)?.clone();
        let surface = Surface::open(x, &chosen, title)?;
        let (tx, rx) = mpsc::channel();
        let (state_tx, state) = watch::channel(DisplayState::Showing {
            output: chosen.clone(),
            since: Instant::now(),
            losses: 0,
            last_loss: None,
        });
        let worker = Worker {
            display: display.map(str::to_string),
            selector,
            title: title.to_string(),
            output: chosen.clone(),
            rx,
            state: state_tx,
            frame: Frame::black(chosen.width, chosen.height),
            waiting: Vec::new(),
            dirty: true,
            losses: 0,
        };
        std::thread::Builder::new()
            .name(format!("window {}", chosen.name))
            .spawn(move || worker.run(Some(surface)))
            .map_err(|e| HwError::Request(format!("starting the window thread: {e}")))?;
        Ok(Self {
            tx,
            state,
            output: chosen,
        })
    }

    /// The output it was opened on.
    pub fn output(&self) -> &Output {
        &self.output
    }

    /// Shows `frame` (of the output's size); `presented` resolves once it is on the screen.
    pub fn show(&self, frame: Frame, presented: Option<oneshot::Sender<()>>) {
        // The thread ends only when every handle is gone, so this cannot fail while `self` is.
        let _ = self.tx.send(Command::Show(frame, presented));
    }

    /// What the display is doing now.
    pub fn state(&self) -> DisplayState {
        self.state.borrow().clone()
    }

    /// Follows the state as it changes.
    pub fn watch(&self) -> watch::Receiver<DisplayState> {
        self.state.clone()
    }
}

struct Worker {
    display: Option<String>,
    selector: OutputSelector,
    title: String,
    output: Output,
    rx: mpsc::Receiver<Command>,
    state: watch::Sender<DisplayState>,
    /// The latest frame: shown again when the window comes back.
    frame: Frame,
    waiting: Vec<oneshot::Sender<()>>,
    dirty: bool,
    losses: u32,
}

impl Worker {
    fn run(mut self, mut surface: Option<Surface>) {
        let mut backoff = BACKOFF_FIRST;
        let mut next_attempt = Instant::now();
        let mut next_check = Instant::now() + OUTPUT_CHECK;
        loop {
            match self.rx.recv_timeout(POLL) {
                Ok(Command::Show(frame, presented)) => {
                    self.frame = frame;
                    self.waiting.extend(presented);
                    self.dirty = true;
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => return,
            }
            // Every frame queued so far: only the latest is shown.
            while let Ok(Command::Show(frame, presented)) = self.rx.try_recv() {
                self.frame = frame;
                self.waiting.extend(presented);
                self.dirty = true;
            }
            let now = Instant::now();
            if surface.is_none() && now >= next_attempt {
                match self.reopen() {
                    Ok(s) => {
                        tracing::info!(output = %self.output.name, "display back");
                        surface = Some(s);
                        backoff = BACKOFF_FIRST;
                        self.dirty = true;
                    }
                    Err(e) => {
                        self.lost(&e.to_string());
                        next_attempt = now + backoff;
                        backoff = (backoff * 2).min(BACKOFF_MAX);
                    }
                }
            }
            let Some(s) = surface.as_mut() else { continue };
            let mut outcome = s.events();
            if outcome.is_ok() && now >= next_check {
                next_check = now + OUTPUT_CHECK;
                outcome = s.check_output(&self.output).map(|()| false);
            }
            let outcome = outcome.and_then(|exposed| {
                if self.dirty || exposed {
                    s.present(&self.frame)?;
                }
                Ok(())
            });
            match outcome {
                Ok(()) => {
                    if self.dirty {
                        self.dirty = false;
                        for w in self.waiting.drain(..) {
                            let _ = w.send(());
                        }
                    }
                    let was_lost = match &*self.state.borrow() {
                        DisplayState::Lost { reason, .. } => Some(reason.clone()),
                        DisplayState::Showing { .. } => None,
                    };
                    if let Some(reason) = was_lost {
                        self.losses += 1;
                        self.state.send_replace(DisplayState::Showing {
                            output: self.output.clone(),
                            since: Instant::now(),
                            losses: self.losses,
                            last_loss: Some(reason),
                        });
                    }
                }
                Err(e) => {
                    surface = None;
                    self.lost(&e.to_string());
                    next_attempt = Instant::now() + backoff;
                }
            }
        }
    }

    /// Records and logs the loss (once per loss; retries are counted).
    fn lost(&mut self, reason: &str) {
        let previous = self.state.borrow().clone();
        let (since, retries) = match previous {
            DisplayState::Lost { since, retries, .. } => (since, retries + 1),
            _ => {
                tracing::warn!(output = %self.output.name, reason, "display lost; retrying");
                (Instant::now(), 0)
            }
        };
        self.state.send_replace(DisplayState::Lost {
            since,
            reason: reason.to_string(),
            retries,
        });
    }

    fn reopen(&mut self) -> Result<Surface, HwError> {
        let x = X11::connect(self.display.as_deref())?;
        let outputs = output::list(&x)?;
        let output = self.selector.pick(&outputs)?.clone();
        if (output.width, output.height) != (self.frame.width, self.frame.height) {
            return Err(HwError::Size {
                what: format!("{} is now {}x{}", output.name, output.width, output.height),
                expected: (self.frame.width, self.frame.height),
            });
        }
        self.output = output;
        Surface::open(x, &self.output, &self.title)
    }
}

/// One open window and its connection.
struct Surface {
    x: X11,
    window: u32,
    gc: u32,
}

impl Surface {
    fn open(x: X11, output: &Output, title: &str) -> Result<Self, HwError> {
        let failed =
            |e: String| HwError::Request(format!("opening a window on {}: {e}", output.name));
        let window = x.conn.generate_id().map_err(|e| failed(e.to_string()))?;
        let gc = x.conn.generate_id().map_err(|e| failed(e.to_string()))?;
        let blank = x.conn.generate_id().map_err(|e| failed(e.to_string()))?;
        let cursor = x.conn.generate_id().map_err(|e| failed(e.to_string()))?;
        let screen = x.screen().clone();
        let run = || -> Result<(), x11rb::errors::ReplyError> {
            // An invisible cursor: a 1×1 cursor whose mask is empty.
            x.conn.create_pixmap(1, blank, screen.root, 1, 1)?;
            x.conn
                .create_cursor(cursor, blank, blank, 0, 0, 0, 0, 0, 0, 0, 0)?;
            x.conn.create_window(
                screen.root_depth,
                window,
                screen.root,
                output.x as i16,
                output.y as i16,
                output.width as u16,
                output.height as u16,
                0,
                WindowClass::INPUT_OUTPUT,
                screen.root_visual,
                &CreateWindowAux::new()
                    .background_pixel(screen.black_pixel)
                    .override_redirect(1)
                    .cursor(cursor)
                    .event_mask(EventMask::STRUCTURE_NOTIFY | EventMask::EXPOSURE),
            )?;
            x.conn.change_property8(
                PropMode::REPLACE,
                window,
                x11rb::protocol::xproto::AtomEnum::WM_NAME,
                x11rb::protocol::xproto::AtomEnum::STRING,
                title.as_bytes(),
            )?;
            x.conn.create_gc(gc, window, &CreateGCAux::new())?;
            x.conn.map_window(window)?;
            x.conn.configure_window(
                window,
                &ConfigureWindowAux::new().stack_mode(StackMode::ABOVE),
            )?;
            x.conn.free_cursor(cursor)?;
            x.conn.free_pixmap(blank)?;
            // A round trip: the window is mapped (or an error is reported) before drawing.
            x.conn.get_input_focus()?.reply()?;
            Ok(())
        };
        run().map_err(|e| failed(e.to_string()))?;
        Ok(Self { x, window, gc })
    }

    /// Reads pending events: Ok(true) when the window needs drawing again, an error when it is
    /// gone.
    fn events(&mut self) -> Result<bool, HwError> {
        let mut exposed = false;
        loop {
            let event = self
                .x
                .conn
                .poll_for_event()
                .map_err(|e| HwError::Lost(format!("the X connection failed: {e}")))?;
            match event {
                None => return Ok(exposed),
                Some(Event::DestroyNotify(e)) if e.window == self.window => {
                    return Err(HwError::Lost("the window was closed (destroyed)".into()));
                }
                Some(Event::UnmapNotify(e)) if e.window == self.window => {
                    return Err(HwError::Lost("the window was closed (unmapped)".into()));
                }
                Some(Event::Expose(e)) if e.window == self.window => exposed = true,
                Some(Event::Error(e)) => {
                    return Err(HwError::Lost(format!("X error {:?}", e.error_kind)));
                }
                Some(_) => {}
            }
        }
    }

    /// Refuses an output that is gone or has moved.
    fn check_output(&self, expected: &Output) -> Result<(), HwError> {
        let outputs = output::list(&self.x)?;
        match outputs.iter().find(|o| o.name == expected.name) {
            Some(o) if o.geometry() == expected.geometry() => Ok(()),
            Some(o) => Err(HwError::Lost(format!(
                "output {} moved from {} to {}",
                expected.name,
                expected.geometry(),
                o.geometry()
            ))),
            None => Err(HwError::Lost(format!("output {} is gone", expected.name))),
        }
    }

    /// Draws `frame` in bands of rows that fit a request and waits until the server has them.
    fn present(&mut self, frame: &Frame) -> Result<(), HwError> {
        let f = self.x.format;
        let width = frame.width as usize;
        let band = (self.x.max_image_bytes() / f.stride(width)).max(1);
        let failed = |e: String| HwError::Lost(format!("drawing: {e}"));
        for (i, rows) in frame.rgb.chunks(band * width).enumerate() {
            let data = f.encode(rows, width);
            self.x
                .conn
                .put_image(
                    ImageFormat::Z_PIXMAP,
                    self.window,
                    self.gc,
                    frame.width as u16,
                    (rows.len() / width) as u16,
                    0,
                    (i * band) as i16,
                    0,
                    f.depth,
                    &data,
                )
                .map_err(|e| failed(e.to_string()))?;
        }
        self.x
            .conn
            .get_input_focus()
            .map_err(|e| failed(e.to_string()))?
            .reply()
            .map_err(|e| failed(e.to_string()))?;
        Ok(())
    }
}

impl Drop for Surface {
    fn drop(&mut self) {
        let _ = self.x.conn.destroy_window(self.window);
        let _ = self.x.conn.flush();
    }
}
