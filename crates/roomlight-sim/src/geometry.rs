//! Geometry: the room's surfaces as parametric faces (for albedo and radiosity elements) and as
//! parry3d colliders in a BVH (for ray casting and visibility).

use crate::scene::{ObjectSpec, RoomSpec, Scene, SceneError, ShapeKind};
use parry3d::bounding_volume::Aabb;
use parry3d::math::{Pose, Rot3, Vector};
use parry3d::partitioning::{Bvh, BvhBuildStrategy};
use parry3d::query::Ray;
use parry3d::shape::{Ball, Cuboid, Cylinder, Shape};
use roomlight_core::LinearRgb;
use std::f32::consts::{PI, TAU};

/// A 3-vector in metres (f32).
pub type V3 = Vector;

/// Millimetres in the file to metres.
pub(crate) fn mm(v: [f64; 3]) -> V3 {
    V3::new(
        (v[0] / 1000.0) as f32,
        (v[1] / 1000.0) as f32,
        (v[2] / 1000.0) as f32,
    )
}

/// A unit vector from a file direction.
pub(crate) fn dir(v: [f64; 3]) -> V3 {
    V3::new(v[0] as f32, v[1] as f32, v[2] as f32).normalize()
}

/// Offset used to leave a surface without hitting it again.
pub const EPS: f32 = 1e-4;

/// The shape of a face, parametrised over `(s, t) ∈ [0, 1]²`.
#[derive(Debug, Clone, Copy)]
pub enum FaceGeom {
    /// `origin + s·u + t·v`.
    Rect {
        origin: V3,
        u: V3,
        v: V3,
        normal: V3,
    },
    /// `s = φ/2π`, `t = θ/π` with θ from +z.
    Sphere { center: V3, radius: f32 },
    /// Side of an upright cylinder from its bottom centre: `s = φ/2π`, `t = z/height`.
    CylinderSide { base: V3, radius: f32, height: f32 },
    /// A disk: `s = φ/2π`, `t = (r/R)²` (equal-area rings).
    Disk {
        center: V3,
        normal: V3,
        e1: V3,
        e2: V3,
        radius: f32,
    },
}

impl FaceGeom {
    /// The point and outward normal at `(s, t)`.
    pub fn point(&self, s: f32, t: f32) -> (V3, V3) {
        match *self {
            Self::Rect {
                origin,
                u,
                v,
                normal,
            } => (origin + u * s + v * t, normal),
            Self::Sphere { center, radius } => {
                let (phi, theta) = (s * TAU, t * PI);
                let n = V3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                );
                (center + n * radius, n)
            }
            Self::CylinderSide {
                base,
                radius,
                height,
            } => {
                let phi = s * TAU;
                let n = V3::new(phi.cos(), phi.sin(), 0.0);
                (base + n * radius + V3::Z * (t * height), n)
            }
            Self::Disk {
                center,
                normal,
                e1,
                e2,
                radius,
            } => {
                let (phi, r) = (s * TAU, t.max(0.0).sqrt() * radius);
                (center + (e1 * phi.cos() + e2 * phi.sin()) * r, normal)
            }
        }
    }

    /// `(s, t)` of a point on (or near) the face, clamped into `[0, 1]²`.
    pub fn param(&self, p: V3) -> (f32, f32) {
        let (s, t) = match *self {
            Self::Rect { origin, u, v, .. } => {
                let d = p - origin;
                (d.dot(u) / u.length_squared(), d.dot(v) / v.length_squared())
            }
            Self::Sphere { center, .. } => {
                let n = (p - center).normalize_or_zero();
                (
                    n.y.atan2(n.x).rem_euclid(TAU) / TAU,
                    n.z.clamp(-1.0, 1.0).acos() / PI,
                )
            }
            Self::CylinderSide { base, height, .. } => {
                let d = p - base;
                (d.y.atan2(d.x).rem_euclid(TAU) / TAU, d.z / height)
            }
            Self::Disk {
                center,
                e1,
                e2,
                radius,
                ..
            } => {
                let d = p - center;
                let (x, y) = (d.dot(e1), d.dot(e2));
                (
                    y.atan2(x).rem_euclid(TAU) / TAU,
                    (x * x + y * y) / (radius * radius),
                )
            }
        };
        (s.clamp(0.0, 1.0), t.clamp(0.0, 1.0))
    }

    /// Area of the part `[s0, s1] × [t0, t1]`.
    pub fn area(&self, s0: f32, s1: f32, t0: f32, t1: f32) -> f32 {
        match *self {
            Self::Rect { u, v, .. } => u.cross(v).length() * (s1 - s0) * (t1 - t0),
            Self::Sphere { radius, .. } => {
                radius * radius * TAU * (s1 - s0) * ((t0 * PI).cos() - (t1 * PI).cos())
            }
            Self::CylinderSide { radius, height, .. } => {
                TAU * radius * height * (s1 - s0) * (t1 - t0)
            }
            Self::Disk { radius, .. } => PI * radius * radius * (s1 - s0) * (t1 - t0),
        }
    }

    /// Lengths along s and t, for choosing the element grid.
    fn extents(&self) -> (f32, f32) {
        match *self {
            Self::Rect { u, v, .. } => (u.length(), v.length()),
            Self::Sphere { radius, .. } => (TAU * radius, PI * radius),
            Self::CylinderSide { radius, height, .. } => (TAU * radius, height),
            Self::Disk { radius, .. } => (TAU * radius, radius),
        }
    }
}

