//! The scene file (TOML): room, objects, charts, projectors, LED lights and presets, camera.
//! Lengths are in millimetres in the file and metres inside the simulator. Every field is
//! checked; an error names the element and the field and says what was expected.

use serde::{Deserialize, Serialize};

/// A whole scene as written in its TOML file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// The room's name (also its mDNS name later).
    pub name: String,
    /// The room's box and its surfaces.
    pub room: RoomSpec,
    /// Furniture, the PM target, boards.
    #[serde(default, rename = "object")]
    pub objects: Vec<ObjectSpec>,
    /// Colour charts (24-patch ColorChecker layout).
    #[serde(default, rename = "chart")]
    pub charts: Vec<ChartSpec>,
    /// Projectors.
    #[serde(default, rename = "projector")]
    pub projectors: Vec<ProjectorSpec>,
    /// LED area lights.
    #[serde(default, rename = "light")]
    pub lights: Vec<LightSpec>,
    /// Named sets of lights that are on together.
    #[serde(default, rename = "preset")]
    pub presets: Vec<PresetSpec>,
    /// The fisheye camera.
    pub camera: CameraSpec,
}

/// The room: an axis-aligned box from (0,0,0) to `size_mm`, z up, floor at z = 0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoomSpec {
    /// Width (x), depth (y), height (z).
    pub size_mm: [f64; 3],
    /// Linear RGB albedo of the four walls.
    pub wall_albedo: [f64; 3],
    /// Linear RGB albedo of the floor.
    pub floor_albedo: [f64; 3],
    /// Linear RGB albedo of the ceiling.
    pub ceiling_albedo: [f64; 3],
    /// Edge length of the radiosity elements.
    pub element_mm: f64,
    /// Inter-reflection on (default) or off (direct light only).
    #[serde(default = "yes")]
    pub interreflection: bool,
}

fn yes() -> bool {
    true
}

/// The kinds of object.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShapeKind {
    /// A box of `size_mm`, turned by `yaw_deg` about z.
    Box,
    /// A rectangle: `size_mm` with exactly one zero component, the normal's axis.
    Plane,
    /// A sphere of `radius_mm`.
    Sphere,
    /// An upright cylinder of `radius_mm` and `height_mm`.
    Cylinder,
}

/// One object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    /// Unique name.
    pub name: String,
    /// Its shape.
    pub shape: ShapeKind,
    /// Centre.
    pub center_mm: [f64; 3],
    /// Box and plane extents.
    #[serde(default)]
    pub size_mm: Option<[f64; 3]>,
    /// Sphere and cylinder radius.
    #[serde(default)]
    pub radius_mm: Option<f64>,
    /// Cylinder height.
    #[serde(default)]
    pub height_mm: Option<f64>,
    /// Rotation about the vertical axis (boxes and planes).
    #[serde(default)]
    pub yaw_deg: f64,
    /// Linear RGB albedo in [0, 1].
    pub albedo: [f64; 3],
    /// True for the projection-mapping target (the bust).
    #[serde(default)]
    pub target: bool,
}

/// A 24-patch chart lying on a surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChartSpec {
    /// Unique name.
    pub name: String,
    /// Centre, on a surface.
    pub center_mm: [f64; 3],
    /// Outward normal of the surface it lies on.
    pub normal: [f64; 3],
    /// The chart's "up" direction (top row of patches), perpendicular to the normal.
    pub up: [f64; 3],
    /// Width (6 patch columns); the height is two thirds of it (4 rows).
    pub width_mm: f64,
}

/// Standard (pinhole) or large-aperture (LCD behind a Fresnel lens) projector.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProjectorKind {
    /// A pinhole projector.
    Standard,
    /// A display behind a thin lens of large aperture.
    LargeAperture,
}

/// What a projector is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProjectorRole {
    /// Lights the room.
    Luminaire,
    /// Projects onto the target.
    Texture,
}

