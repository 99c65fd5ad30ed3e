//! What a node agent remembers across sessions and restarts: the value each node last showed,
//! the calibration epoch they belong to, the assignment and attenuation the camera agent sent,
//! and the state file that keeps them on disk (written atomically, at most once a second).
//!
//! It knows nothing of the wire or of sessions: the session hands it values and columns, and the
//! node agent asks it to relight a display or to flush. A state file that cannot be read, or
//! that is another projector's, is set aside (renamed `*.corrupt-<unix time>`) and the node
//! starts fresh, saying why: a projector must never stay dark for a bad file. Values of nodes
//! the camera agent does not assign to this projector are forgotten.

use crate::AgentError;
use crate::hardware::{Assignment, Display, Gains};
use roomlight_core::{AttenuationColumn, LinearRgb};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// What a node agent keeps on disk: the values its nodes show, and the calibration they belong to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SavedState {
    /// Calibration epoch the values were computed under.
    pub calibration_epoch: u64,
    /// Node id → linear light shown.
    pub values: Vec<(u32, LinearRgb)>,
    /// The nodes' weights and response when the camera agent segmented this projector over
    /// the wire (so that a restarted node can draw its values before it reconnects).
    #[serde(default)]
    pub assignment: Option<Assignment>,
    /// Node id → its attenuation column as the camera agent last sent it (sent back in Hello
    /// with the values).
    #[serde(default)]
    pub attenuation: Vec<(u32, AttenuationColumn)>,
    /// The projector whose state this is (absent in files of older builds).
    #[serde(default)]
    pub projector: Option<String>,
    /// Its per-pixel shading gains (checked against their size and bounds when read).
    #[serde(default)]
    pub gains: Option<Gains>,
}

impl SavedState {
    /// Reads a state file; a missing file is `Ok(None)`, an unreadable one an error naming it.
    pub fn load(path: &Path) -> Result<Option<Self>, AgentError> {
        let named = |e: &dyn std::fmt::Display| {
            AgentError::Protocol(format!("state file {}: {e}", path.display()))
        };
        let text = match std::fs::read_to_string(path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(named(&e)),
        };
        let mut state: Self = serde_json::from_str(&text).map_err(|e| named(&e))?;
        if state.values.iter().any(|(_, v)| !v.is_finite()) {
            return Err(named(&"a value is not finite"));
        }
        if let Some(a) = &state.assignment {
            crate::hardware::validate_assignment(a, &format!("state file {}", path.display()))?;
        }
        // Deserialised columns are not checked: build them anew.
        for (node, column) in &mut state.attenuation {
            *column = AttenuationColumn::new(column.support().to_vec(), column.values().to_vec())
                .map_err(|e| named(&format!("attenuation of node {node}: {e}")))?;
        }
        Ok(Some(state))
    }

    /// Writes the state atomically: a temporary file beside it, synced, then renamed over it.
    pub fn save(&self, path: &Path) -> Result<(), AgentError> {
        let io =
            |e: std::io::Error| AgentError::Protocol(format!("state file {}: {e}", path.display()));
        let tmp = path.with_extension("tmp");
        let text = serde_json::to_string(self).map_err(|e| AgentError::Protocol(e.to_string()))?;
        {
            let mut f = std::fs::File::create(&tmp).map_err(io)?;
            f.write_all(text.as_bytes()).map_err(io)?;
            f.sync_all().map_err(io)?;
        }
        std::fs::rename(&tmp, path).map_err(io)
    }
}

/// A node agent's memory: what the next session starts from, and its state file.
#[derive(Debug)]
pub(super) struct Memory {
    /// The last value each node showed: the start of the next session.
    pub(super) values: HashMap<u32, LinearRgb>,
    /// The calibration epoch of `values`.
    pub(super) epoch: u64,
    /// The assignment received over the wire, kept with the values.
    pub(super) assignment: Option<Assignment>,
    /// Each node's last attenuation column.
    pub(super) attenuation: HashMap<u32, AttenuationColumn>,
    /// The per-pixel shading gains its display draws with (kept across sessions, not in the
    /// state file: a restarted node starts flat and the camera agent's passes step it again).
    pub(super) gains: Option<Gains>,
    path: Option<PathBuf>,
    last_write: Option<Instant>,
    /// Whose memory this is (written into the state file).
    projector: String,
}

