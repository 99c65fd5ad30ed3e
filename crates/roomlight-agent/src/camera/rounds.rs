//! The round loop: calibrate the projectors waiting for it (backing off on failure) while the
//! others go on; wait until every live projector shows its last frame (late ones are left out),
//! capture, send each node the errors on its support, collect contributions, run model rounds,
//! and report a status. It knows nothing of the handshake or how a peer's stream is read.

use super::capture::Captures;
use super::registry::Outbox;
use super::{Contribution, RoomStatus, Shared};
use crate::hardware::Camera;
use prost::Message;
use roomlight_core::LinearRgb;
use roomlight_core::aggregator::{ErrorAggregator, ErrorKind, RoundSummary};
use roomlight_core::closed_loop::objective_noise;
use roomlight_proto::convert::to_sparse;
use roomlight_proto::v1;
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tokio_util::sync::CancellationToken;

/// What to do after looking at the projectors waiting for their calibration.
enum Next {
    /// Nothing runs meanwhile: look again.
    Again,
    /// Stop requested.
    Stop,
    /// Run a measured round.
    Round,
}

/// The round loop's state: the camera, the errors, and what it has done so far.
pub(super) struct Rounds<C> {
    shared: Arc<Shared>,
    eye: Captures<C>,
    contributions: mpsc::Receiver<Contribution>,
    status: watch::Sender<RoomStatus>,
    aggregator: ErrorAggregator,
    /// The model's per-patch noise (for the settle rule).
    sigma: Vec<LinearRgb>,
    calibrated_hot: u64,
    /// Projector → when to try its calibration again, and its failures so far.
    retry: HashMap<String, (tokio::time::Instant, u32)>,
    /// `G` of the last measured round.
    previous: Option<f64>,
    /// Measured rounds running whose `G` moved less than its noise.
    quiet: u32,
}

impl<C: Camera> Rounds<C> {
    pub(super) fn new(
        shared: Arc<Shared>,
        camera: C,
        contributions: mpsc::Receiver<Contribution>,
        status: watch::Sender<RoomStatus>,
    ) -> Self {
        let (patches, sigma) = {
            let live = shared.live();
            (live.problem.patches(), live.problem.noise().to_vec())
        };
        Self {
            shared,
            eye: Captures::new(camera),
            contributions,
            status,
            aggregator: ErrorAggregator::new(patches),
            sigma,
            calibrated_hot: 0,
            retry: HashMap::new(),
            previous: None,
            quiet: 0,
        }
    }

    /// Runs rounds until `cancel`: a stop request ends them between two rounds, never inside one.
    pub(super) async fn run(mut self, cancel: CancellationToken) {
        while !cancel.is_cancelled() {
            // Someone must be there, and have shown its last frame (or wait to be measured).
            let present = tokio::select! {
                present = self.shared.registry.wait_for(Duration::from_secs(3600), |r| {
                    r.peers.values().any(|p| p.shown.is_some() || !p.calibrated)
                }) => present,
                () = cancel.cancelled() => break,
            };
            if !present {
                continue;
            }
            match self.calibrate_waiting(&cancel).await {
                Next::Again => continue,
                Next::Stop => break,
                Next::Round => self.measured_cycle().await,
            }
        }
    }

