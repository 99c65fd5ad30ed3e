//! Large aperture against a standard projector over the desk (DESIGN §5): a hand-sized box
//! between the projector and the desk, the direct irradiance measured across its shadow's edge
//! with and without the box, and the emitted radiance each needs for the same desk irradiance.

use anyhow::{Context, Result};
use roomlight_core::metrics::luminance;
use roomlight_sim::scene::{ObjectSpec, ProjectorKind, ProjectorSpec, Scene, ShapeKind};
use roomlight_sim::{Frame, Room};

/// Exit pupil assumed for a standard projector (the simulator models it as a pinhole): a
/// typical projection lens' clear aperture.
pub const STANDARD_PUPIL_MM: f64 = 25.0;

/// One projector kind's shadow.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Shadow {
    /// "large_aperture" or "standard".
    pub kind: String,
    /// Width of the shadow's edge, 10% to 90% of the unoccluded irradiance, in mm.
    pub penumbra_mm: f64,
    /// Irradiance ratio (occluded / unoccluded) along the scan, every millimetre.
    pub profile: Vec<(f64, f64)>,
    /// Emitted radiance (per unit desk irradiance at the axis point) through the exit pupil.
    pub radiance_per_irradiance: f64,
    /// Exit pupil diameter used, mm.
    pub pupil_mm: f64,
}

/// Both kinds and the ratio of their peak radiances (standard / large aperture).
#[derive(Debug, Clone, serde::Serialize)]
pub struct ShadowComparison {
    /// The large aperture, then the standard projector at the same place.
    pub kinds: Vec<Shadow>,
    /// Peak emitted radiance of the standard projector over the large aperture's, for equal
    /// desk irradiance.
    pub peak_radiance_ratio: f64,
}

/// Runs the comparison for the first large-aperture projector of `base`.
pub fn run(base: &Scene) -> Result<ShadowComparison> {
    let (k, spec) = base
        .projectors
        .iter()
        .enumerate()
        .find(|(_, p)| p.kind == ProjectorKind::LargeAperture)
        .with_context(|| format!("scene {} has no large-aperture projector", base.name))?;
    let setup = Setup::new(k, spec);
    let kinds = [ProjectorKind::LargeAperture, ProjectorKind::Standard]
        .into_iter()
        .map(|kind| setup.measure(base, spec, kind))
        .collect::<Result<Vec<_>>>()?;
    let peak_radiance_ratio = match kinds.as_slice() {
        [large, standard] if large.radiance_per_irradiance > 0.0 => {
            standard.radiance_per_irradiance / large.radiance_per_irradiance
        }
        _ => 0.0,
    };
    Ok(ShadowComparison {
        kinds,
        peak_radiance_ratio,
    })
}

/// Where the projector, the desk, the box and its shadow's edge are (millimetres).
struct Setup {
    /// The projector's index in the scene.
    k: usize,
    /// Where its axis meets the desk.
    axis: [f64; 3],
    box_center: [f64; 3],
    box_size: [f64; 3],
    /// The lens's height over the desk.
    height: f64,
    /// The shadow's near edge on the desk, along x.
    edge_x: f64,
}

impl Setup {
    fn new(k: usize, spec: &ProjectorSpec) -> Self {
        let axis = spec.look_at_mm;
        let lens = spec.position_mm;
        // A hand-sized box 200 mm over the desk, 250 mm to the side of the axis (clear of the
        // bust).
        let box_center = [axis[0] - 250.0, axis[1], axis[2] + 200.0];
        let box_size = [100.0, 180.0, 30.0];
        // Its shadow's near edge on the desk plane, by similar triangles from the lens centre.
        let scale = (lens[2] - axis[2]) / (lens[2] - box_center[2]);
        Self {
            k,
            axis,
            box_center,
            box_size,
            height: lens[2] - axis[2],
            edge_x: lens[0] + (box_center[0] + 0.5 * box_size[0] - lens[0]) * scale,
        }
    }

