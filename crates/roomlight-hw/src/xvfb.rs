//! A virtual X server for tests and for the simulator chain: `Xvfb` on a free display number,
//! with RandR monitors on regions of its screen standing for projectors, killed when dropped.
//! It must not know what is shown on it.

use crate::HwError;
use crate::output::Geometry;
use crate::x11::X11;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

/// One Xvfb starts at a time in a process: two choosing a display number together can both
/// take one whose files a killed server left behind, and then share it.
static STARTING: Mutex<()> = Mutex::new(());
use x11rb::connection::Connection;
use x11rb::protocol::randr::{ConnectionExt as _, MonitorInfo};
use x11rb::protocol::xproto::ConnectionExt as _;

/// A running Xvfb; killed on drop.
#[derive(Debug)]
pub struct Xvfb {
    child: Child,
    display: String,
}

impl Xvfb {
    /// Starts `Xvfb` with one `width`×`height`×24 screen (black root window) and RandR, on a display number it
    /// picks itself (`-displayfd`). Fails, saying that `.ci/run` installs it, when Xvfb is not
    /// on PATH.
    pub fn start(width: u32, height: u32) -> Result<Self, HwError> {
        let _one_at_a_time = STARTING.lock().unwrap_or_else(PoisonError::into_inner);
        let mut child = Command::new("Xvfb")
            .args(["-displayfd", "1", "-screen", "0"])
            .arg(format!("{width}x{height}x24"))
            .args(["+extension", "RANDR", "-nolisten", "tcp", "-noreset", "-br"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| {
                HwError::Xvfb(format!(
                    "cannot start Xvfb ({e}); .ci/run installs it (apt-get install xvfb)"
                ))
            })?;
        // Xvfb writes the display number once it accepts connections; EOF means it died.
        let mut line = String::new();
        let read = child
            .stdout
            .take()
            .map(|out| BufReader::new(out).read_line(&mut line));
        let number = line.trim();
        if !matches!(read, Some(Ok(n)) if n > 0) || number.parse::<u32>().is_err() {
            let _ = child.kill();
            let status = child.wait().map(|s| s.to_string()).unwrap_or_default();
            return Err(HwError::Xvfb(format!(
                "Xvfb did not report a display number ({status})"
            )));
        }
        Ok(Self {
            display: format!(":{number}"),
            child,
        })
    }

    /// Its display name, e.g. `:7`.
    pub fn display(&self) -> &str {
        &self.display
    }

    /// Makes `region` an output named `name` (a RandR monitor without a physical output, as
    /// `xrandr --setmonitor NAME GEOMETRY none` does).
    pub fn add_output(&self, name: &str, region: Geometry) -> Result<(), HwError> {
        let x = X11::connect(Some(&self.display))?;
        let failed = |e: String| HwError::Request(format!("adding output {name}: {e}"));
        let atom = x
            .conn
            .intern_atom(false, name.as_bytes())
            .map_err(|e| failed(e.to_string()))?
            .reply()
            .map_err(|e| failed(e.to_string()))?
            .atom;
        let monitor = MonitorInfo {
            name: atom,
            primary: false,
            automatic: false,
            x: region.x as i16,
            y: region.y as i16,
            width: region.width as u16,
            height: region.height as u16,
            // At 96 dpi; nothing reads it.
            width_in_millimeters: region.width * 254 / 960,
            height_in_millimeters: region.height * 254 / 960,
            outputs: Vec::new(),
        };
        x.conn
            .randr_set_monitor(x.root(), monitor)
            .map_err(|e| failed(e.to_string()))?
            .check()
            .map_err(|e| failed(e.to_string()))?;
        x.conn.flush().map_err(|e| failed(e.to_string()))?;
        Ok(())
    }

    /// Removes the output `name` (an unplugged projector).
    pub fn remove_output(&self, name: &str) -> Result<(), HwError> {
        let x = X11::connect(Some(&self.display))?;
        let failed = |e: String| HwError::Request(format!("removing output {name}: {e}"));
        let atom = x
            .conn
            .intern_atom(true, name.as_bytes())
            .map_err(|e| failed(e.to_string()))?
            .reply()
            .map_err(|e| failed(e.to_string()))?
            .atom;
        x.conn
            .randr_delete_monitor(x.root(), atom)
            .map_err(|e| failed(e.to_string()))?
            .check()
            .map_err(|e| failed(e.to_string()))?;
        Ok(())
    }
}

impl Drop for Xvfb {
    /// SIGTERM first, so that Xvfb removes its lock file and socket; SIGKILL if it has not
    /// ended within a second.
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .stderr(Stdio::null())
            .status();
        let deadline = Instant::now() + Duration::from_secs(1);
        while Instant::now() < deadline {
            if !matches!(self.child.try_wait(), Ok(None)) {
                return;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
