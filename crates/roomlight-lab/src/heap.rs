//! glibc's allocator, tuned for the simulated room: two calls into `libc`, the only unsafe code
//! of the crate (no crate wraps `mallopt` or `malloc_trim`). Elsewhere both do nothing.
//!
//! The simulator renders frames of tens of megabytes on rayon's and tokio's workers. glibc keeps
//! what each thread's arena freed, so the full demo's resident memory grew with the number of
//! arenas and with whatever a phase left freed but mapped: its peak, in projection mapping, was
//! 915 MB with the default arenas, 747–804 MB over three runs with two, and 683–720 MB with two
//! and the freed memory handed back between phases (2026-11-28; docs/results.md).

/// Caps glibc's malloc arenas at two. Call it first thing in `main`, before any thread starts.
///
/// With the default (up to eight per core) the demo peaked at 915 MB, with two at 770 MB, at
/// the same speed (2026-11-28, `GLIBC_TUNABLES=glibc.malloc.arena_max=2`). The agents allocate
/// little on their hot paths, so two serve them as well.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
pub fn limit_arenas() {
    // SAFETY: mallopt only sets a tuning parameter of glibc's allocator; it reports failure by
    // its return value, which leaves the default in place.
    let _ = unsafe { libc::mallopt(libc::M_ARENA_MAX, 2) };
}

/// Caps glibc's malloc arenas (nothing to do with another allocator).
#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn limit_arenas() {}

/// Hands the pages every arena holds free back to the system (`malloc_trim(0)`), so that what
/// one phase freed does not stay resident beside what the next allocates in another arena.
/// A few milliseconds; call it between phases, not per capture.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
pub fn release_free() {
    // SAFETY: malloc_trim takes each arena's lock and only returns whole free pages (madvise);
    // it touches no memory in use, and is safe to call from any thread at any time.
    let _ = unsafe { libc::malloc_trim(0) };
}

/// Hands free memory back to the system (nothing to do with another allocator).
#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn release_free() {}

#[cfg(test)]
mod tests {
    use super::*;

    /// Freed pages leave the resident set: 128 MB of 64 KB buffers (under glibc's mmap
    /// threshold, so in an arena's heap), touched and freed, mostly leave the resident set
    /// after `release_free` (none of it without: 132.8 → 132.8 MB, 2026-11-28). Read from
    /// /proc, so Linux and glibc only.
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[test]
    fn freed_pages_leave_the_resident_set() {
        fn resident_mb() -> f64 {
            let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
            let line = status
                .lines()
                .find(|l| l.starts_with("VmRSS:"))
                .expect("VmRSS line");
            let kb: f64 = line
                .split_whitespace()
                .nth(1)
                .and_then(|v| v.parse().ok())
                .expect("VmRSS in kB");
            kb / 1024.0
        }
        // Other tests of the crate run beside this one and may allocate between the two
        // readings: the best of three tries counts.
        let mut best = f64::NEG_INFINITY;
        let mut readings = Vec::new();
        for _ in 0..3 {
            // Many small buffers (each below any mmap threshold) land in the heap, touched so
            // they are resident, with small ones kept between them so that the heap's top
            // cannot simply shrink.
            let mut kept = Vec::new();
            let mut freed = Vec::new();
            for _ in 0..2048 {
                freed.push(vec![1u8; 64 * 1024]);
                kept.push(vec![2u8; 64]);
            }
            let before = resident_mb();
            drop(freed);
            release_free();
            let after = resident_mb();
            drop(kept);
            best = best.max(before - after);
            readings.push(format!("{before:.1} → {after:.1} MB"));
            if best > 64.0 {
                break;
            }
        }
        assert!(
            best > 64.0,
            "release_free gave back at most {best:.1} MB of 128 MB freed (resident {})",
            readings.join(", ")
        );
    }
}