/// One projector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProjectorSpec {
    /// Unique name.
    pub name: String,
    /// Standard or large aperture.
    pub kind: ProjectorKind,
    /// Luminaire or texture.
    pub role: ProjectorRole,
    /// Lens centre.
    pub position_mm: [f64; 3],
    /// A point on the optical axis.
    pub look_at_mm: [f64; 3],
    /// Up direction of the image (default +z).
    #[serde(default = "z_up")]
    pub up: [f64; 3],
    /// Horizontal field of view.
    pub fov_deg: f64,
    /// Width and height in pixels.
    pub resolution: [u32; 2],
    /// Light at code 0 as a share of full white (native black level).
    #[serde(default)]
    pub black_level: f64,
    /// Irradiance per channel on a surface facing the lens 1 m away along the axis, at white.
    pub peak: [f64; 3],
    /// Per-channel response exponent: light ∝ code^gamma. The system must measure it.
    #[serde(default = "unit_gamma")]
    pub gamma: [f64; 3],
    /// Optional 3×3 primaries mixing (rows: output channel, columns: input channel).
    #[serde(default)]
    pub mixing: Option<[[f64; 3]; 3]>,
    /// Large aperture: lens diameter.
    #[serde(default)]
    pub aperture_mm: Option<f64>,
    /// Large aperture: distance along the axis at which the display is in focus.
    #[serde(default)]
    pub focus_mm: Option<f64>,
    /// Large aperture: lens samples per point (accuracy against speed).
    #[serde(default)]
    pub lens_samples: Option<u32>,
}

fn z_up() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

fn unit_gamma() -> [f64; 3] {
    [1.0; 3]
}

/// A rectangular LED panel emitting on its front side.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightSpec {
    /// Unique name.
    pub name: String,
    /// Centre.
    pub center_mm: [f64; 3],
    /// Direction it emits towards.
    pub normal: [f64; 3],
    /// Width and height.
    pub size_mm: [f64; 2],
    /// Colour temperature in kelvin (1667 to 25000).
    pub cct_k: f64,
    /// Luminance scale: irradiance on a facing surface 1 m below a 1 m² panel is about this.
    pub intensity: f64,
}

/// A set of lights on together, optionally at another colour temperature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PresetSpec {
    /// Unique name.
    pub name: String,
    /// Names of the lights that are on.
    pub lights: Vec<String>,
    /// Overrides every listed light's colour temperature.
    #[serde(default)]
    pub cct_k: Option<f64>,
    /// Scales every listed light's intensity (finite, > 0; 1 when left out): a dimmer.
    #[serde(default = "unit_intensity")]
    pub intensity: f64,
    /// Weight of the light on the projection-mapping target in the luminaires' objective under
    /// this preset (issue 22: each target patch's squared light against a chart patch's 1;
    /// finite, >= 0; 0 when left out: the charts alone).
    #[serde(default)]
    pub dark_weight: f64,
}

fn unit_intensity() -> f64 {
    1.0
}

/// A fisheye camera with the equidistant model `r = f θ`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Centre of projection.
    pub position_mm: [f64; 3],
    /// A point on the optical axis.
    pub look_at_mm: [f64; 3],
    /// Up direction of the image.
    #[serde(default = "z_up")]
    pub up: [f64; 3],
    /// Field of view across the image circle (up to 200°).
    pub fov_deg: f64,
    /// Width and height in pixels.
    pub resolution: [u32; 2],
    /// Exposure: camera value per unit radiance.
    pub exposure: f64,
    /// Read noise (standard deviation in camera values).
    #[serde(default)]
    pub read_noise: f64,
    /// Shot noise: standard deviation at value 1 (it grows with √value).
    #[serde(default)]
    pub shot_noise: f64,
    /// Values clip here.
    #[serde(default = "one")]
    pub saturation: f64,
    /// Seed of the noise.
    #[serde(default)]
    pub seed: u64,
}

fn one() -> f64 {
    1.0
}

/// What is wrong with a scene.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SceneError {
    /// The TOML does not parse or does not match the schema.
    #[error("scene file {file}: {message}")]
    Parse { file: String, message: String },
    /// A field has a value outside what is allowed.
    #[error("scene {scene}: {element}: {field} {problem}")]
    Invalid {
        scene: String,
        element: String,
        field: &'static str,
        problem: String,
    },
}

impl Scene {
    /// Parses and validates a scene; `file` names it in errors.
    pub fn from_toml(text: &str, file: &str) -> Result<Self, SceneError> {
        let scene: Scene = toml::from_str(text).map_err(|e| SceneError::Parse {
            file: file.to_string(),
            message: e.to_string(),
        })?;
        scene.validate_fields()?;
        Ok(scene)
    }

    /// Builds an error about `element`'s `field`.
    pub(crate) fn invalid(
        &self,
        element: impl Into<String>,
        field: &'static str,
        problem: impl Into<String>,
    ) -> SceneError {
        SceneError::Invalid {
            scene: self.name.clone(),
            element: element.into(),
            field,
            problem: problem.into(),
        }
    }

