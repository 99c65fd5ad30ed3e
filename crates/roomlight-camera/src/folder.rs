//! `folder:DIR`: a capture is the next new image file in a folder — for cameras operated by
//! hand (or tethering software that saves each shot) and for tests. Files present when the
//! capture was asked are ignored; a new file counts once it is complete: its size has stayed
//! the same for `settle` and it decodes (a file renamed into place is complete at once; hidden
//! and `.part`/`.tmp` files are never taken). inotify through `notify` wakes the wait; a poll
//! every 50 ms covers file systems without events. It must not know radiometry.
//!
//! Armed, the backend announces that it wants a photograph: it writes `DIR/.wanted` holding a
//! sequence number, one more than the file held before (so it keeps rising across restarts),
//! after listing the folder. A tethering script, a person watching the folder, or the
//! simulator's grab mode (`roomlight sim --grab`) shoots once per new number; the file is
//! hidden, so it is never taken for a photograph.

use crate::Backend;
use crate::error::CameraError;
use crate::frame::{Frame, decode_file};
use notify::Watcher;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const POLL: Duration = Duration::from_millis(50);
const IMAGE_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "tif", "tiff", "dng"];
/// The file an armed backend writes its request's sequence number to, in its folder.
pub const WANTED: &str = ".wanted";

/// The sequence number in `dir`'s [`WANTED`] file; 0 when there is none (or it is not one).
pub fn wanted(dir: &Path) -> u64 {
    std::fs::read_to_string(dir.join(WANTED))
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(0)
}

/// Waits for new image files in a folder.
#[derive(Debug, Clone)]
pub struct FolderBackend {
    name: String,
    dir: PathBuf,
    settle: Duration,
    max_pixels: u64,
}

/// What is known of a candidate file: its size and since when it has had it.
#[derive(Debug)]
struct Seen {
    len: u64,
    since: Instant,
    /// The last decode error at this size, kept for the timeout's message.
    failed: Option<CameraError>,
}

impl FolderBackend {
    pub fn new(dir: PathBuf, settle: Duration, max_pixels: u64) -> Self {
        Self {
            name: format!("folder:{}", dir.display()),
            dir,
            settle,
            max_pixels,
        }
    }

    fn images(&self) -> Result<Vec<(PathBuf, u64)>, CameraError> {
        let gone = |e: std::io::Error| CameraError::Gone {
            camera: self.name.clone(),
            reason: e.to_string(),
        };
        let mut out = Vec::new();
        for entry in std::fs::read_dir(&self.dir).map_err(gone)? {
            let entry = entry.map_err(gone)?;
            let path = entry.path();
            if is_image_name(&path) {
                // A file deleted between the listing and here is simply not a candidate.
                if let Ok(meta) = entry.metadata()
                    && meta.is_file()
                {
                    out.push((path, meta.len()));
                }
            }
        }
        out.sort();
        Ok(out)
    }
}

fn is_image_name(path: &Path) -> bool {
    let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
        return false;
    };
    !name.starts_with('.')
        && path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// A capture asked for: the files present then are ignored, events are being watched.
/// [`FolderBackend::capture`] arms and waits at once; arming first lets a caller ask for the
/// capture before it causes the photograph (or, in tests, before writing the file).
#[derive(Debug)]
pub struct Armed {
    backend: FolderBackend,
    started: Instant,
    before: HashSet<PathBuf>,
    events: std::sync::mpsc::Receiver<()>,
    /// Kept alive for the wait: dropping it stops the events.
    _watcher: Option<notify::RecommendedWatcher>,
}

impl FolderBackend {
    /// Lists the folder now; only files that appear after this count.
    pub fn arm(&self) -> Result<Armed, CameraError> {
        let started = Instant::now();
        let (tx, events) = std::sync::mpsc::channel();
        // Watching before listing: a file written in between is an event, not lost. Without
        // inotify (a network file system, limits reached) the poll still finds it.
        let watcher = notify::recommended_watcher(move |_event| {
            let _ = tx.send(());
        })
        .and_then(|mut w| {
            w.watch(&self.dir, notify::RecursiveMode::NonRecursive)?;
            Ok(w)
        });
        if let Err(e) = &watcher {
            tracing::debug!(camera = %self.name, "no file events ({e}); polling");
        }
        let before = self.images()?.into_iter().map(|(p, _)| p).collect();
        self.announce()?;
        Ok(Armed {
            backend: self.clone(),
            started,
            before,
            events,
            _watcher: watcher.ok(),
        })
    }
}

impl FolderBackend {
    /// Writes the next sequence number to `.wanted`, renamed into place so that a reader never
    /// sees half a number.
    fn announce(&self) -> Result<(), CameraError> {
        let next = wanted(&self.dir) + 1;
        let tmp = self.dir.join(format!("{WANTED}.tmp"));
        std::fs::write(&tmp, format!("{next}\n"))
            .and_then(|()| std::fs::rename(&tmp, self.dir.join(WANTED)))
            .map_err(|e| CameraError::Gone {
                camera: self.name.clone(),
                reason: format!("announcing the capture in {WANTED}: {e}"),
            })
    }
}

impl Armed {
    /// The first new file that is complete, decoded; a timeout naming the camera (or the
    /// decode error of a file that never became readable) at `deadline`.
    pub fn wait(self, deadline: Instant) -> Result<Frame, CameraError> {
        let this = &self.backend;
        let mut candidates: HashMap<PathBuf, Seen> = HashMap::new();
        loop {
            let now = Instant::now();
            for (path, len) in this.images()? {
                if self.before.contains(&path) {
                    continue;
                }
                let seen = candidates.entry(path.clone()).or_insert(Seen {
                    len,
                    since: now,
                    failed: None,
                });
                if seen.len != len {
                    *seen = Seen {
                        len,
                        since: now,
                        failed: None,
                    };
                }
                if len > 0 && seen.failed.is_none() && now - seen.since >= this.settle {
                    match decode_file(&path, this.max_pixels) {
                        Ok(frame) => return Ok(frame),
                        Err(e) => seen.failed = Some(e),
                    }
                }
            }
            let now = Instant::now();
            if now >= deadline {
                // A file that arrived but never decoded says more than "nothing came".
                let failed = candidates.into_values().filter_map(|s| s.failed).next();
                return Err(failed.unwrap_or(CameraError::Timeout {
                    camera: this.name.clone(),
                    after: now - self.started,
                }));
            }
            let _ = self.events.recv_timeout(POLL.min(deadline - now));
        }
    }
}

impl Backend for FolderBackend {
    fn name(&self) -> &str {
        &self.name
    }

    fn capture(&mut self, deadline: Instant) -> Result<Frame, CameraError> {
        self.arm()?.wait(deadline)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each arming announces one more than the folder's `.wanted` held, restarts included, and
    /// the announcement is not taken for a photograph.
    #[test]
    fn arming_announces_a_rising_sequence_number() {
        let dir = tempfile::tempdir().expect("temp dir");
        assert_eq!(wanted(dir.path()), 0);
        let backend = FolderBackend::new(dir.path().to_path_buf(), Duration::ZERO, 1 << 20);
        let first = backend.arm().expect("arm");
        assert_eq!(wanted(dir.path()), 1);
        drop(first);
        let again = FolderBackend::new(dir.path().to_path_buf(), Duration::ZERO, 1 << 20);
        let armed = again.arm().expect("arm");
        assert_eq!(wanted(dir.path()), 2);
        let err = armed
            .wait(Instant::now() + Duration::from_millis(120))
            .expect_err("nothing but .wanted was written");
        assert!(matches!(err, CameraError::Timeout { .. }), "{err}");
    }
}