/// A face of the room or of an object, with its radiosity element grid.
#[derive(Debug, Clone)]
pub struct Face {
    /// Its shape.
    pub geom: FaceGeom,
    /// Linear RGB albedo (charts override it where they lie).
    pub albedo: LinearRgb,
    /// Index of the object in the scene, or `None` for the room's walls.
    pub object: Option<usize>,
    /// True for faces of the projection-mapping target.
    pub target: bool,
    /// Elements along s and t.
    pub grid: (usize, usize),
    /// Index of this face's first element; elements run s-fastest.
    pub first_element: usize,
}

/// One radiosity element.
#[derive(Debug, Clone, Copy)]
pub struct Element {
    /// Centre.
    pub center: V3,
    /// Outward normal at the centre.
    pub normal: V3,
    /// Area in m².
    pub area: f32,
    /// The face it belongs to.
    pub face: usize,
    /// Albedo.
    pub albedo: LinearRgb,
}

#[derive(Debug, Clone)]
enum ColliderShape {
    Cuboid(Cuboid),
    Ball(Ball),
    Cylinder(Cylinder),
}

#[derive(Debug, Clone)]
struct Collider {
    shape: ColliderShape,
    pose: Pose,
    /// Faces this collider's surface belongs to.
    faces: Vec<usize>,
}

impl Collider {
    fn shape(&self) -> &dyn Shape {
        match &self.shape {
            ColliderShape::Cuboid(s) => s,
            ColliderShape::Ball(s) => s,
            ColliderShape::Cylinder(s) => s,
        }
    }
}

/// A ray hit.
#[derive(Debug, Clone, Copy)]
pub struct Hit {
    /// Distance along the (unit) ray.
    pub distance: f32,
    /// The point hit.
    pub point: V3,
    /// The surface normal, facing the ray's origin.
    pub normal: V3,
    /// The face hit.
    pub face: usize,
}

/// A chart placed on a surface: its frame in metres.
#[derive(Debug, Clone)]
pub struct ChartFrame {
    /// Centre.
    pub center: V3,
    /// Outward normal.
    pub normal: V3,
    /// Towards the patch columns' increasing index.
    pub right: V3,
    /// Towards the top row.
    pub up: V3,
    /// Width (6 columns).
    pub width: f32,
    /// Height (4 rows).
    pub height: f32,
}

/// Albedo of the black frame between patches.
pub const CHART_BORDER_ALBEDO: f64 = 0.03;

impl ChartFrame {
    /// Centre of patch `k` (0..24, row by row from the top left).
    pub fn patch_center(&self, k: usize) -> V3 {
        let (row, col) = ((k / 6) as f32, (k % 6) as f32);
        let x = -0.5 * self.width + (col + 0.5) * self.width / 6.0;
        let y = 0.5 * self.height - (row + 0.5) * self.height / 4.0;
        self.center + self.right * x + self.up * y
    }

