//! Calibration over the wire: a projector the model does not know is shown structured light and
//! a response ramp through its node agent, decoded, segmented and assigned its nodes; a projector
//! whose attenuation is unknown (hot) is measured node by node while the others keep their
//! values. The interface is narrow on purpose (the round loop calls [`calibrate_hot`] and the
//! service [`assign_message`]): the one calibration procedure of roomlight-calib is to replace
//! what is inside.

use super::capture::Captures;
use super::model::joining_start;
use super::registry::Outbox;
use super::{Shared, Survey};
use crate::hardware::{Assignment, Camera, Fill as Pattern};
use roomlight_calib::graycode::{Coding, DecodeConfig, Manifest};
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::response::{fit_response, footprint_ramp, ramp_codes};
use roomlight_core::conventional::conventional_value;
use roomlight_core::{AttenuationColumn, LinearRgb, Problem};
use roomlight_proto::convert::to_rgb;
use roomlight_proto::v1;
use std::collections::HashSet;
use std::sync::atomic::Ordering;

/// Sends `projector` a Show pattern and waits until it has it on its display; false when it
/// left or did not show it within the deadline (logged).
async fn show_pattern(
    shared: &Shared,
    projector: &str,
    tx: &Outbox,
    pattern: v1::show::Pattern,
) -> bool {
    let seq = shared.pattern_seq.fetch_add(1, Ordering::Relaxed) + 1;
    let show = v1::room_message::Body::Show(v1::Show {
        seq,
        pattern: Some(pattern),
        mask: Vec::new(),
    });
    if !shared.offer(projector, tx, vec![show]) {
        return false;
    }
    let shown = shared
        .registry
        .wait_for(shared.config.deadline, |r| {
            r.peer(projector)
                .is_some_and(|p| p.pattern_shown.is_some_and(|s| s >= seq))
        })
        .await;
    if !shown {
        tracing::warn!(%projector, seq, "pattern not shown within the deadline");
    }
    shown
}

/// Shows `lit` at white and the projector's other nodes at black (all black for `None`), waits
/// for the projector to acknowledge the pattern, and captures (see [`Captures::measured`]).
async fn show_and_capture(
    shared: &Shared,
    eye: &mut Captures<impl Camera>,
    projector: &str,
    (tx, nodes): (&Outbox, &[u32]),
    lit: Option<u32>,
) -> Option<(Vec<LinearRgb>, Vec<bool>)> {
    let values = nodes
        .iter()
        .map(|&n| v1::NodeState {
            node: n,
            x: Some(to_rgb(if lit == Some(n) {
                LinearRgb::ONE
            } else {
                LinearRgb::ZERO
            })),
            attenuation: None,
        })
        .collect();
    let pattern = v1::show::Pattern::Nodes(v1::NodeValues { values });
    if !show_pattern(shared, projector, tx, pattern).await {
        return None;
    }
    eye.measured(shared).await
}

/// Shows a whole-frame pattern on `projector`, waits for it, and captures a whole image (the
/// camera's stale frames discarded first, every frame counted).
async fn show_and_capture_image(
    shared: &Shared,
    eye: &mut Captures<impl Camera>,
    projector: &str,
    tx: &Outbox,
    pattern: Pattern,
) -> Option<LinearImage> {
    if !show_pattern(shared, projector, tx, wire_pattern(pattern)).await {
        return None;
    }
    eye.image(shared).await
}

/// A whole-frame pattern as a Show pattern (white and black as uniform codes).
fn wire_pattern(pattern: Pattern) -> v1::show::Pattern {
    use roomlight_calib::graycode::{Axis, Pattern as Gray};
    let uniform = |v: f64| {
        v1::show::Pattern::Uniform(v1::Uniform {
            code: Some(to_rgb(LinearRgb::splat(v))),
        })
    };
    match pattern {
        Pattern::Uniform(code) => v1::show::Pattern::Uniform(v1::Uniform {
            code: Some(to_rgb(LinearRgb(code.map(f64::from)))),
        }),
        Pattern::Structured {
            pattern: Gray::White,
            ..
        } => uniform(1.0),
        Pattern::Structured {
            pattern: Gray::Black,
            ..
        } => uniform(0.0),
        Pattern::Structured {
            pattern: Gray::Bit { axis, bit, inverse },
            coding,
        } => v1::show::Pattern::Gray(v1::GrayBit {
            axis: match axis {
                Axis::Column => v1::Axis::Column,
                Axis::Row => v1::Axis::Row,
            } as i32,
            bit,
            inverse,
            coding: match coding {
                Coding::Gray => v1::Coding::Gray,
                Coding::Xor04 => v1::Coding::Xor04,
            } as i32,
        }),
    }
}

