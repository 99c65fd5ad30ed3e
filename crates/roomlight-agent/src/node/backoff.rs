//! How long a node agent waits before reconnecting: exponential backoff with jitter, so that the
//! node agents of a room whose camera agent restarts do not all knock at the same instant.
//!
//! It knows nothing of sessions or of why a connection ended; the caller resets it after a
//! session that was established and ended cleanly.

use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// First wait before reconnecting.
pub(super) const MIN_BACKOFF: Duration = Duration::from_millis(100);
/// Largest step the wait doubles to (before jitter).
pub(super) const MAX_BACKOFF: Duration = Duration::from_secs(5);

/// The reconnect wait: it starts at [`MIN_BACKOFF`], doubles after each wait up to
/// [`MAX_BACKOFF`], and each wait adds up to half its step as jitter.
#[derive(Debug, Clone)]
pub(super) struct Backoff {
    step: Duration,
}

impl Backoff {
    pub(super) fn new() -> Self {
        Self { step: MIN_BACKOFF }
    }

    /// Back to the first step: the last session was established and ended cleanly.
    pub(super) fn reset(&mut self) {
        self.step = MIN_BACKOFF;
    }

    /// The next wait, given a jitter fraction in [0, 1): the step plus that fraction of half the
    /// step. The step then doubles, up to [`MAX_BACKOFF`].
    pub(super) fn next_wait(&mut self, jitter: f64) -> Duration {
        let wait = self.step + self.step.mul_f64(jitter.clamp(0.0, 1.0) / 2.0);
        self.step = (self.step * 2).min(MAX_BACKOFF);
        wait
    }

    /// Sleeps the next wait; false when `cancel` fired first.
    pub(super) async fn sleep(&mut self, cancel: &CancellationToken) -> bool {
        let wait = self.next_wait(clock_jitter());
        tokio::select! {
            () = cancel.cancelled() => false,
            () = tokio::time::sleep(wait) => true,
        }
    }
}

/// A jitter fraction in [0, 1) from the wall clock's nanoseconds: node agents started together
/// still differ there, and it needs no generator.
fn clock_jitter() -> f64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    f64::from(nanos % 1000) / 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::time::Instant;

    #[test]
    fn waits_double_up_to_the_largest_step_with_at_most_half_a_step_of_jitter() {
        let mut backoff = Backoff::new();
        let steps: Vec<Duration> = (0..8).map(|_| backoff.next_wait(0.0)).collect();
        let ms: Vec<u128> = steps.iter().map(Duration::as_millis).collect();
        assert_eq!(ms, [100, 200, 400, 800, 1600, 3200, 5000, 5000]);
        let mut backoff = Backoff::new();
        assert_eq!(backoff.next_wait(0.999), Duration::from_micros(149_950));
        assert_eq!(backoff.next_wait(1.0), Duration::from_millis(300));
        assert_eq!(
            backoff.next_wait(-3.0),
            Duration::from_millis(400),
            "clamped"
        );
        backoff.reset();
        assert_eq!(backoff.next_wait(0.5), Duration::from_millis(125));
    }

    #[tokio::test(start_paused = true)]
    async fn a_sleep_lasts_its_wait_and_ends_at_once_on_cancel() {
        let cancel = CancellationToken::new();
        let mut backoff = Backoff::new();
        for step in [100, 200, 400] {
            let start = Instant::now();
            assert!(backoff.sleep(&cancel).await);
            let slept = start.elapsed();
            let step = Duration::from_millis(step);
            assert!(
                slept >= step && slept <= step + step / 2,
                "slept {slept:?} for a step of {step:?}"
            );
        }
        cancel.cancel();
        let start = Instant::now();
        assert!(!backoff.sleep(&cancel).await);
        assert_eq!(start.elapsed(), Duration::ZERO);
    }
}
