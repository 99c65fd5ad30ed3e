//! The round loop: calibrate the projectors waiting for it (backing off on failure) while the
//! others go on; wait until every live projector shows its last frame (late ones are left out),
//! capture, send each node agent the errors on its nodes' supports, collect contributions, run
//! model rounds, and report a status. A capture that fails or hangs abandons the round: nothing
//! is sent (the projectors keep their light) and the loop waits out the camera's backoff before
//! it captures again (`faults`). What the next round is, its restart flag and whether the
//! room has settled are the core's round controller's decisions (`roomlight_core::round::
//! Controller`, the same the in-memory closed loop makes); this loop carries them out over the
//! wire. It knows nothing of the handshake or how a peer's stream is read.

use super::capture::Captures;
use super::operator::{Refused, Request};
use super::{Contribution, Shared};
use crate::hardware::Camera;
use roomlight_core::LinearRgb;
use roomlight_core::aggregator::{ErrorKind, RoundSummary};
use roomlight_core::round::{Backoff, Collection, Controller, Next as NextRound, Received};
use roomlight_proto::convert::node_errors;
use roomlight_proto::v1;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::sync::mpsc;
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

/// The round loop's state: the camera, the round controller, and what it has done so far.
pub(super) struct Rounds<C> {
    shared: Arc<Shared>,
    eye: Captures<C>,
    contributions: mpsc::Receiver<Contribution>,
    /// Captures and model rounds, the errors, restarts and settling.
    controller: Controller,
    calibrated_hot: u64,
    /// Captures taken when the last calibration ended (see `RoomStatus::calibrated_at`).
    calibrated_at: u64,
    /// When to try a failed calibration again.
    backoff: Backoff,
    /// The round controller's clock: time since the loop started.
    epoch: tokio::time::Instant,
    /// The console's requests, carried out between rounds.
    requests: mpsc::Receiver<Request>,
    /// Paused by the console: no round runs (requests are still served).
    paused: bool,
    /// Times the target changed.
    restarts: u64,
    /// Captures refused as stale since the last one measured, and the most ever in a row
    /// (logged when it grows: the camera's latency, which `stale_frames` can name instead).
    stale: (usize, usize),
}

impl<C: Camera> Rounds<C> {
    pub(super) fn new(
        shared: Arc<Shared>,
        camera: C,
        contributions: mpsc::Receiver<Contribution>,
        requests: mpsc::Receiver<Request>,
    ) -> Self {
        let sigma = shared.live().problem.noise().to_vec();
        let model_rounds = shared.config.model_rounds;
        Self {
            shared,
            eye: Captures::new(camera),
            contributions,
            controller: Controller::new(sigma, model_rounds),
            calibrated_hot: 0,
            calibrated_at: 0,
            backoff: Backoff::default(),
            epoch: tokio::time::Instant::now(),
            requests,
            paused: false,
            restarts: 0,
            stale: (0, 0),
        }
    }

    /// Runs rounds until `cancel`: a stop request ends them between two rounds, never inside one.
    pub(super) async fn run(mut self, cancel: CancellationToken) {
        if std::mem::take(&mut self.shared.shading().unsaved) {
            super::shading::save(&self.shared).await;
        }
        while !cancel.is_cancelled() {
            // The console's requests, between two rounds.
            while let Ok(request) = self.requests.try_recv() {
                self.serve(request).await;
            }
            if self.paused {
                tokio::select! {
                    Some(request) = self.requests.recv() => self.serve(request).await,
                    () = cancel.cancelled() => break,
                }
                continue;
            }
            // Someone must be there, and have shown its last frame (or wait to be measured).
            let present = tokio::select! {
                present = self.shared.registry.wait_for(Duration::from_secs(3600), |r| {
                    r.projectors().any_present()
                }) => present,
                Some(request) = self.requests.recv() => {
                    self.serve(request).await;
                    continue;
                }
                () = cancel.cancelled() => break,
            };
            if !present {
                continue;
            }
            // A failing camera is tried again only after its backoff: meanwhile nothing is
            // captured, no errors are sent, and the projectors keep their light.
            if let Some(at) = self.eye.retry_at() {
                tokio::select! {
                    () = tokio::time::sleep_until(at) => {}
                    () = cancel.cancelled() => break,
                }
            }
            match self.calibrate_waiting(&cancel).await {
                Next::Again => continue,
                Next::Stop => break,
                Next::Round => self.measured_cycle(&cancel).await,
            }
        }
    }

