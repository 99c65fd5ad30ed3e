//! Per-pixel shading over the wire (issue 22 item 2; `roomlight_calib::shading` has the
//! method): once the rounds have settled on a target, the camera agent photographs the room's
//! light, compares it camera pixel by camera pixel with the LEDs' photograph of that target,
//! lands the ratios on each standard projector's blocks through its decode, and sends each node
//! agent its projector's ratios (a `Shade` message). The node agent steps its own gains and
//! draws with them. The next pass follows on the next capture, the rounds correcting the
//! charts meanwhile (the light changed there too), up to `CameraConfig::shading_passes`
//! passes per target; then the rounds settle on the shaded light. A pass works on the
//! photograph the rounds' capture took (no capture of its own, unless the camera agent has no
//! survey and its captures are patches only).
//!
//! What a pass needs, kept here: the dark room (the survey's photograph, else the bring-up's
//! dark capture), the LEDs' light (the survey's photographs, then the two captures of each
//! preset change, with and without the LEDs), and each projector's decode from its calibration
//! over the wire. They are kept beside the model file (`store`): a camera agent restarted
//! from its model file reads them back and shades the next preset chosen without calibrating
//! anew (without the file it waits, said once in the log, for a calibration and a preset). A
//! projector calibrated again starts from flat gains (its nodes are new), and any calibration
//! starts the passes over (the room's light changed).

mod store;

use super::Shared;
use super::capture::Captures;
use crate::hardware::Camera;
use crate::node::shade_to_wire;
use roomlight_calib::graycode::Correspondence;
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::shading::{Photographs, Ratios, ratios};
use roomlight_proto::v1;
use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// How far a pass steps a gain towards its ratio (`Gains::step`'s exponent): the lab's passes
/// converge in 4–6 with it, one full step overshoots where inter-reflection answers.
pub const RATE: f64 = 0.8;

/// What the passes need and how many were done for the current target.
#[derive(Default)]
pub(super) struct Inputs {
    /// The room dark (every projector black, LEDs off): the bring-up's dark capture.
    dark: Option<Arc<LinearImage>>,
    /// The LEDs' light alone, `with − without` of the last preset change (negatives cut).
    leds: Option<Arc<LinearImage>>,
    /// Each standard projector's decode from its calibration over the wire.
    decodes: HashMap<String, Arc<Correspondence>>,
    /// Projectors whose next Shade starts from flat gains.
    fresh: HashSet<String>,
    /// Passes done for the current target and room.
    pub(super) passes: usize,
    /// Told the log why nothing is shaded.
    said: bool,
    /// Taken from the survey's photographs and not yet kept beside the model file.
    pub(super) unsaved: bool,
}

impl Inputs {
    /// What the survey's photographs give (the dark room, the LEDs' light) for a camera of
    /// `size`; nothing without them, or when their size is not the camera's (logged).
    pub(super) fn surveyed(
        photographs: Option<&super::SurveyPhotographs>,
        size: Option<(u32, u32)>,
    ) -> Self {
        let mut inputs = Self::default();
        let Some(p) = photographs else {
            return inputs;
        };
        let fits = |im: &LinearImage| {
            Some((im.width, im.height)) == size
                && im.pixels.len() == im.width as usize * im.height as usize
        };
        if !(fits(&p.dark) && fits(&p.leds)) {
            tracing::warn!(
                dark = ?(p.dark.width, p.dark.height),
                leds = ?(p.leds.width, p.leds.height),
                camera = ?size,
                "the survey's photographs are not the camera's size: shading waits for a preset chosen"
            );
            return inputs;
        }
        inputs.dark = Some(Arc::new(p.dark.clone()));
        inputs.retargeted(Some(&p.leds), Some(&p.dark));
        inputs.unsaved = true;
        inputs
    }

