//! Memory as the benches report it: the process's resident set from `/proc/self/status`
//! (`VmRSS` now, `VmHWM` its peak), not a counting allocator in the production binary. The
//! figures are whole pages the process holds, freed or not: memory the allocator keeps after a
//! free is still counted, and memory freed by an earlier case can be reused by a later one
//! without showing as growth. Deltas are meaningful over many nodes or large structures, where
//! one 4 KiB page does not matter. Off Linux there are no figures (`None`).

/// The resident set now and its peak, in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Resident {
    pub now: u64,
    pub peak: u64,
}

/// Reads `VmRSS` and `VmHWM`; `None` where `/proc/self/status` does not exist or lacks them.
pub fn resident() -> Option<Resident> {
    resident_in("/proc/self/status")
}

/// The same of another process (`/proc/PID/status`); `None` once it has gone.
pub fn resident_of(pid: u32) -> Option<Resident> {
    resident_in(&format!("/proc/{pid}/status"))
}

fn resident_in(path: &str) -> Option<Resident> {
    let status = std::fs::read_to_string(path).ok()?;
    let field = |name: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|rest| rest.trim().strip_suffix("kB"))
            .and_then(|kb| kb.trim().parse::<u64>().ok())
            .map(|kb| kb * 1024)
    };
    Some(Resident {
        now: field("VmRSS:")?,
        peak: field("VmHWM:")?,
    })
}

/// Resets the peak to the resident set now (Linux ≥ 4.0: `5` into `/proc/self/clear_refs`);
/// false when it could not, and the peak then is the process's since it started.
pub fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// Runs `f` and returns its value with how far the resident set's peak rose above where it
/// was, in MB (`None` without the figures or when the peak could not be reset).
pub fn peak_growth<T>(f: impl FnOnce() -> T) -> (T, Option<f64>) {
    let before = resident();
    let reset = reset_peak();
    let value = f();
    let grown = match (before, resident()) {
        (Some(b), Some(a)) if reset => Some(a.peak.saturating_sub(b.now) as f64 / 1e6),
        _ => None,
    };
    (value, grown)
}

/// A figure in MB for a table: `n/a` without one.
pub fn mb(v: Option<f64>) -> String {
    v.map_or_else(|| "n/a".into(), |v| format!("{v:.1} MB"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_resident_set_grows_with_touched_memory() {
        let Some(before) = resident() else {
            return; // not Linux: nothing to measure
        };
        assert!(before.now > 0 && before.peak >= before.now);
        // 64 MB touched page by page must show, whatever the allocator keeps.
        let (sum, grown) = peak_growth(|| {
            let v = vec![1u8; 64 << 20];
            v.iter().step_by(4096).map(|&b| u64::from(b)).sum::<u64>()
        });
        assert_eq!(sum, (64 << 20) / 4096);
        if let Some(g) = grown {
            assert!(g > 60.0, "peak grew {g} MB for 64 MB touched");
        }
    }
}
