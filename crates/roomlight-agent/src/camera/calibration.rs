//! Calibration over the wire: the camera agent drives the one calibration procedure
//! ([`roomlight_calib::procedure`]) on its peers through the [`WireRig`]. Projectors waiting for
//! their nodes while the room is still dark are brought up together (footprints, those that do
//! not overlap coded at the same time, second passes, responses, nodes feathered together,
//! Hadamard attenuation); a projector joining a lit room is calibrated alone while the others
//! keep their values (structured light against inverses, its nodes beside what the others'
//! weights leave, its attenuation measured hot). A projector whose nodes the model knows but
//! whose attenuation it does not is measured hot: through the charts of whole images with a
//! survey, through the camera's patches without one.
//!
//! It owns turning the procedure's results into the live model (node ids, columns over the
//! model's patches, starts) and the registry (nodes, calibrated); it must not know the order
//! of captures (the procedure's) or how a frame reaches a display (the rig's). The round loop
//! calls [`calibrate`]; the service sends [`assign_message`]s.

use super::capture::Captures;
use super::model::joining_start;
use super::rig::WireRig;
use super::{Shared, Survey};
use crate::hardware::Camera;
use roomlight_calib::attenuation::Attenuation;
use roomlight_calib::graycode::Correspondence;
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::procedure::{
    Hot, Placed, Procedure, ProcedureError, Settings, place_calibrated,
};
use roomlight_calib::rig::{Frame, Rig, RigError};
use roomlight_core::conventional::conventional_value;
use roomlight_core::{AttenuationColumn, LinearRgb, ModelError, Problem};

pub(super) use super::rig::assign_message;

mod notes;
use notes::{Notes, log_event};

/// Hadamard columns keep the entries above this many standard deviations of their own noise
/// (DESIGN §2), as the in-process pipeline does.
const MULTIPLEXED_SIGMAS: f64 = roomlight_calib::attenuation::SUPPORT_SIGMAS;

/// Each node's column over the model's patches, and which model patches every capture could
/// measure.
type Measured = (Vec<(u32, AttenuationColumn)>, Vec<bool>);

/// What one calibration measured, ready for the live model.
struct Outcome {
    /// Projectors segmented now (none when only attenuation was measured).
    placed: Vec<Placed>,
    /// The projectors calibrated, with their nodes.
    projectors: Vec<(String, Vec<u32>)>,
    /// Each node's column over the model's patches.
    columns: Vec<(u32, AttenuationColumn)>,
    /// Which model patches every capture could measure.
    measurable: Vec<bool>,
    captures: usize,
    /// The standard projectors' decodes (segmented now), for per-pixel shading.
    decodes: Vec<(String, Correspondence)>,
    /// The dark room, when this was a bring-up in the dark.
    dark: Option<LinearImage>,
}

/// Calibrates `projector` and, at bring-up (the room still dark), every other projector waiting
/// for its nodes with it; then their nodes join the model and the rounds. `errors`: the room's
/// current errors without them (once a round measured them), where a projector joining a lit
/// room starts. Returns the projectors calibrated; none when it failed (logged: the round loop
/// tries again later).
pub(super) async fn calibrate(
    shared: &Shared,
    eye: &mut Captures<impl Camera>,
    projector: &str,
    errors: Option<&[LinearRgb]>,
) -> Vec<String> {
    let Some((_, nodes)) = shared.registry.lock().outbox(projector) else {
        return Vec::new();
    };
    let notes = Notes::begin(shared, projector);
    let calibrated = measure_and_install(shared, eye, projector, nodes, errors, &notes).await;
    notes.end(shared, &calibrated);
    calibrated
}

