//! The simulated projectors and camera behind the agents during a run: frames through the measured
//! responses into the simulator, captures sampled through the charts with noise and latency.

use anyhow::Result;
use roomlight_agent::hardware::{Camera, Display};
use roomlight_core::LinearRgb;
use roomlight_sim::{CameraNoise, Room};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use super::*;

/// The simulated projectors and camera behind the agents: node values in, turned into codes
/// through the measured responses and rendered by the simulator (with its hidden gamma); out,
/// the chart patches sampled from the capture with camera noise, exactly as calibration
/// measured them.
#[derive(Clone)]
pub(super) struct SimHardware {
    pub(super) room: Arc<Room>,
    pub(super) frames: Arc<FrameBuilder>,
    /// How calibration sampled the room patches.
    pub(super) setup: Arc<Setup>,
    /// The camera pixels the room patches' sampling reads, the only ones rendered.
    pub(super) pixels: Arc<roomlight_sim::PixelSubset>,
    pub(super) shown: Arc<Mutex<Vec<LinearRgb>>>,
    pub(super) patches: Arc<Vec<usize>>,
    /// Each model patch's row scale: a weighed patch's measurement is scaled as its row is.
    pub(super) scale: Arc<Vec<f64>>,
    pub(super) noise: Arc<Mutex<CameraNoise>>,
    /// Every capture: when, the noisy patch values returned and the noiseless ones.
    pub(super) log: Arc<Mutex<Vec<CaptureLog>>>,
    /// A camera with this many captures of latency hands the camera agent the image taken that
    /// many captures earlier (the first one while there is none that old): stale errors.
    pub(super) latency: usize,
    pub(super) delayed: Arc<Mutex<VecDeque<Vec<LinearRgb>>>>,
    /// Holds each capture until the run's driver has handled the last status.
    pub(super) gate: Arc<gate::Gate>,
}

pub(super) struct CaptureLog {
    /// When the capture was asked for (the rounds before it had ended).
    pub(super) asked: Instant,
    /// When it was handed over.
    pub(super) at: Instant,
    /// How long the capture took (render, noise, sampling): the simulated camera's time.
    pub(super) took: Duration,
    pub(super) shown: Vec<LinearRgb>,
    pub(super) measured: Vec<LinearRgb>,
    /// What a noiseless camera saw of the same frame.
    pub(super) noiseless: Vec<LinearRgb>,
}

impl SimHardware {
    /// The model's patches of every room patch's values, scaled as the model's rows are (the
    /// camera measures the room; the model weighs some patches).
    pub(super) fn pick(&self, all: &[LinearRgb]) -> Vec<LinearRgb> {
        self.patches
            .iter()
            .zip(self.scale.iter())
            .map(|(&i, s)| all[i] * *s)
            .collect()
    }

    /// The capture of node values `x` on the chart pixels (nothing else is read of it).
    pub(super) fn render(&self, x: &[LinearRgb]) -> Result<roomlight_sim::Capture> {
        Ok(self
            .room
            .render_subset(&self.pixels, &self.frames.frames(x), None)?)
    }

    /// What a noiseless camera would measure on the model's patches for node values `x`.
    pub(super) fn noiseless(&self, x: &[LinearRgb]) -> Result<Vec<LinearRgb>> {
        Ok(self.pick(&sample(&self.render(x)?, &self.setup)?))
    }

    pub(super) fn shown(&self) -> Vec<LinearRgb> {
        self.shown
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    pub(super) fn measure(&self, asked: Instant) -> Result<Vec<LinearRgb>> {
        let started = Instant::now();
        let shown = self.shown();
        let capture = self.render(&shown)?;
        let noiseless = self.pick(&sample(&capture, &self.setup)?);
        let noisy = self
            .noise
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .expose(&capture);
        let measured = self.pick(&sample(&noisy, &self.setup)?);
        let handed = {
            let mut delayed = self.delayed.lock().unwrap_or_else(PoisonError::into_inner);
            delayed.push_back(measured.clone());
            while delayed.len() > self.latency + 1 {
                delayed.pop_front();
            }
            delayed.front().cloned().unwrap_or_else(|| measured.clone())
        };
        self.log
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(CaptureLog {
                asked,
                at: Instant::now(),
                took: started.elapsed(),
                shown,
                measured,
                noiseless,
            });
        Ok(handed)
    }
}

impl Display for SimHardware {
    fn show(&mut self, node: u32, value: LinearRgb) {
        if let Some(v) = self
            .shown
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .get_mut(node as usize)
        {
            *v = value.clamp_unit();
        }
    }
}

impl Camera for SimHardware {
    fn capture(
        &mut self,
    ) -> impl Future<Output = Result<Vec<LinearRgb>, roomlight_agent::AgentError>> + Send {
        let hw = self.clone();
        async move {
            let asked = Instant::now();
            hw.gate.wait().await;
            hw.measure(asked)
                .map_err(|e| roomlight_agent::AgentError::Protocol(format!("capture: {e:#}")))
        }
    }
}