    /// Calibrates the next projector waiting whose retry is due; when nothing else runs, waits
    /// for the next retry or a change.
    async fn calibrate_waiting(&mut self, cancel: &CancellationToken) -> Next {
        let shared = self.shared.clone();
        let now = self.now();
        let waiting = shared.registry.lock().projectors().uncalibrated();
        let due = self.backoff.next_due(&waiting, now).cloned();
        self.backoff.retain(&waiting);
        if let Some(projector) = due {
            // The room's errors without it, once a round has measured them.
            let errors = self
                .controller
                .has_measured()
                .then(|| self.controller.errors());
            let calibrated =
                super::calibration::calibrate(&shared, &mut self.eye, &projector, errors).await;
            if !calibrated.is_empty() {
                self.calibrated_hot += calibrated.len() as u64;
                self.calibrated_at = self.eye.count;
                calibrated.iter().for_each(|p| self.backoff.forget(p));
                return Next::Again;
            }
            // Tried again after the others (the cause is logged each time).
            self.backoff.failed(&projector, self.now());
            // Projectors kept dark for a bring-up light up now rather than wait for one that
            // may never be measured.
            if shared.registry.lock().projectors().any_unlit() {
                shared.light_all();
            }
        }
        // Meanwhile the calibrated projectors go on with their rounds: one that cannot be
        // calibrated must not stop the others' corrections.
        if waiting.is_empty() || shared.registry.lock().projectors().any_running() {
            return Next::Round;
        }
        let next = self.epoch + self.backoff.earliest().unwrap_or_else(|| self.now());
        tokio::select! {
            () = tokio::time::sleep_until(next) => Next::Again,
            () = shared.registry.changed() => Next::Again,
            Some(request) = self.requests.recv() => {
                self.serve(request).await;
                Next::Again
            }
            () = cancel.cancelled() => Next::Stop,
        }
    }

    /// The controller's time.
    fn now(&self) -> Duration {
        self.epoch.elapsed()
    }

    /// One capture and the rounds that follow it: the measured round, then the model rounds
    /// the controller asks for, until `cancel` (a stop does not wait for the model rounds left:
    /// every node shows what its last round gave it); then the status.
    async fn measured_cycle(&mut self, cancel: &CancellationToken) {
        let shared = self.shared.clone();
        shared
            .registry
            .wait_for(shared.config.deadline, |r| r.projectors().all_shown())
            .await;
        let Some((y, ok, photograph)) = self.eye.measured_image(&shared).await else {
            // The round is abandoned (logged, the camera's state published): nothing is sent,
            // the lights stay as they are, and the loop tries again after the backoff.
            return;
        };
        self.leave_out_unmeasurable(&ok).await;
        let errors = shared.live().errors(&y);
        self.note_live();
        if self.controller.stale(&errors) {
            // Nothing is sent: the next cycle takes another capture (counted like every one).
            self.stale.0 += 1;
            tracing::debug!(
                captures = self.eye.count,
                "stale capture: it shows the values before the nodes' last step; taking another"
            );
            return;
        }
        let (in_row, most) = std::mem::take(&mut self.stale);
        self.stale.1 = most.max(in_row);
        if in_row > most {
            tracing::info!(
                frames = in_row,
                configured = shared.config.stale_frames,
                "the camera handed over frames late: captures refused until one showed the nodes' last step (stale_frames in the camera's configuration discards them without judging)"
            );
        }
        let summary = match self.controller.measured(errors) {
            Ok(s) => s,
            Err(e) => {
                tracing::error!(error = %e, "capture refused");
                return;
            }
        };
        let mut round = summary.round;
        let measured_objective = summary.objective;
        self.round_trip(&summary).await;
        while self.controller.next() == NextRound::Model && !cancel.is_cancelled() {
            // Acknowledgements follow contributions: wait for them too.
            shared
                .registry
                .wait_for(shared.config.deadline, |r| r.projectors().all_shown())
                .await;
            self.note_live();
            let Some(summary) = self.controller.predicted() else {
                break;
            };
            round = summary.round;
            self.round_trip(&summary).await;
        }
        let (live_projectors, displays_lost) = {
            let peers = shared.registry.lock();
            (peers.len(), peers.displays_lost())
        };
        let mut settled = self.controller.settled();
        // Per-pixel shading, while passes are due: the first once the rounds have settled on
        // the target, then one on every capture, each on the photograph the rounds just
        // measured; the rounds settle on the shaded light after the last. Settling between
        // passes instead took the lab 32–35 captures a preset for 6 passes, this 18–21 for
        // 10 and the same whole room (docs/results.md).
        let shading = shared.shading().passes > 0;
        if (settled || shading)
            && !cancel.is_cancelled()
            && super::shading::pass(&shared, &mut self.eye, photograph).await
        {
            self.controller.retarget();
            settled = false;
        }
        let shading_passes = shared.shading().passes;
        shared.status.send_modify(|s| {
            s.round = round;
            s.captures = self.eye.count;
            s.measured_objective = measured_objective;
            s.averaged = self.controller.averaged();
            s.late_frames = self.stale.1;
            s.live_projectors = live_projectors;
            s.bytes_out = shared.bytes_out.swap(0, Ordering::Relaxed);
            s.bytes_in = shared.bytes_in.swap(0, Ordering::Relaxed);
            s.settled = settled;
            s.calibrated_hot = self.calibrated_hot;
            s.calibrated_at = self.calibrated_at;
            s.camera = self.eye.state().clone();
            s.displays_lost = displays_lost;
            s.shading_passes = shading_passes;
        });
    }