/// An assignment as the Assign message that carries it.
pub(super) fn assign_message(a: &Assignment) -> v1::Assign {
    v1::Assign {
        nodes: a
            .nodes
            .iter()
            .map(|(n, w)| v1::NodeAssignment {
                node: *n,
                chart: *n,
                pixels: w.iter().map(|p| p.0).collect(),
                weights: w.iter().map(|p| p.1).collect(),
            })
            .collect(),
        width: a.width,
        height: a.height,
        gamma: a.response.gamma.to_vec(),
    }
}

/// Levels of the response ramp shown over the wire (DESIGN §4: at least 9).
const RAMP_LEVELS: usize = 9;

/// A projector decoded over the wire and its response fitted, not yet segmented.
struct Decoded {
    projector: String,
    tx: Outbox,
    width: u32,
    height: u32,
    large: bool,
    corr: roomlight_calib::graycode::Correspondence,
    response: roomlight_calib::response::Response,
}

/// Calibrates a projector the model does not know, over the wire (DESIGN §4.2–4.4, §4.7): its
/// node agent shows structured light and a response ramp while the other projectors keep their
/// values (the decode compares each pattern with its inverse and the response fit subtracts the
/// ramp's first level, so their light cancels); the camera agent decodes and segments it
/// (off the runtime's threads), appends its nodes to the model with empty columns, records
/// each node's chart for its conventional start, and sends it the nodes' weights and the
/// response. At bring-up (no projector lit yet) every other projector waiting for its nodes is
/// decoded too and all are segmented together, feathered against each other; a projector that
/// joins a lit room takes what the others' weights leave ([`assign_decoded`]). False when the
/// projector left, a pattern was not shown, the camera failed, or the decode or the response
/// fit was refused (logged; it is tried again).
async fn segment_over_wire(
    shared: &Shared,
    eye: &mut Captures<impl Camera>,
    projector: &str,
) -> bool {
    let Some(first) = decode_over_wire(shared, eye, projector).await else {
        return false;
    };
    let mut batch = vec![first];
    let others: Vec<String> = {
        let reg = shared.registry.lock();
        let room = reg.projectors();
        if room.dark() {
            room.iter()
                .filter(|(id, p)| *id != projector && !p.calibrated() && p.nodes().is_empty())
                .map(|(id, _)| id.clone())
                .collect()
        } else {
            Vec::new()
        }
    };
    for other in others {
        if let Some(d) = decode_over_wire(shared, eye, &other).await {
            batch.push(d);
        }
    }
    assign_decoded(shared, batch)
        .await
        .iter()
        .any(|p| p == projector)
}