    /// Side of a patch's square (80% of the pitch; the rest is black frame).
    pub fn patch_side(&self) -> f32 {
        0.8 * self.width / 6.0
    }

    /// The chart's albedo at `p` if `p` lies on it: `Some((patch, albedo))`, with patch `None`
    /// on the black frame.
    pub fn albedo_at(&self, p: V3) -> Option<(Option<usize>, LinearRgb)> {
        let d = p - self.center;
        if d.dot(self.normal).abs() > 0.01 {
            return None;
        }
        let (x, y) = (d.dot(self.right), d.dot(self.up));
        if x.abs() > 0.5 * self.width || y.abs() > 0.5 * self.height {
            return None;
        }
        let pitch = self.width / 6.0;
        let col = (((x + 0.5 * self.width) / pitch) as usize).min(5);
        let row = (((0.5 * self.height - y) / pitch) as usize).min(3);
        let k = row * 6 + col;
        let c = self.patch_center(k) - self.center;
        let half = 0.5 * self.patch_side();
        if (x - c.dot(self.right)).abs() <= half && (y - c.dot(self.up)).abs() <= half {
            Some((Some(k), roomlight_core::colorchecker::reflectance(k)))
        } else {
            Some((None, LinearRgb::splat(CHART_BORDER_ALBEDO)))
        }
    }
}

/// The room's geometry.
#[derive(Debug)]
pub struct Geometry {
    /// All faces.
    pub faces: Vec<Face>,
    /// All radiosity elements.
    pub elements: Vec<Element>,
    /// The charts.
    pub charts: Vec<ChartFrame>,
    colliders: Vec<Collider>,
    bvh: Bvh,
    /// Room size in metres.
    pub size: V3,
}

fn rgb(a: [f64; 3]) -> LinearRgb {
    LinearRgb(a)
}

/// The faces and colliders of a scene as they are added: a face's index is its place here,
/// and each collider names the faces it bounds.
#[derive(Default)]
struct Shapes {
    faces: Vec<Face>,
    colliders: Vec<Collider>,
}

impl Shapes {
    /// Adds a face (its element grid is made later) and returns its index.
    fn face(
        &mut self,
        geom: FaceGeom,
        albedo: LinearRgb,
        object: Option<usize>,
        target: bool,
    ) -> usize {
        self.faces.push(Face {
            geom,
            albedo,
            object,
            target,
            grid: (1, 1),
            first_element: 0,
        });
        self.faces.len() - 1
    }

    /// The room: six inward faces, and six slabs outside them for ray casting.
    fn room_box(&mut self, room: &RoomSpec, size: V3) {
        let (w, d, h) = (size.x, size.y, size.z);
        let walls = [
            (
                V3::new(0.0, 0.0, 0.0),
                V3::new(w, 0.0, 0.0),
                V3::new(0.0, d, 0.0),
                V3::Z,
                rgb(room.floor_albedo),
            ),
            (
                V3::new(0.0, 0.0, h),
                V3::new(0.0, d, 0.0),
                V3::new(w, 0.0, 0.0),
                -V3::Z,
                rgb(room.ceiling_albedo),
            ),
            (
                V3::new(0.0, 0.0, 0.0),
                V3::new(0.0, 0.0, h),
                V3::new(w, 0.0, 0.0),
                V3::Y,
                rgb(room.wall_albedo),
            ),
            (
                V3::new(0.0, d, 0.0),
                V3::new(w, 0.0, 0.0),
                V3::new(0.0, 0.0, h),
                -V3::Y,
                rgb(room.wall_albedo),
            ),
            (
                V3::new(0.0, 0.0, 0.0),
                V3::new(0.0, d, 0.0),
                V3::new(0.0, 0.0, h),
                V3::X,
                rgb(room.wall_albedo),
            ),
            (
                V3::new(w, 0.0, 0.0),
                V3::new(0.0, 0.0, h),
                V3::new(0.0, d, 0.0),
                -V3::X,
                rgb(room.wall_albedo),
            ),
        ];
        let slab = 0.05;
        for (origin, u, v, normal, albedo) in walls {
            let f = self.face(
                FaceGeom::Rect {
                    origin,
                    u,
                    v,
                    normal,
                },
                albedo,
                None,
                false,
            );
            let center = origin + (u + v) * 0.5 - normal * slab;
            let half = (u.abs() + v.abs()) * 0.5 + V3::splat(slab);
            self.colliders.push(Collider {
                shape: ColliderShape::Cuboid(Cuboid::new(half)),
                pose: Pose::from_translation(center),
                faces: vec![f],
            });
        }
    }