    /// The open desk and the desk with the box, lit by the projector as `kind`.
    fn rooms(&self, base: &Scene, kind: ProjectorKind) -> Result<(Room, Room)> {
        let mut scene = base.clone();
        // Only the direct light is measured: a tiny camera keeps the build quick.
        scene.camera.resolution = [64, 48];
        if kind == ProjectorKind::Standard {
            let p = &mut scene.projectors[self.k];
            p.kind = ProjectorKind::Standard;
            p.aperture_mm = None;
            p.focus_mm = None;
            p.lens_samples = None;
        }
        let open = Room::build(scene.clone()).context("building the open desk")?;
        scene.objects.push(ObjectSpec {
            name: "occluder".into(),
            shape: ShapeKind::Box,
            center_mm: self.box_center,
            size_mm: Some(self.box_size),
            radius_mm: None,
            height_mm: None,
            yaw_deg: 0.0,
            albedo: [0.5, 0.5, 0.5],
            target: false,
        });
        let shaded = Room::build(scene).context("building the desk with the box")?;
        Ok((open, shaded))
    }

    /// The luminance of the projector's direct light at white on the desk at `x_mm`.
    fn at(&self, room: &Room, x_mm: f64) -> Result<f64> {
        let p = [
            (x_mm / 1000.0) as f32,
            (self.axis[1] / 1000.0) as f32,
            (self.axis[2] / 1000.0) as f32,
        ];
        let white = Frame::Uniform([1.0, 1.0, 1.0]);
        Ok(luminance(room.direct_irradiance_at(
            self.k,
            &white,
            p,
            [0.0, 0.0, 1.0],
        )?))
    }

    /// The penumbra, the profile and the radiance per irradiance of the projector as `kind`.
    fn measure(&self, base: &Scene, spec: &ProjectorSpec, kind: ProjectorKind) -> Result<Shadow> {
        let (open, shaded) = self.rooms(base, kind)?;
        let edge_x = self.edge_x;
        // Scan 160 mm either side of the geometric edge, every millimetre.
        let profile = (-160..=160)
            .map(|d| {
                let x = edge_x + f64::from(d);
                let lit = self.at(&open, x)?;
                // Unlit in the open room too: report 1 (nothing to shade).
                let ratio = if lit > 0.0 {
                    self.at(&shaded, x)? / lit
                } else {
                    1.0
                };
                Ok((f64::from(d), ratio))
            })
            .collect::<Result<Vec<_>>>()?;
        // The open desk must be lit somewhere along the scan for the radiance to mean anything.
        let e_open = (-160..=160)
            .map(|d| self.at(&open, edge_x + f64::from(d)))
            .collect::<Result<Vec<_>>>()?
            .into_iter()
            .fold(0.0, f64::max);
        let pupil_mm = match kind {
            ProjectorKind::LargeAperture => spec.aperture_mm.unwrap_or(STANDARD_PUPIL_MM),
            ProjectorKind::Standard => STANDARD_PUPIL_MM,
        };
        // On the axis, E = L · A / d² for a small source: L per unit E is d²/A.
        let d = self.height / 1000.0;
        let area = std::f64::consts::PI * (pupil_mm / 2000.0).powi(2);
        let radiance_per_irradiance = if e_open > 0.0 { d * d / area } else { 0.0 };
        Ok(Shadow {
            kind: match kind {
                ProjectorKind::LargeAperture => "large_aperture".into(),
                ProjectorKind::Standard => "standard".into(),
            },
            penumbra_mm: penumbra(&profile),
            profile,
            radiance_per_irradiance,
            pupil_mm,
        })
    }
}

/// The width of the penumbra in a profile: going outward from the shadow (decreasing x is
/// inside the shadow), from the first 10% crossing to the first 90% one; the whole scan
/// (320 mm) when the shadow never went below 10% or never rose to 90%.
fn penumbra(profile: &[(f64, f64)]) -> f64 {
    let cross = |level: f64| {
        profile
            .iter()
            .rev()
            .find(|(_, r)| *r <= level)
            .map_or(f64::NAN, |(d, _)| *d)
    };
    let (lo, hi) = (cross(0.1), cross(0.9));
    if lo.is_finite() && hi.is_finite() {
        (hi - lo).abs().max(1.0)
    } else {
        320.0
    }
}
