//! When to try a failed calibration again ([`Backoff`]).

use std::collections::HashMap;
use std::time::Duration;

/// When to try a failed calibration again: 200 ms · 2^failures after each failure, at most
/// 3.2 s, so one projector that cannot be calibrated is retried after the others.
#[derive(Debug, Clone, Default)]
pub struct Backoff {
    /// Projector → when it may be tried again and its failures so far.
    retry: HashMap<String, (Duration, u32)>,
}

impl Backoff {
    /// The first wait's unit.
    pub const UNIT: Duration = Duration::from_millis(200);
    /// The longest wait.
    pub const MAX: Duration = Duration::from_millis(3200);

    /// Its calibration failed at `now`; when to try again.
    pub fn failed(&mut self, id: &str, now: Duration) -> Duration {
        let failures = self.retry.get(id).map_or(0, |r| r.1).saturating_add(1);
        let at = now.saturating_add((Self::UNIT * (1 << failures.min(4))).min(Self::MAX));
        self.retry.insert(id.to_string(), (at, failures));
        at
    }

    /// It was calibrated (or left): forget its failures.
    pub fn forget(&mut self, id: &str) {
        self.retry.remove(id);
    }

    /// Keeps only the projectors still waiting.
    pub fn retain(&mut self, waiting: &[String]) {
        self.retry.retain(|id, _| waiting.contains(id));
    }

    /// It may be tried at `now`.
    pub fn due(&self, id: &str, now: Duration) -> bool {
        self.retry.get(id).is_none_or(|(at, _)| now >= *at)
    }

    /// The first of `waiting` whose try is due at `now`.
    pub fn next_due<'a>(&self, waiting: &'a [String], now: Duration) -> Option<&'a String> {
        waiting.iter().find(|id| self.due(id, now))
    }

    /// The earliest retry time, if any projector is backing off.
    pub fn earliest(&self) -> Option<Duration> {
        self.retry.values().map(|(at, _)| *at).min()
    }
}