/// Shows a projector's structured light and response ramp, decodes the one and fits the other
/// (off the runtime's threads). `None` when it left, a pattern was not shown, the camera failed
/// or the decode or fit was refused (logged).
async fn decode_over_wire(
    shared: &Shared,
    eye: &mut Captures<impl Camera>,
    projector: &str,
) -> Option<Decoded> {
    let survey = shared.survey.clone()?;
    let (tx, width, height, kind) = shared
        .registry
        .lock()
        .peer(projector)
        .map(|p| (p.tx.clone(), p.width, p.height, p.kind))?;
    // A large aperture's defocus blurs XOR-04's fine stripes: plain Gray code, one node.
    let large = kind == v1::ProjectorKind::LargeAperture;
    let coding = if large { Coding::Gray } else { Coding::Xor04 };
    let (manifest, codes) = match (
        Manifest::with_coding(width, height, coding),
        ramp_codes(RAMP_LEVELS),
    ) {
        (Ok(m), Ok(c)) => (m, c),
        (Err(e), _) | (_, Err(e)) => {
            tracing::error!(%projector, error = %e, "cannot calibrate over the wire");
            return None;
        }
    };
    tracing::info!(%projector, width, height, patterns = manifest.patterns.len(), "structured light over the wire");
    let mut images = Vec::with_capacity(manifest.patterns.len());
    for file in &manifest.patterns {
        let pattern = Pattern::Structured {
            pattern: file.pattern,
            coding,
        };
        images.push(show_and_capture_image(shared, eye, projector, &tx, pattern).await?);
    }
    let mut ramp = Vec::with_capacity(codes.len());
    for &code in &codes {
        let pattern = Pattern::Uniform([code as f32; 3]);
        ramp.push(show_and_capture_image(shared, eye, projector, &tx, pattern).await?);
    }
    // Dark again until its attenuation is measured: at bring-up others are decoded and measured
    // after it, and its last ramp level would light their captures.
    if !show_pattern(
        shared,
        projector,
        &tx,
        wire_pattern(Pattern::Uniform([0.0; 3])),
    )
    .await
    {
        return None;
    }
    let worked = tokio::task::spawn_blocking(move || {
        decode_and_fit(&manifest, &images, &ramp, &codes, &survey)
    })
    .await;
    match worked {
        Ok(Ok((corr, response))) => Some(Decoded {
            projector: projector.to_string(),
            tx,
            width,
            height,
            large,
            corr,
            response,
        }),
        Ok(Err(e)) => {
            tracing::error!(%projector, error = %e, "calibration over the wire refused");
            None
        }
        Err(e) => {
            tracing::error!(%projector, error = %e, "calibration over the wire failed");
            None
        }
    }
}

/// Decodes a projector's structured light and fits its response to the ramp (blocking work).
fn decode_and_fit(
    manifest: &Manifest,
    images: &[LinearImage],
    ramp: &[LinearImage],
    codes: &[f64],
    survey: &Survey,
) -> Result<
    (
        roomlight_calib::graycode::Correspondence,
        roomlight_calib::response::Response,
    ),
    String,
> {
    let corr = roomlight_calib::graycode::decode(manifest, &DecodeConfig::default(), |f| {
        let k = manifest
            .patterns
            .iter()
            .position(|p| p.file == f.file)
            .unwrap_or(0);
        Ok(&images[k])
    })
    .map_err(|e| format!("decode: {e}"))?;
    if corr.map.len() != survey.target_mask.len() {
        return Err(format!(
            "the camera's images have {} pixels, the survey's target mask {}",
            corr.map.len(),
            survey.target_mask.len()
        ));
    }
    let (measured, noise) = footprint_ramp(ramp, &corr);
    let response = fit_response(codes, &measured, &noise).map_err(|e| format!("response: {e}"))?;
    Ok((corr, response))
}

/// Segments decoded projectors (off the runtime's threads) and assigns them their nodes: the
/// standard ones that light a chart together, feathered against each other, beside the
/// projectors segmented before (which keep their weights: the new ones share what those leave,
/// [`roomlight_calib::nodes::segment_beside`]); a large aperture, or a projector that lights no
/// chart, is one node over its frame but the target. Their nodes join the model with empty
/// columns. Returns the projectors whose assignment was sent.
async fn assign_decoded(shared: &Shared, batch: Vec<Decoded>) -> Vec<String> {
    let Some(survey) = shared.survey.clone() else {
        return Vec::new();
    };
    // What the attached projectors segmented before give each camera pixel (those decoded now
    // are segmented anew, whatever they had). One that is not attached now does not hold its
    // share: a projector that replaces a dead one takes its place (should the old one come
    // back, the model holds both where they overlap).
    let attached: HashSet<String> = shared
        .registry
        .lock()
        .projectors()
        .iter()
        .map(|(id, _)| id.clone())
        .collect();
    let claimed: Option<Vec<f32>> = {
        let live = shared.live();
        let mut sum: Option<Vec<f32>> = None;
        for (id, claim) in &live.claims {
            if !attached.contains(id)
                || batch.iter().any(|d| &d.projector == id)
                || claim.len() != survey.target_mask.len()
            {
                continue;
            }
            roomlight_calib::nodes::add_claim(
                sum.get_or_insert_with(|| vec![0.0; claim.len()]),
                claim,
            );
        }
        sum
    };
    let segmented =
        tokio::task::spawn_blocking(move || segment_batch(batch, &survey, claimed.as_deref()))
            .await;
    let segmented = match segmented {
        Ok(s) => s,
        Err(e) => {
            tracing::error!(error = %e, "segmentation over the wire failed");
            return Vec::new();
        }
    };
    let mut assigned = Vec::with_capacity(segmented.len());
    for (d, nodes, claim, decoded) in segmented {
        let projector = d.projector.as_str();
        let Some(assignment) = install_assignment(shared, &d, nodes, claim) else {
            continue;
        };
        let ids: Vec<u32> = assignment.nodes.iter().map(|(n, _)| *n).collect();
        shared.registry.lock().set_nodes(projector, ids.clone());
        let assign = v1::room_message::Body::Assign(assign_message(&assignment));
        if !shared.offer(projector, &d.tx, vec![assign]) {
            continue;
        }
        tracing::info!(%projector, nodes = ids.len(), decoded = format!("{:.1}%", 100.0 * decoded), gamma = ?assignment.response.gamma, "segmented over the wire");
        assigned.push(d.projector);
    }
    assigned
}