    /// Carries out one of the console's requests (between rounds).
    async fn serve(&mut self, request: Request) {
        match request {
            Request::Pause(paused) => {
                if paused != self.paused {
                    tracing::info!(
                        paused,
                        "rounds {} by the console",
                        if paused { "paused" } else { "resumed" }
                    );
                }
                self.paused = paused;
            }
            Request::Calibrate(which, reply) => {
                let _ = reply.send(self.recalibrate(which));
            }
            Request::Preset(preset, reply) => {
                let _ = reply.send(self.retarget(preset).await);
            }
            Request::Photograph(reply) => {
                let photo = self.eye.photograph(&self.shared).await;
                let _ = reply.send(photo.map(|image| {
                    let (w, h) = (image.width, image.height);
                    (self.shared.publish_photo(Arc::new(image)), w, h)
                }));
            }
        }
    }

    /// Queues `which` (every attached projector when `None`) to be measured again: they leave
    /// the rounds, keeping their light, until their calibration ends.
    fn recalibrate(&mut self, which: Option<String>) -> Result<Vec<String>, Refused> {
        let queued = {
            let mut peers = self.shared.registry.lock();
            let ids: Vec<String> = match which {
                Some(id) if peers.peer(&id).is_some() => vec![id],
                Some(id) => return Err(Refused::UnknownProjector(id)),
                None => {
                    let mut ids: Vec<String> = peers
                        .projectors()
                        .iter()
                        .map(|(id, _)| id.clone())
                        .collect();
                    ids.sort();
                    ids
                }
            };
            ids.into_iter()
                .filter(|id| peers.recalibrate(id))
                .collect::<Vec<_>>()
        };
        for id in &queued {
            self.backoff.forget(id);
        }
        tracing::info!(projectors = ?queued, "calibration requested by the console");
        self.shared.registry.notify();
        Ok(queued)
    }

    /// Reproduces the LED preset `preset` from now on: its light is measured as the difference
    /// of two captures, with and without the LEDs, while the projectors keep theirs, and the
    /// target becomes the room's black plus it (a dark target's stays the black); the rounds
    /// restart.
    async fn retarget(&mut self, preset: String) -> Result<(), Refused> {
        let shared = self.shared.clone();
        let Some(lights) = shared.lights.clone() else {
            return Err(Refused::NoLights);
        };
        let presets = lights.presets();
        if !presets.contains(&preset) {
            return Err(Refused::UnknownPreset(preset, presets.join(", ")));
        }
        let capture = async |rounds: &mut Self| {
            shared
                .registry
                .wait_for(shared.config.deadline, |r| r.projectors().all_shown())
                .await;
            rounds
                .eye
                .measured_image(&shared)
                .await
                .ok_or_else(|| Refused::Camera("the capture failed (see the warnings)".into()))
        };
        let (without, ok_without, without_image) = capture(self).await?;
        lights
            .switch(Some(preset.clone()))
            .await
            .map_err(Refused::Lights)?;
        let with = capture(self).await;
        // Off again whatever happened: the projectors light the room, not the LEDs.
        let off = lights.switch(None).await.map_err(Refused::Lights);
        let (with, ok_with, with_image) = with?;
        off?;
        {
            let mut live = shared.live_mut();
            let black = live.problem.black().to_vec();
            let old = live.problem.target().to_vec();
            let survey = shared.survey.as_ref();
            let target: Vec<LinearRgb> = (0..black.len())
                .map(|i| {
                    // The target kept dark: its reference stays the room's black, whatever
                    // light the LEDs throw on it.
                    if survey.is_some_and(|s| s.kept_dark(i)) {
                        return black[i];
                    }
                    let measured = ok_without.get(i) == Some(&true)
                        && ok_with.get(i) == Some(&true)
                        && live.excluded.get(i) != Some(&true);
                    if !measured {
                        // Left out, or not measurable under one of the two: as it was.
                        return old[i];
                    }
                    // The LEDs add light; a negative difference is noise.
                    black[i] + (with[i] - without[i]).map(|v| v.max(0.0))
                })
                .collect();
            live.problem = live
                .problem
                .with_target(target)
                .map_err(|e| Refused::Model(format!("the new target was refused: {e}")))?;
        }
        // Per-pixel shading starts over on the new target: the nodes drop their gains now.
        let flat = shared
            .shading()
            .retargeted(with_image.as_deref(), without_image.as_deref());
        super::shading::save(&shared).await;
        super::shading::reset(&shared, &flat).await;
        self.controller.retarget();
        self.restarts += 1;
        tracing::info!(%preset, "new target measured: the rounds restart");
        let restarts = self.restarts;
        shared.overview.send_modify(|s| {
            s.preset = Some(preset);
            s.restarts = restarts;
        });
        shared.status.send_modify(|s| s.settled = false);
        shared.save_model();
        Ok(())
    }