    /// The checks that need no geometry (geometry checks happen when the room is built): each
    /// element in file order, names unique per kind, the first problem reported.
    pub fn validate_fields(&self) -> Result<(), SceneError> {
        self.check_room()?;
        let mut names = std::collections::HashSet::new();
        let mut unique = |kind: &str, name: &str| -> Result<(), SceneError> {
            if names.insert(format!("{kind}:{name}")) {
                Ok(())
            } else {
                Err(self.invalid(format!("{kind} {name}"), "name", "is used twice"))
            }
        };
        for o in &self.objects {
            unique("object", &o.name)?;
            self.check_object(o)?;
        }
        for c in &self.charts {
            unique("chart", &c.name)?;
            self.check_chart(c)?;
        }
        for p in &self.projectors {
            unique("projector", &p.name)?;
            self.check_projector(p)?;
        }
        for l in &self.lights {
            unique("light", &l.name)?;
            self.check_light(l)?;
        }
        for p in &self.presets {
            unique("preset", &p.name)?;
            self.check_preset(p)?;
        }
        self.check_camera()
    }

    /// The room's box, albedos and element size.
    fn check_room(&self) -> Result<(), SceneError> {
        let r = &self.room;
        if !finite3(&r.size_mm) || r.size_mm.iter().any(|&v| v <= 0.0) {
            return Err(self.invalid(
                "room",
                "size_mm",
                format!("is {:?}, expected three lengths > 0", r.size_mm),
            ));
        }
        for (field, a) in [
            ("wall_albedo", &r.wall_albedo),
            ("floor_albedo", &r.floor_albedo),
            ("ceiling_albedo", &r.ceiling_albedo),
        ] {
            if !albedo_ok(a) {
                return Err(self.invalid(
                    "room",
                    field,
                    format!("is {a:?}, expected three values in [0, 1]"),
                ));
            }
        }
        if !(r.element_mm.is_finite() && r.element_mm >= 20.0) {
            return Err(self.invalid(
                "room",
                "element_mm",
                format!("is {}, expected at least 20 mm", r.element_mm),
            ));
        }
        Ok(())
    }

    /// An object: centre, albedo and the size its shape needs.
    fn check_object(&self, o: &ObjectSpec) -> Result<(), SceneError> {
        let el = format!("object {}", o.name);
        if !finite3(&o.center_mm) {
            return Err(self.invalid(el, "center_mm", "must be finite"));
        }
        if !albedo_ok(&o.albedo) {
            return Err(self.invalid(
                el,
                "albedo",
                format!("is {:?}, expected three values in [0, 1]", o.albedo),
            ));
        }
        match o.shape {
            ShapeKind::Box => match o.size_mm {
                Some(s) if finite3(&s) && s.iter().all(|&v| v > 0.0) => {}
                other => {
                    return Err(self.invalid(
                        el,
                        "size_mm",
                        format!("is {other:?}, a box needs three lengths > 0"),
                    ));
                }
            },
            ShapeKind::Plane => match o.size_mm {
                Some(s)
                    if finite3(&s)
                        && s.iter().filter(|&&v| v == 0.0).count() == 1
                        && s.iter().all(|&v| v >= 0.0) => {}
                other => {
                    return Err(self.invalid(el, "size_mm", format!("is {other:?}, a plane needs exactly one zero (its normal axis) and two lengths > 0")));
                }
            },
            ShapeKind::Sphere => {
                if !o.radius_mm.is_some_and(|v| v.is_finite() && v > 0.0) {
                    return Err(self.invalid(
                        el,
                        "radius_mm",
                        format!("is {:?}, a sphere needs a radius > 0", o.radius_mm),
                    ));
                }
            }
            ShapeKind::Cylinder => {
                if !o.radius_mm.is_some_and(|v| v.is_finite() && v > 0.0) {
                    return Err(self.invalid(
                        el,
                        "radius_mm",
                        format!("is {:?}, a cylinder needs a radius > 0", o.radius_mm),
                    ));
                }
                if !o.height_mm.is_some_and(|v| v.is_finite() && v > 0.0) {
                    return Err(self.invalid(
                        el,
                        "height_mm",
                        format!("is {:?}, a cylinder needs a height > 0", o.height_mm),
                    ));
                }
            }
        }
        Ok(())
    }

