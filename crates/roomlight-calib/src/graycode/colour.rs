//! Up to three groups of projectors coded at the same time in different primaries, their
//! footprints overlapping, and told apart by the camera's colour (DESIGN §4.2: "projectors
//! whose footprints do not overlap can be coded at the same time"; this goes further). Group
//! `g` shows its bit patterns in one primary only ([`Primary`]); before them, each group's
//! white in that primary alone is captured once. At every camera pixel those whites, less the
//! dark capture, are the columns `v_g` of a 3 × n matrix: a capture less dark is `Σ_g s_g v_g`
//! plus noise, `s_g` being how much of group `g`'s primary white is lit there. The
//! least-squares `s` ([`Unmixing::reduce`]) times `v_g`'s intensity is what a capture of group
//! `g` alone would have given in its primary, in the units the decoder reads
//! ([`super::less_black`]), so each group then decodes as if it had been shown alone.
//!
//! The columns are measured, not assumed: a real camera's channels see every projector primary
//! a little (crosstalk) and a coloured surface turns each column's direction, so no channel
//! belongs to a group. Where two columns are close to parallel (a saturated surface that
//! reflects one primary only) the unmixing amplifies the noise: a group whose share's noise
//! there exceeds [`MAX_NOISE_GAIN`] times what it would be alone is left out of the solve and
//! taken as not reaching the pixel, so that it decodes as unknown there rather than wrong; the
//! groups kept are trusted only where the light of those left out cannot move their shares by
//! more than [`MAX_DISTURBANCE`].
//!
//! Hand-written: a per-pixel least-squares solve of at most 3 × 3 (nalgebra), which no
//! structured-light crate offers.

use crate::CalibError;
use crate::image_io::LinearImage;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// One primary of a projector: what a structured pattern lights when several groups are
/// coded at once in different colours ([`Primary::tint`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Primary {
    Red,
    Green,
    Blue,
}

impl Primary {
    /// The three, in the order groups take them.
    pub const ALL: [Self; 3] = [Self::Red, Self::Green, Self::Blue];

    /// The code channel it drives (0 red, 1 green, 2 blue).
    pub fn channel(self) -> usize {
        match self {
            Self::Red => 0,
            Self::Green => 1,
            Self::Blue => 2,
        }
    }

    /// The uniform code of this primary at full power, the others black.
    pub fn white(self) -> [f32; 3] {
        let mut code = [0.0; 3];
        code[self.channel()] = 1.0;
        code
    }

    /// Keeps this primary of every code and blacks out the others: a white pattern drawn in it.
    pub fn tint(self, codes: &mut [[f32; 3]]) {
        let keep = self.channel();
        for code in codes {
            for (c, v) in code.iter_mut().enumerate() {
                if c != keep {
                    *v = 0.0;
                }
            }
        }
    }
}

/// A group's share is trusted where its noise is at most this many times what it would be were
/// the group alone at the pixel: `|v_g| · |row_g of the pseudo-inverse|` (1 where `v_g` is
/// orthogonal to the other columns, as for three primaries on a grey surface without
/// crosstalk). Above it the group is left out of the pixel's solve and does not reach it
/// ([`Unmixing`]). 1.5 costs a single-shot decision, whose margin is several noise
/// deviations, at most a third of it.
pub const MAX_NOISE_GAIN: f32 = 1.5;

/// A group takes part in a pixel's solve where its primary's white raises the pixel by more
/// than this share of the most it raises any pixel: its inter-reflected light too, which would
/// otherwise bias the others' shares as ambient light does. Below it its light is noise, and a
/// column of noise would make the solve ill-conditioned.
pub const PRESENT_SHARE: f32 = 2e-3;

/// A group left out of a pixel's solve (its noise gain over [`MAX_NOISE_GAIN`]) still lights
/// it; the groups kept are trusted there only while all left out together can move their
/// share by at most this much of its range (0 to 1). A single shot decides a bit at half the
/// range, so this keeps at least half of its margin.
pub const MAX_DISTURBANCE: f32 = 0.25;

