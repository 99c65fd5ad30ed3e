//! What a noiseless camera would see: the room's true transport and, per target, the true
//! problem the metrics are measured against. Only the metrics read it, never the agents.

use anyhow::Result;
use roomlight_calib::charts::ChartCorners;
use roomlight_calib::procedure::Setup;
use roomlight_core::{AttenuationColumn, LinearRgb, Problem};
use roomlight_sim::{Frame, NodeBasis, NodeRegion, PixelSubset, Room};
use std::sync::Arc;

use super::*;

/// The room as a noiseless camera sees it through the room patches (charts, target, walls):
/// every node's light at full white and the black level, on every room patch. Measured once
/// per calibration.
#[derive(Debug)]
pub struct Transport {
    /// How calibration sampled the room patches.
    pub(super) setup: Arc<Setup>,
    pub(super) black: Vec<LinearRgb>,
    pub(super) columns: Vec<Vec<LinearRgb>>,
    /// The camera pixels the room patches' sampling reads: a run's captures render only these.
    pub(super) pixels: Arc<PixelSubset>,
    /// The same without the walls' (charts and target): a run whose model leaves the walls out
    /// renders only these.
    pub(super) charts: Arc<PixelSubset>,
}

impl Transport {
    /// Renders each node alone at full white (and all black), noiselessly, and samples the
    /// room patches as `setup` does: the captures of a [`NodeBasis`], one at a time.
    pub fn new(room: &Room, regions: &[NodeRegion], setup: &Setup) -> Result<Self> {
        let mut black: Vec<LinearRgb> = Vec::new();
        let mut columns: Vec<Vec<LinearRgb>> = Vec::with_capacity(regions.len());
        let mut failed = None;
        NodeBasis::visit_node_captures(room, regions, None, |node, capture| {
            match sample(&capture, setup) {
                Ok(values) => match node {
                    None => black = values,
                    Some(_) => columns.push(
                        values
                            .iter()
                            .zip(&black)
                            .map(|(a, b)| (*a - *b).map(|v| v.max(0.0)))
                            .collect(),
                    ),
                },
                Err(e) => failed = failed.take().or(Some(e)),
            }
            Ok(())
        })?;
        if let Some(e) = failed {
            return Err(e);
        }
        Ok(Self {
            pixels: Arc::new(room.pixel_subset(patch_pixels(room, setup))?),
            charts: Arc::new(
                room.pixel_subset(
                    chart_pixels(room, &setup.corners)
                        .chain(setup.target_patches.iter().flatten().copied()),
                )?,
            ),
            setup: Arc::new(setup.clone()),
            black,
            columns,
        })
    }
}

/// Every camera pixel sampling `setup`'s room patches reads: the charts' ([`chart_pixels`]),
/// and the target's and walls' own pixel lists.
pub(super) fn patch_pixels<'a>(room: &Room, setup: &'a Setup) -> impl Iterator<Item = u32> + 'a {
    chart_pixels(room, &setup.corners).chain(setup.region_pixels())
}

/// Every camera pixel within 2 pixels of a chart's bounding box: all that sampling the charts
/// through these corners reads (patches lie inside the chart's quadrilateral).
pub(super) fn chart_pixels<'a>(
    room: &Room,
    corners: &'a [ChartCorners],
) -> impl Iterator<Item = u32> + 'a {
    let [w, h] = room.scene().camera.resolution;
    corners.iter().flat_map(move |chart| {
        let span = |axis: usize, size: u32| {
            let (lo, hi) = chart
                .corners
                .iter()
                .fold((f64::MAX, f64::MIN), |(lo, hi), c| {
                    (lo.min(c[axis]), hi.max(c[axis]))
                });
            // Corners are checked finite and inside the image before sampling; a bad one here
            // only widens or empties the box (saturating casts).
            let lo = ((lo.floor() - 2.0).max(0.0) as u32).min(size);
            let hi = ((hi.ceil() + 3.0).max(0.0) as u32).min(size);
            lo..hi
        };
        let (xs, ys) = (span(0, w), span(1, h));
        ys.flat_map(move |y| xs.clone().map(move |x| y * w + x))
    })
}

/// The truth for one target on the model's patches, as a noiseless camera sees it.
#[derive(Debug)]
pub struct Truth {
    /// The LED target.
    pub target: Vec<LinearRgb>,
    /// The true problem (true transport and target): its optimum is what the room could reach;
    /// the measured model's optimum differs from it by the calibration's errors.
    pub problem: Problem,
}

impl Truth {
    /// `G` of what a noiseless camera measured against the true target.
    pub fn objective(&self, values: &[LinearRgb]) -> f64 {
        let errors: Vec<LinearRgb> = self
            .target
            .iter()
            .zip(values)
            .map(|(r, y)| *r - *y)
            .collect();
        roomlight_core::metrics::objective(&errors)
    }

