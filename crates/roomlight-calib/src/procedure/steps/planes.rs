//! A coding group's reduced captures as they wait to be decoded ([`Planes`]): in single
//! precision, or in half precision while the other groups of a set coded in their primaries
//! are captured and decoded.
//!
//! A set of three groups holds 3 × 34 planes of the lab's camera until its first group is
//! decoded: 320 MB in single precision, which put the calibration's peak over issue 22's
//! 800 MB. In half precision (the `half` crate's IEEE binary16) a plane is 1.6 MB, and a group
//! is widened back to single precision only when it is decoded, then dropped. Rounding to
//! half precision is within 2⁻¹² of a value (under 2.5e-4 at white's level, 1), a tenth of
//! the decoder's noise floor (0.002) and a thirtieth of the shot noise there (0.007); values
//! the capture units can hold (a few times white at most) are far below binary16's largest
//! (65 504), and what is not finite stays so, as the decoder's checks expect.

use half::f16;

/// One reduced capture (less black, or a group's share), in single or half precision.
#[derive(Debug, Clone)]
enum Plane {
    Full(Vec<f32>),
    Half(Vec<f16>),
}

/// A group's planes in slot order.
#[derive(Debug, Clone, Default)]
pub(super) struct Planes(Vec<Plane>);

impl Planes {
    /// Planes kept as given.
    #[cfg(test)]
    pub(super) fn full(planes: Vec<Vec<f32>>) -> Self {
        Self(planes.into_iter().map(Plane::Full).collect())
    }

    /// Adds `plane`, rounded to half precision when `compact`.
    pub(super) fn push(&mut self, plane: Vec<f32>, compact: bool) {
        self.0.push(if compact {
            Plane::Half(plane.iter().map(|v| f16::from_f32(*v)).collect())
        } else {
            Plane::Full(plane)
        });
    }

    pub(super) fn len(&self) -> usize {
        self.0.len()
    }

    /// Every plane in single precision (what the decoder reads), one at a time so that a
    /// group is never held twice.
    pub(super) fn widen(&mut self) {
        for plane in &mut self.0 {
            if let Plane::Half(h) = plane {
                let wide: Vec<f32> = h.iter().map(|v| v.to_f32()).collect();
                *plane = Plane::Full(wide);
            }
        }
    }

    /// Plane `j` as the decoder reads it: `None` beyond the last, or while it is still in
    /// half precision ([`Self::widen`] first).
    pub(super) fn get(&self, j: usize) -> Option<&[f32]> {
        match self.0.get(j)? {
            Plane::Full(v) => Some(v),
            Plane::Half(_) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_planes_widen_to_within_their_rounding() {
        let plane: Vec<f32> = (0..1000)
            .map(|i| (i as f32 - 100.0) * 0.0037)
            .chain([f32::NAN, f32::INFINITY, 0.0])
            .collect();
        let mut planes = Planes::default();
        planes.push(plane.clone(), true);
        planes.push(plane.clone(), false);
        assert_eq!(planes.len(), 2);
        assert!(
            planes.get(0).is_none(),
            "a half plane is not read before widening"
        );
        let full = planes.get(1).expect("a full plane");
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert!(bits(full) == bits(&plane), "a full plane is kept exact");
        planes.widen();
        let wide = planes.get(0).expect("widened");
        for (w, v) in wide.iter().zip(&plane) {
            if v.is_finite() {
                assert!(
                    (w - v).abs() <= v.abs() * 2f32.powi(-11) + 1e-7,
                    "{v} → {w}"
                );
            } else {
                assert_eq!(w.is_nan(), v.is_nan());
                assert_eq!(w.is_infinite(), v.is_infinite());
            }
        }
        assert!(planes.get(2).is_none());
    }
}
