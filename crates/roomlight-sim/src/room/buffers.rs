//! The buffer a render needs for each projector frame (the light of every pixel, then its
//! summed-area table in place), kept for the next render. A lab projector's is 19 MB; allocated
//! afresh for every frame, glibc mapped and unmapped it each time, and the page faults of
//! zeroing it again cost more wall time than computing the light: 36.7 s of system time in the
//! full demo's 244 s of CPU, 10.4 M page faults; with the buffer kept, 7.6 s and 0.98 M
//! (2026-11-28, docs/results.md, "Faster simulated captures"). Hand-written: a mutex around a
//! short list, which no pool crate makes simpler.

use roomlight_core::LinearRgb;
use std::sync::{Mutex, PoisonError};

/// Buffers kept beyond this many are freed: a render needs one at a time (its frames one after
/// the other), and the demo renders one capture at a time. Two kept added their 19 MB to the
/// demo's peak, in projection mapping, where two rooms are alive.
const KEPT: usize = 1;

/// A pool of per-pixel light buffers, shared by the renders of a room on any thread.
#[derive(Default)]
pub(super) struct Buffers(Mutex<Vec<Vec<LinearRgb>>>);

impl std::fmt::Debug for Buffers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kept = self.0.lock().unwrap_or_else(PoisonError::into_inner).len();
        write!(f, "Buffers({kept} kept)")
    }
}

impl Buffers {
    /// A buffer of `len` values, reusing a kept one when there is one: what a kept one held is
    /// still there (the caller writes every value; zeroing 19 MB first was 2.5% of a capture).
    pub(super) fn take(&self, len: usize) -> Vec<LinearRgb> {
        let mut v = self
            .0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .pop()
            .unwrap_or_default();
        v.resize(len, LinearRgb::ZERO);
        v
    }

    /// Keeps `v` for a later [`Self::take`] (frees it when enough are kept).
    pub(super) fn give(&self, v: Vec<LinearRgb>) {
        let mut kept = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        if kept.len() < KEPT {
            kept.push(v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A buffer given back comes out again at the length asked, with its memory reused; a new
    /// one is zeros.
    #[test]
    fn a_kept_buffer_is_reused() {
        let pool = Buffers::default();
        let mut v = pool.take(1000);
        assert_eq!(v.len(), 1000);
        assert!(v.iter().all(|l| l.0.map(f64::to_bits) == [0; 3]));
        v[3] = LinearRgb([1.0, 2.0, 3.0]);
        let at = v.as_ptr();
        pool.give(v);
        let w = pool.take(500);
        assert_eq!(w.as_ptr(), at, "the kept allocation is reused");
        assert_eq!(w.len(), 500);
        pool.give(w);
        assert_eq!(pool.take(2000).len(), 2000);
        for _ in 0..KEPT + 3 {
            pool.give(vec![LinearRgb::ZERO; 4]);
        }
        assert_eq!(pool.0.lock().expect("pool").len(), KEPT);
    }
}