impl Memory {
    /// The memory kept in `path` (empty when there is no file or no path), shown at once on
    /// `display` so that the lights come back before any camera agent is reachable. A file that
    /// cannot be read or is another projector's is set aside and the memory starts empty (the
    /// nodes start at the configured start value), with a warning saying why.
    pub(super) fn relight(
        path: Option<PathBuf>,
        display: &mut impl Display,
        projector: &str,
    ) -> Self {
        let mut memory = Self {
            values: HashMap::new(),
            epoch: 0,
            assignment: None,
            attenuation: HashMap::new(),
            gains: None,
            path,
            last_write: None,
            projector: projector.to_string(),
        };
        let Some(path) = memory.path.as_deref() else {
            return memory;
        };
        let saved = match SavedState::load(path) {
            Ok(Some(saved)) => match &saved.projector {
                Some(other) if other != projector => {
                    set_aside(path, &format!("it is projector {other:?}'s"));
                    return memory;
                }
                _ => saved,
            },
            Ok(None) => return memory,
            Err(e) => {
                set_aside(path, &e.to_string());
                return memory;
            }
        };
        if let Some(a) = &saved.assignment {
            display.assign(a);
        }
        if let Some(g) = &saved.gains {
            display.shade(Some(g));
        }
        for &(node, value) in &saved.values {
            display.show(node, value);
        }
        tracing::info!(%projector, nodes = saved.values.len(), "relit from the state file");
        memory.values = saved.values.into_iter().collect();
        memory.epoch = saved.calibration_epoch;
        memory.assignment = saved.assignment;
        memory.attenuation = saved.attenuation.into_iter().collect();
        memory.gains = saved.gains;
        memory
    }

    /// The camera agent assigned `nodes` to this projector: values and columns of any other
    /// node (a state file's, not this projector's) are forgotten.
    pub(super) fn keep_only(&mut self, nodes: &[u32]) {
        let before = self.values.len() + self.attenuation.len();
        self.values.retain(|n, _| nodes.contains(n));
        self.attenuation.retain(|n, _| nodes.contains(n));
        let dropped = before - self.values.len() - self.attenuation.len();
        if dropped > 0 {
            tracing::warn!(
                dropped,
                "remembered nodes this projector is not assigned: forgotten"
            );
        }
    }

    /// Values from another calibration mean nothing now: forget them.
    pub(super) fn forget_values(&mut self) {
        self.values.clear();
        self.attenuation.clear();
    }

    /// Writes the state file unless it was written less than a second ago.
    pub(super) fn maybe_flush(&mut self) {
        if self
            .last_write
            .is_none_or(|t| t.elapsed() >= Duration::from_secs(1))
        {
            self.flush();
        }
    }

    /// Writes the state file now (when there is one).
    pub(super) fn flush(&mut self) {
        let Some(path) = &self.path else { return };
        let mut values: Vec<(u32, LinearRgb)> = self.values.iter().map(|(&n, &v)| (n, v)).collect();
        values.sort_by_key(|(n, _)| *n);
        let mut attenuation: Vec<(u32, AttenuationColumn)> = self
            .attenuation
            .iter()
            .map(|(&n, c)| (n, c.clone()))
            .collect();
        attenuation.sort_by_key(|(n, _)| *n);
        let saved = SavedState {
            calibration_epoch: self.epoch,
            values,
            assignment: self.assignment.clone(),
            attenuation,
            projector: Some(self.projector.clone()),
            gains: self.gains.clone(),
        };
        if let Err(e) = saved.save(path) {
            // The lights matter more than the file: log and carry on.
            tracing::warn!(error = %e, "could not write the state file");
        }
        self.last_write = Some(Instant::now());
    }
}

