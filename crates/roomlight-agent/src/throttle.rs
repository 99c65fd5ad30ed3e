//! Rate-limited logging of repeated events (peers refused, dropped for lagging or misbehaving,
//! connections over the limit): the first event of a burst is logged at once, the rest are
//! counted and reported with their count in one line at most once an interval, so a flood from
//! the network cannot fill the disk. It knows nothing of what the events are.

use std::time::Duration;
use tokio::time::Instant;

/// How often a repeated warning may write a line.
pub(crate) const LOG_INTERVAL: Duration = Duration::from_secs(1);

/// Counts events and says when one may be logged.
#[derive(Debug)]
pub(crate) struct Throttle {
    interval: Duration,
    last: Option<Instant>,
    unlogged: u64,
}

impl Default for Throttle {
    fn default() -> Self {
        Self::new(LOG_INTERVAL)
    }
}

impl Throttle {
    pub(crate) fn new(interval: Duration) -> Self {
        Self {
            interval,
            last: None,
            unlogged: 0,
        }
    }

    /// Counts one event; `Some(n)` when a line is due now, `n` the events since the last line
    /// (this one included).
    pub(crate) fn hit(&mut self) -> Option<u64> {
        self.unlogged += 1;
        let now = Instant::now();
        if self
            .last
            .is_some_and(|t| now.duration_since(t) < self.interval)
        {
            return None;
        }
        self.last = Some(now);
        Some(std::mem::take(&mut self.unlogged))
    }
}

/// A throttle behind a lock, for events from many tasks.
#[derive(Debug, Default)]
pub(crate) struct Shared(std::sync::Mutex<Throttle>);

impl Shared {
    /// See [`Throttle::hit`].
    pub(crate) fn hit(&self) -> Option<u64> {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .hit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn a_burst_writes_one_line_then_one_summary_an_interval() {
        let mut t = Throttle::default();
        assert_eq!(t.hit(), Some(1), "the first is logged at once");
        let lines: Vec<u64> = (0..1000).filter_map(|_| t.hit()).collect();
        assert!(lines.is_empty(), "{lines:?}");
        tokio::time::advance(LOG_INTERVAL).await;
        assert_eq!(t.hit(), Some(1001), "the summary counts everything since");
        assert_eq!(t.hit(), None);
    }
}
