//! The large-aperture projector's target mask (DESIGN §5): a display pixel's light leaves the
//! whole lens and converges on its focus point, so a pixel must be off when its cone (lens disc
//! → focus point, and on beyond it) meets the target's volume, not only when it focuses on the
//! target. The ring this darkens around the target is handed to the texture projector.

use crate::CalibError;
use crate::graycode::Correspondence;
use crate::nodes::{Node, dilate};
use serde::{Deserialize, Serialize};

type V = [f64; 3];

fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn add(a: V, b: V) -> V {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn mul(a: V, k: f64) -> V {
    [a[0] * k, a[1] * k, a[2] * k]
}
fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V, b: V) -> V {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn unit(a: V) -> Option<V> {
    let n = dot(a, a).sqrt();
    (n > 0.0 && n.is_finite()).then(|| mul(a, 1.0 / n))
}

/// A large-aperture projector as mounted (from the room config), lengths in millimetres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ThinLens {
    /// Lens centre.
    pub position_mm: V,
    /// A point on the optical axis.
    pub look_at_mm: V,
    /// Image up direction.
    pub up: V,
    /// Horizontal field of view.
    pub fov_deg: f64,
    /// Display width and height in pixels.
    pub resolution: [u32; 2],
    /// Lens diameter.
    pub aperture_mm: f64,
    /// Focus distance along the axis.
    pub focus_mm: f64,
}

/// The target's bounding sphere.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sphere {
    /// Centre.
    pub center_mm: V,
    /// Radius.
    pub radius_mm: f64,
}

