//! The agents' config files (deploy/camera.toml, deploy/node.toml) as types: enums, not
//! strings; unknown fields refused; every number range-checked once, at load, with the file and
//! the field in the error. `camera` and `node` each end in the one function that turns a checked
//! config into what the process runs. Nothing here knows what the agents do with it.

mod camera;
mod node;

pub use camera::load_camera;
pub use node::{CameraLocation, load_node};

use anyhow::{Context, Result, bail};
use serde::Deserialize;
use std::fmt::Display;
use std::ops::RangeInclusive;
use std::path::Path;

/// The simulator a process drives; real hardware has keys of its own (a camera agent's
/// `camera`, a node's `display`).
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Hardware {
    /// A `roomlight sim` process at this endpoint: `hardware = { sim = "http://host:port" }`.
    Sim(String),
}

impl Hardware {
    /// The endpoint of the process that serves it.
    fn endpoint(&self) -> &str {
        match self {
            Self::Sim(endpoint) => endpoint,
        }
    }
}

/// Reads and parses `path`; serde's message names the field and the line.
fn read_toml<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    toml::from_str(&text).with_context(|| format!("{}: not a valid config", path.display()))
}

/// Refuses `value` of `field` outside `range`, naming the file, the field and what was expected.
fn check<T: PartialOrd + Display>(
    path: &Path,
    field: &str,
    value: T,
    range: RangeInclusive<T>,
    unit: &str,
) -> Result<()> {
    if !range.contains(&value) {
        bail!(
            "{}: {field} = {value}: expected {} to {} {unit}",
            path.display(),
            range.start(),
            range.end()
        );
    }
    Ok(())
}

/// Refuses an empty string field (an endpoint, a room, a projector id).
fn check_nonempty(path: &Path, field: &str, value: &str) -> Result<()> {
    if value.trim().is_empty() {
        bail!("{}: {field} is empty", path.display());
    }
    Ok(())
}

/// The room token as a config gives it: `token = "..."` in the file, or kept out of it (a
/// config is often readable by more people than the secret should be):
/// `token = { credential = "room-token" }`, a systemd credential (`LoadCredential=`, read from
/// `$CREDENTIALS_DIRECTORY`), or `token = { file = "/etc/roomlight/room-token" }`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum Token {
    Inline(String),
    Credential { credential: String },
    File { file: std::path::PathBuf },
}

/// The largest token file read (a token is at most `MAX_TOKEN_BYTES`; a newline may follow).
const TOKEN_FILE_MAX: u64 = 4096;

impl Token {
    /// The token, checked; errors name the config file and where the token was to come from,
    /// never the token.
    fn resolve(&self, path: &Path) -> Result<String> {
        let read = |from: &Path| -> Result<String> {
            let mut text = String::new();
            std::io::Read::read_to_string(
                &mut std::io::Read::take(
                    std::fs::File::open(from).with_context(|| {
                        format!("{}: token from {}", path.display(), from.display())
                    })?,
                    TOKEN_FILE_MAX,
                ),
                &mut text,
            )
            .with_context(|| format!("{}: token from {}", path.display(), from.display()))?;
            Ok(text.trim_end_matches(['\n', '\r']).to_string())
        };
        let token = match self {
            Self::Inline(token) => token.clone(),
            Self::File { file } => read(file)?,
            Self::Credential { credential } => {
                let Some(dir) = std::env::var_os("CREDENTIALS_DIRECTORY") else {
                    bail!(
                        "{}: token.credential {credential:?}: $CREDENTIALS_DIRECTORY is not set \
                         (run under systemd with LoadCredential={credential}:FILE, or give \
                         token = {{ file = \"FILE\" }})",
                        path.display()
                    );
                };
                if credential.contains('/') || credential.is_empty() {
                    bail!(
                        "{}: token.credential {credential:?}: expected a name",
                        path.display()
                    );
                }
                read(&Path::new(&dir).join(credential))?
            }
        };
        check_token(path, &token)?;
        Ok(token)
    }
}

/// Refuses an empty room token (it would admit anyone who sends none) or one longer than the
/// camera agent compares; the error never prints the token.
fn check_token(path: &Path, token: &str) -> Result<()> {
    if token.trim().is_empty() {
        bail!(
            "{}: token is empty: expected the room's shared secret (an empty token would admit anyone)",
            path.display()
        );
    }
    let max = roomlight_proto::bounds::MAX_TOKEN_BYTES;
    if token.len() > max {
        bail!(
            "{}: token of {} bytes: expected at most {max}",
            path.display(),
            token.len()
        );
    }
    Ok(())
}

fn mdns_port_default() -> u16 {
    5353
}
