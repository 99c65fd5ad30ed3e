//! Where the room's irradiance probes sit (camera pixels, radiosity elements, chart patches)
//! and the light transport from every projector and LED panel to them, computed once when the
//! room is built. It must not know frames or captures: rendering reads the maps made here.

use super::{PATCH_SAMPLES, PixelInfo, Probes, ProjectorMap, Room, Sample};
use crate::geometry::{EPS, Geometry};
use crate::optics::{Fisheye, Light, Pinhole, Projector};
use parry3d::query::Ray;
use rayon::prelude::*;
use roomlight_core::LinearRgb;

/// A set of probes before their transport is computed: per probe its albedo and bilinear
/// weights into the elements (for indirect light), and the surface samples that make it up.
pub(super) struct ProbeSet {
    pub(super) samples: Vec<Sample>,
    pub(super) albedo: Vec<LinearRgb>,
    pub(super) interp: Vec<[(u32, f32); 4]>,
}

/// One ray per camera pixel: what each pixel sees, and a probe per pixel.
pub(super) fn camera_view(camera: &Fisheye, geometry: &Geometry) -> (Vec<PixelInfo>, ProbeSet) {
    let (w, h) = (camera.width, camera.height);
    // The rays over the cores, in pixel order.
    let seen: Vec<_> = (0..w * h)
        .into_par_iter()
        .with_min_len(1024)
        .map(|index| {
            let (u, v) = (index % w, index / w);
            camera
                .ray(u as f32 + 0.5, v as f32 + 0.5)
                .and_then(|d| geometry.cast(&Ray::new(camera.position, d), 100.0))
                .map(|hit| {
                    let (chart, albedo) = geometry.albedo_at(hit.face, hit.point);
                    let interp = geometry.element_weights(hit.face, hit.point);
                    (hit, chart, albedo, interp)
                })
        })
        .collect();
    let mut pixels = Vec::with_capacity((w * h) as usize);
    let mut camera_samples: Vec<Sample> = Vec::new();
    let mut camera_albedo = Vec::with_capacity((w * h) as usize);
    let mut camera_interp = Vec::with_capacity((w * h) as usize);
    for (index, seen) in seen.into_iter().enumerate() {
        match seen {
            Some((hit, chart, albedo, interp)) => {
                pixels.push(PixelInfo {
                    point: Some(hit.point.to_array()),
                    face: Some(hit.face),
                    target: geometry.faces[hit.face].target,
                    chart,
                });
                camera_albedo.push(albedo);
                camera_interp.push(interp);
                camera_samples.push((index as u32, hit.point, hit.normal, 1.0, None));
            }
            None => {
                pixels.push(PixelInfo {
                    point: None,
                    face: None,
                    target: false,
                    chart: None,
                });
                camera_albedo.push(LinearRgb::ZERO);
                camera_interp.push([(0, 0.0); 4]);
            }
        }
    }
    let probes = ProbeSet {
        samples: camera_samples,
        albedo: camera_albedo,
        interp: camera_interp,
    };
    (pixels, probes)
}

/// Every radiosity element as 3×3 samples, each integrating the frame over its cell (no
/// indirect light of its own: radiosity computes that).
pub(super) fn element_samples(geometry: &Geometry) -> ProbeSet {
    let mut samples = Vec::new();
    for (e, el) in geometry.elements.iter().enumerate() {
        let face = &geometry.faces[el.face];
        let (ns, nt) = face.grid;
        let (i, j) = ((e - face.first_element) % ns, (e - face.first_element) / ns);
        for b in 0..3 {
            for a in 0..3 {
                let s = (i as f32 + (a as f32 + 0.5) / 3.0) / ns as f32;
                let t = (j as f32 + (b as f32 + 0.5) / 3.0) / nt as f32;
                let (p, n) = face.geom.point(s, t);
                let (ds, dt) = (0.5 / (3.0 * ns as f32), 0.5 / (3.0 * nt as f32));
                let cell = [(-ds, -dt), (ds, -dt), (ds, dt), (-ds, dt)]
                    .map(|(a, b)| face.geom.point(s + a, t + b).0);
                samples.push((e as u32, p, n, 1.0 / 9.0, Some(cell)));
            }
        }
    }
    let albedo: Vec<LinearRgb> = geometry.elements.iter().map(|e| e.albedo).collect();
    let interp = vec![[(0, 0.0); 4]; albedo.len()];
    ProbeSet {
        samples,
        albedo,
        interp,
    }
}