/// [`calibrate`]'s work, reporting to `notes`.
async fn measure_and_install(
    shared: &Shared,
    eye: &mut Captures<impl Camera>,
    projector: &str,
    nodes: Vec<u32>,
    errors: Option<&[LinearRgb]>,
    notes: &Notes,
) -> Vec<String> {
    let measured = match &shared.survey {
        Some(survey) if nodes.is_empty() => {
            let mut batch = batch(shared, projector).await;
            notes.batch(shared, &batch);
            let mut measured = over_the_wire(shared, eye, survey, batch.clone(), notes).await;
            // One projector that fails (left, shows nothing, refused) must not hold the others'
            // bring-up back: once more without it, or alone when the cause is not one of them.
            if let (Err(e), true) = (&measured, batch.len() > 1) {
                tracing::warn!(error = %e, ?batch, "bring-up failed: once more without the cause");
                match e.projector() {
                    Some(culprit) if culprit != projector => batch.retain(|id| id != culprit),
                    _ => batch.truncate(1),
                }
                notes.batch(shared, &batch);
                measured = over_the_wire(shared, eye, survey, batch, notes).await;
            }
            measured
        }
        Some(survey) => hot_images(shared, eye, survey, projector, nodes, notes).await,
        None => hot_patches(shared, eye, projector, nodes).await,
    };
    let mut outcome = match measured {
        Ok(outcome) => outcome,
        Err(e) => {
            tracing::error!(%projector, error = %e, "calibration over the wire failed");
            notes.warn(projector, format!("failed: {e}"));
            return Vec::new();
        }
    };
    notes.captures(outcome.captures);
    tracing::info!(projectors = ?outcome.projectors.iter().map(|p| &p.0).collect::<Vec<_>>(), captures = outcome.captures, "calibrated over the wire");
    let (dark, decodes) = (outcome.dark.take(), std::mem::take(&mut outcome.decodes));
    let Some(calibrated) = install(shared, outcome, errors) else {
        return Vec::new();
    };
    shared.shading().calibrated(dark.as_ref(), decodes);
    super::shading::save(shared).await;
    light(shared, &calibrated);
    calibrated.into_iter().map(|(id, _)| id).collect()
}

/// Who is calibrated with `projector`: in a dark room, once joins have paused for a heartbeat
/// (projectors switched on together are coded together), every projector waiting for its
/// nodes, by id; in a lit room it alone.
async fn batch(shared: &Shared, projector: &str) -> Vec<String> {
    let waiting = |shared: &Shared| {
        let registry = shared.registry.lock();
        let room = registry.projectors();
        room.dark().then(|| {
            let mut ids: Vec<String> = room
                .iter()
                .filter(|(id, p)| *id != projector && !p.calibrated() && p.nodes().is_empty())
                .map(|(id, _)| id.clone())
                .collect();
            ids.sort();
            ids
        })
    };
    if waiting(shared).is_some() {
        // Bounded: a stream of joins cannot hold the bring-up back for more than ten periods.
        for _ in 0..10 {
            let changed = shared.registry.changed();
            if tokio::time::timeout(shared.config.heartbeat, changed)
                .await
                .is_err()
            {
                break;
            }
        }
    }
    let mut batch = vec![projector.to_string()];
    batch.extend(waiting(shared).unwrap_or_default());
    // By id, whoever joined first: the same projectors are coded the same way (their
    // primaries, their node ids) however their joins interleaved.
    batch.sort();
    batch
}

