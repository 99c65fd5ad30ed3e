//! The objective against rounds and time: one point per measured round the status reports, the
//! last [`KEPT`]; with the room's exact optimum `G*` (computed off the round loop, again
//! whenever the model changes, for rooms of at most [`MAX_OPTIMUM_NODES`] nodes) each point's
//! excess over it.

use crate::Console;
use roomlight_core::optimum::Optimum;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, PoisonError};
use tokio_util::sync::CancellationToken;

/// Points kept.
pub const KEPT: usize = 2000;
/// Larger rooms get no optimum on the console (it would take seconds of a core each time).
pub const MAX_OPTIMUM_NODES: usize = 2000;

/// One measured round.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Point {
    pub round: u64,
    pub captures: u64,
    /// Seconds since the console started.
    pub t: f64,
    pub objective: f64,
    /// `(G − G*) / G*` when `G*` is known.
    pub excess: Option<f64>,
}

/// The points and the optimum.
#[derive(Debug, Default)]
pub struct History {
    points: Mutex<VecDeque<Point>>,
    optimum: Mutex<Option<Optimum>>,
}

impl History {
    pub fn points(&self) -> Vec<Point> {
        self.points
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .cloned()
            .collect()
    }

    /// `G*`, when known.
    pub fn optimum(&self) -> Option<f64> {
        self.optimum
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .as_ref()
            .map(|o| o.objective)
    }

    /// The excess of `objective` over `G*`, when known and finite.
    pub fn excess(&self, objective: f64) -> Option<f64> {
        self.optimum
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .as_ref()
            .map(|o| o.excess(objective))
            .filter(|e| e.is_finite())
    }
}

/// Follows the status: a point per new measured round; the optimum again when the model
/// changed (projectors calibrated, a new target).
pub async fn follow(console: Arc<Console>, cancel: CancellationToken) {
    let mut status = console.status.clone();
    let mut last_round = None;
    let mut model_key = None;
    loop {
        tokio::select! {
            changed = status.changed() => if changed.is_err() { return },
            () = cancel.cancelled() => return,
        }
        let (round, captures, objective, key) = {
            let s = status.borrow_and_update();
            let o = console.overview.borrow();
            // The model changes with a calibration or a new target.
            let calibrated: Vec<u64> = o.calibrations.iter().map(|c| c.at_round).collect();
            let key = (s.calibrated_hot, o.restarts, calibrated, s.live_projectors);
            (s.round, s.captures, s.measured_objective, key)
        };
        if model_key.as_ref() != Some(&key) {
            model_key = Some(key);
            let problem = console.control.problem();
            let optimum = if (1..=MAX_OPTIMUM_NODES).contains(&problem.nodes()) {
                tokio::task::spawn_blocking(move || roomlight_core::optimum::optimum(&problem).ok())
                    .await
                    .ok()
                    .flatten()
            } else {
                None
            };
            *console
                .history
                .optimum
                .lock()
                .unwrap_or_else(PoisonError::into_inner) = optimum;
        }
        if captures == 0 || last_round == Some(round) || !objective.is_finite() {
            continue;
        }
        last_round = Some(round);
        let point = Point {
            round,
            captures,
            t: console.started.elapsed().as_secs_f64(),
            objective,
            excess: console.history.excess(objective),
        };
        let mut points = console
            .history
            .points
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if points.len() >= KEPT {
            points.pop_front();
        }
        points.push_back(point);
    }
}
