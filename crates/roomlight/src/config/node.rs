//! A node agent's config file and the one conversion into the agent's `NodeConfig`.

use super::{Hardware, check, check_nonempty, read_toml};
use anyhow::{Context, Result, bail};
use roomlight_agent::discovery::MdnsConfig;
use roomlight_agent::node::NodeConfig;
use roomlight_core::{LinearRgb, StepRule};
use roomlight_lab::process::NodeDisplay;
use roomlight_proto::v1;
use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, Visitor};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Where the camera agent is: `camera = "http://host:port"`, or `camera = { mdns = "ROOM" }`
/// to find the agent of that room over mDNS. `camera = "mdns"` (the old form) means the agent
/// of the node's own `room`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CameraLocation {
    Address(String),
    Mdns(String),
}

/// As written: the old `"mdns"` string has no room of its own until the file's `room` is read.
#[derive(Debug)]
enum Written {
    Address(String),
    Mdns(Option<String>),
}

impl<'de> Deserialize<'de> for Written {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Camera;
        impl<'de> Visitor<'de> for Camera {
            type Value = Written;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str(r#"an endpoint like "http://host:port", or { mdns = "ROOM" }"#)
            }
            fn visit_str<E: de::Error>(self, s: &str) -> Result<Written, E> {
                Ok(if s == "mdns" {
                    Written::Mdns(None)
                } else {
                    Written::Address(s.to_string())
                })
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Written, A::Error> {
                #[derive(Deserialize)]
                #[serde(deny_unknown_fields)]
                struct Mdns {
                    mdns: String,
                }
                let m = Mdns::deserialize(de::value::MapAccessDeserializer::new(map))?;
                Ok(Written::Mdns(Some(m.mdns)))
            }
        }
        d.deserialize_any(Camera)
    }
}

/// The update rule of the node's values (DESIGN §3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum Rule {
    Safe,
    Momentum,
    Paper,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum Kind {
    Standard,
    /// Decoded with plain Gray code; one node.
    LargeAperture,
}

/// What the projector is: `display = { kind = "window", output = "HDMI-1", settle_ms = 80 }`
/// for a real one, or the simulator (`kind = "sim"`, the default) reached through `hardware`.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
enum DisplayFile {
    Sim,
    Window {
        /// A name (`HDMI-1`), an index, or a geometry `WxH+X+Y` (`roomlight hw displays`).
        output: String,
        /// How long the projector takes to show a frame the X server has, in milliseconds.
        #[serde(default = "settle_ms_default")]
        settle_ms: u64,
        /// The X display (`:0`); `$DISPLAY` when absent.
        #[serde(default)]
        x_display: Option<String>,
    },
}