/// A segmented projector: its nodes' weights over the camera pixels with their charts, its claim
/// on the camera pixels (charted projectors), and the share of its frame decoded.
type Segmented = (
    Decoded,
    Vec<(Vec<f32>, Option<usize>)>,
    Option<Vec<f32>>,
    f64,
);

/// Segments a batch of decoded projectors (blocking work): the standard ones that light a chart
/// together beside what `claimed` holds, the others one node over their frame.
fn segment_batch(batch: Vec<Decoded>, survey: &Survey, claimed: Option<&[f32]>) -> Vec<Segmented> {
    let config = roomlight_calib::nodes::NodeConfig::default();
    let charted: Vec<bool> = batch
        .iter()
        .map(|d| {
            !d.large
                && roomlight_calib::nodes::charts_lit(&d.corr, &survey.corners, &config)
                    .is_ok_and(|c| !c.is_empty())
        })
        .collect();
    let together: Vec<roomlight_calib::graycode::Correspondence> = batch
        .iter()
        .zip(&charted)
        .filter(|(_, c)| **c)
        .map(|(d, _)| d.corr.clone())
        .collect();
    let seg = roomlight_calib::nodes::segment_beside(
        &together,
        &survey.corners,
        Some(&survey.target_mask),
        &config,
        claimed,
    );
    let mut seg = match seg {
        Ok(seg) => Some(seg),
        Err(e) => {
            tracing::error!(error = %e, "segmentation over the wire refused");
            None
        }
    };
    let mut out = Vec::with_capacity(batch.len());
    let mut k = 0;
    for (d, charted) in batch.into_iter().zip(charted) {
        let decoded = d.corr.decoded_share();
        let whole =
            || roomlight_calib::nodes::whole_frame(&d.corr, &survey.corners, &survey.target_mask);
        let (nodes, claim) = if charted {
            let Some(seg) = seg.as_mut() else {
                continue;
            };
            let nodes: Vec<(Vec<f32>, Option<usize>)> = seg
                .nodes
                .iter_mut()
                .filter(|n| n.projector == k)
                .map(|n| (std::mem::take(&mut n.weights), Some(n.chart)))
                .collect();
            let claim = std::mem::take(&mut seg.claims[k]);
            k += 1;
            (nodes, Some(claim))
        } else {
            tracing::info!(projector = %d.projector, large = d.large, "one node over its frame");
            (vec![whole()], None)
        };
        out.push((d, nodes, claim, decoded));
    }
    out
}