    /// A box, or a plane as a board 2 mm thick: six faces around one cuboid collider.
    fn cuboid(&mut self, o: &ObjectSpec, index: usize) {
        let c = mm(o.center_mm);
        let albedo = rgb(o.albedo);
        let obj = Some(index);
        let mut s = mm(o.size_mm.unwrap_or([0.0; 3]));
        // A plane is a board 2 mm thick.
        s = s.max(V3::splat(0.002));
        let yaw = (o.yaw_deg as f32).to_radians();
        let rot = Rot3::from_rotation_z(yaw);
        let axes = [rot * V3::X, rot * V3::Y, V3::Z];
        let half = [s.x * 0.5, s.y * 0.5, s.z * 0.5];
        let mut ids = Vec::new();
        for a in 0..3 {
            let (b, cc) = ((a + 1) % 3, (a + 2) % 3);
            for sign in [1.0f32, -1.0] {
                let normal = axes[a] * sign;
                // Keep u × v along the outward normal.
                let (u, v) = if sign > 0.0 {
                    (axes[b] * s[b], axes[cc] * s[cc])
                } else {
                    (axes[cc] * s[cc], axes[b] * s[b])
                };
                let origin = c + normal * half[a] - (u + v) * 0.5;
                ids.push(self.face(
                    FaceGeom::Rect {
                        origin,
                        u,
                        v,
                        normal,
                    },
                    albedo,
                    obj,
                    o.target,
                ));
            }
        }
        self.colliders.push(Collider {
            shape: ColliderShape::Cuboid(Cuboid::new(s * 0.5)),
            pose: Pose::from_parts(c, rot),
            faces: ids,
        });
    }

    /// A sphere: one face, one ball.
    fn sphere(&mut self, o: &ObjectSpec, index: usize) {
        let c = mm(o.center_mm);
        let albedo = rgb(o.albedo);
        let obj = Some(index);
        let r = (o.radius_mm.unwrap_or(0.0) / 1000.0) as f32;
        let f = self.face(
            FaceGeom::Sphere {
                center: c,
                radius: r,
            },
            albedo,
            obj,
            o.target,
        );
        self.colliders.push(Collider {
            shape: ColliderShape::Ball(Ball::new(r)),
            pose: Pose::from_translation(c),
            faces: vec![f],
        });
    }

    /// An upright cylinder: its side, top and bottom around one cylinder collider.
    fn cylinder(&mut self, o: &ObjectSpec, index: usize) {
        let c = mm(o.center_mm);
        let albedo = rgb(o.albedo);
        let obj = Some(index);
        let r = (o.radius_mm.unwrap_or(0.0) / 1000.0) as f32;
        let height = (o.height_mm.unwrap_or(0.0) / 1000.0) as f32;
        let base = c - V3::Z * (0.5 * height);
        let side = self.face(
            FaceGeom::CylinderSide {
                base,
                radius: r,
                height,
            },
            albedo,
            obj,
            o.target,
        );
        let top = self.face(
            FaceGeom::Disk {
                center: base + V3::Z * height,
                normal: V3::Z,
                e1: V3::X,
                e2: V3::Y,
                radius: r,
            },
            albedo,
            obj,
            o.target,
        );
        let bottom = self.face(
            FaceGeom::Disk {
                center: base,
                normal: -V3::Z,
                e1: V3::Y,
                e2: V3::X,
                radius: r,
            },
            albedo,
            obj,
            o.target,
        );
        self.colliders.push(Collider {
            shape: ColliderShape::Cylinder(Cylinder::new(0.5 * height, r)),
            pose: Pose::from_parts(c, Rot3::from_rotation_x(std::f32::consts::FRAC_PI_2)),
            faces: vec![side, top, bottom],
        });
    }
}