    /// The truth for `model`'s patches under `preset`, in the model's terms: each patch's row
    /// scaled as the model's is ([`roomlight_calib::procedure::Target::scale`]), and the target
    /// patches kept dark asking for the black level, as the model asks.
    pub fn new(room: &Room, transport: &Transport, model: &Model, preset: usize) -> Result<Self> {
        let scale = &model.target.scale;
        let pick = |v: &[LinearRgb]| {
            model
                .patches
                .iter()
                .zip(scale)
                .map(|(&i, s)| v[i] * *s)
                .collect::<Vec<_>>()
        };
        let led = pick(&sample(
            &room.render(&vec![Frame::Black; room.projectors().len()], Some(preset))?,
            &transport.setup,
        )?);
        let black = pick(&transport.black);
        let dark = transport.setup.target_patch_range();
        let target: Vec<LinearRgb> = model
            .patches
            .iter()
            .enumerate()
            .map(|(k, i)| if dark.contains(i) { black[k] } else { led[k] })
            .collect();
        let columns = transport
            .columns
            .iter()
            .map(|c| {
                let dense = pick(c);
                AttenuationColumn::from_dense_with_cutoff(
                    &dense,
                    &vec![LinearRgb::ZERO; dense.len()],
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        let problem = Problem::new(
            columns,
            black,
            target.clone(),
            model.problem.noise().to_vec(),
        )?;
        Ok(Self { target, problem })
    }
}

/// The partition of unity of a calibration's blending projectors (their nodes' blend weights,
/// before any shaping, summed per projector pixel), as [`placed_partition`] reads placed
/// projectors.
pub fn calibrated_partition(
    room: &Room,
    cal: &Calibrated,
) -> Result<roomlight_calib::nodes::Partition> {
    let mut projectors = Vec::with_capacity(cal.blending.len());
    let blend = cal.blend_regions(room)?;
    for (id, excluded) in &cal.blending {
        let k = room.projector(id)?;
        let p = &room.projectors()[k].pinhole;
        let nodes = blend.iter().filter(|r| r.projector == k);
        let weights = summed(p.width * p.height, nodes.map(|r| r.weights.as_slice()));
        projectors.push((k, weights, excluded.clone()));
    }
    Ok(through_truth(room, projectors))
}

/// The partition of unity of placed projectors (each one's nodes summed), as
/// [`through_truth`] measures it. A projector the room does not have is refused, named.
pub fn placed_partition(
    room: &Room,
    placed: &[&roomlight_calib::procedure::Placed],
) -> Result<roomlight_calib::nodes::Partition> {
    use anyhow::Context;
    let mut projectors = Vec::with_capacity(placed.len());
    for p in placed {
        let k = room
            .projector(&p.projector.id)
            .with_context(|| format!("no projector {} in the room", p.projector.id))?;
        let nodes = p.nodes.iter().map(|n| n.weights.as_slice());
        let weights = summed(p.projector.width * p.projector.height, nodes);
        projectors.push((k, weights, p.excluded.clone()));
    }
    Ok(through_truth(room, projectors))
}

/// The partition of unity of projectors, each as its room index, its weight per projector
/// pixel and its pixels kept black, through the simulator's true correspondence, away from the
/// target (its mask dilated by 8 pixels: the margin luminaires keep black), as the
/// segmentation's is measured.
fn through_truth(
    room: &Room,
    projectors: Vec<(usize, Vec<f32>, Vec<bool>)>,
) -> roomlight_calib::nodes::Partition {
    let mask: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let (w, h) = (room.camera().width as usize, room.camera().height as usize);
    let (truth, (weights, dark)): (Vec<_>, (Vec<_>, Vec<_>)) = projectors
        .into_iter()
        .map(|(k, weights, dark)| (room.true_correspondence(k), (weights, dark)))
        .unzip();
    roomlight_calib::nodes::partition_of_unity(
        &truth,
        &weights,
        &dark,
        &roomlight_calib::nodes::dilate(&mask, w, h, 8),
    )
}

/// Node weights summed per projector pixel (`pixels` of them).
fn summed<'w>(pixels: u32, nodes: impl Iterator<Item = &'w [f32]>) -> Vec<f32> {
    let mut sum = vec![0.0f32; pixels as usize];
    for weights in nodes {
        sum.iter_mut().zip(weights).for_each(|(s, w)| *s += w);
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run's captures render only the room patches' pixels: sampled as calibration samples
    /// them (charts, target, walls), with the camera's noise, they give the same patch values
    /// as the full render, to the bit.
    #[test]
    fn the_patch_pixels_hold_everything_the_sampling_reads() {
        // The quick demo's camera: enough pixels per patch.
        let mut scene = roomlight_sim::scenes::small().expect("scene");
        scene.camera.resolution = [640, 480];
        let room = Room::build(scene).expect("room");
        let setup = setup(&room, true).expect("setup");
        assert!(!setup.target_patches.is_empty() && setup.wall_patches.len() > 50);
        let subset = room
            .pixel_subset(patch_pixels(&room, &setup))
            .expect("subset");
        assert!(
            subset.pixels().len() < room.pixels().len() / 2,
            "a real subset"
        );
        let frames: Vec<Frame> = (0..room.projectors().len())
            .map(|k| Frame::Uniform([0.2 + 0.1 * k as f32, 0.3, 0.4 - 0.1 * k as f32]))
            .collect();
        let preset = None;
        let noisy = |capture| roomlight_sim::CameraNoise::with_seed(&room, 7).expose(&capture);
        let full = sample(
            &noisy(room.render(&frames, preset).expect("render")),
            &setup,
        )
        .expect("sample");
        let part = room
            .render_subset(&subset, &frames, preset)
            .expect("subset render");
        let part = sample(&noisy(part), &setup).expect("sample");
        assert_eq!(
            full.len(),
            room.patches() + setup.target_patches.len() + setup.wall_patches.len()
        );
        let bits = |v: &[LinearRgb]| -> Vec<[u64; 3]> {
            v.iter().map(|p| p.0.map(f64::to_bits)).collect()
        };
        assert_eq!(bits(&full), bits(&part));
        let lit = full.iter().filter(|p| p[1] > 0.0).count();
        assert!(4 * lit > 3 * full.len(), "the patches are lit ({lit})");
    }
}