    /// Tells the controller which projectors take part now (a change restarts the next round).
    fn note_live(&mut self) {
        let generation = self.shared.registry.lock().projectors().generation();
        self.controller.live(generation);
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
            shared.light_all();
            shared.save_model();
        }
    }

    /// Sends the round's errors and collects its contributions.
    async fn round_trip(&mut self, summary: &RoundSummary) {
        let sent = broadcast(&self.shared, self.controller.errors(), summary);
        let collection =
            Collection::new(summary.round, sent, self.now(), self.shared.config.deadline);
        self.collect(collection).await;
    }

    /// Collects a round's contributions into the controller until every node sent has answered
    /// or left, or the deadline passes. O(1) per message: a projector that leaves hands the
    /// round its nodes (the registry keeps them), nothing scans the peers.
    async fn collect(&mut self, mut collection: Collection) {
        let until = self.epoch + collection.deadline();
        loop {
            let changed = self.shared.registry.changed();
            // A projector that left will not answer: its nodes are not waited for.
            let gone = self.shared.registry.lock().take_departed();
            collection.left(&gone);
            if collection.done() {
                return;
            }
            let received = tokio::select! {
                received = tokio::time::timeout_at(until, self.contributions.recv()) => received,
                () = changed => continue,
            };
            match received {
                Ok(Some(c)) => self.count(&mut collection, c),
                Ok(None) | Err(_) => {
                    tracing::warn!(
                        round = collection.round(),
                        missing = collection.missing(),
                        "contributions missing at the deadline"
                    );
                    return;
                }
            }
        }
    }
}

impl<C> Rounds<C> {
    /// Counts one node agent's message: each awaited node's contribution `p_n Δx_n`, formed
    /// from the model's column (the one the node was sent), goes to the controller.
    fn count(&mut self, collection: &mut Collection, c: Contribution) {
        let shared = self.shared.clone();
        let live = shared.live();
        let columns = live.problem.columns();
        let mut values = shared.values();
        for (node, change) in c.nodes {
            match collection.receive(c.round, node) {
                Received::Counted => {
                    if let Some(x) = values.get_mut(&node) {
                        *x = (*x + change).clamp_unit();
                    }
                    let Some(column) = columns.get(node as usize) else {
                        continue;
                    };
                    let delta = column.values().iter().map(|p| p.hadamard(change));
                    let delta = column.support().iter().copied().zip(delta);
                    if let Err(e) = self.controller.contribution(delta) {
                        tracing::warn!(node, error = %e, "contribution refused");
                    }
                }
                Received::OtherRound => tracing::debug!(
                    node,
                    round = c.round,
                    expected = collection.round(),
                    "out-of-order contribution ignored"
                ),
                Received::NotAwaited => {}
            }
        }
    }
}

/// Sends every ready projector the errors of its nodes, one message per projector, without
/// waiting for any (a peer whose queue is full is dropped: see `Shared::offer`); returns the
/// nodes that were sent.
fn broadcast(shared: &Shared, errors: &[LinearRgb], summary: &RoundSummary) -> Vec<u32> {
    let kind = match summary.kind {
        ErrorKind::Measured => v1::ErrorKind::Measured,
        ErrorKind::Predicted => v1::ErrorKind::Predicted,
    };
    let (ready, late) = shared.registry.lock().start_round(summary.round);
    for projector in late {
        tracing::warn!(%projector, round = summary.round, "late: left out of this round");
    }
    let mut sent = Vec::new();
    for (projector, tx, nodes) in ready {
        let entries: Vec<v1::NodeErrors> = {
            let live = shared.live();
            let columns = live.problem.columns();
            nodes
                .iter()
                .filter_map(|&n| {
                    let support = columns.get(n as usize)?.support();
                    let values = support.iter().map(|&i| errors[i as usize]);
                    Some(node_errors(n, support.len(), values))
                })
                .collect()
        };
        let body = v1::room_message::Body::Errors(v1::Errors {
            round: summary.round,
            kind: kind as i32,
            objective: summary.objective,
            restart: summary.restart,
            nodes: entries,
        });
        // A failed offer means the node left or lags: it is not waited for.
        if shared.offer(&projector, &tx, vec![body]) {
            sent.extend_from_slice(&nodes);
        }
    }
    sent
}
