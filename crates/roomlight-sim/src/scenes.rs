//! The embedded rooms: the paper's lab, a small test room, and the hard-case variants of
//! DESIGN §9 derived from the lab.

use crate::scene::{ProjectorKind, ProjectorRole, ProjectorSpec, Scene, SceneError};

/// The lab scene's TOML text.
pub const LAB_TOML: &str = include_str!("scenes/lab.toml");
/// The small test room's TOML text.
pub const SMALL_TOML: &str = include_str!("scenes/small.toml");

/// The paper's lab (DESIGN §7).
pub fn lab() -> Result<Scene, SceneError> {
    Scene::from_toml(LAB_TOML, "embedded lab.toml")
}

/// A small, fast room for tests.
pub fn small() -> Result<Scene, SceneError> {
    Scene::from_toml(SMALL_TOML, "embedded small.toml")
}

/// The hard cases of DESIGN §9 that are properties of the room.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HardCase {
    /// Walls, floor and ceiling of albedo 0.9: strong inter-reflection.
    Reflective,
    /// A second standard projector beside the left-wall one: nearly collinear columns.
    TwoOnOneWall,
    /// The front-wall projector at a tenth of its output.
    DimProjector,
    /// A projector aimed at the ceiling corner where no chart is: nodes with no chart.
    NodeWithoutChart,
    /// Ten times the camera's read and shot noise.
    HeavyNoise,
    /// Strong, unequal projector gammas (the system must measure and invert them).
    UncorrectedGamma,
    /// The LED lights four times as bright: a target brighter than the projectors can give,
    /// so the bounds are active at the optimum.
    BrightTarget,
}

impl HardCase {
    /// All hard cases.
    pub const ALL: [HardCase; 7] = [
        Self::Reflective,
        Self::TwoOnOneWall,
        Self::DimProjector,
        Self::NodeWithoutChart,
        Self::HeavyNoise,
        Self::UncorrectedGamma,
        Self::BrightTarget,
    ];

    /// A short name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Reflective => "reflective",
            Self::TwoOnOneWall => "two-on-one-wall",
            Self::DimProjector => "dim-projector",
            Self::NodeWithoutChart => "node-without-chart",
            Self::HeavyNoise => "heavy-noise",
            Self::UncorrectedGamma => "uncorrected-gamma",
            Self::BrightTarget => "bright-target",
        }
    }
}

/// The lab changed for one hard case.
pub fn hard_case(case: HardCase) -> Result<Scene, SceneError> {
    hard_case_of(lab()?, case)
}

/// Any room changed for one hard case. The projector twinned or dimmed is the left-wall or
/// front-wall one of the lab, or the first standard luminaire of another room; the chartless
/// projector looks into the ceiling corner at the room's far right front.
pub fn hard_case_of(mut scene: Scene, case: HardCase) -> Result<Scene, SceneError> {
    scene.name = format!("{}-{}", scene.name, case.name());
    let pick = |scene: &Scene, name: &str| {
        scene
            .projectors
            .iter()
            .position(|p| p.name == name)
            .or_else(|| {
                scene.projectors.iter().position(|p| {
                    p.kind == ProjectorKind::Standard && p.role == ProjectorRole::Luminaire
                })
            })
    };
    let [width, _, height] = scene.room.size_mm;
    match case {
        HardCase::Reflective => {
            scene.room.wall_albedo = [0.9; 3];
            scene.room.floor_albedo = [0.9; 3];
            scene.room.ceiling_albedo = [0.9; 3];
        }
        HardCase::TwoOnOneWall => {
            if let Some(k) = pick(&scene, "wall-left") {
                let mut twin = scene.projectors[k].clone();
                twin.name = format!("{}-twin", twin.name);
                twin.position_mm[1] += 250.0;
                twin.look_at_mm[1] += 150.0;
                scene.projectors.push(twin);
            }
        }
        HardCase::DimProjector => {
            if let Some(k) = pick(&scene, "wall-front") {
                scene.projectors[k].peak = scene.projectors[k].peak.map(|v| v * 0.1);
            }
        }
        HardCase::NodeWithoutChart => scene.projectors.push(ProjectorSpec {
            name: "ceiling-corner".into(),
            kind: ProjectorKind::Standard,
            role: ProjectorRole::Luminaire,
            position_mm: [width - 300.0, 300.0, height / 2.0],
            look_at_mm: [width - 50.0, 100.0, height - 50.0],
            up: [0.0, 1.0, 0.0],
            fov_deg: 30.0,
            resolution: [320, 240],
            black_level: 0.002,
            peak: [0.5; 3],
            gamma: [2.2; 3],
            mixing: None,
            aperture_mm: None,
            focus_mm: None,
            lens_samples: None,
        }),
        HardCase::HeavyNoise => {
            scene.camera.read_noise *= 10.0;
            scene.camera.shot_noise *= 10.0;
        }
        HardCase::UncorrectedGamma => {
            for p in &mut scene.projectors {
                p.gamma = [2.6, 2.2, 1.8];
            }
        }
        HardCase::BrightTarget => {
            for light in &mut scene.lights {
                light.intensity *= 4.0;
            }
        }
    }
    scene.validate_fields()?;
    Ok(scene)
}
