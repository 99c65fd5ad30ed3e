//! The camera agent's config file and the one conversion into the process that runs it.

use super::{Hardware, check, check_nonempty, read_toml};
use anyhow::{Context, Result, bail};
use roomlight_agent::camera::CameraConfig;
use roomlight_agent::discovery::MdnsConfig;
use roomlight_lab::process::{
    CameraHardware, CameraProcess, CameraSource, ConsoleProcess, LightsSpec,
};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::time::Duration;

type Tls = Option<roomlight_agent::tls::ServerTls>;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraFile {
    room: String,
    token: super::Token,
    listen: String,
    /// The simulator's camera: `hardware = { sim = "http://host:port" }`; or `camera`.
    #[serde(default)]
    hardware: Option<Hardware>,
    /// A real camera: `camera = "folder:/path"` (any roomlight-camera spec), or a table of
    /// roomlight-camera's `CameraConfig` (`camera = { spec = "...", timeout_s = 5, response =
    /// "linear", ... }`); read in `real_camera`.
    #[serde(default)]
    camera: Option<toml::Value>,
    /// With `camera` and `survey`: how the survey switches the LEDs to measure the room's black
    /// and target: `manual:DIR` (a person, asked through `DIR/lights-wanted`, answers in
    /// `DIR/lights`), or the rendered room (`roomlight sim --grab`) whose LEDs it switches.
    #[serde(default)]
    lights: Option<String>,
    /// The calibrated model (`roomlight calibrate` or `roomlight sim` writes it); or `survey`.
    #[serde(default)]
    model: Option<PathBuf>,
    /// A rendered room: the charts file (`roomlight calibrate` writes it); absent: the
    /// synthetic room's patches.
    #[serde(default)]
    charts: Option<PathBuf>,
    /// Calibration over the wire on a rendered room: the survey file (`roomlight calibrate
    /// --survey-only` writes it). Instead of `model` and `charts`.
    #[serde(default)]
    survey: Option<PathBuf>,
    /// With `survey`: the LED preset whose light the projectors reproduce (default: the first).
    #[serde(default)]
    preset: Option<String>,
    /// Where to write the model whenever a projector has been calibrated over the wire or hot.
    #[serde(default)]
    model_out: Option<PathBuf>,
    #[serde(default = "heartbeat_default")]
    heartbeat_ms: u64,
    #[serde(default = "deadline_default")]
    deadline_ms: u64,
    /// Model rounds between two captures (default `DEFAULT_MODEL_ROUNDS`, the bench's rule).
    #[serde(default = "model_rounds_default")]
    model_rounds: usize,
    #[serde(default = "epoch_default")]
    calibration_epoch: u64,
    #[serde(default)]
    stale_frames: usize,
    /// Calibration over the wire codes up to three groups of projectors at once, each in its
    /// own primary (the default); `primaries = false`: one group at a time in white, for
    /// projectors that do not show their primaries at once (a single-chip DLP's colour wheel
    /// photographed faster than it turns). A lit room is coded in white either way.
    #[serde(default = "primaries_default")]
    primaries: bool,
    /// Per-pixel shading passes per preset (default 10; 0: none), the first once the rounds
    /// settle on it, then one a capture: each multiplies every standard projector's light
    /// block by block towards the LEDs' photograph, beyond the charts. Needs calibration over
    /// the wire (the decodes) and a preset chosen (the LEDs' photograph).
    #[serde(default = "shading_passes_default")]
    shading_passes: usize,
    /// With `survey`: the weight of the light on the target in the luminaires' objective (a
    /// target patch's squared light against a chart patch's; default 1, 0: the charts alone),
    /// so that they keep it dark at a cost in the room's accuracy (docs/calibration.md).
    #[serde(default = "dark_target_weight_default")]
    dark_target_weight: f64,
    /// Advertise the camera agent over mDNS.
    #[serde(default = "mdns_default")]
    mdns: bool,
    #[serde(default = "super::mdns_port_default")]
    mdns_port: u16,
    /// mDNS on the loopback interface only (one machine).
    #[serde(default)]
    mdns_loopback_only: bool,
    /// `tls = { cert, key, ca, require_client_cert }`, or plaintext: loopback or `insecure`.
    #[serde(default)]
    tls: Option<roomlight_agent::tls::TlsFiles>,
    #[serde(default)]
    insecure: bool,
    /// The installer's web console: `console = "127.0.0.1:8080"`, or `console = { listen =
    /// "...", token = ... }` with a token of its own (the room token by default).
    #[serde(default)]
    console: Option<ConsoleSpec>,
}

