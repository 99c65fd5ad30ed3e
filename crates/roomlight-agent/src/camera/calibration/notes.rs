//! A calibration's progress as the installer follows it: each procedure event logged, and
//! the console's overview kept current (which projectors, the step, captures done of those
//! planned; per projector the share decoded and what looked wrong). It knows nothing of how
//! projectors are measured.

use crate::camera::Shared;
use roomlight_calib::procedure::Event;

/// Reports the procedure's progress in the log.
pub(super) fn log_event(event: Event) {
    match event {
        Event::Stage { stage, captures } => tracing::info!(?stage, captures, "calibration step"),
        Event::Captured { .. } => {}
        Event::Grouped { groups } => tracing::info!(?groups, "coded at the same time"),
        Event::Primaries { sets } => {
            tracing::info!(?sets, "groups coded at the same time in their primaries")
        }
        Event::Shaped {
            projector,
            nodes,
            spread,
        } => tracing::info!(%projector, nodes, ?spread, "nodes shaped to the reference"),
        Event::Decoded { projector, share } => {
            tracing::info!(%projector, decoded = format!("{:.1}%", 100.0 * share), "structured light decoded")
        }
        Event::SecondPass { projector, pass } => tracing::info!(%projector, ?pass, "second pass"),
        Event::Response { projector, gamma } => tracing::info!(%projector, ?gamma, "response"),
        Event::RampApart { reason } => {
            tracing::warn!(%reason, "ramp shown together refused; each projector shows its own")
        }
        Event::WholeFrame { projector, chart } => {
            tracing::info!(%projector, ?chart, "one node over its frame")
        }
    }
}

/// A calibration's progress and findings, published for the console: which projectors are
/// measured, the step, captures done of those planned; per projector the share its structured
/// light decoded and what looked wrong.
#[derive(Debug, Default)]
pub(super) struct Notes {
    found: std::sync::Mutex<Found>,
}

#[derive(Debug, Default)]
struct Found {
    batch: Vec<String>,
    decoded: Vec<(String, f64)>,
    warnings: Vec<(String, String)>,
    captures: usize,
}

impl Notes {
    fn found(&self) -> std::sync::MutexGuard<'_, Found> {
        self.found
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// `projector`'s calibration begins.
    pub(super) fn begin(shared: &Shared, projector: &str) -> Self {
        let notes = Self::default();
        notes.batch(shared, &[projector.to_string()]);
        notes
    }

    /// These projectors are measured together.
    pub(super) fn batch(&self, shared: &Shared, batch: &[String]) {
        self.found().batch = batch.to_vec();
        shared.overview.send_modify(|s| {
            s.calibrating = Some(crate::camera::CalibrationProgress {
                projectors: batch.to_vec(),
                stage: "starting".into(),
                done: 0,
                expected: 0,
            });
        });
        shared.publish_projectors();
    }

    pub(super) fn warn(&self, projector: &str, warning: String) {
        self.found().warnings.push((projector.to_string(), warning));
    }

    pub(super) fn captures(&self, captures: usize) {
        self.found().captures = captures;
    }

    /// The procedure's progress: logged, and published.
    pub(super) fn reporter<'a>(&'a self, shared: &'a Shared) -> impl FnMut(Event) + Send + 'a {
        move |event: Event| {
            match &event {
                Event::Stage { stage, captures } => shared.overview.send_modify(|s| {
                    if let Some(c) = s.calibrating.as_mut() {
                        c.stage = format!("{stage:?}");
                        c.expected = c.done + captures;
                    }
                }),
                Event::Captured { .. } => shared.overview.send_modify(|s| {
                    if let Some(c) = s.calibrating.as_mut() {
                        c.done += 1;
                        c.expected = c.expected.max(c.done);
                    }
                }),
                Event::Decoded { projector, share } => {
                    self.found().decoded.push((projector.clone(), *share));
                }
                Event::SecondPass { projector, .. } => {
                    self.warn(
                        projector,
                        "a second pass over pixels the first left unknown".into(),
                    );
                }
                Event::WholeFrame { projector, chart } => self.warn(
                    projector,
                    match chart {
                        Some(c) => format!("one node over its whole frame (lights chart {c} most)"),
                        None => "one node over its whole frame: it lights no chart".into(),
                    },
                ),
                _ => {}
            }
            log_event(event);
        }
    }

    /// The calibration ended; `calibrated` are the projectors it measured (none: it failed).
    pub(super) fn end(&self, shared: &Shared, calibrated: &[String]) {
        let found = std::mem::take(&mut *self.found());
        let nodes: std::collections::HashMap<String, usize> = {
            let live = shared.live();
            found
                .batch
                .iter()
                .map(|id| (id.clone(), live.owners.get(id).map_or(0, Vec::len)))
                .collect()
        };
        let round = shared.status.borrow().round;
        shared.overview.send_modify(|s| {
            s.calibrating = None;
            for id in &found.batch {
                let mut warnings: Vec<String> = found
                    .warnings
                    .iter()
                    .filter(|(p, _)| p == id)
                    .map(|(_, w)| w.clone())
                    .collect();
                if !calibrated.contains(id) && warnings.is_empty() {
                    warnings.push("not calibrated (see the log)".into());
                }
                let result = crate::camera::CalibrationResult {
                    projector: id.clone(),
                    decoded: found
                        .decoded
                        .iter()
                        .rev()
                        .find(|(p, _)| p == id)
                        .map(|d| d.1),
                    nodes: nodes.get(id).copied().unwrap_or(0),
                    captures: found.captures,
                    at_round: round,
                    warnings,
                };
                match s.calibrations.iter_mut().find(|r| r.projector == *id) {
                    Some(slot) => *slot = result,
                    None => s.calibrations.push(result),
                }
            }
            s.calibrations.sort_by(|a, b| a.projector.cmp(&b.projector));
        });
        shared.publish_projectors();
    }
}