/// Brings up `batch` (a dark room) or calibrates it joining a lit room, through the procedure's
/// steps: black offset, whites, structured light, responses, nodes beside the attached
/// projectors' claims, then their attenuation (Hadamard against the dark capture; hot in a lit
/// room, the others keeping their values).
async fn over_the_wire(
    shared: &Shared,
    eye: &mut Captures<impl Camera>,
    survey: &Survey,
    batch: Vec<String>,
    notes: &Notes,
) -> Result<Outcome, Failed> {
    let setup = survey.setup();
    let lit = !shared.registry.lock().projectors().dark();
    let claimed = claims_beside(shared, survey, &batch);
    let first = shared.live().problem.nodes() as u32;
    let settings = Settings {
        primaries: shared.config.primaries,
        ..Settings::default()
    };
    let settings = if lit { settings.lit_room() } else { settings };
    let mut rig = WireRig::new(shared, eye, batch);
    let mut procedure = Procedure::new(&mut rig, settings, notes.reporter(shared));
    let live = procedure.rig().projectors();
    if live.is_empty() {
        return Err(Failed::Nothing("left before its calibration".into()));
    }
    let dark = procedure.dark(&live).await?;
    let whites = procedure.whites(&live).await?;
    // A second pass only where the room still needs the batch's light.
    let needed = claimed.as_deref().map(roomlight_calib::procedure::needed);
    let decoded = procedure
        .structured_light(&live, &dark, &whites, needed.as_deref())
        .await?;
    let measured = procedure.responses(decoded, &live, &dark, &whites).await?;
    drop(whites);
    let decodes: Vec<(String, Correspondence)> = measured
        .iter()
        .filter(|m| m.projector.blends())
        .map(|m| (m.projector.id.clone(), m.corr.clone()))
        .collect();
    let to_place = setup.clone();
    let placed = procedure
        .rig()
        .offload(move || {
            place_calibrated(
                &to_place,
                &measured,
                claimed.as_deref(),
                first,
                &settings,
                &mut log_event,
            )
        })
        .await??;
    if placed.is_empty() {
        return Err(Failed::Nothing("no projector could be placed".into()));
    }
    procedure.assign(&placed).await?;
    let excluded = shared.live().excluded.clone();
    let (columns, measurable) = if lit {
        let mut hot = Vec::with_capacity(placed.len());
        for p in &placed {
            // Every projector of the batch black, the others lit: the room as `dark` saw it.
            hot.push(
                procedure
                    .hot(&setup, &p.projector.id, &p.ids(), Some(&dark))
                    .await?,
            );
        }
        hot_columns(survey, &excluded, &hot)?
    } else {
        let columns = procedure.attenuation(&setup, &placed, Some(&dark)).await?;
        multiplexed_columns(survey, &excluded, &columns.ids, &columns.attenuation)?
    };
    Ok(Outcome {
        projectors: placed
            .iter()
            .map(|p| (p.projector.id.clone(), p.ids()))
            .collect(),
        placed,
        columns,
        measurable,
        captures: procedure.captures(),
        decodes,
        // Lit, `dark` holds the other projectors' light.
        dark: (!lit).then_some(dark),
    })
}

/// What the attached projectors segmented before give each camera pixel (those in `batch` are
/// segmented anew, whatever they had). One that is not attached now does not hold its share: a
/// projector that replaces a dead one takes its place (should the old one come back, the
/// model holds both where they overlap).
fn claims_beside(shared: &Shared, survey: &Survey, batch: &[String]) -> Option<Vec<f32>> {
    let registry = shared.registry.lock();
    let live = shared.live();
    let mut sum: Option<Vec<f32>> = None;
    for (id, claim) in &live.claims {
        if registry.peer(id).is_none()
            || batch.contains(id)
            || claim.len() != survey.target_mask.len()
        {
            continue;
        }
        roomlight_calib::nodes::add_claim(sum.get_or_insert_with(|| vec![0.0; claim.len()]), claim);
    }
    sum
}

/// Hot calibration of a projector whose nodes the model knows, through the charts of whole
/// images ([`Procedure::hot`]).
async fn hot_images(
    shared: &Shared,
    eye: &mut Captures<impl Camera>,
    survey: &Survey,
    projector: &str,
    nodes: Vec<u32>,
    notes: &Notes,
) -> Result<Outcome, Failed> {
    let excluded = shared.live().excluded.clone();
    let mut rig = WireRig::new(shared, eye, vec![projector.to_string()]);
    let mut procedure = Procedure::new(&mut rig, Settings::default(), notes.reporter(shared));
    let hot = procedure
        .hot(&survey.setup(), projector, &nodes, None)
        .await?;
    let (columns, measurable) = hot_columns(survey, &excluded, std::slice::from_ref(&hot))?;
    Ok(Outcome {
        placed: Vec::new(),
        projectors: vec![(projector.to_string(), nodes)],
        columns,
        measurable,
        captures: procedure.captures(),
        decodes: Vec::new(),
        dark: None,
    })
}

