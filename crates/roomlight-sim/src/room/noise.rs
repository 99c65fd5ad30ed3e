//! Camera noise (DESIGN §7): shot noise growing with √value, read noise and saturation, applied
//! to the noiseless captures the room renders. Knows the scene's camera, nothing of the transport.

use super::{Capture, Room};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Camera noise: shot noise growing with √value, read noise, and saturation (DESIGN §7).
#[derive(Debug, Clone)]
pub struct CameraNoise {
    rng: ChaCha8Rng,
    read: f64,
    shot: f64,
    saturation: f64,
}

impl CameraNoise {
    /// The noise of a scene's camera, from its seed.
    pub fn new(room: &Room) -> Self {
        let c = &room.scene.camera;
        Self {
            rng: ChaCha8Rng::seed_from_u64(c.seed),
            read: c.read_noise,
            shot: c.shot_noise,
            saturation: c.saturation,
        }
    }

    /// The noise of a scene's camera with another seed (repeated experiments).
    pub fn with_seed(room: &Room, seed: u64) -> Self {
        Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
            ..Self::new(room)
        }
    }

    /// Adds noise to a noiseless capture and clips at zero and saturation.
    pub fn expose(&mut self, capture: &Capture) -> Capture {
        self.expose_longer(capture, 1.0)
    }

    /// A capture with an exposure `factor` times the scene's, in the units of a normal one
    /// (divided by `factor`): read noise shrinks by `factor`, shot noise by its square root,
    /// and saturation comes at `1/factor` of the normal level. A factor that is not a finite
    /// number ≥ 1 is taken as 1.
    pub fn expose_longer(&mut self, capture: &Capture, factor: f64) -> Capture {
        let f = if factor.is_finite() && factor >= 1.0 {
            factor
        } else {
            1.0
        };
        let pixels = capture
            .pixels
            .iter()
            .map(|p| {
                p.map(|v| {
                    let v = f64::from(v.max(0.0)) * f;
                    let sigma = (self.shot * self.shot * v + self.read * self.read).sqrt();
                    let z: f64 = StandardNormal.sample(&mut self.rng);
                    ((v + sigma * z).clamp(0.0, self.saturation) / f) as f32
                })
            })
            .collect();
        Capture {
            width: capture.width,
            height: capture.height,
            pixels,
        }
    }
}
