//! `command:CMD`: a capture runs a program through `sh -c` with `{out}` replaced by a fresh
//! path in a temp dir of its own; the program is killed (its whole process group) at the
//! timeout, and a failure carries its exit status and the tail of its stderr. For cameras with
//! a command-line tool of their own (gphoto2 --capture-image-and-download, ffmpeg, a vendor
//! SDK's sample). It must not know radiometry.

use crate::Backend;
use crate::error::CameraError;
use crate::frame::{Frame, decode_file};
use nix::sys::signal::{Signal, killpg};
use nix::unistd::Pid;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How often a running command is checked: the cost of a capture's latency, not a wait.
const POLL: Duration = Duration::from_millis(10);
/// Bytes of stderr kept in an error.
const STDERR_TAIL: usize = 2000;

/// Runs a command per capture.
#[derive(Debug)]
pub struct CommandBackend {
    name: String,
    command: String,
    dir: tempfile::TempDir,
    captures: u64,
    max_pixels: u64,
}

/// Quotes a path for `sh`: inside single quotes nothing is special but the quote itself.
fn sh_quote(path: &Path) -> String {
    format!("'{}'", path.display().to_string().replace('\'', r"'\''"))
}

impl CommandBackend {
    pub fn new(command: String, max_pixels: u64) -> Result<Self, CameraError> {
        let name = format!("command:{command}");
        let dir = tempfile::Builder::new()
            .prefix("roomlight-camera-")
            .tempdir()
            .map_err(|e| CameraError::io(&name, "creating a temp dir", e))?;
        Ok(Self {
            name,
            command,
            dir,
            captures: 0,
            max_pixels,
        })
    }
}

impl Backend for CommandBackend {
    fn name(&self) -> &str {
        &self.name
    }

    fn capture(&mut self, deadline: Instant) -> Result<Frame, CameraError> {
        self.captures += 1;
        let started = Instant::now();
        let out = self
            .dir
            .path()
            .join(format!("capture-{}.png", self.captures));
        let err_path = self
            .dir
            .path()
            .join(format!("capture-{}.stderr", self.captures));
        let stderr = std::fs::File::create(&err_path)
            .map_err(|e| CameraError::io(&self.name, "creating the stderr file", e))?;
        let script = self.command.replace("{out}", &sh_quote(&out));
        // Its own process group, so that the timeout kills what it started too.
        let mut child = Command::new("sh")
            .arg("-c")
            .arg(&script)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(stderr)
            .process_group(0)
            .spawn()
            .map_err(|e| CameraError::io(&self.name, "starting sh", e))?;
        let group = Pid::from_raw(i32::try_from(child.id()).unwrap_or(i32::MAX));
        let status = loop {
            match child.try_wait() {
                Ok(Some(status)) => break status,
                Ok(None) if Instant::now() < deadline => std::thread::sleep(POLL),
                Ok(None) => {
                    let _ = killpg(group, Signal::SIGKILL);
                    let _ = child.wait();
                    return Err(CameraError::Timeout {
                        camera: self.name.clone(),
                        after: started.elapsed(),
                    });
                }
                Err(e) => return Err(CameraError::io(&self.name, "waiting for the command", e)),
            }
        };
        // Whatever it left running in the background would hold the camera: gone too.
        let _ = killpg(group, Signal::SIGKILL);
        let result = if status.success() {
            decode_file(&out, self.max_pixels)
        } else {
            let bytes = std::fs::read(&err_path).unwrap_or_default();
            let tail = &bytes[bytes.len().saturating_sub(STDERR_TAIL)..];
            Err(CameraError::Command {
                camera: self.name.clone(),
                status: status.to_string(),
                stderr_tail: String::from_utf8_lossy(tail).trim().to_string(),
            })
        };
        let _ = std::fs::remove_file(&out);
        let _ = std::fs::remove_file(&err_path);
        result
    }
}