/// A column over the model's patches from one over the room's patches (model patch `k` is
/// room patch `survey.patches[k]`): scaled as the model's rows are ([`Survey::scale`]: a dark
/// target's by `√w`), negatives clipped to 0, entries at or below `threshold` dropped (none on
/// a dark target), and none on a patch some capture could not measure or the model left out.
fn model_column(
    survey: &Survey,
    excluded: &[bool],
    p: &[LinearRgb],
    threshold: &[LinearRgb],
    usable: &[bool],
) -> Result<AttenuationColumn, ModelError> {
    let at =
        |v: &[LinearRgb], i: usize| v.get(i).copied().unwrap_or(LinearRgb::ZERO) * survey.scale(i);
    let dense: Vec<LinearRgb> = survey
        .patches
        .iter()
        .enumerate()
        .map(|(k, &i)| {
            let kept = usable.get(i) == Some(&true) && excluded.get(k) != Some(&true);
            if kept {
                at(p, i).map(|x| x.max(0.0))
            } else {
                LinearRgb::ZERO
            }
        })
        .collect();
    // On a dark target every positive entry is kept, however faint (as in process,
    // `Attenuation::columns_whole_on`): the target gets no luminaire's direct light, only what
    // every node inter-reflects onto it, each entry below the cut and together what it weighs.
    let threshold: Vec<LinearRgb> = survey
        .patches
        .iter()
        .map(|&i| {
            if survey.is_dark(i) {
                LinearRgb::ZERO
            } else {
                at(threshold, i)
            }
        })
        .collect();
    AttenuationColumn::from_dense_with_cutoff(&dense, &threshold)
}

/// Which model patches the chart patches `usable` cover.
fn model_measurable(survey: &Survey, usable: &[bool]) -> Vec<bool> {
    survey
        .patches
        .iter()
        .map(|&i| usable.get(i) == Some(&true))
        .collect()
}

/// Columns of hot measurements: entries above [`MULTIPLEXED_SIGMAS`] standard deviations of
/// the difference (its own noise, √2 σ of one capture), as the Hadamard columns keep; at 3√2 σ
/// the lab's model dropped enough faint light that the room measured 6% below its optimum.
fn hot_columns(survey: &Survey, excluded: &[bool], hot: &[Hot]) -> Result<Measured, ModelError> {
    let Some(first) = hot.first() else {
        return Ok((Vec::new(), vec![true; survey.patches.len()]));
    };
    let mut usable = vec![true; first.measurable.len()];
    for h in hot {
        for (u, m) in usable.iter_mut().zip(&h.measurable) {
            *u &= *m;
        }
    }
    let mut columns = Vec::new();
    for h in hot {
        for ((node, p), sigma) in h.columns.iter().zip(&h.sigma) {
            let threshold: Vec<LinearRgb> = sigma.iter().map(|s| *s * MULTIPLEXED_SIGMAS).collect();
            columns.push((
                *node,
                model_column(survey, excluded, p, &threshold, &usable)?,
            ));
        }
    }
    Ok((columns, model_measurable(survey, &usable)))
}

/// Columns of a multiplexed measurement, entries above [`MULTIPLEXED_SIGMAS`].
fn multiplexed_columns(
    survey: &Survey,
    excluded: &[bool],
    ids: &[u32],
    attenuation: &Attenuation,
) -> Result<Measured, ModelError> {
    let mut columns = Vec::with_capacity(ids.len());
    for ((&node, p), sigma) in ids.iter().zip(&attenuation.dense).zip(&attenuation.sigma) {
        let threshold: Vec<LinearRgb> = sigma.iter().map(|s| *s * MULTIPLEXED_SIGMAS).collect();
        let column = model_column(survey, excluded, p, &threshold, &attenuation.usable)?;
        columns.push((node, column));
    }
    Ok((columns, model_measurable(survey, &attenuation.usable)))
}