    /// Calibrates the next projector waiting whose retry is due; when nothing else runs, waits
    /// for the next retry or a change.
    async fn calibrate_waiting(&mut self, cancel: &CancellationToken) -> Next {
        let shared = self.shared.clone();
        let now = tokio::time::Instant::now();
        let (waiting, due) = {
            let reg = shared.registry.lock();
            let waiting: Vec<String> = reg
                .peers
                .iter()
                .filter(|(_, p)| !p.calibrated)
                .map(|(id, _)| id.clone())
                .collect();
            let due = waiting
                .iter()
                .find(|id| self.retry.get(*id).is_none_or(|(at, _)| now >= *at))
                .cloned();
            (waiting, due)
        };
        self.retry.retain(|id, _| waiting.contains(id));
        if let Some(projector) = due {
            // The room's errors without it, once a round has measured them.
            let errors = self.previous.is_some().then(|| self.aggregator.errors());
            if super::calibration::calibrate_hot(&shared, &mut self.eye, &projector, errors).await {
                self.calibrated_hot += 1;
                self.retry.remove(&projector);
                return Next::Again;
            }
            // Tried again after the others, backing off to 3.2 s (the cause is logged each time).
            let failures = self
                .retry
                .get(&projector)
                .map_or(0, |r| r.1)
                .saturating_add(1);
            let wait = Duration::from_millis(200) * (1 << failures.min(4));
            self.retry
                .insert(projector, (tokio::time::Instant::now() + wait, failures));
            // Projectors kept dark for a bring-up light up now rather than wait for one that
            // may never be measured.
            let unlit = shared
                .registry
                .lock()
                .peers
                .values()
                .any(|p| p.calibrated && p.shown.is_none());
            if unlit {
                shared.light_all().await;
            }
        }
        if waiting.is_empty() {
            return Next::Round;
        }
        // Meanwhile the calibrated projectors go on with their rounds: one that cannot be
        // calibrated must not stop the others' corrections.
        let others = shared
            .registry
            .lock()
            .peers
            .values()
            .any(|p| p.calibrated && p.shown.is_some());
        if others {
            return Next::Round;
        }
        let next = self
            .retry
            .values()
            .map(|(at, _)| *at)
            .min()
            .unwrap_or_else(tokio::time::Instant::now);
        tokio::select! {
            () = tokio::time::sleep_until(next) => Next::Again,
            () = shared.registry.changed() => Next::Again,
            () = cancel.cancelled() => Next::Stop,
        }
    }

    /// One capture and the rounds that follow it: the measured round, then the model rounds;
    /// then the status.
    async fn measured_cycle(&mut self) {
        let shared = self.shared.clone();
        shared
            .registry
            .wait_for(shared.config.deadline, |r| r.all_shown())
            .await;
        let Some((y, ok)) = self.eye.measured(&shared).await else {
            // The camera is unreachable: the lights stay as they are; try again.
            tokio::time::sleep(Duration::from_millis(200)).await;
            return;
        };
        self.leave_out_unmeasurable(&ok).await;
        let errors = shared.live().errors(&y);
        let summary = match self.aggregator.measured(errors) {
            Ok(s) => s,
            Err(e) => {
                tracing::error!(error = %e, "capture refused");
                return;
            }
        };
        let mut round = summary.round;
        let measured_objective = summary.objective;
        let noise = objective_noise(self.aggregator.errors(), &self.sigma);
        self.quiet = match self.previous {
            // A noiseless camera: settled when G stops changing to rounding.
            Some(g)
                if (measured_objective - g).abs()
                    <= (3.0 * std::f64::consts::SQRT_2 * noise)
                        .max(1e-12 * measured_objective.max(g)) =>
            {
                self.quiet + 1
            }
            _ => 0,
        };
        self.previous = Some(measured_objective);
        self.round_trip(&summary).await;
        for _ in 0..shared.config.model_rounds {
            // Acknowledgements follow contributions: wait for them too.
            shared
                .registry
                .wait_for(shared.config.deadline, |r| r.all_shown())
                .await;
            let summary = self.aggregator.predicted();
            round = summary.round;
            self.round_trip(&summary).await;
        }
        let live_projectors = shared.registry.lock().peers.len();
        self.status.send_replace(RoomStatus {
            round,
            captures: self.eye.count,
            measured_objective,
            live_projectors,
            bytes_out: shared.bytes_out.swap(0, Ordering::Relaxed),
            bytes_in: shared.bytes_in.swap(0, Ordering::Relaxed),
            settled: self.quiet >= 2,
            calibrated_hot: self.calibrated_hot,
        });
    }

    /// Calibrated over the wire: a patch the room's light now saturates or an edge now crosses
    /// leaves the model, and everyone gets the cut columns.
    async fn leave_out_unmeasurable(&mut self, ok: &[bool]) {
        let shared = &self.shared;
        let cut = {
            let mut live = shared.live_mut();
            let newly = live.newly_unmeasurable(ok);
            if newly.is_empty() {
                return;
            }
            let columns = live.problem.columns().to_vec();
            match live.leave_out_with(&newly, columns) {
                Ok(()) => Some(newly),
                Err(e) => {
                    tracing::error!(error = %e, "patches could not be left out");
                    None
                }
            }
        };
        if let Some(newly) = cut {
            tracing::info!(patches = ?newly, "patches no longer measurable under the room's light: left out");
            shared.light_all().await;
            shared.save_model();
        }
    }