    /// A chart: width, and a normal and up that are nonzero and perpendicular.
    fn check_chart(&self, c: &ChartSpec) -> Result<(), SceneError> {
        let el = format!("chart {}", c.name);
        if !(c.width_mm.is_finite() && c.width_mm > 0.0) {
            return Err(self.invalid(el, "width_mm", format!("is {}, expected > 0", c.width_mm)));
        }
        let n = norm(c.normal);
        let u = norm(c.up);
        if !(n > 0.0 && u > 0.0 && finite3(&c.center_mm)) {
            return Err(self.invalid(el, "normal/up", "must be finite, nonzero vectors"));
        }
        if dot(c.normal, c.up).abs() / (n * u) > 1e-3 {
            return Err(self.invalid(
                el,
                "up",
                format!(
                    "{:?} is not perpendicular to the normal {:?}",
                    c.up, c.normal
                ),
            ));
        }
        Ok(())
    }

    /// A projector: optics, response, pose, and a large aperture's lens.
    fn check_projector(&self, p: &ProjectorSpec) -> Result<(), SceneError> {
        let el = format!("projector {}", p.name);
        if !(p.fov_deg.is_finite() && p.fov_deg > 1.0 && p.fov_deg < 170.0) {
            return Err(self.invalid(
                el,
                "fov_deg",
                format!("is {}, expected between 1 and 170", p.fov_deg),
            ));
        }
        if p.resolution.iter().any(|&v| v == 0 || v > 8192) {
            return Err(self.invalid(
                el,
                "resolution",
                format!("is {:?}, expected 1 to 8192 pixels", p.resolution),
            ));
        }
        if !(p.black_level.is_finite() && (0.0..0.5).contains(&p.black_level)) {
            return Err(self.invalid(
                el,
                "black_level",
                format!("is {}, expected in [0, 0.5)", p.black_level),
            ));
        }
        if !finite3(&p.peak) || p.peak.iter().any(|&v| v < 0.0) || p.peak.iter().all(|&v| v == 0.0)
        {
            return Err(self.invalid(
                el,
                "peak",
                format!("is {:?}, expected nonnegative values, not all zero", p.peak),
            ));
        }
        if !finite3(&p.gamma) || p.gamma.iter().any(|&g| !(0.2..=5.0).contains(&g)) {
            return Err(self.invalid(
                el,
                "gamma",
                format!("is {:?}, expected values in [0.2, 5]", p.gamma),
            ));
        }
        if let Some(m) = p.mixing
            && m.iter().flatten().any(|v| !v.is_finite() || *v < 0.0)
        {
            return Err(self.invalid(el, "mixing", "must hold finite values >= 0"));
        }
        let axis = sub(p.look_at_mm, p.position_mm);
        if norm(axis) == 0.0 || !finite3(&p.position_mm) || !finite3(&p.look_at_mm) {
            return Err(self.invalid(el, "look_at_mm", "must differ from position_mm"));
        }
        if norm(cross(axis, p.up)) <= 1e-6 * norm(axis) * norm(p.up) {
            return Err(self.invalid(el, "up", "must not be parallel to the optical axis"));
        }
        if p.kind == ProjectorKind::LargeAperture {
            if !p.aperture_mm.is_some_and(|v| v.is_finite() && v > 0.0) {
                return Err(self.invalid(
                    el,
                    "aperture_mm",
                    "a large-aperture projector needs a lens diameter > 0",
                ));
            }
            if !p.focus_mm.is_some_and(|v| v.is_finite() && v > 0.0) {
                return Err(self.invalid(
                    el,
                    "focus_mm",
                    "a large-aperture projector needs a focus distance > 0",
                ));
            }
            if p.lens_samples.is_some_and(|n| !(1..=4096).contains(&n)) {
                return Err(self.invalid(el, "lens_samples", "expected 1 to 4096"));
            }
        }
        Ok(())
    }