/// Hot calibration through the camera's patches (no survey, so no whole images to read charts
/// in): the projector's nodes all black, then each alone at white, one capture each, while the
/// others keep their values; `p = max(y_white − y_black, 0)` with the entries at or below
/// [`MULTIPLEXED_SIGMAS`] · √2 σ of the model's patch noise dropped (see [`hot_columns`]). The same captures as
/// [`Procedure::hot`], which reads them from images.
async fn hot_patches(
    shared: &Shared,
    eye: &mut Captures<impl Camera>,
    projector: &str,
    nodes: Vec<u32>,
) -> Result<Outcome, Failed> {
    let frame = |on: Option<u32>| {
        let values = nodes
            .iter()
            .map(|&n| {
                let x = if on == Some(n) {
                    LinearRgb::ONE
                } else {
                    LinearRgb::ZERO
                };
                (n, x)
            })
            .collect();
        [(projector, Frame::Nodes(values))]
    };
    let threshold: Vec<LinearRgb> = shared
        .live()
        .problem
        .noise()
        .iter()
        .map(|s| *s * (MULTIPLEXED_SIGMAS * std::f64::consts::SQRT_2))
        .collect();
    let camera = || RigError::Camera("the capture failed (logged)".into());
    let mut rig = WireRig::new(shared, eye, vec![projector.to_string()]);
    rig.show(&frame(None)).await?;
    let (black, mut measurable) = rig.measured().await.ok_or_else(camera)?;
    let mut columns = Vec::with_capacity(nodes.len());
    for &n in &nodes {
        rig.show(&frame(Some(n))).await?;
        let (white, ok) = rig.measured().await.ok_or_else(camera)?;
        for (m, o) in measurable.iter_mut().zip(ok) {
            *m &= o;
        }
        let dense: Vec<LinearRgb> = white
            .iter()
            .zip(&black)
            .map(|(w, b)| (*w - *b).map(|v| v.max(0.0)))
            .collect();
        let column = AttenuationColumn::from_dense_with_cutoff(&dense, &threshold)?;
        columns.push((n, column));
    }
    rig.show(&frame(None)).await?;
    Ok(Outcome {
        placed: Vec::new(),
        projectors: vec![(projector.to_string(), nodes.clone())],
        columns,
        measurable,
        captures: nodes.len() + 1,
        decodes: Vec::new(),
        dark: None,
    })
}

