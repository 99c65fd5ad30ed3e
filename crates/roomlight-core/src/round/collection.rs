//! The contributions one round waits for, until a deadline ([`Collection`]).

use std::collections::HashSet;
use std::time::Duration;

/// What a contribution did to the round waiting for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Received {
    /// Awaited: counts (add it to the errors).
    Counted,
    /// Of another round (late or early): ignored.
    OtherRound,
    /// Of a node not awaited (not sent, already in, or its projector left): ignored.
    NotAwaited,
}

/// The contributions one round waits for, until a deadline. O(1) per message.
#[derive(Debug, Clone)]
pub struct Collection {
    round: u64,
    outstanding: HashSet<u32>,
    deadline: Duration,
}

impl Collection {
    /// Round `round` was sent to `nodes` at `now`; it waits until `now + wait`.
    pub fn new(
        round: u64,
        nodes: impl IntoIterator<Item = u32>,
        now: Duration,
        wait: Duration,
    ) -> Self {
        Self {
            round,
            outstanding: nodes.into_iter().collect(),
            deadline: now.saturating_add(wait),
        }
    }

    /// The round collected.
    pub fn round(&self) -> u64 {
        self.round
    }

    /// A contribution of `node` for `round` arrived.
    pub fn receive(&mut self, round: u64, node: u32) -> Received {
        if round != self.round {
            Received::OtherRound
        } else if self.outstanding.remove(&node) {
            Received::Counted
        } else {
            Received::NotAwaited
        }
    }

    /// These nodes left (their projector did): they will not answer.
    pub fn left(&mut self, nodes: &[u32]) {
        for n in nodes {
            self.outstanding.remove(n);
        }
    }

    /// Every node awaited has answered or left.
    pub fn done(&self) -> bool {
        self.outstanding.is_empty()
    }

    /// Nodes still awaited.
    pub fn missing(&self) -> usize {
        self.outstanding.len()
    }

    /// When the round stops waiting.
    pub fn deadline(&self) -> Duration {
        self.deadline
    }

    /// The deadline has passed at `now`.
    pub fn expired(&self, now: Duration) -> bool {
        now >= self.deadline
    }
}