/// How the captures of up to three groups coded at once in different primaries are told
/// apart at each camera pixel (see the module doc).
#[derive(Debug, Clone)]
pub struct Unmixing {
    groups: usize,
    /// Per camera pixel, per group: the pseudo-inverse's row scaled by the intensity of the
    /// group's column, so that a capture less dark gives the group's rise in intensity units;
    /// zero where the group does not reach the pixel (or was left out of its solve).
    rows: Vec<[[f32; 3]; 3]>,
    /// Per group, per camera pixel: the intensity its primary's white adds to dark where it
    /// reaches the pixel, 0 elsewhere.
    rises: Vec<Vec<f32>>,
}

impl Unmixing {
    /// The unmixing of groups whose primaries' whites are `whites` (one capture each, the
    /// group's members at their primary's white, all else as in `dark`). One to three groups;
    /// captures of another size than `dark` are refused, named.
    pub fn new(dark: &LinearImage, whites: &[&LinearImage]) -> Result<Self, CalibError> {
        let groups = whites.len();
        if !(1..=3).contains(&groups) {
            return Err(CalibError::Invalid {
                field: "groups coded in colour",
                problem: format!("{groups}, expected 1 to 3 (one per primary)"),
            });
        }
        for (g, w) in whites.iter().enumerate() {
            w.expect_size(dark.width, dark.height, &format!("primary white {}", g + 1))?;
        }
        let n = dark.pixels.len();
        let column = |g: usize, i: usize| -> Vector3<f64> {
            let (w, d) = (whites[g].pixels[i], dark.pixels[i]);
            Vector3::from_fn(|c, _| f64::from(w[c]) - f64::from(d[c]))
        };
        // A column that is not finite (a broken capture) counts as no light.
        let rise = |v: &Vector3<f64>| {
            let s = v.sum();
            if s.is_finite() { s.max(0.0) } else { 0.0 }
        };
        let peaks: Vec<f64> = (0..groups)
            .map(|g| (0..n).map(|i| rise(&column(g, i))).fold(0.0, f64::max))
            .collect();
        let mut rows = vec![[[0.0f32; 3]; 3]; n];
        let mut rises = vec![vec![0.0f32; n]; groups];
        for i in 0..n {
            let columns: Vec<Vector3<f64>> = (0..groups).map(|g| column(g, i)).collect();
            let mut solved: Vec<usize> = (0..groups)
                .filter(|&g| {
                    peaks[g] > 0.0 && rise(&columns[g]) > f64::from(PRESENT_SHARE) * peaks[g]
                })
                .collect();
            let mut left_out: Vec<usize> = Vec::new();
            // Solve; while some group's noise gain is over the bound, leave the worst out
            // (its light then disturbs the others' shares, bounded below) and solve again.
            let trusted = loop {
                let Some(rows) = pseudo_inverse(&columns, &solved) else {
                    // Two columns parallel: nobody here is told apart.
                    break Vec::new();
                };
                let gains: Vec<f64> = solved
                    .iter()
                    .zip(&rows)
                    .map(|(&g, row)| columns[g].norm() * row.norm())
                    .collect();
                let worst = gains
                    .iter()
                    .enumerate()
                    .filter(|(_, v)| !(v.is_finite() && **v <= f64::from(MAX_NOISE_GAIN)))
                    .max_by(|a, b| a.1.total_cmp(b.1))
                    .map(|(a, _)| a);
                match worst {
                    Some(a) => left_out.push(solved.remove(a)),
                    None => break solved.iter().copied().zip(rows).collect::<Vec<_>>(),
                }
            };
            for (g, row) in trusted {
                // The share of its own range the groups left out can move this one's.
                let disturbed: f64 = left_out.iter().map(|&h| row.dot(&columns[h]).abs()).sum();
                let intensity = rise(&columns[g]);
                if disturbed <= f64::from(MAX_DISTURBANCE) && intensity > 0.0 {
                    rows[i][g] = std::array::from_fn(|c| (row[c] * intensity) as f32);
                    rises[g][i] = intensity as f32;
                }
            }
        }
        Ok(Self {
            groups,
            rows,
            rises,
        })
    }

    /// How many groups it tells apart.
    pub fn groups(&self) -> usize {
        self.groups
    }

    /// Group `g`'s primary white less dark, in intensity, where it reaches (0 elsewhere).
    pub fn rise(&self, g: usize) -> &[f32] {
        &self.rises[g]
    }