/// Why a calibration failed.
#[derive(Debug, thiserror::Error)]
enum Failed {
    #[error(transparent)]
    Procedure(#[from] ProcedureError),
    #[error(transparent)]
    Rig(#[from] RigError),
    #[error(transparent)]
    Calib(#[from] roomlight_calib::CalibError),
    #[error("attenuation: {0}")]
    Model(#[from] ModelError),
    /// Nothing to calibrate, or the model's nodes changed while the procedure ran.
    #[error("{0}")]
    Nothing(String),
}

/// The projector a rig's failure names, if any.
fn rig_projector(e: &RigError) -> Option<&str> {
    match e {
        RigError::Gone(id) | RigError::NotShown(id) | RigError::Unsupported(id, _) => Some(id),
        _ => None,
    }
}

impl Failed {
    /// The projector that caused it, when one did.
    fn projector(&self) -> Option<&str> {
        match self {
            Self::Rig(e) | Self::Procedure(ProcedureError::Rig(e)) => rig_projector(e),
            Self::Procedure(ProcedureError::Projector { projector, .. }) => Some(projector),
            _ => None,
        }
    }
}

/// Puts what a calibration measured into the live model: the nodes of projectors segmented now
/// (appended with their assignments, charts and claims), every measured column, patches some
/// capture could not measure left out for good (every column loses them, their target becomes
/// their black level, so the model and the measured `G` agree), the nodes' starts (the
/// conventional value of their chart; joining a lit room, the best fill of the room's current
/// `errors`). The projectors calibrated with their nodes; `None` when the model refused
/// (logged).
fn install(
    shared: &Shared,
    outcome: Outcome,
    errors: Option<&[LinearRgb]>,
) -> Option<Vec<(String, Vec<u32>)>> {
    let mut guard = shared.live_mut();
    let live = &mut *guard;
    if let Err(e) = append_nodes(live, &outcome.placed) {
        tracing::error!(error = %e, "calibration over the wire refused");
        return None;
    }
    let mut columns = live.problem.columns().to_vec();
    for (n, column) in outcome.columns {
        if let Some(slot) = columns.get_mut(n as usize) {
            *slot = column;
        }
    }
    let newly = live.newly_unmeasurable(&outcome.measurable);
    if !newly.is_empty() {
        tracing::info!(patches = ?newly, "patches not measurable under the new light: left out");
    }
    if let Err(e) = live.leave_out_with(&newly, columns) {
        tracing::error!(error = %e, "calibration over the wire refused");
        return None;
    }
    let nodes: Vec<u32> = outcome
        .projectors
        .iter()
        .flat_map(|(_, n)| n.iter().copied())
        .collect();
    starts(shared.survey.as_ref(), live, &nodes, errors);
    for (id, _) in &outcome.projectors {
        live.uncalibrated.remove(id);
    }
    Some(outcome.projectors)
}

/// Appends the nodes of projectors segmented now (ids from the model's node count on, as the
/// procedure numbered them) with empty columns, and records their assignments, charts and
/// claims.
fn append_nodes(live: &mut super::model::Live, placed: &[Placed]) -> Result<(), Failed> {
    let Some(first) = placed.iter().flat_map(|p| &p.nodes).map(|n| n.id).next() else {
        return Ok(());
    };
    if first as usize != live.problem.nodes() {
        return Err(Failed::Nothing(format!(
            "nodes numbered from {first}, the model has {}",
            live.problem.nodes()
        )));
    }
    let count: usize = placed.iter().map(|p| p.nodes.len()).sum();
    let mut columns = live.problem.columns().to_vec();
    columns.resize(columns.len() + count, AttenuationColumn::default());
    live.problem = Problem::new(
        columns,
        live.problem.black().to_vec(),
        live.problem.target().to_vec(),
        live.problem.noise().to_vec(),
    )?;
    live.start.resize(live.start.len() + count, None);
    for p in placed {
        let id = p.projector.id.clone();
        for n in &p.nodes {
            if let Some(chart) = n.chart {
                live.charts.insert(n.id, chart);
            }
        }
        live.owners.insert(id.clone(), p.ids());
        live.assignments.insert(id.clone(), p.assignment());
        match &p.claim {
            Some(claim) => live.claims.insert(id, claim.clone()),
            None => live.claims.remove(&id),
        };
    }
    Ok(())
}

/// Nodes segmented over the wire start from the conventional value of their chart; joining a
/// lit room (`errors`), where they best fill what the room lacks now (the bounded least-squares
/// fit of their columns to the current errors, the others held), not where they would light
/// their charts alone: the others then adjust in the rounds.
fn starts(
    survey: Option<&Survey>,
    live: &mut super::model::Live,
    nodes: &[u32],
    errors: Option<&[LinearRgb]>,
) {
    let problem = &live.problem;
    if let Some(survey) = survey {
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
    if let Some(e) = errors.filter(|e| e.len() == problem.patches()) {
        match joining_start(problem, nodes, e) {
            Ok(x) => {
                for (&n, x) in nodes.iter().zip(x) {
                    if let Some(slot) = live.start.get_mut(n as usize) {
                        *slot = Some(x);
                    }
                }
            }
            Err(err) => tracing::warn!(error = %err, "no joining start: the conventional one"),
        }
    }
}

/// The calibrated projectors take part in the rounds. Bring-up: while the room is still dark
/// and others wait for their calibration, they stay dark (the procedure left their nodes
/// black), so that the others are measured in the dark as well (lit projectors add camera noise
/// and cost decoded pixels); all light up once the last is measured. Otherwise every
/// calibrated projector gets its attenuation and `s` anew (the new light changes it).
fn light(shared: &Shared, calibrated: &[(String, Vec<u32>)]) {
    let dark = {
        let mut registry = shared.registry.lock();
        for (id, nodes) in calibrated {
            registry.set_nodes(id, nodes.clone());
            registry.mark_calibrated(id);
        }
        let room = registry.projectors();
        room.dark() && room.any_uncalibrated()
    };
    if !dark {
        shared.light_all();
    }
    tracing::info!(projectors = calibrated.len(), dark, "calibration done");
    shared.save_model();
    shared.registry.notify();
}
