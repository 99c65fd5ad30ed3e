//! The agents under systemd (`Type=notify`, `WatchdogSec=`), through the sd-notify crate: the
//! service manager is told READY once the process does its job (a camera agent serving, a node
//! agent whose projector shows its first frame), fed WATCHDOG from the process's main loop at
//! half the interval systemd asked for, and told STOPPING on the way out. Every call is a no-op
//! when systemd did not start the process (no `$NOTIFY_SOCKET`), and a failed notification is
//! logged, never fatal: the room's light does not depend on the service manager. A notification
//! is one datagram on a blocking socket, as the crate sends it: it waits only when the manager
//! stops reading its socket (its queue holds a few messages), which systemd does not do.

use roomlight_agent::hardware::{Assignment, Display, DisplayFeed, Pattern};
use roomlight_core::LinearRgb;
use sd_notify::NotifyState;
use std::time::Duration;

fn notify(states: &[NotifyState]) {
    if let Err(e) = sd_notify::notify(states) {
        tracing::warn!(error = %e, "cannot notify the service manager");
    }
}

/// READY, with a status line `systemctl status` shows.
pub fn ready(status: &str) {
    notify(&[NotifyState::Ready, NotifyState::Status(status)]);
}

/// STOPPING: a stop was asked and the process is on its way out.
pub fn stopping() {
    notify(&[NotifyState::Stopping]);
}

/// The watchdog systemd asked for (`WatchdogSec=`, seen as `$WATCHDOG_USEC`): `tick` resolves
/// at half its interval and `feed` tells systemd the main loop is alive; without a watchdog
/// `tick` never resolves.
pub struct Watchdog(Option<tokio::time::Interval>);

impl Watchdog {
    pub fn from_env() -> Self {
        // Half the interval, as sd_watchdog_enabled(3) advises; at least 10 ms so that a tiny
        // value cannot spin the loop.
        Self(sd_notify::watchdog_enabled().map(|usec| {
            let mut every = tokio::time::interval((usec / 2).max(Duration::from_millis(10)));
            every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            every
        }))
    }

    pub async fn tick(&mut self) {
        match &mut self.0 {
            Some(every) => {
                every.tick().await;
            }
            None => std::future::pending().await,
        }
    }

    pub fn feed(&self) {
        notify(&[NotifyState::Watchdog]);
    }
}

/// A node agent's display that tells systemd READY once its first frame is on the projector
/// (after the first flush that followed something shown); otherwise the display itself.
pub struct ReadyOnShow<D> {
    inner: D,
    shown: bool,
    ready: bool,
    projector: String,
}

impl<D> ReadyOnShow<D> {
    pub fn new(inner: D, projector: &str) -> Self {
        Self {
            inner,
            shown: false,
            ready: false,
            projector: projector.to_string(),
        }
    }
}

impl<D: Display> Display for ReadyOnShow<D> {
    fn show(&mut self, node: u32, value: LinearRgb) {
        self.shown = true;
        self.inner.show(node, value);
    }

    fn show_pattern(&mut self, pattern: Pattern) -> bool {
        let shown = self.inner.show_pattern(pattern);
        self.shown |= shown;
        shown
    }

    fn assign(&mut self, assignment: &Assignment) {
        self.inner.assign(assignment);
    }

    fn resolution(&self) -> Option<(u32, u32)> {
        self.inner.resolution()
    }

    async fn flush(&mut self) {
        self.inner.flush().await;
        if self.shown && !self.ready {
            self.ready = true;
            ready(&format!(
                "projector {} attached and showing",
                self.projector
            ));
        }
    }

    fn state_feed(&self) -> Option<DisplayFeed> {
        self.inner.state_feed()
    }
}

/// Runs `main` (a process's main loop) and feeds the watchdog from the same task while it
/// runs: a loop that blocks its thread or stops being polled starves the watchdog too, and
/// systemd restarts the process. STOPPING is sent when `main` ends.
pub async fn with_watchdog<F: Future>(main: F) -> F::Output {
    let mut watchdog = Watchdog::from_env();
    tokio::pin!(main);
    let out = loop {
        tokio::select! {
            out = &mut main => break out,
            () = watchdog.tick() => watchdog.feed(),
        }
    };
    stopping();
    out
}