    /// A capture of every group showing its pattern, less `dark`, as each group alone would
    /// have raised it: per group, per camera pixel, in intensity units (0 where the group does
    /// not reach). A capture of another size is refused, named by `what`.
    pub fn reduce(
        &self,
        capture: &LinearImage,
        dark: &LinearImage,
        what: &str,
    ) -> Result<Vec<Vec<f32>>, CalibError> {
        capture.expect_size(dark.width, dark.height, what)?;
        let mut out = vec![vec![0.0f32; self.rows.len()]; self.groups];
        for (i, (rows, (c, d))) in self
            .rows
            .iter()
            .zip(capture.pixels.iter().zip(&dark.pixels))
            .enumerate()
        {
            let less: [f32; 3] = std::array::from_fn(|k| c[k] - d[k]);
            for (g, plane) in out.iter_mut().enumerate() {
                let r = rows[g];
                let v = r[0] * less[0] + r[1] * less[1] + r[2] * less[2];
                // A capture that is not finite gives no light rather than NaN downstream.
                plane[i] = if v.is_finite() { v } else { 0.0 };
            }
        }
        Ok(out)
    }
}

/// The rows of the least-squares inverse `(MᵀM)⁻¹Mᵀ` of the columns `solved` picks, in its
/// order; `None` when they are parallel (the normal matrix singular). No columns: no rows.
fn pseudo_inverse(columns: &[Vector3<f64>], solved: &[usize]) -> Option<Vec<Vector3<f64>>> {
    // The normal matrix of the columns, padded with the identity to 3 × 3.
    let mut normal = Matrix3::<f64>::identity();
    for (a, &g) in solved.iter().enumerate() {
        for (b, &h) in solved.iter().enumerate() {
            normal[(a, b)] = columns[g].dot(&columns[h]);
        }
    }
    let inverse = normal.try_inverse()?;
    Some(
        (0..solved.len())
            .map(|a| {
                solved
                    .iter()
                    .enumerate()
                    .map(|(b, &h)| columns[h] * inverse[(a, b)])
                    .sum()
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w × h` image of one colour.
    fn flat(w: u32, h: u32, rgb: [f32; 3]) -> LinearImage {
        LinearImage {
            width: w,
            height: h,
            pixels: vec![rgb; (w * h) as usize],
        }
    }

    /// What a camera with crosstalk `mix` (rows: camera channel, columns: primary) sees of
    /// surface albedo `albedo` lit by primaries at `light`, over `ambient`.
    fn seen(mix: [[f32; 3]; 3], albedo: [f32; 3], light: [f32; 3], ambient: f32) -> [f32; 3] {
        std::array::from_fn(|c| {
            ambient + albedo[c] * (0..3).map(|p| mix[c][p] * light[p]).sum::<f32>()
        })
    }

    const CROSSTALK: [[f32; 3]; 3] = [[0.9, 0.2, 0.05], [0.15, 1.0, 0.15], [0.02, 0.25, 0.8]];

    /// Three groups overlapping on a grey surface, seen through a camera whose channels mix
    /// the primaries: each group's share comes back as if it had been shown alone, for every
    /// combination of lit and unlit groups.
    #[test]
    fn three_overlapping_groups_come_apart_through_crosstalk() {
        let grey = [0.5, 0.45, 0.4];
        let peaks = [[0.8, 0.0, 0.0], [0.0, 0.6, 0.0], [0.0, 0.0, 1.1]];
        let dark = flat(2, 1, seen(CROSSTALK, grey, [0.0; 3], 0.01));
        let whites: Vec<LinearImage> = peaks
            .iter()
            .map(|p| flat(2, 1, seen(CROSSTALK, grey, *p, 0.01)))
            .collect();
        let unmix = Unmixing::new(&dark, &whites.iter().collect::<Vec<_>>()).expect("unmixing");
        for lit in 0..8u32 {
            let on: [f32; 3] = std::array::from_fn(|g| ((lit >> g) & 1) as f32);
            let light = std::array::from_fn(|c| (0..3).map(|g| on[g] * peaks[g][c]).sum());
            let capture = flat(2, 1, seen(CROSSTALK, grey, light, 0.01));
            let shares = unmix.reduce(&capture, &dark, "capture").expect("reduce");
            for g in 0..3 {
                let alone = on[g] * unmix.rise(g)[0];
                assert!(
                    (shares[g][0] - alone).abs() < 1e-5,
                    "lit {lit:03b}, group {g}: {} against {alone}",
                    shares[g][0]
                );
            }
        }
    }

    /// On a surface that reflects red alone, green's and blue's columns turn towards red's:
    /// those groups are not trusted there (they decode unknown, never from red's light); red's
    /// share stays within the disturbance the others' light can give it.
    #[test]
    fn a_saturated_surface_leaves_the_groups_it_hides_unknown() {
        let red_paint = [0.7, 0.02, 0.01];
        let peaks = [[0.8, 0.0, 0.0], [0.0, 0.6, 0.0], [0.0, 0.0, 1.1]];
        let dark = flat(1, 1, [0.0; 3]);
        let whites: Vec<LinearImage> = peaks
            .iter()
            .map(|p| flat(1, 1, seen(CROSSTALK, red_paint, *p, 0.0)))
            .collect();
        let unmix = Unmixing::new(&dark, &whites.iter().collect::<Vec<_>>()).expect("unmixing");
        assert!(unmix.rise(0)[0] > 0.0);
        assert_eq!(unmix.rise(1)[0].to_bits(), 0, "green is hidden");
        assert_eq!(unmix.rise(2)[0].to_bits(), 0, "blue is hidden");
        let capture = flat(1, 1, seen(CROSSTALK, red_paint, peaks[1], 0.0));
        let shares = unmix.reduce(&capture, &dark, "capture").expect("reduce");
        assert_eq!(shares[1][0].to_bits(), 0);
        assert_eq!(shares[2][0].to_bits(), 0);
        let moved = shares[0][0] / unmix.rise(0)[0];
        assert!(
            moved > 0.0 && moved <= MAX_DISTURBANCE,
            "green's light moves red's share by {moved}"
        );
    }

    /// A group whose primary does not reach a pixel stays out of its solve: the others there
    /// are told apart as a pair, and it reads nothing.
    #[test]
    fn a_group_absent_from_a_pixel_reads_nothing_there() {
        let grey = [0.5; 3];
        let dark = flat(2, 1, [0.0; 3]);
        let mut blue = flat(2, 1, seen(CROSSTALK, grey, [0.0, 0.0, 1.0], 0.0));
        blue.pixels[1] = [0.0; 3];
        let whites = [
            flat(2, 1, seen(CROSSTALK, grey, [1.0, 0.0, 0.0], 0.0)),
            flat(2, 1, seen(CROSSTALK, grey, [0.0, 1.0, 0.0], 0.0)),
            blue,
        ];
        let unmix = Unmixing::new(&dark, &whites.iter().collect::<Vec<_>>()).expect("unmixing");
        assert_eq!(unmix.rise(2)[1].to_bits(), 0);
        let capture = flat(2, 1, seen(CROSSTALK, grey, [1.0, 0.0, 0.0], 0.0));
        let shares = unmix.reduce(&capture, &dark, "capture").expect("reduce");
        assert!((shares[0][1] - unmix.rise(0)[1]).abs() < 1e-5);
        assert!(shares[1][1].abs() < 1e-5);
        assert_eq!(shares[2][1].to_bits(), 0);
    }

    /// Four groups, none, and captures of another size are refused; NaN in a capture reads as
    /// no light.
    #[test]
    fn bad_input_is_refused_or_contained() {
        let dark = flat(2, 2, [0.0; 3]);
        let white = flat(2, 2, [1.0; 3]);
        assert!(Unmixing::new(&dark, &[]).is_err());
        assert!(Unmixing::new(&dark, &[&white, &white, &white, &white]).is_err());
        assert!(Unmixing::new(&dark, &[&flat(3, 2, [1.0; 3])]).is_err());
        let unmix = Unmixing::new(&dark, &[&white]).expect("one group");
        assert!(unmix.reduce(&flat(1, 1, [0.0; 3]), &dark, "small").is_err());
        let mut broken = flat(2, 2, [0.5; 3]);
        broken.pixels[0] = [f32::NAN, 0.5, 0.5];
        let shares = unmix.reduce(&broken, &dark, "broken").expect("reduce");
        assert_eq!(shares[0][0].to_bits(), 0);
        assert!((shares[0][1] - 1.5).abs() < 1e-5);
    }
}