/// True when the segment `a → b` passes within `r` of `c`.
fn segment_hits(a: V, b: V, c: V, r: f64) -> bool {
    let ab = sub(b, a);
    let len2 = dot(ab, ab);
    // A zero-length segment is the point a.
    let t = if len2 > 0.0 {
        (dot(sub(c, a), ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let d = sub(add(a, mul(ab, t)), c);
    dot(d, d) <= r * r
}

/// Display pixels whose light cone meets the target sphere grown by `margin_mm`.
pub fn cone_mask(
    lens: &ThinLens,
    target: &Sphere,
    margin_mm: f64,
) -> Result<Vec<bool>, CalibError> {
    let bad = |problem: &str| CalibError::Invalid {
        field: "large-aperture projector",
        problem: problem.into(),
    };
    let forward = unit(sub(lens.look_at_mm, lens.position_mm))
        .ok_or_else(|| bad("look_at_mm equals position_mm"))?;
    let right =
        unit(cross(forward, lens.up)).ok_or_else(|| bad("up is parallel to the optical axis"))?;
    let down = cross(forward, right);
    let [w, h] = lens.resolution;
    let valid = w > 0
        && h > 0
        && lens.fov_deg > 0.0
        && lens.fov_deg < 180.0
        && lens.aperture_mm >= 0.0
        && lens.aperture_mm.is_finite()
        && lens.focus_mm > 0.0
        && lens.focus_mm.is_finite();
    if !valid {
        return Err(bad(
            "needs a resolution, a field of view in (0, 180), an aperture >= 0 and a focus distance > 0",
        ));
    }
    let focal_px = 0.5 * f64::from(w) / (0.5 * lens.fov_deg.to_radians()).tan();
    // Lens samples: the centre, and rings out to the rim (where the cone is widest).
    let mut samples = vec![lens.position_mm];
    for (ring, count) in [(0.5, 8), (1.0, 16)] {
        for k in 0..count {
            let a = std::f64::consts::TAU * f64::from(k) / f64::from(count);
            let r = 0.5 * lens.aperture_mm * ring;
            samples.push(add(
                lens.position_mm,
                add(mul(right, r * a.cos()), mul(down, r * a.sin())),
            ));
        }
    }
    let radius = target.radius_mm + margin_mm;
    Ok((0..w * h)
        .map(|i| {
            let (u, v) = (f64::from(i % w) + 0.5, f64::from(i / w) + 0.5);
            let ray = add(
                forward,
                add(
                    mul(right, (u - 0.5 * f64::from(w)) / focal_px),
                    mul(down, (v - 0.5 * f64::from(h)) / focal_px),
                ),
            );
            // The focus point of this pixel: on its chief ray, at the focus distance along the axis.
            let focus = add(
                lens.position_mm,
                mul(ray, lens.focus_mm / dot(ray, forward)),
            );
            // Each lens point's ray through the focus point, on to twice the distance.
            samples.iter().any(|&l| {
                segment_hits(l, add(l, mul(sub(focus, l), 2.0)), target.center_mm, radius)
            })
        })
        .collect())
}

/// The ring that the cone mask darkens around the target, as a node of the texture projector:
/// camera pixels that the large aperture lights through masked display pixels and that are not
/// on the target, mapped into the texture projector and dilated by `grow_px`.
pub fn ring_node(
    large: &Correspondence,
    mask: &[bool],
    target: &[bool],
    texture: &Correspondence,
    texture_index: usize,
    chart: usize,
    grow_px: u32,
) -> Result<Node, CalibError> {
    if mask.len() != (large.projector_width * large.projector_height) as usize
        || target.len() != large.map.len()
        || texture.map.len() != large.map.len()
    {
        return Err(CalibError::Invalid {
            field: "ring",
            problem: "cone mask, target mask and correspondences do not match in size".into(),
        });
    }
    let (tw, th) = (
        texture.projector_width as usize,
        texture.projector_height as usize,
    );
    let mut ring = vec![false; tw * th];
    let mut count = 0usize;
    for ((m, &on_target), t) in large.map.iter().zip(target).zip(&texture.map) {
        let Some((x, y)) = *m else { continue };
        if on_target || !mask[(y * large.projector_width + x) as usize] {
            continue;
        }
        if let Some((tx, ty)) = *t {
            ring[ty as usize * tw + tx as usize] = true;
            count += 1;
        }
    }
    if count == 0 {
        return Err(CalibError::Invalid {
            field: "ring",
            problem: "the texture projector sees none of the darkened ring".into(),
        });
    }
    let grown = dilate(&ring, tw, th, grow_px);
    let (mut sx, mut sy, mut n) = (0.0f32, 0.0f32, 0.0f32);
    for (p, &on) in grown.iter().enumerate() {
        if on {
            sx += (p % tw) as f32;
            sy += (p / tw) as f32;
            n += 1.0;
        }
    }
    Ok(Node {
        projector: texture_index,
        chart,
        anchor: (sx / n, sy / n),
        weights: grown.into_iter().map(|b| f32::from(u8::from(b))).collect(),
    })
}

/// Shapes the ring node so that one level fills the ring evenly: its weight at each texture
/// pixel is the light the cone mask removed there (`missing`, per camera pixel: a capture with
/// the large aperture unmasked minus one with it masked) over the texture projector's own light
/// there (`gain`, per camera pixel: texture at white minus black), scaled so the largest is 1.
/// Texture pixels of the ring that no camera pixel measures take the mean ratio.
pub fn shape_ring(
    node: &mut Node,
    texture: &Correspondence,
    missing: &[f32],
    gain: &[f32],
) -> Result<(), CalibError> {
    if missing.len() != texture.map.len() || gain.len() != texture.map.len() {
        return Err(CalibError::Invalid {
            field: "ring",
            problem: "measurements do not match the camera".into(),
        });
    }
    let tw = texture.projector_width as usize;
    let in_node = |m: &Option<(u32, u32)>| {
        m.map(|(x, y)| y as usize * tw + x as usize)
            .filter(|&p| node.weights.get(p).is_some_and(|w| *w > 0.0))
    };
    // Where the texture projector gives little light (under a tenth of its median over the
    // node: grazing surfaces, pixels lit only through inter-reflection) the ratio means nothing,
    // and one such outlier would set the scale of the whole node.
    let mut gains: Vec<f32> = texture
        .map
        .iter()
        .zip(gain)
        .filter(|(m, g)| in_node(m).is_some() && g.is_finite())
        .map(|(_, g)| *g)
        .collect();
    gains.sort_by(f32::total_cmp);
    let floor = gains
        .get(gains.len() / 2)
        .map_or(1e-6, |median| (0.1 * median).max(1e-6));
    let mut sum = vec![0.0f64; node.weights.len()];
    let mut count = vec![0u32; node.weights.len()];
    for (i, m) in texture.map.iter().enumerate() {
        if let Some(p) = in_node(m)
            && gain[i] > floor
            && missing[i].is_finite()
        {
            sum[p] += f64::from((missing[i] / gain[i]).max(0.0));
            count[p] += 1;
        }
    }
    let measured: Vec<f64> = sum
        .iter()
        .zip(&count)
        .filter(|(_, c)| **c > 0)
        .map(|(s, c)| s / f64::from(*c))
        .collect();
    if measured.is_empty() {
        return Err(CalibError::Invalid {
            field: "ring",
            problem: "no camera pixel measures the ring".into(),
        });
    }
    let mean = measured.iter().sum::<f64>() / measured.len() as f64;
    let ratio: Vec<f64> = (0..node.weights.len())
        .map(|p| {
            if node.weights[p] <= 0.0 {
                0.0
            } else if count[p] > 0 {
                sum[p] / f64::from(count[p])
            } else {
                mean
            }
        })
        .collect();
    let top = ratio.iter().copied().fold(0.0, f64::max);
    // All-zero ratios (nothing missing): the node stays as it is.
    if top > 0.0 {
        for (w, r) in node.weights.iter_mut().zip(&ratio) {
            *w = (r / top) as f32;
        }
    }
    Ok(())
}