    /// Sends the round's errors and collects its contributions.
    async fn round_trip(&mut self, summary: &RoundSummary) {
        let sent = broadcast(&self.shared, self.aggregator.errors(), summary).await;
        collect(
            &self.shared,
            &mut self.contributions,
            &mut self.aggregator,
            summary.round,
            sent,
        )
        .await;
    }
}

/// Sends every ready projector the errors of its nodes; returns the nodes that were sent.
async fn broadcast(shared: &Shared, errors: &[LinearRgb], summary: &RoundSummary) -> Vec<u32> {
    let kind = match summary.kind {
        ErrorKind::Measured => v1::ErrorKind::Measured,
        ErrorKind::Predicted => v1::ErrorKind::Predicted,
    };
    let mut outbox: Vec<(Outbox, u32, v1::Errors)> = Vec::new();
    {
        let mut reg = shared.registry.lock();
        let live = shared.live();
        for (projector, peer) in reg.peers.iter_mut().filter(|(_, p)| p.calibrated) {
            if !peer.ready() {
                tracing::warn!(%projector, round = summary.round, "late: left out of this round");
                continue;
            }
            peer.awaiting = Some(summary.round);
            for &n in &peer.nodes {
                let column = &live.problem.columns()[n as usize];
                let e: Vec<LinearRgb> = column
                    .support()
                    .iter()
                    .map(|&i| errors[i as usize])
                    .collect();
                outbox.push((
                    peer.tx.clone(),
                    n,
                    v1::Errors {
                        round: summary.round,
                        kind: kind as i32,
                        objective: summary.objective,
                        restart: summary.restart,
                        node: n,
                        errors: Some(to_sparse(column.support(), &e)),
                    },
                ));
            }
        }
    }
    let mut sent = Vec::with_capacity(outbox.len());
    for (tx, n, msg) in outbox {
        shared
            .bytes_out
            .fetch_add(msg.encoded_len() as u64, Ordering::Relaxed);
        // A failed send means the node left; its reader removes it.
        let message = v1::RoomMessage {
            body: Some(v1::room_message::Body::Errors(msg)),
        };
        if tx.send(Ok(message)).await.is_ok() {
            sent.push(n);
        }
    }
    sent
}

/// Collects the contributions of `nodes` for `round` into the aggregator (until the deadline).
async fn collect(
    shared: &Shared,
    rx: &mut mpsc::Receiver<Contribution>,
    aggregator: &mut ErrorAggregator,
    round: u64,
    mut nodes: Vec<u32>,
) {
    let until = tokio::time::Instant::now() + shared.config.deadline;
    while !nodes.is_empty() {
        let changed = shared.registry.changed();
        // A projector that left will not answer: its nodes are not waited for.
        {
            let reg = shared.registry.lock();
            nodes.retain(|n| reg.peers.values().any(|p| p.nodes.contains(n)));
        }
        if nodes.is_empty() {
            return;
        }
        let received = tokio::select! {
            received = tokio::time::timeout_at(until, rx.recv()) => received,
            () = changed => continue,
        };
        match received {
            Ok(Some(c)) if c.round == round => {
                if let Some(k) = nodes.iter().position(|&n| n == c.node) {
                    nodes.swap_remove(k);
                    if let Err(e) = aggregator.add_contribution(c.delta) {
                        tracing::warn!(node = c.node, error = %e, "contribution refused");
                    }
                }
            }
            Ok(Some(c)) => tracing::debug!(
                node = c.node,
                round = c.round,
                expected = round,
                "out-of-order contribution ignored"
            ),
            Ok(None) | Err(_) => {
                tracing::warn!(
                    round,
                    missing = nodes.len(),
                    "contributions missing at the deadline"
                );
                return;
            }
        }
    }
}