/// The chart patches: 4×4 samples over the inner half of each patch, with the patch's
/// reflectance and the element weights for indirect light.
pub(super) fn patch_samples(geometry: &Geometry) -> ProbeSet {
    let mut samples = Vec::new();
    let mut albedo = Vec::new();
    let mut interp = Vec::new();
    for (m, chart) in geometry.charts.iter().enumerate() {
        for k in 0..24 {
            let center = chart.patch_center(k);
            let face = geometry
                .cast(&Ray::new(center + chart.normal * 0.02, -chart.normal), 0.05)
                .map_or(0, |h| h.face);
            let half = 0.25 * chart.patch_side();
            // A 4×4 grid of cell centres over the inner half of the patch (the area a
            // camera's sample box averages), one probe each.
            for b in [-0.75f32, -0.25, 0.25, 0.75] {
                for a in [-0.75f32, -0.25, 0.25, 0.75] {
                    let id = ((m * 24 + k) * PATCH_SAMPLES + samples.len() % PATCH_SAMPLES) as u32;
                    let p = center + chart.right * (a * half) + chart.up * (b * half);
                    albedo.push(roomlight_core::colorchecker::reflectance(k));
                    interp.push(geometry.element_weights(face, p));
                    samples.push((id, p, chart.normal, 1.0, None));
                }
            }
        }
    }
    ProbeSet {
        samples,
        albedo,
        interp,
    }
}

impl Room {
    /// Transport from every projector and light to a set of probes.
    pub(super) fn probes(&self, set: ProbeSet) -> Probes {
        let ProbeSet {
            samples,
            albedo,
            interp,
        } = set;
        let samples = samples.as_slice();
        let count = albedo.len();
        // Each projector's and light's transport on its own core (independent, same result).
        let projectors = self
            .projectors
            .par_iter()
            .map(|projector| self.projector_map(projector, count, samples))
            .collect();
        let lights = self
            .lights
            .par_iter()
            .map(|light| self.light_factors(light, count, samples))
            .collect();
        Probes {
            albedo,
            interp,
            projectors,
            lights,
        }
    }

    /// One projector's light at `count` probes: per pixel for point samples, per pixel box
    /// for samples standing for a cell of surface.
    fn projector_map(
        &self,
        projector: &Projector,
        count: usize,
        samples: &[Sample],
    ) -> ProjectorMap {
        let mut map = ProjectorMap {
            entries: Vec::new(),
            boxes: Vec::new(),
            white: vec![0.0; count],
        };
        let pin = &projector.pinhole;
        for &(probe, p, n, weight, cell) in samples {
            let lifted = p + n * EPS;
            let half = cell.and_then(|corners| cell_half_extent(pin, p, corners));
            projector.footprint(p, n, |lens, px, factor| {
                if !self.geometry.visible(lens, lifted) {
                    return;
                }
                map.white[probe as usize] += factor * weight;
                match half {
                    Some(half) => {
                        map.boxes
                            .push((probe, pixel_box(pin, px, half), factor * weight))
                    }
                    None => map.entries.push((probe, px, factor * weight)),
                }
            });
        }
        map
    }

    /// One light's geometric factor at `count` probes, visibility included.
    fn light_factors(&self, light: &Light, count: usize, samples: &[Sample]) -> Vec<f32> {
        let mut factor = vec![0.0f32; count];
        for &(probe, p, n, weight, _) in samples {
            let lifted = p + n * EPS;
            let mut sum = 0.0;
            light.samples_to(p, n, |q, f| {
                if self.geometry.visible(q + light.normal * EPS, lifted) {
                    sum += f;
                }
            });
            factor[probe as usize] += sum * weight;
        }
        factor
    }
}

/// Half the extent, in projector pixels, of a cell's image around its sample's (`None` when a
/// corner or the sample is behind the projector).
fn cell_half_extent(
    pin: &Pinhole,
    p: crate::geometry::V3,
    corners: [crate::geometry::V3; 4],
) -> Option<(f32, f32)> {
    let (u, v) = pin.project(p)?;
    let (mut hx, mut hy) = (0.0f32, 0.0f32);
    for c in corners {
        let (cu, cv) = pin.project(c)?;
        (hx, hy) = (hx.max((cu - u).abs()), hy.max((cv - v).abs()));
    }
    Some((hx, hy))
}

/// The half-open box of pixels `half` around pixel `px`, clipped to the image, and at least
/// the pixel itself.
fn pixel_box(pin: &Pinhole, px: u32, (hx, hy): (f32, f32)) -> [u32; 4] {
    let (x, y) = ((px % pin.width) as f32 + 0.5, (px / pin.width) as f32 + 0.5);
    let clip = |v: f32, max: u32| (v.round().max(0.0) as u32).min(max);
    let b = [
        clip(x - hx, pin.width),
        clip(y - hy, pin.height),
        clip(x + hx, pin.width),
        clip(y + hy, pin.height),
    ];
    if b[2] <= b[0] || b[3] <= b[1] {
        [
            px % pin.width,
            px / pin.width,
            px % pin.width + 1,
            px / pin.width + 1,
        ]
    } else {
        b
    }
}
