//! Linear RGB triples: the unit every value of the optimiser is in.

use serde::{Deserialize, Serialize};
use std::ops::{Add, AddAssign, Index, IndexMut, Mul, Sub, SubAssign};

/// A linear-light RGB triple (camera or projector channels, not sRGB-encoded).
///
/// The three channels are independent in the default model (DESIGN §2), so almost every
/// operation here is element-wise. The small ones are `#[inline]`: other crates call them per
/// pixel, and without it (no LTO) each was a call of its own (adding and scaling took 12.7% of
/// the CPU in the demo's calibration phase, 2026-11-28).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct LinearRgb(pub [f64; 3]);

impl LinearRgb {
    /// Black.
    pub const ZERO: Self = Self([0.0; 3]);
    /// Full white (every channel 1).
    pub const ONE: Self = Self([1.0; 3]);

    /// The same value on all three channels.
    pub const fn splat(v: f64) -> Self {
        Self([v; 3])
    }

    /// Applies `f` to every channel.
    pub fn map(self, f: impl Fn(f64) -> f64) -> Self {
        Self(self.0.map(f))
    }

    /// Combines two triples channel by channel.
    pub fn zip(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        Self([
            f(self.0[0], other.0[0]),
            f(self.0[1], other.0[1]),
            f(self.0[2], other.0[2]),
        ])
    }

    /// Channel-wise product.
    #[inline]
    pub fn hadamard(self, other: Self) -> Self {
        self.zip(other, |a, b| a * b)
    }

    /// Clamps every channel into the display range `[0, 1]`.
    #[inline]
    pub fn clamp_unit(self) -> Self {
        self.map(|v| v.clamp(0.0, 1.0))
    }

    /// Sum of squares over the channels.
    #[inline]
    pub fn norm_squared(self) -> f64 {
        self.0.iter().map(|v| v * v).sum()
    }

    /// Largest absolute channel value.
    #[inline]
    pub fn max_abs(self) -> f64 {
        self.0.iter().fold(0.0, |m, v| m.max(v.abs()))
    }

    /// True when every channel is a finite number.
    #[inline]
    pub fn is_finite(self) -> bool {
        self.0.iter().all(|v| v.is_finite())
    }

    /// Smallest channel value.
    #[inline]
    pub fn min_channel(self) -> f64 {
        self.0.iter().fold(f64::INFINITY, |m, &v| m.min(v))
    }
}

impl Index<usize> for LinearRgb {
    type Output = f64;
    #[inline]
    fn index(&self, c: usize) -> &f64 {
        &self.0[c]
    }
}

impl IndexMut<usize> for LinearRgb {
    #[inline]
    fn index_mut(&mut self, c: usize) -> &mut f64 {
        &mut self.0[c]
    }
}

impl Add for LinearRgb {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        self.zip(o, |a, b| a + b)
    }
}

impl AddAssign for LinearRgb {
    #[inline]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}

impl Sub for LinearRgb {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        self.zip(o, |a, b| a - b)
    }
}

impl SubAssign for LinearRgb {
    #[inline]
    fn sub_assign(&mut self, o: Self) {
        *self = *self - o;
    }
}

impl Mul<f64> for LinearRgb {
    type Output = Self;
    #[inline]
    fn mul(self, k: f64) -> Self {
        self.map(|v| v * k)
    }
}

impl From<[f64; 3]> for LinearRgb {
    #[inline]
    fn from(v: [f64; 3]) -> Self {
        Self(v)
    }
}
