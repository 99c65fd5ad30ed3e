//! Large aperture against a standard projector over the desk (DESIGN §5): a hand-sized box
//! between the projector and the desk, the direct irradiance measured across its shadow's edge
//! with and without the box, and the emitted radiance each needs for the same desk irradiance.

use anyhow::{Context, Result};
use roomlight_core::metrics::luminance;
use roomlight_sim::scene::{ObjectSpec, ProjectorKind, Scene, ShapeKind};
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
    let axis = spec.look_at_mm;
    let lens = spec.position_mm;
    // A hand-sized box 200 mm over the desk, 250 mm to the side of the axis (clear of the bust).
    let height = lens[2] - axis[2];
    let box_center = [axis[0] - 250.0, axis[1], axis[2] + 200.0];
    let box_size = [100.0, 180.0, 30.0];
    // Its shadow's near edge on the desk plane, by similar triangles from the lens centre.
    let scale = (lens[2] - axis[2]) / (lens[2] - box_center[2]);
    let edge_x = lens[0] + (box_center[0] + 0.5 * box_size[0] - lens[0]) * scale;
    let mut kinds = Vec::new();
    for kind in [ProjectorKind::LargeAperture, ProjectorKind::Standard] {
        let mut scene = base.clone();
        // Only the direct light is measured: a tiny camera keeps the build quick.
        scene.camera.resolution = [64, 48];
        if kind == ProjectorKind::Standard {
            let p = &mut scene.projectors[k];
            p.kind = ProjectorKind::Standard;
            p.aperture_mm = None;
            p.focus_mm = None;
            p.lens_samples = None;
        }
        let open = Room::build(scene.clone()).context("building the open desk")?;
        scene.objects.push(ObjectSpec {
            name: "occluder".into(),
            shape: ShapeKind::Box,
            center_mm: box_center,
            size_mm: Some(box_size),
            radius_mm: None,
            height_mm: None,
            yaw_deg: 0.0,
            albedo: [0.5, 0.5, 0.5],
            target: false,
        });
        let shaded = Room::build(scene).context("building the desk with the box")?;
        let white = Frame::Uniform([1.0, 1.0, 1.0]);
        let at = |room: &Room, x_mm: f64| -> Result<f64> {
            let p = [
                (x_mm / 1000.0) as f32,
                (axis[1] / 1000.0) as f32,
                (axis[2] / 1000.0) as f32,
            ];
            Ok(luminance(room.direct_irradiance_at(
                k,
                &white,
                p,
                [0.0, 0.0, 1.0],
            )?))
        };
        // Scan 160 mm either side of the geometric edge, every millimetre.
        let profile = (-160..=160)
            .map(|d| {
                let x = edge_x + f64::from(d);
                let lit = at(&open, x)?;
                // Unlit in the open room too: report 1 (nothing to shade).
                let ratio = if lit > 0.0 {
                    at(&shaded, x)? / lit
                } else {
                    1.0
                };
                Ok((f64::from(d), ratio))
            })
            .collect::<Result<Vec<_>>>()?;
        // Going outward from the shadow (decreasing x is inside the shadow): first 10% and
        // 90% crossings.
        let cross = |level: f64| {
            profile
                .iter()
                .rev()
                .find(|(_, r)| *r <= level)
                .map_or(f64::NAN, |(d, _)| *d)
        };
        let (lo, hi) = (cross(0.1), cross(0.9));
        let penumbra_mm = if lo.is_finite() && hi.is_finite() {
            (hi - lo).abs().max(1.0)
        } else {
            // The shadow never went below 10% (or never rose to 90%): the whole scan.
            320.0
        };
        // The open desk must be lit somewhere along the scan for the radiance to mean anything.
        let e_open = (-160..=160)
            .map(|d| at(&open, edge_x + f64::from(d)))
            .collect::<Result<Vec<_>>>()?
            .into_iter()
            .fold(0.0, f64::max);
        let pupil_mm = match kind {
            ProjectorKind::LargeAperture => spec.aperture_mm.unwrap_or(STANDARD_PUPIL_MM),
            ProjectorKind::Standard => STANDARD_PUPIL_MM,
        };
        // On the axis, E = L · A / d² for a small source: L per unit E is d²/A.
        let d = height / 1000.0;
        let area = std::f64::consts::PI * (pupil_mm / 2000.0).powi(2);
        let radiance_per_irradiance = if e_open > 0.0 { d * d / area } else { 0.0 };
        kinds.push(Shadow {
            kind: match kind {
                ProjectorKind::LargeAperture => "large_aperture".into(),
                ProjectorKind::Standard => "standard".into(),
            },
            penumbra_mm,
            profile,
            radiance_per_irradiance,
            pupil_mm,
        });
    }
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