/// Appends a segmented projector's nodes to the live model with empty columns and records its
/// assignment, charts and claim. `None` when the model refused them (logged).
fn install_assignment(
    shared: &Shared,
    d: &Decoded,
    nodes: Vec<(Vec<f32>, Option<usize>)>,
    claim: Option<Vec<f32>>,
) -> Option<Assignment> {
    let projector = d.projector.as_str();
    let mut live = shared.live_mut();
    let first = live.problem.nodes() as u32;
    let ids: Vec<u32> = (first..).take(nodes.len()).collect();
    let mut columns = live.problem.columns().to_vec();
    columns.extend(nodes.iter().map(|_| AttenuationColumn::default()));
    let problem = match Problem::new(
        columns,
        live.problem.black().to_vec(),
        live.problem.target().to_vec(),
        live.problem.noise().to_vec(),
    ) {
        Ok(p) => p,
        Err(e) => {
            tracing::error!(%projector, error = %e, "calibration over the wire refused");
            return None;
        }
    };
    live.problem = problem;
    live.start.extend(nodes.iter().map(|_| None));
    for (&n, (_, chart)) in ids.iter().zip(&nodes) {
        if let Some(c) = chart {
            live.charts.insert(n, *c);
        }
    }
    let assignment = Assignment {
        width: d.width,
        height: d.height,
        response: d.response.clone(),
        nodes: ids
            .iter()
            .zip(&nodes)
            .map(|(&n, (w, _))| {
                let sparse = w
                    .iter()
                    .enumerate()
                    .filter(|(_, w)| **w > 0.0)
                    .map(|(i, w)| (i as u32, w.min(1.0)))
                    .collect();
                (n, sparse)
            })
            .collect(),
    };
    live.owners.insert(projector.to_string(), ids.clone());
    live.assignments
        .insert(projector.to_string(), assignment.clone());
    match claim {
        Some(claim) => live.claims.insert(projector.to_string(), claim),
        None => live.claims.remove(projector),
    };
    Some(assignment)
}

/// Measures a hot projector's attenuation (DESIGN §4): its nodes all at black, then each alone
/// at white, one capture each, while every other projector keeps its values (no errors are
/// sent meanwhile). `p = max(y_white − y_black, 0)`, entries at or below √2 σ (one standard
/// deviation of a difference of two captures) dropped: about the level the Hadamard path's 3σ
/// cut reaches with its lower variance. At 3√2 σ the calibrated lab's model dropped enough
/// faint light that the room measured 6% below the model's optimum (1.4% at √2 σ). Also
/// patches a capture could not measure leave the model (see [`Captures::measured`]). Then the
/// projector gets its attenuation and every
/// attached projector its `s` anew (the new light changes it). False when the projector left,
/// did not show a pattern in time, or the camera failed: it stays uncalibrated and is tried
/// again.
pub(super) async fn calibrate_hot(
    shared: &Shared,
    eye: &mut Captures<impl Camera>,
    projector: &str,
    errors: Option<&[LinearRgb]>,
) -> bool {
    let needs_nodes = shared
        .registry
        .lock()
        .projectors()
        .get(projector)
        .is_some_and(|p| p.nodes().is_empty());
    if needs_nodes && !segment_over_wire(shared, eye, projector).await {
        return false;
    }
    let Some((tx, nodes)) = shared.registry.lock().outbox(projector) else {
        return false;
    };
    tracing::info!(%projector, nodes = nodes.len(), "hot calibration");
    let Some((measured, measurable)) = measure_columns(shared, eye, projector, &tx, &nodes).await
    else {
        return false;
    };
    if !install_columns(shared, projector, &nodes, measured, &measurable, errors) {
        return false;
    }
    // Bring-up: while the room is still dark (no projector has shown a round's frame) and
    // others wait for their calibration, this one stays dark too, so that theirs is measured
    // in the dark as well (the light of lit projectors adds camera noise and costs decoded
    // pixels); all are lit once the last is measured.
    let dark = {
        let mut reg = shared.registry.lock();
        let room = reg.projectors();
        let dark = room.dark()
            && room
                .iter()
                .any(|(id, p)| id != projector && !p.calibrated());
        reg.mark_calibrated(projector);
        dark
    };
    if dark {
        let values = nodes
            .iter()
            .map(|&n| v1::NodeState {
                node: n,
                x: Some(to_rgb(LinearRgb::ZERO)),
                attenuation: None,
            })
            .collect();
        let black = v1::show::Pattern::Nodes(v1::NodeValues { values });
        if !show_pattern(shared, projector, &tx, black).await {
            shared.light_all();
        }
    } else {
        // Its attenuation to the new projector, `s` anew to everyone; then it joins the rounds.
        shared.light_all();
    }
    tracing::info!(%projector, dark, "hot calibration done");
    shared.save_model();
    shared.registry.notify();
    true
}