/// Where the console listens, and optionally its own token.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum ConsoleSpec {
    Listen(String),
    Table(ConsoleTable),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConsoleTable {
    listen: String,
    #[serde(default)]
    token: Option<super::Token>,
}

fn heartbeat_default() -> u64 {
    500
}
fn deadline_default() -> u64 {
    2000
}
fn model_rounds_default() -> usize {
    roomlight_agent::camera::DEFAULT_MODEL_ROUNDS
}
fn epoch_default() -> u64 {
    1
}
fn mdns_default() -> bool {
    true
}
fn primaries_default() -> bool {
    true
}
fn shading_passes_default() -> usize {
    10
}
fn dark_target_weight_default() -> f64 {
    roomlight_agent::camera::DEFAULT_DARK_WEIGHT
}

/// The camera agent's config file, checked and turned into the process to run.
pub fn load_camera(path: &Path) -> Result<CameraProcess> {
    let mut file: CameraFile = read_toml(path)?;
    let token = file.token.resolve(path)?;
    file.check(path)?;
    let hardware = file.hardware(path)?;
    let tls = roomlight_agent::tls::server(path, file.tls.as_ref(), &file.listen, file.insecure)?;
    let console = match file.console.take() {
        None => None,
        Some(ConsoleSpec::Listen(listen)) => Some(ConsoleProcess {
            listen,
            token: token.clone(),
        }),
        Some(ConsoleSpec::Table(ConsoleTable { listen, token: own })) => Some(ConsoleProcess {
            listen,
            token: match own {
                Some(t) => t
                    .resolve(path)
                    .with_context(|| format!("{}: console.token", path.display()))?,
                None => token.clone(),
            },
        }),
    };
    if let Some(c) = &console {
        check_nonempty(path, "console", &c.listen)?;
        let Ok(addr) = c.listen.parse::<std::net::SocketAddr>() else {
            bail!(
                "{}: console {:?}: expected an address and port, such as \"127.0.0.1:8080\"",
                path.display(),
                c.listen
            );
        };
        if !addr.ip().is_loopback() && c.token.chars().count() < 12 {
            bail!(
                "{}: console {}: beyond this machine its token needs at least 12 characters (it has {}): it opens the room to any browser on the network",
                path.display(),
                c.listen,
                c.token.chars().count()
            );
        }
    }
    let mut process = file.into_process(hardware, token, tls);
    process.console = console;
    Ok(process)
}

/// `camera` as a spec string or a `CameraConfig` table, validated.
fn real_camera(value: &toml::Value) -> Result<roomlight_camera::CameraConfig> {
    let config = match value {
        toml::Value::String(spec) => roomlight_camera::CameraConfig::new(spec.parse()?),
        table => table.clone().try_into()?,
    };
    config.validate()?;
    Ok(config)
}

impl CameraFile {
    fn check(&self, path: &Path) -> Result<()> {
        check_nonempty(path, "room", &self.room)?;
        check_nonempty(path, "listen", &self.listen)?;
        if let Some(hardware) = &self.hardware {
            check_nonempty(path, "hardware.sim", hardware.endpoint())?;
        }
        if let Some(lights) = &self.lights {
            check_nonempty(path, "lights", lights)?;
            if let LightsSpec::Manual(dir) = LightsSpec::parse(lights)
                && !dir.is_dir()
            {
                bail!(
                    "{}: lights = {lights:?}: {} is not a folder (the survey asks for the LEDs \
                     there)",
                    path.display(),
                    dir.display()
                );
            }
        }
        // Under 50 ms heartbeats swamp a large room; over a minute a dead node holds rounds.
        check(
            path,
            "heartbeat_ms",
            self.heartbeat_ms,
            50..=60_000,
            "milliseconds",
        )?;
        // Time arithmetic on the deadline must not overflow (u64::MAX ms panicked).
        check(
            path,
            "deadline_ms",
            self.deadline_ms,
            10..=600_000,
            "milliseconds",
        )?;
        check(path, "model_rounds", self.model_rounds, 0..=1_000, "rounds")?;
        // Any epoch is valid: it is only compared with the node state files'.
        check(path, "stale_frames", self.stale_frames, 0..=100, "frames")?;
        check(
            path,
            "shading_passes",
            self.shading_passes,
            0..=64,
            "passes",
        )?;
        check(
            path,
            "mdns_port",
            self.mdns_port,
            1..=u16::MAX,
            "(a UDP port)",
        )?;
        if self.model.is_some() == self.survey.is_some() {
            bail!(
                "{}: give either model (a calibrated room) or survey (calibration over the wire)",
                path.display()
            );
        }
        if self.survey.is_some() && self.charts.is_some() {
            bail!("{}: charts comes with model, not survey", path.display());
        }
        // Without its model a restarted camera agent would measure the room's black and target
        // again while the node agents keep their light on, and get both wrong.
        if self.survey.is_some() && self.model_out.is_none() {
            bail!(
                "{}: survey needs model_out, the file from which a restarted camera agent resumes",
                path.display()
            );
        }
        if self.model.is_some() && self.preset.is_some() {
            bail!("{}: preset comes with survey, not model", path.display());
        }
        let max = roomlight_agent::camera::MAX_DARK_WEIGHT;
        if !(self.dark_target_weight.is_finite() && (0.0..=max).contains(&self.dark_target_weight))
        {
            bail!(
                "{}: dark_target_weight = {}, expected 0 to {max}",
                path.display(),
                self.dark_target_weight
            );
        }
        Ok(())
    }

