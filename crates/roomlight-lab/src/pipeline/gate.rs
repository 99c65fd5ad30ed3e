//! Captures in step with a run's driver, so that a run at a fixed seed is the same on every run
//! and every machine. The camera agent publishes its status after each capture's rounds and
//! then, at once, goes on to the next capture; a driver that reacts to the status (a projector
//! leaves, another joins, the budget is spent) would otherwise act somewhere inside the next
//! rounds, wherever the scheduler happened to put it. The gate holds every capture until the
//! driver has handled the latest status: churn then lands between two captures, and a run
//! stops exactly after the rounds of its last capture. A capture held here is asked for
//! before it waits: the run's clock of the rounds ends at the request and leaves the wait out.
//! A driver that must act where the camera agent cannot be (its console requests are read
//! between two captures' rounds; what the projectors show is final only once they have shown
//! the last round's values) waits for the next capture to be held ([`Gate::held`]).

use roomlight_agent::camera::{Overview, ProjectorState, ProjectorStatus, RoomStatus};
use std::sync::OnceLock;
use std::time::Duration;
use tokio::sync::watch;

/// Where the driver is: the captures of the last status it handled, or open (the run is over
/// and captures are no longer held).
#[derive(Debug, Clone, Copy, Default)]
struct Handled {
    captures: Option<u64>,
    open: bool,
}

/// Holds each capture until the driver has handled the camera agent's latest status.
#[derive(Debug, Default)]
pub struct Gate {
    status: OnceLock<watch::Receiver<RoomStatus>>,
    handled: watch::Sender<Handled>,
    /// The status (its captures) a capture is held after, while one is.
    holding: watch::Sender<Option<u64>>,
}

impl Gate {
    /// A gate that holds nothing until it [`Gate::follow`]s a status.
    pub fn new() -> Self {
        Self::default()
    }

    /// Follows the camera agent's status (set once, before its first capture; later calls
    /// are ignored).
    pub fn follow(&self, status: watch::Receiver<RoomStatus>) {
        let _ = self.status.set(status);
    }

    /// The driver has done what the status after `captures` captures asked (the status
    /// before any capture is 0): the next capture may be taken.
    pub fn handled(&self, captures: u64) {
        self.handled.send_modify(|h| h.captures = Some(captures));
    }

    /// The run is over (or failed): captures are no longer held, so the camera agent can
    /// finish its round and stop.
    pub fn open(&self) {
        self.handled.send_modify(|h| h.open = true);
    }

    /// Waits until a capture may be taken. The camera agent publishes a
    /// capture's status before it asks for the next capture, so the status read here is the
    /// one the driver must have handled.
    pub async fn wait(&self) {
        let Some(status) = self.status.get() else {
            return;
        };
        let seen = status.borrow().captures;
        let mut handled = self.handled.subscribe();
        self.holding.send_replace(Some(seen));
        // The sender lives in `self`: the wait ends only when the condition holds.
        let _ = handled
            .wait_for(|h| h.open || h.captures.is_some_and(|c| c >= seen))
            .await;
        self.holding.send_replace(None);
    }

    /// Waits, at most `limit`, until a capture is held after the status of `captures`
    /// captures: the camera agent has shown the rounds' last values (it waits for every
    /// projector's acknowledgement before it captures) and has read its console requests.
    pub async fn held(&self, captures: u64, limit: Duration) -> anyhow::Result<()> {
        let mut holding = self.holding.subscribe();
        tokio::time::timeout(limit, holding.wait_for(|h| *h == Some(captures)))
            .await
            .map_err(|_| {
                anyhow::anyhow!(
                    "the camera agent took no capture after the status of {captures} captures within {limit:?}"
                )
            })?
            .map_err(|_| anyhow::anyhow!("the gate went away"))?;
        Ok(())
    }
}

/// Waits until the console's list of projectors satisfies `done` (the list is published at
/// most five times a second), at most `limit`.
pub async fn wait_for_projectors(
    overview: &mut watch::Receiver<Overview>,
    limit: Duration,
    done: impl Fn(&[ProjectorStatus]) -> bool,
) -> anyhow::Result<()> {
    tokio::time::timeout(limit, overview.wait_for(|o| done(&o.projectors)))
        .await
        .map_err(|_| anyhow::anyhow!("the projectors did not come as expected within {limit:?}"))?
        .map_err(|_| anyhow::anyhow!("the camera agent stopped"))?;
    Ok(())
}

/// True when `id` is in the rounds: calibrated, not late, and showing a frame.
pub fn live(projectors: &[ProjectorStatus], id: &str) -> bool {
    projectors
        .iter()
        .any(|p| p.id == id && p.state == ProjectorState::Live && p.shown.is_some())
}

/// True when `id` is attached, whatever its state.
pub fn attached(projectors: &[ProjectorStatus], id: &str) -> bool {
    projectors.iter().any(|p| p.id == id)
}
