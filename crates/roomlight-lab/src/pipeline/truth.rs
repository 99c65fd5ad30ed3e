//! What a noiseless camera would see: the room's true transport and, per target, the true
//! problem the metrics are measured against. Only the metrics read it, never the agents.

use anyhow::Result;
use roomlight_calib::charts::{ChartCorners, SampleConfig};
use roomlight_core::{AttenuationColumn, LinearRgb, Problem};
use roomlight_sim::{Frame, NodeBasis, NodeRegion, Room};
use std::sync::Arc;

use super::*;

/// The room as a noiseless camera sees it through the charts: every node's light at full
/// white and the black level, on every room patch. Measured once per calibration.
#[derive(Debug)]
pub struct Transport {
    pub(super) corners: Arc<Vec<ChartCorners>>,
    pub(super) config: SampleConfig,
    pub(super) black: Vec<LinearRgb>,
    pub(super) columns: Vec<Vec<LinearRgb>>,
}

impl Transport {
    /// Renders each node alone at full white (and all black), noiselessly, and samples the
    /// charts: the captures of a [`NodeBasis`], one at a time.
    pub fn new(
        room: &Room,
        regions: &[NodeRegion],
        corners: &[ChartCorners],
        config: SampleConfig,
    ) -> Result<Self> {
        let mut black: Vec<LinearRgb> = Vec::new();
        let mut columns: Vec<Vec<LinearRgb>> = Vec::with_capacity(regions.len());
        let mut failed = None;
        NodeBasis::visit_node_captures(room, regions, None, |node, capture| {
            match sample(&capture, corners, &config) {
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
            corners: Arc::new(corners.to_vec()),
            config,
            black,
            columns,
        })
    }
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

    /// The truth for `model`'s patches under `preset`.
    pub fn new(room: &Room, transport: &Transport, model: &Model, preset: usize) -> Result<Self> {
        let pick = |v: &[LinearRgb]| model.patches.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let target = pick(&sample(
            &room.render(&vec![Frame::Black; room.projectors().len()], Some(preset))?,
            &transport.corners,
            &transport.config,
        )?);
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
            pick(&transport.black),
            target.clone(),
            model.problem.noise().to_vec(),
        )?;
        Ok(Self { target, problem })
    }
}