    /// Exactly one of `hardware` and `camera`; `lights` only with `camera`, and needed by a
    /// survey; a real camera's model needs its charts.
    fn hardware(&self, path: &Path) -> Result<CameraHardware> {
        let p = path.display();
        let camera = match (&self.hardware, &self.camera) {
            (Some(_), Some(_)) | (None, None) => bail!(
                "{p}: give either hardware = {{ sim = \"...\" }} (the simulator's camera) or \
                 camera = \"folder:DIR\" (a real camera)"
            ),
            (Some(Hardware::Sim(endpoint)), None) => {
                if self.lights.is_some() {
                    bail!("{p}: lights comes with camera, not hardware");
                }
                return Ok(CameraHardware::Sim(endpoint.clone()));
            }
            (None, Some(value)) => real_camera(value).with_context(|| format!("{p}: camera"))?,
        };
        if self.survey.is_some() && self.lights.is_none() {
            bail!(
                "{p}: survey with a real camera needs lights: \"manual:DIR\" (a person switches the LEDs when asked) or the rendered room that switches its own"
            );
        }
        if self.model.is_some() && self.charts.is_none() {
            bail!("{p}: model with a real camera needs charts, where its patches are");
        }
        Ok(CameraHardware::Real {
            camera: Box::new(camera),
            lights: self.lights.as_deref().map(LightsSpec::parse),
        })
    }