    /// A calibration over the wire measured `decodes` (standard projectors), and `dark` when it
    /// brought up a dark room: they start from flat gains, and the passes start over.
    pub(super) fn calibrated(
        &mut self,
        dark: Option<&LinearImage>,
        decodes: impl IntoIterator<Item = (String, Correspondence)>,
    ) {
        if let Some(dark) = dark {
            self.dark = Some(Arc::new(dark.clone()));
        }
        for (id, corr) in decodes {
            self.fresh.insert(id.clone());
            self.decodes.insert(id, Arc::new(corr));
        }
        self.passes = 0;
    }

    /// A preset change measured the LEDs' light as `with − without` (both the camera's
    /// whole images; `None` when either is missing or their sizes differ): every projector
    /// starts from flat gains, and the passes start over. Returns the projectors whose node
    /// agents must drop their gains now (the rounds settle on the new target without them).
    pub(super) fn retargeted(
        &mut self,
        with: Option<&LinearImage>,
        without: Option<&LinearImage>,
    ) -> Vec<String> {
        self.leds = match (with, without) {
            (Some(a), Some(b)) if a.pixels.len() == b.pixels.len() => Some(Arc::new(LinearImage {
                width: a.width,
                height: a.height,
                pixels: a
                    .pixels
                    .iter()
                    .zip(&b.pixels)
                    .map(|(w, o)| std::array::from_fn(|c| (w[c] - o[c]).max(0.0)))
                    .collect(),
            })),
            _ => None,
        };
        self.passes = 0;
        let mut ids: Vec<String> = self.decodes.keys().cloned().collect();
        ids.sort();
        self.fresh.extend(ids.iter().cloned());
        ids
    }

    /// What a camera agent wrote beside `model_out` before it was restarted, for a camera of
    /// `size` and the projectors `known` to the resumed model; nothing when there is no such
    /// file, or it is refused (logged, naming the file and why). The node agents kept their
    /// gains (their state files): the current target's passes go on from the count written
    /// beside it (`store::read_passes`, at most `passes`, the configured count; none written:
    /// all of them again, from the kept gains), the next preset chosen starts them over, and
    /// its Shades start from flat gains as after any preset.
    pub(super) fn resumed(
        model_out: &std::path::Path,
        size: (u32, u32),
        known: impl Fn(&str) -> bool,
        passes: usize,
    ) -> Self {
        let path = store::path(model_out);
        if !path.exists() {
            return Self::default();
        }
        let (stored, notes) = match store::Stored::read(&path, size, known) {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(error = %e, "the shading's inputs were not resumed: shading waits for a calibration and a preset chosen");
                return Self::default();
            }
        };
        for note in notes {
            tracing::warn!(file = %path.display(), "{note}");
        }
        let (w, h) = size;
        let decodes: HashMap<String, Arc<Correspondence>> = stored
            .decodes
            .iter()
            .map(|d| (d.projector.clone(), Arc::new(d.correspondence(w, h))))
            .collect();
        let mut ids: Vec<&String> = decodes.keys().collect();
        ids.sort();
        tracing::info!(
            file = %path.display(),
            dark = stored.dark.is_some(),
            leds = stored.leds.is_some(),
            decodes = ?ids,
            "shading's inputs resumed"
        );
        let done = match store::read_passes(model_out, passes) {
            Ok(done) => done.unwrap_or(0),
            Err(e) => {
                tracing::warn!(error = %e, "the shading passes sent are not known: all of them again");
                0
            }
        };
        Self {
            passes: if stored.leds.is_some() { done } else { 0 },
            dark: stored.image(&stored.dark).map(Arc::new),
            leds: stored.image(&stored.leds).map(Arc::new),
            decodes,
            ..Self::default()
        }
    }
}