fn settle_ms_default() -> u64 {
    80
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NodeFile {
    room: String,
    token: super::Token,
    camera: Written,
    #[serde(default = "super::mdns_port_default")]
    mdns_port: u16,
    #[serde(default)]
    mdns_loopback_only: bool,
    /// How long to look for the camera agent over mDNS, in seconds.
    #[serde(default = "mdns_wait_default")]
    mdns_wait_s: u64,
    /// The simulator's endpoint; absent for a window display.
    #[serde(default)]
    hardware: Option<Hardware>,
    #[serde(default)]
    display: Option<DisplayFile>,
    /// A rendered room: this projector's frame file (`roomlight calibrate` writes it).
    #[serde(default)]
    frame: Option<PathBuf>,
    /// A rendered room without a frame file: the camera agent calibrates this projector over
    /// the wire.
    #[serde(default)]
    rendered: bool,
    #[serde(default = "kind_default")]
    kind: Kind,
    projector: String,
    #[serde(default)]
    state_file: Option<PathBuf>,
    #[serde(default = "rule_default")]
    rule: Rule,
    #[serde(default = "theta_default")]
    theta: f64,
    #[serde(default = "start_default")]
    start: f64,
    /// `tls = { ca, cert, key, camera_name }`, or plaintext: loopback or `insecure`.
    #[serde(default)]
    tls: Option<roomlight_agent::tls::TlsFiles>,
    #[serde(default)]
    insecure: bool,
}

fn mdns_wait_default() -> u64 {
    30
}
fn kind_default() -> Kind {
    Kind::Standard
}
fn rule_default() -> Rule {
    Rule::Momentum
}
fn theta_default() -> f64 {
    1.0
}
fn start_default() -> f64 {
    0.5
}

/// A checked node config: where the camera agent is, and the rest of the agent's config once
/// it is found.
#[derive(Debug)]
pub struct NodeSetup {
    pub camera: CameraLocation,
    pub mdns: MdnsConfig,
    pub mdns_wait: Duration,
    /// The endpoint of the display's `roomlight sim` process (empty for a window display).
    pub hardware: String,
    pub display: NodeDisplay,
    pub tls: Option<roomlight_agent::tls::ClientTls>,
    room: String,
    token: roomlight_proto::bounds::Secret,
    projector: String,
    kind: v1::ProjectorKind,
    rule: StepRule,
    start: f64,
    state_file: Option<PathBuf>,
}

/// A node agent's config file, checked.
pub fn load_node(path: &Path) -> Result<NodeSetup> {
    let file: NodeFile = read_toml(path)?;
    let token = file.token.resolve(path)?;
    file.check(path)?;
    file.into_setup(path, token)
}

impl NodeFile {
    fn check(&self, path: &Path) -> Result<()> {
        check_nonempty(path, "room", &self.room)?;
        check_nonempty(path, "projector", &self.projector)?;
        self.check_display(path)?;
        match &self.camera {
            Written::Address(a) => check_nonempty(path, "camera", a)?,
            Written::Mdns(Some(room)) => check_nonempty(path, "camera.mdns", room)?,
            Written::Mdns(None) => {}
        }
        check(
            path,
            "mdns_port",
            self.mdns_port,
            1..=u16::MAX,
            "(a UDP port)",
        )?;
        check(path, "mdns_wait_s", self.mdns_wait_s, 1..=3_600, "seconds")?;
        if !self.start.is_finite() {
            bail!(
                "{}: start = {}: expected 0 to 1",
                path.display(),
                self.start
            );
        }
        check(path, "start", self.start, 0.0..=1.0, "(a node value)")?;
        if !self.theta.is_finite() {
            bail!(
                "{}: theta = {}: expected a number in (0, 2)",
                path.display(),
                self.theta
            );
        }
        if self.frame.is_some() && self.rendered {
            bail!(
                "{}: give frame (weights from `roomlight calibrate`) or rendered = true \
                 (calibrated over the wire), not both",
                path.display()
            );
        }
        Ok(())
    }

    /// A window display stands alone; the simulator needs its endpoint.
    fn check_display(&self, path: &Path) -> Result<()> {
        let Some(DisplayFile::Window {
            output, settle_ms, ..
        }) = &self.display
        else {
            let Some(hardware) = &self.hardware else {
                bail!(
                    "{}: hardware is missing (the simulator's endpoint), or give a real \
                     display = {{ kind = \"window\", output = \"HDMI-1\" }}",
                    path.display()
                );
            };
            return check_nonempty(path, "hardware.sim", hardware.endpoint());
        };
        if self.hardware.is_some() || self.frame.is_some() || self.rendered {
            bail!(
                "{}: display.kind = \"window\" drives a real projector: no hardware, frame or \
                 rendered",
                path.display()
            );
        }
        output
            .parse::<roomlight_hw::OutputSelector>()
            .with_context(|| format!("{}: display.output", path.display()))?;
        check(
            path,
            "display.settle_ms",
            *settle_ms,
            0..=10_000,
            "milliseconds",
        )
    }

    fn into_setup(self, path: &Path, token: String) -> Result<NodeSetup> {
        let rule = match self.rule {
            Rule::Safe => StepRule::Safe { theta: self.theta },
            Rule::Momentum => StepRule::Momentum { theta: self.theta },
            Rule::Paper => StepRule::paper(),
        };
        rule.validate()
            .with_context(|| format!("{}: theta = {}", path.display(), self.theta))?;
        let camera = match self.camera {
            Written::Address(a) => CameraLocation::Address(a),
            Written::Mdns(room) => CameraLocation::Mdns(room.unwrap_or_else(|| self.room.clone())),
        };
        let display = match (self.display, self.frame, self.rendered) {
            (
                Some(DisplayFile::Window {
                    output,
                    settle_ms,
                    x_display,
                }),
                ..,
            ) => NodeDisplay::Window(roomlight_hw::WindowSpec {
                x_display,
                output: output
                    .parse()
                    .with_context(|| format!("{}: display.output", path.display()))?,
                settle: Duration::from_millis(settle_ms),
            }),
            (_, Some(frame), _) => NodeDisplay::Frame(frame),
            (_, None, true) => NodeDisplay::OverTheWire,
            (_, None, false) => NodeDisplay::Synthetic,
        };
        let hardware = match self.hardware {
            Some(Hardware::Sim(endpoint)) => endpoint,
            None => String::new(),
        };
        let to = match &camera {
            CameraLocation::Address(a) => ("camera", Some(a.as_str())),
            CameraLocation::Mdns(_) => ("camera.mdns", self.mdns_loopback_only.then_some("::1")),
        };
        let tls = roomlight_agent::tls::client(path, self.tls.as_ref(), to, self.insecure)?;
        Ok(NodeSetup {
            tls,
            camera,
            mdns: MdnsConfig {
                port: self.mdns_port,
                loopback_only: self.mdns_loopback_only,
            },
            mdns_wait: Duration::from_secs(self.mdns_wait_s),
            hardware,
            display,
            room: self.room,
            token: roomlight_proto::bounds::Secret(token),
            projector: self.projector,
            kind: match self.kind {
                Kind::Standard => v1::ProjectorKind::Standard,
                Kind::LargeAperture => v1::ProjectorKind::LargeAperture,
            },
            rule,
            start: self.start,
            state_file: self.state_file,
        })
    }
}

impl NodeSetup {
    /// The one place a checked node config becomes the agent's `NodeConfig`, once the camera
    /// agent's `endpoint` is known.
    pub fn agent_config(&self, endpoint: String) -> NodeConfig {
        NodeConfig {
            endpoint,
            room: self.room.clone(),
            token: self.token.0.clone(),
            projector_id: self.projector.clone(),
            kind: self.kind,
            rule: self.rule,
            start: LinearRgb::splat(self.start),
            state_file: self.state_file.clone(),
        }
    }
}