/// Cuts every face into elements of about `el` metres (curved faces at least six around) and
/// records each face's grid; returns the elements, face by face.
fn element_grids(faces: &mut [Face], el: f32) -> Vec<Element> {
    let mut elements = Vec::new();
    for (fi, face) in faces.iter_mut().enumerate() {
        let (ls, lt) = face.geom.extents();
        let min_s = match face.geom {
            FaceGeom::Rect { .. } => 1,
            _ => 6,
        };
        let ns = ((ls / el).ceil() as usize).clamp(min_s, 512);
        let nt = ((lt / el).ceil() as usize).clamp(1, 512);
        face.grid = (ns, nt);
        face.first_element = elements.len();
        for j in 0..nt {
            for i in 0..ns {
                let (s0, s1) = (i as f32 / ns as f32, (i + 1) as f32 / ns as f32);
                let (t0, t1) = (j as f32 / nt as f32, (j + 1) as f32 / nt as f32);
                let (center, normal) = face.geom.point(0.5 * (s0 + s1), 0.5 * (t0 + t1));
                elements.push(Element {
                    center,
                    normal,
                    area: face.geom.area(s0, s1, t0, t1),
                    face: fi,
                    albedo: face.albedo,
                });
            }
        }
    }
    elements
}

impl Geometry {
    /// Builds faces, elements and colliders from a scene (already field-validated).
    pub fn build(scene: &Scene) -> Result<Self, SceneError> {
        let size = mm(scene.room.size_mm);
        let mut shapes = Shapes::default();
        shapes.room_box(&scene.room, size);
        for (index, o) in scene.objects.iter().enumerate() {
            match o.shape {
                ShapeKind::Box | ShapeKind::Plane => shapes.cuboid(o, index),
                ShapeKind::Sphere => shapes.sphere(o, index),
                ShapeKind::Cylinder => shapes.cylinder(o, index),
            }
        }
        let Shapes {
            mut faces,
            colliders,
        } = shapes;
        let elements = element_grids(&mut faces, (scene.room.element_mm / 1000.0) as f32);
        let aabbs: Vec<Aabb> = colliders
            .iter()
            .map(|c| c.shape().compute_aabb(&c.pose))
            .collect();
        let bvh = Bvh::from_leaves(BvhBuildStrategy::default(), &aabbs);
        let mut geometry = Self {
            faces,
            elements,
            charts: Vec::new(),
            colliders,
            bvh,
            size,
        };
        geometry.place_charts(scene)?;
        geometry.check_inside(scene)?;
        Ok(geometry)
    }

    fn place_charts(&mut self, scene: &Scene) -> Result<(), SceneError> {
        for c in &scene.charts {
            let normal = dir(c.normal);
            let up = dir(c.up);
            let center = mm(c.center_mm);
            // The chart must lie on a surface facing along its normal.
            let probe = Ray::new(center + normal * 0.02, -normal);
            let on_surface = self
                .cast(&probe, 0.05)
                .is_some_and(|h| (h.distance - 0.02).abs() < 0.01 && h.normal.dot(normal) > 0.99);
            if !on_surface {
                return Err(scene.invalid(format!("chart {}", c.name), "center_mm", format!("{:?} with normal {:?} does not lie on any surface (within 10 mm, facing the same way)", c.center_mm, c.normal)));
            }
            let width = (c.width_mm / 1000.0) as f32;
            self.charts.push(ChartFrame {
                center,
                normal,
                right: up.cross(normal),
                up,
                width,
                height: width * 2.0 / 3.0,
            });
        }
        Ok(())
    }