    /// An LED panel: size, colour temperature, intensity, normal.
    fn check_light(&self, l: &LightSpec) -> Result<(), SceneError> {
        let el = format!("light {}", l.name);
        if l.size_mm.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(self.invalid(
                el,
                "size_mm",
                format!("is {:?}, a light needs a width and height > 0", l.size_mm),
            ));
        }
        if !(l.cct_k.is_finite() && (1667.0..=25000.0).contains(&l.cct_k)) {
            return Err(self.invalid(
                el,
                "cct_k",
                format!("is {}, expected 1667 to 25000 K", l.cct_k),
            ));
        }
        if !(l.intensity.is_finite() && l.intensity > 0.0) {
            return Err(self.invalid(el, "intensity", format!("is {}, expected > 0", l.intensity)));
        }
        if norm(l.normal) == 0.0 || !finite3(&l.normal) {
            return Err(self.invalid(el, "normal", "must be a finite, nonzero vector"));
        }
        Ok(())
    }

    /// A preset: lights that exist, a colour temperature in range.
    fn check_preset(&self, p: &PresetSpec) -> Result<(), SceneError> {
        for name in &p.lights {
            if !self.lights.iter().any(|l| &l.name == name) {
                return Err(self.invalid(
                    format!("preset {}", p.name),
                    "lights",
                    format!("names {name:?}, which is no light of this scene"),
                ));
            }
        }
        if p.cct_k
            .is_some_and(|k| !(k.is_finite() && (1667.0..=25000.0).contains(&k)))
        {
            return Err(self.invalid(
                format!("preset {}", p.name),
                "cct_k",
                "expected 1667 to 25000 K",
            ));
        }
        if !(p.intensity.is_finite() && p.intensity > 0.0) {
            return Err(self.invalid(
                format!("preset {}", p.name),
                "intensity",
                format!("is {}, expected a finite scale > 0", p.intensity),
            ));
        }
        if !(p.dark_weight.is_finite() && p.dark_weight >= 0.0) {
            return Err(self.invalid(
                format!("preset {}", p.name),
                "dark_weight",
                format!("is {}, expected a finite weight >= 0", p.dark_weight),
            ));
        }
        Ok(())
    }

    /// The camera: field of view, resolution, exposure, noise, and an axis not parallel to up.
    fn check_camera(&self) -> Result<(), SceneError> {
        let c = &self.camera;
        if !(c.fov_deg.is_finite() && c.fov_deg > 10.0 && c.fov_deg <= 200.0) {
            return Err(self.invalid(
                "camera",
                "fov_deg",
                format!("is {}, expected between 10 and 200", c.fov_deg),
            ));
        }
        if c.resolution.iter().any(|&v| v == 0 || v > 8192) {
            return Err(self.invalid(
                "camera",
                "resolution",
                format!("is {:?}, expected 1 to 8192 pixels", c.resolution),
            ));
        }
        for (field, v) in [("exposure", c.exposure), ("saturation", c.saturation)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(self.invalid("camera", field, format!("is {v}, expected > 0")));
            }
        }
        for (field, v) in [("read_noise", c.read_noise), ("shot_noise", c.shot_noise)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(self.invalid("camera", field, format!("is {v}, expected >= 0")));
            }
        }
        let axis = sub(c.look_at_mm, c.position_mm);
        if norm(axis) == 0.0 || norm(cross(axis, c.up)) <= 1e-6 * norm(axis) * norm(c.up) {
            return Err(self.invalid(
                "camera",
                "look_at_mm/up",
                "the axis must be nonzero and not parallel to up",
            ));
        }
        Ok(())
    }
}

/// Three finite values.
fn finite3(v: &[f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Three finite values in [0, 1].
fn albedo_ok(a: &[f64; 3]) -> bool {
    a.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x))
}

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(crate) fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A preset's dark-target weight: 0 when left out, else finite and at least 0, or the scene
    /// is refused naming the preset and the field.
    #[test]
    fn a_presets_dark_weight_defaults_to_zero_and_is_checked() {
        let text = crate::scenes::SMALL_TOML;
        let plain = Scene::from_toml(text, "small.toml").expect("small");
        assert!(plain.presets.iter().all(|p| p.dark_weight <= 0.0));
        let with = |w: &str| {
            let from = "lights = [\"ceiling\"]";
            assert!(text.contains(from));
            Scene::from_toml(
                &text.replacen(from, &format!("{from}\ndark_weight = {w}"), 1),
                "t.toml",
            )
        };
        let weighed = with("2.5").expect("a weight of 2.5");
        assert!((weighed.presets[0].dark_weight - 2.5).abs() < 1e-12);
        for bad in ["-1.0", "nan", "inf"] {
            let e = with(bad).expect_err(bad).to_string();
            assert!(
                e.contains("preset on") && e.contains("dark_weight") && e.contains(">= 0"),
                "{bad}: {e}"
            );
        }
    }
}