/// Keeps the shading's inputs beside the model file (when there is one, and a survey gives the
/// camera's size), off the runtime; a failure is logged and the rounds go on.
pub(super) async fn save(shared: &Shared) {
    let (Some(model_out), Some(survey)) = (&shared.config.model_out, &shared.survey) else {
        return;
    };
    let path = store::path(model_out);
    let size = (survey.width, survey.height);
    let (dark, leds, decodes) = {
        let inputs = shared.shading();
        (
            inputs.dark.clone(),
            inputs.leds.clone(),
            inputs.decodes.clone(),
        )
    };
    let out = model_out.clone();
    let written = tokio::task::spawn_blocking(move || {
        let started = std::time::Instant::now();
        // New inputs, no pass sent on them yet: a restart in between counts none.
        store::forget_passes(&out)?;
        let mut decodes: Vec<store::Decode> = decodes
            .iter()
            .map(|(id, corr)| store::Decode::of(id, corr))
            .collect();
        decodes.sort_by(|a, b| a.projector.cmp(&b.projector));
        let bytes =
            store::Stored::new(size, dark.as_deref(), leds.as_deref(), decodes).write(&path)?;
        Ok::<_, String>((path, bytes, started.elapsed()))
    })
    .await
    .unwrap_or_else(|e| Err(e.to_string()));
    match written {
        Ok((path, bytes, took)) => tracing::info!(
            file = %path.display(),
            bytes,
            ms = took.as_millis() as u64,
            "shading's inputs kept"
        ),
        Err(e) => tracing::warn!(error = %e, "could not keep the shading's inputs"),
    }
}

/// Sends each of `ids` a reset to flat gains and waits (within the deadline) for them to
/// show it.
pub(super) async fn reset(shared: &Shared, ids: &[String]) {
    let sent: Vec<_> = ids
        .iter()
        .filter_map(|id| {
            let shade = v1::Shade {
                reset: true,
                ..v1::Shade::default()
            };
            send(shared, id, shade)
        })
        .collect();
    {
        let mut inputs = shared.shading();
        for (id, _, _) in &sent {
            inputs.fresh.remove(id);
        }
    }
    wait_shown(shared, &sent).await;
}