    /// The one place a checked camera config becomes the agent's `CameraConfig` and process.
    fn into_process(self, hardware: CameraHardware, token: String, tls: Tls) -> CameraProcess {
        let source = match (self.model, self.survey) {
            (Some(model), _) => CameraSource::Model {
                model,
                charts: self.charts,
            },
            (None, survey) => CameraSource::Survey {
                survey: survey.unwrap_or_default(),
                preset: self.preset,
                dark_weight: self.dark_target_weight,
            },
        };
        CameraProcess {
            agent: CameraConfig {
                room: self.room,
                token,
                heartbeat: Duration::from_millis(self.heartbeat_ms),
                deadline: Duration::from_millis(self.deadline_ms),
                model_rounds: self.model_rounds,
                calibration_epoch: self.calibration_epoch,
                stale_frames: self.stale_frames,
                model_out: self.model_out,
                primaries: self.primaries,
                shading_passes: self.shading_passes,
            },
            hardware,
            source,
            listen: self.listen,
            tls,
            console: None,
            status_lines: Default::default(),
            advertise: self.mdns.then_some(MdnsConfig {
                port: self.mdns_port,
                loopback_only: self.mdns_loopback_only,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera.toml that does not set `model_rounds` runs the bench's default rule, as the
    /// lab's pipeline does.
    #[test]
    fn model_rounds_default_to_the_benchs_rule() {
        let file: CameraFile = toml::from_str(
            "room = \"r\"\ntoken = \"t\"\nlisten = \"127.0.0.1:0\"\n\
             hardware = { sim = \"http://127.0.0.1:1\" }\nmodel = \"m.json\"\n",
        )
        .expect("a minimal camera.toml");
        assert_eq!(file.model_rounds, 100);
        assert_eq!(
            file.model_rounds,
            roomlight_lab::bench::room::MODEL_ROUNDS,
            "the deployed default is the bench's rule"
        );
        assert_eq!(
            roomlight_lab::pipeline::RunOptions::default_rule(1).model_rounds,
            file.model_rounds
        );
        let set: CameraFile = toml::from_str(
            "room = \"r\"\ntoken = \"t\"\nlisten = \"127.0.0.1:0\"\n\
             hardware = { sim = \"http://127.0.0.1:1\" }\nmodel = \"m.json\"\nmodel_rounds = 0\n",
        )
        .expect("model_rounds = 0");
        assert_eq!(set.model_rounds, 0);
    }

    /// Calibration over the wire codes in primaries unless the file says `primaries = false`,
    /// and the agent gets what the file says; anything but a boolean is refused.
    #[test]
    fn primaries_default_to_the_procedures_and_can_be_turned_off() {
        let minimal = "room = \"r\"\ntoken = \"t\"\nlisten = \"127.0.0.1:0\"\n\
                       hardware = { sim = \"http://127.0.0.1:1\" }\nmodel = \"m.json\"\n";
        let agent = |text: &str| {
            let file: CameraFile = toml::from_str(text).expect("camera.toml");
            let hardware = CameraHardware::Sim("http://127.0.0.1:1".into());
            file.into_process(hardware, "t".into(), None).agent
        };
        let default = agent(minimal);
        assert!(default.primaries);
        assert_eq!(
            default.primaries,
            roomlight_calib::procedure::Settings::default().primaries
        );
        assert!(!agent(&format!("{minimal}primaries = false\n")).primaries);
        assert!(
            toml::from_str::<CameraFile>(&format!("{minimal}primaries = \"white\"\n")).is_err()
        );
    }

    /// Shading passes default to 10, reach the agent as the file says, and a count beyond 64 is
    /// refused naming the field and the range.
    #[test]
    fn shading_passes_default_to_ten_and_are_range_checked() {
        let minimal = "room = \"r\"\ntoken = \"t\"\nlisten = \"127.0.0.1:0\"\n\
                       hardware = { sim = \"http://127.0.0.1:1\" }\nmodel = \"m.json\"\n";
        let file = |text: &str| toml::from_str::<CameraFile>(text).expect("camera.toml");
        let agent = |text: &str| {
            let hardware = CameraHardware::Sim("http://127.0.0.1:1".into());
            file(text).into_process(hardware, "t".into(), None).agent
        };
        assert_eq!(agent(minimal).shading_passes, 10);
        assert_eq!(
            agent(&format!("{minimal}shading_passes = 0\n")).shading_passes,
            0
        );
        let path = Path::new("camera.toml");
        assert!(
            file(&format!("{minimal}shading_passes = 64\n"))
                .check(path)
                .is_ok()
        );
        let e = file(&format!("{minimal}shading_passes = 65\n"))
            .check(path)
            .expect_err("65 passes");
        let e = format!("{e:#}");
        assert!(
            e.contains("camera.toml") && e.contains("shading_passes"),
            "{e}"
        );
        assert!(e.contains("64"), "{e}");
    }

    /// The dark-target weight defaults to the agent's, reaches the survey as the file says, and
    /// a negative, non-finite or too large one is refused naming the field.
    #[test]
    fn the_dark_target_weight_defaults_to_one_and_is_range_checked() {
        let minimal = "room = \"r\"\ntoken = \"t\"\nlisten = \"127.0.0.1:0\"\n\
                       hardware = { sim = \"http://127.0.0.1:1\" }\nsurvey = \"s.json\"\n\
                       model_out = \"m.json\"\n";
        let file = |text: &str| toml::from_str::<CameraFile>(text).expect("camera.toml");
        let weight = |text: &str| {
            let hardware = CameraHardware::Sim("http://127.0.0.1:1".into());
            match file(text).into_process(hardware, "t".into(), None).source {
                CameraSource::Survey { dark_weight, .. } => dark_weight,
                other => panic!("not a survey: {other:?}"),
            }
        };
        assert!((weight(minimal) - 1.0).abs() < 1e-12);
        assert!(weight(&format!("{minimal}dark_target_weight = 10.0\n")) > 9.99);
        let path = Path::new("camera.toml");
        assert!(file(minimal).check(path).is_ok());
        for bad in ["-1.0", "nan", "inf", "1000.5"] {
            let e = file(&format!("{minimal}dark_target_weight = {bad}\n"))
                .check(path)
                .expect_err(bad);
            let e = format!("{e:#}");
            assert!(
                e.contains("camera.toml") && e.contains("dark_target_weight"),
                "{e}"
            );
        }
    }
}