    /// Projectors, lights and the camera must be inside the room and outside every object.
    fn check_inside(&self, scene: &Scene) -> Result<(), SceneError> {
        let mut points: Vec<(String, V3)> = Vec::new();
        for p in &scene.projectors {
            points.push((format!("projector {}", p.name), mm(p.position_mm)));
        }
        for l in &scene.lights {
            points.push((
                format!("light {}", l.name),
                mm(l.center_mm) + dir(l.normal) * 0.005,
            ));
        }
        points.push(("camera".into(), mm(scene.camera.position_mm)));
        for (name, p) in points {
            let inside_room = p.x > 0.0
                && p.y > 0.0
                && p.z > 0.0
                && p.x < self.size.x
                && p.y < self.size.y
                && p.z < self.size.z;
            if !inside_room {
                return Err(scene.invalid(
                    name,
                    "position",
                    format!(
                        "({:.3}, {:.3}, {:.3}) m is not inside the room's walls",
                        p.x, p.y, p.z
                    ),
                ));
            }
            for c in self.colliders.iter().skip(6) {
                if c.shape().contains_point(&c.pose, p) {
                    let object = self.faces[c.faces[0]]
                        .object
                        .map_or("a wall".to_string(), |o| scene.objects[o].name.clone());
                    return Err(scene.invalid(
                        name,
                        "position",
                        format!(
                            "({:.3}, {:.3}, {:.3}) m is inside object {object}",
                            p.x, p.y, p.z
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The first surface along a ray (its direction must be unit length) within `max`.
    pub fn cast(&self, ray: &Ray, max: f32) -> Option<Hit> {
        let (leaf, _) = self.bvh.cast_ray(ray, max, |leaf, best| {
            let c = &self.colliders[leaf as usize];
            c.shape().cast_ray(&c.pose, ray, best, true)
        })?;
        let c = &self.colliders[leaf as usize];
        let hit = c.shape().cast_ray_and_get_normal(&c.pose, ray, max, true)?;
        let point = ray.point_at(hit.time_of_impact);
        let mut normal = hit.normal.normalize_or_zero();
        if normal.dot(ray.dir) > 0.0 {
            normal = -normal;
        }
        // Pick the face of this collider whose normal agrees best.
        let face = c
            .faces
            .iter()
            .copied()
            .max_by(|&a, &b| {
                let score = |f: usize| self.face_score(f, point, normal);
                score(a).total_cmp(&score(b))
            })
            .unwrap_or(c.faces[0]);
        Some(Hit {
            distance: hit.time_of_impact,
            point,
            normal,
            face,
        })
    }

    fn face_score(&self, f: usize, p: V3, n: V3) -> f32 {
        match self.faces[f].geom {
            FaceGeom::Rect { normal, .. } | FaceGeom::Disk { normal, .. } => normal.dot(n),
            FaceGeom::Sphere { .. } => 1.0,
            FaceGeom::CylinderSide { .. } => {
                let (_, normal) = self.faces[f].geom.point(self.faces[f].geom.param(p).0, 0.5);
                normal.dot(n)
            }
        }
    }

    /// True when nothing blocks the segment from `a` to `b`.
    pub fn visible(&self, a: V3, b: V3) -> bool {
        let d = b - a;
        let len = d.length();
        if len <= 2.0 * EPS {
            return true;
        }
        let dirn = d / len;
        let ray = Ray::new(a + dirn * EPS, dirn);
        self.cast(&ray, len - 2.0 * EPS).is_none()
    }

    /// Albedo at a surface point: a chart's patch or frame where a chart lies, else the face's.
    pub fn albedo_at(&self, face: usize, p: V3) -> (Option<(usize, Option<usize>)>, LinearRgb) {
        for (ci, chart) in self.charts.iter().enumerate() {
            if let Some((patch, albedo)) = chart.albedo_at(p) {
                return (Some((ci, patch)), albedo);
            }
        }
        (None, self.faces[face].albedo)
    }

    /// Bilinear weights of the (up to four) element centres around a point of a face.
    pub fn element_weights(&self, face: usize, p: V3) -> [(u32, f32); 4] {
        let f = &self.faces[face];
        let (s, t) = f.geom.param(p);
        let (ns, nt) = f.grid;
        let x = (s * ns as f32 - 0.5).clamp(0.0, (ns - 1) as f32);
        let y = (t * nt as f32 - 0.5).clamp(0.0, (nt - 1) as f32);
        let (i0, j0) = (x.floor() as usize, y.floor() as usize);
        let (i1, j1) = ((i0 + 1).min(ns - 1), (j0 + 1).min(nt - 1));
        let (fx, fy) = (x - i0 as f32, y - j0 as f32);
        let id = |i: usize, j: usize| (f.first_element + j * ns + i) as u32;
        [
            (id(i0, j0), (1.0 - fx) * (1.0 - fy)),
            (id(i1, j0), fx * (1.0 - fy)),
            (id(i0, j1), (1.0 - fx) * fy),
            (id(i1, j1), fx * fy),
        ]
    }
}