/// One shading pass, when one is due (passes are configured and left, and everything a pass
/// needs is there): on `photograph` (the room's light as the rounds' capture took it; `None`:
/// one capture of its own), each standard projector's ratios sent, and their
/// acknowledgements awaited. True when a pass ran (the light changed: the rounds must settle
/// again).
pub(super) async fn pass<C: Camera>(
    shared: &Shared,
    eye: &mut Captures<C>,
    photograph: Option<Arc<LinearImage>>,
) -> bool {
    let wanted = shared.config.shading_passes;
    let (dark, leds, decodes) = {
        let mut inputs = shared.shading();
        if wanted == 0 || inputs.passes >= wanted {
            return false;
        }
        let missing = match (&inputs.dark, &inputs.leds, inputs.decodes.is_empty()) {
            (None, _, _) => Some("the dark room (measured at a bring-up over the wire)"),
            (_, None, _) => Some("the LEDs' light (measured when a preset is chosen)"),
            (_, _, true) => Some("a projector calibrated over the wire"),
            _ => None,
        };
        if let Some(missing) = missing {
            if !std::mem::replace(&mut inputs.said, true) {
                tracing::info!("per-pixel shading waits for {missing}");
            }
            return false;
        }
        let (Some(dark), Some(leds)) = (inputs.dark.clone(), inputs.leds.clone()) else {
            return false;
        };
        (dark, leds, inputs.decodes.clone())
    };
    let Some(survey) = &shared.survey else {
        return false;
    };
    let live: Vec<(String, Arc<Correspondence>)> = {
        let registry = shared.registry.lock();
        let mut live: Vec<_> = decodes
            .into_iter()
            .filter(|(id, _)| registry.peer(id).is_some())
            .collect();
        live.sort_by(|a, b| a.0.cmp(&b.0));
        live
    };
    if live.is_empty() {
        return false;
    }
    let current = match photograph {
        Some(image) => image,
        None => {
            shared
                .registry
                .wait_for(shared.config.deadline, |r| r.projectors().all_shown())
                .await;
            let Some(image) = eye.image_exposed(shared, 1.0).await else {
                return false;
            };
            Arc::new(image)
        }
    };
    let saturation = eye.limits().saturation;
    let excluded = survey.target_mask.clone();
    let computed = tokio::task::spawn_blocking(move || {
        // The LEDs' photograph as the dark room plus their light.
        let reference = LinearImage {
            width: dark.width,
            height: dark.height,
            pixels: dark
                .pixels
                .iter()
                .zip(&leds.pixels)
                .map(|(d, l)| std::array::from_fn(|c| d[c] + l[c]))
                .collect(),
        };
        let photos = Photographs {
            reference: &reference,
            current: &current,
            dark: &dark,
            excluded: &excluded,
            saturation,
        };
        // Each block's light goes with its ratios in units of the LEDs' white, so that a node
        // short of headroom can choose the closest colour it can still give.
        let white = roomlight_calib::shading::white(&photos);
        live.into_iter()
            .map(|(id, corr)| {
                let r = ratios(&photos, &corr).map(|r| r.relative_to(white));
                (id, r)
            })
            .collect::<Vec<_>>()
    })
    .await;
    let computed = match computed {
        Ok(c) => c,
        Err(e) => {
            tracing::error!(error = %e, "shading pass failed");
            return false;
        }
    };
    let mut sent = Vec::new();
    let mut read = (0, 0);
    for (id, r) in computed {
        let r: Ratios = match r {
            Ok(r) => r,
            Err(e) => {
                tracing::warn!(projector = %id, error = %e, "no shading for this projector");
                continue;
            }
        };
        let (got, all) = r.read();
        read = (read.0 + got, read.1 + all);
        let reset = shared.shading().fresh.remove(&id);
        if let Some(s) = send(shared, &id, shade_to_wire(0, &r, RATE, reset)) {
            sent.push(s);
        }
    }
    wait_shown(shared, &sent).await;
    let passes = {
        let mut inputs = shared.shading();
        inputs.passes += 1;
        inputs.passes
    };
    // Counted beside the inputs before the rounds report it: a restart goes on from here.
    if let (Some(out), Some(_)) = (shared.config.model_out.clone(), &shared.survey) {
        let kept = tokio::task::spawn_blocking(move || store::write_passes(&out, passes))
            .await
            .unwrap_or_else(|e| Err(e.to_string()));
        if let Err(e) = kept {
            tracing::warn!(error = %e, "could not count the shading pass beside the model");
        }
    }
    tracing::info!(
        pass = passes,
        of = wanted,
        projectors = sent.len(),
        blocks_read = read.0,
        blocks = read.1,
        "per-pixel shading pass sent"
    );
    true
}

/// A Shade sent to `id` with the next pattern sequence number: its id, queue and number, or
/// `None` when it is gone or lagging.
fn send(shared: &Shared, id: &str, mut shade: v1::Shade) -> Option<(String, super::Outbox, u64)> {
    let tx = shared.registry.lock().peer(id)?.tx.clone();
    let seq = shared.pattern_seq.fetch_add(1, Ordering::Relaxed) + 1;
    shade.seq = seq;
    shared
        .offer(id, &tx, vec![v1::room_message::Body::Shade(shade)])
        .then(|| (id.to_string(), tx, seq))
}

/// Waits, within the deadline, until every projector sent a Shade has shown it (or left);
/// one that did not is logged and the room goes on.
async fn wait_shown(shared: &Shared, sent: &[(String, super::Outbox, u64)]) {
    let shown = |peers: &super::registry::Peers, (id, tx, seq): &(String, super::Outbox, u64)| {
        peers
            .peer(id)
            .filter(|p| p.tx.same_channel(tx))
            .is_none_or(|p| p.pattern_shown.is_some_and(|s| s >= *seq))
    };
    shared
        .registry
        .wait_for(shared.config.deadline, |peers| {
            sent.iter().all(|s| shown(peers, s))
        })
        .await;
    let peers = shared.registry.lock();
    for s in sent.iter().filter(|s| !shown(&peers, s)) {
        tracing::warn!(projector = %s.0, "shading not shown within the deadline");
    }
}