/// Renames an unusable state file to `<name>.corrupt-<unix seconds>` (kept for a post-mortem,
/// out of the node's way) and says why; if even that fails, says so (the node starts fresh and
/// its next flush overwrites the file).
fn set_aside(path: &Path, why: &str) {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let mut aside = path.as_os_str().to_owned();
    aside.push(format!(".corrupt-{secs}"));
    let aside = PathBuf::from(aside);
    match std::fs::rename(path, &aside) {
        Ok(()) => tracing::warn!(
            file = %path.display(), moved_to = %aside.display(), why,
            "state file unusable: set aside; the nodes start fresh"
        ),
        Err(e) => tracing::warn!(
            file = %path.display(), why, error = %e,
            "state file unusable and could not be set aside; the nodes start fresh"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A state file whose attenuation is not a valid column (unsorted support) is refused
    /// with a message that names the file and the node; a valid one reads back as written.
    #[test]
    fn state_files_check_their_attenuation() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("p.state.json");
        let column = AttenuationColumn::new(
            vec![1, 4],
            vec![LinearRgb::splat(0.5), LinearRgb::splat(0.25)],
        )
        .expect("column");
        let saved = SavedState {
            calibration_epoch: 3,
            values: vec![(7, LinearRgb::splat(0.4))],
            assignment: None,
            attenuation: vec![(7, column)],
            projector: Some("p".into()),
            gains: None,
        };
        saved.save(&path).expect("save");
        assert_eq!(SavedState::load(&path).expect("load"), Some(saved));
        let text = std::fs::read_to_string(&path).expect("read");
        std::fs::write(&path, text.replace("[1,4]", "[4,1]")).expect("corrupt");
        let e = SavedState::load(&path)
            .expect_err("unsorted support")
            .to_string();
        assert!(e.contains("p.state.json") && e.contains("node 7"), "{e}");
    }

    /// Shading gains survive a restart: saved, read back equal, and drawn by the display the
    /// node relights; gains out of their bounds (or of another block count) are refused naming
    /// the file, and the node starts flat.
    #[test]
    fn state_files_keep_the_shading_gains_and_check_them() {
        use roomlight_calib::shading::{Gains, Ratios};
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("g.state.json");
        let (w, h) = (40, 20);
        let mut gains = Gains::flat(w, h).expect("gains");
        let ratios = Ratios::from_blocks(w, h, vec![Some([2.0, 1.0, 0.5]); 6]).expect("ratios");
        gains.step(&ratios, 1.0).expect("step");
        let saved = SavedState {
            calibration_epoch: 1,
            values: vec![(2, LinearRgb::splat(0.3))],
            assignment: None,
            attenuation: Vec::new(),
            projector: Some("g".into()),
            gains: Some(gains.clone()),
        };
        saved.save(&path).expect("save");
        assert_eq!(SavedState::load(&path).expect("load"), Some(saved));
        struct Shaded(Option<Gains>);
        impl Display for Shaded {
            fn show(&mut self, _: u32, _: LinearRgb) {}
            fn shade(&mut self, gains: Option<&Gains>) {
                self.0 = gains.cloned();
            }
        }
        let mut display = Shaded(None);
        let memory = Memory::relight(Some(path.clone()), &mut display, "g");
        assert_eq!(display.0.as_ref(), Some(&gains));
        assert_eq!(memory.gains.as_ref(), Some(&gains));
        let text = std::fs::read_to_string(&path).expect("read");
        for (edit, says) in [
            (
                text.replacen("[2.0,1.0,0.5]", "[2.0,1.0,500.0]", 1),
                "block 0",
            ),
            (text.replacen("[2.0,1.0,0.5],", "", 1), "5 blocks"),
        ] {
            assert_ne!(edit, text, "the edit applies");
            std::fs::write(&path, &edit).expect("corrupt");
            let e = SavedState::load(&path).expect_err(says).to_string();
            assert!(e.contains("g.state.json") && e.contains(says), "{e}");
        }
        let mut display = Shaded(None);
        let memory = Memory::relight(Some(path), &mut display, "g");
        assert!(display.0.is_none() && memory.gains.is_none());
    }

    /// A missing file is no state; a file that is not JSON, or whose value is out of range
    /// (JSON has no infinity), is refused naming the file.
    #[test]
    fn missing_files_are_empty_and_broken_ones_are_named() {
        // Over 80 lines: one case after another, each a file and what loading it must say.
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("q.state.json");
        assert_eq!(SavedState::load(&path).expect("missing"), None);
        std::fs::write(&path, "{ not json").expect("write");
        let e = SavedState::load(&path).expect_err("not json").to_string();
        assert!(e.contains("q.state.json"), "{e}");
        std::fs::write(
            &path,
            r#"{"calibration_epoch":1,"values":[[0,[1e999,0,0]]]}"#,
        )
        .expect("write");
        let e = SavedState::load(&path).expect_err("infinite").to_string();
        assert!(e.contains("q.state.json"), "{e}");
    }

    /// A display that records what it was told to show.
    #[derive(Default)]
    struct Recorder(HashMap<u32, LinearRgb>);

    impl Display for Recorder {
        fn show(&mut self, node: u32, value: LinearRgb) {
            self.0.insert(node, value);
        }
    }

    /// The memory written by one node agent relights the next one's display and starts its
    /// session from the same values and epoch.
    #[test]
    fn a_flushed_memory_relights_the_next_run() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("r.state.json");
        let mut first = Memory::relight(Some(path.clone()), &mut Recorder::default(), "r");
        assert!(first.values.is_empty() && first.epoch == 0);
        first.values.insert(2, LinearRgb::splat(0.3));
        first.epoch = 5;
        first.flush();
        let mut display = Recorder::default();
        let second = Memory::relight(Some(path), &mut display, "r");
        assert_eq!(second.epoch, 5);
        assert_eq!(second.values, first.values);
        assert_eq!(display.0, first.values);
    }

    /// The files in `dir` whose name starts with `prefix`.
    fn named(dir: &Path, prefix: &str) -> Vec<String> {
        std::fs::read_dir(dir)
            .expect("list")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(prefix))
            .collect()
    }

    /// A corrupt state file does not keep a projector dark: it is renamed `*.corrupt-<time>`
    /// and the node starts fresh (its configured start, nothing relit).
    #[test]
    fn a_corrupt_state_file_is_set_aside_and_the_node_starts_fresh() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("c.state.json");
        std::fs::write(&path, "{ not json").expect("write");
        let mut display = Recorder::default();
        let memory = Memory::relight(Some(path.clone()), &mut display, "c");
        assert!(memory.values.is_empty() && display.0.is_empty());
        assert!(!path.exists(), "moved out of the way");
        let aside = named(dir.path(), "c.state.json.corrupt-");
        assert_eq!(aside.len(), 1, "{aside:?}");
        assert_eq!(
            std::fs::read_to_string(dir.path().join(&aside[0])).expect("kept"),
            "{ not json"
        );
    }

    /// Another projector's state file relights nothing (it is set aside); values of nodes the
    /// camera agent does not assign are forgotten.
    #[test]
    fn another_projectors_state_and_foreign_nodes_are_not_relit() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("d.state.json");
        let saved = SavedState {
            calibration_epoch: 1,
            values: vec![(0, LinearRgb::splat(0.9)), (5, LinearRgb::splat(0.2))],
            assignment: None,
            attenuation: Vec::new(),
            projector: Some("p1".into()),
            gains: None,
        };
        saved.save(&path).expect("save");
        let mut display = Recorder::default();
        let memory = Memory::relight(Some(path.clone()), &mut display, "p0");
        assert!(
            memory.values.is_empty() && display.0.is_empty(),
            "p1's nodes lit by p0"
        );
        assert_eq!(named(dir.path(), "d.state.json.corrupt-").len(), 1);
        // An older file without a projector: relit, then cut to what the camera assigns.
        let older = SavedState {
            projector: None,
            gains: None,
            ..saved
        };
        older.save(&path).expect("save");
        let mut memory = Memory::relight(Some(path), &mut display, "p0");
        assert_eq!(memory.values.len(), 2);
        memory.keep_only(&[5]);
        assert_eq!(memory.values.keys().copied().collect::<Vec<_>>(), [5]);
    }
}