/// Each of a hot projector's nodes' columns: all its nodes at black, then each alone at white,
/// one capture each; with which patches every capture could measure. `None` when it left, did
/// not show a pattern in time, the camera failed or a column was refused (logged).
async fn measure_columns(
    shared: &Shared,
    eye: &mut Captures<impl Camera>,
    projector: &str,
    tx: &Outbox,
    nodes: &[u32],
) -> Option<(Vec<(u32, AttenuationColumn)>, Vec<bool>)> {
    let (black, mut measurable) =
        show_and_capture(shared, eye, projector, (tx, nodes), None).await?;
    let threshold: Vec<LinearRgb> = shared
        .live()
        .problem
        .noise()
        .iter()
        .map(|s| *s * (1.0 * std::f64::consts::SQRT_2))
        .collect();
    let mut measured = Vec::with_capacity(nodes.len());
    for &n in nodes {
        let (white, ok) = show_and_capture(shared, eye, projector, (tx, nodes), Some(n)).await?;
        for (m, o) in measurable.iter_mut().zip(ok) {
            *m &= o;
        }
        let dense: Vec<LinearRgb> = white
            .iter()
            .zip(&black)
            .map(|(w, b)| (*w - *b).map(|v| v.max(0.0)))
            .collect();
        match AttenuationColumn::from_dense_with_cutoff(&dense, &threshold) {
            Ok(column) => measured.push((n, column)),
            Err(e) => {
                tracing::error!(%projector, node = n, error = %e, "hot calibration refused");
                return None;
            }
        }
    }
    Some((measured, measurable))
}

/// Puts a hot projector's measured columns into the live model: patches its light makes
/// unmeasurable leave the model for good (every column loses them, their target becomes their
/// black level and their errors are zero, so the model and the measured G agree and no node
/// acts on them); its nodes get their start; it is no longer uncalibrated. False when the model
/// refused the columns (logged).
fn install_columns(
    shared: &Shared,
    projector: &str,
    nodes: &[u32],
    measured: Vec<(u32, AttenuationColumn)>,
    measurable: &[bool],
    errors: Option<&[LinearRgb]>,
) -> bool {
    let mut guard = shared.live_mut();
    let live = &mut *guard;
    let mut columns = live.problem.columns().to_vec();
    for (n, column) in measured {
        if let Some(slot) = columns.get_mut(n as usize) {
            *slot = column;
        }
    }
    let newly = live.newly_unmeasurable(measurable);
    if !newly.is_empty() {
        tracing::info!(%projector, patches = ?newly, "patches not measurable under its light: left out");
    }
    if let Err(e) = live.leave_out_with(&newly, columns) {
        tracing::error!(%projector, error = %e, "hot calibration refused");
        return false;
    }
    let problem = &live.problem;
    // Nodes segmented over the wire start from the conventional value of their chart.
    if let Some(survey) = &shared.survey {
        for &n in nodes {
            let (Some(&chart), Some(column)) =
                (live.charts.get(&n), problem.columns().get(n as usize))
            else {
                continue;
            };
            let start = conventional_value(
                column,
                &survey.chart_patches(chart),
                problem.target(),
                problem.black(),
                LinearRgb::splat(0.5),
            );
            if let (Ok(x), Some(slot)) = (start, live.start.get_mut(n as usize)) {
                *slot = Some(x);
            }
        }
    }
    // Joining a lit room: the new nodes start where they best fill what the room lacks now
    // (the bounded least-squares fit of their columns to the current errors, the others held),
    // not where they would light their charts alone; the others then adjust in the rounds.
    if let Some(e) = errors.filter(|e| e.len() == problem.patches()) {
        match joining_start(problem, nodes, e) {
            Ok(x) => {
                for (&n, x) in nodes.iter().zip(x) {
                    if let Some(slot) = live.start.get_mut(n as usize) {
                        *slot = Some(x);
                    }
                }
            }
            Err(err) => {
                tracing::warn!(%projector, error = %err, "no joining start: the conventional one")
            }
        }
    }
    live.uncalibrated.remove(projector);
    true
}
