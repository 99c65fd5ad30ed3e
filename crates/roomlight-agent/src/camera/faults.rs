//! The camera's health as the round loop sees it: a typed state ([`CameraState`], published in
//! the room's status for the console) and how long to wait before the next capture after a
//! failure (200 ms doubling to 10 s). Pure: the time is passed in. It knows nothing of rounds,
//! peers or how a capture is taken.

use std::time::{Duration, SystemTime};

/// The first wait after a failed capture.
pub const RETRY_FIRST: Duration = Duration::from_millis(200);
/// The longest wait between two attempts: a camera plugged back in is used within this.
pub const RETRY_MAX: Duration = Duration::from_secs(10);

/// Whether the camera agent's camera delivers captures it can use.
#[derive(Debug, Clone, Default, PartialEq)]
pub enum CameraState {
    /// The last capture worked (or none has been tried yet).
    #[default]
    Ok,
    /// The last `failures` captures failed (or timed out) since `since` (wall clock); the next
    /// is tried `retry_in` after the last failure. Rounds are abandoned meanwhile and the
    /// projectors keep their light.
    Failing {
        since: SystemTime,
        failures: u32,
        last_error: String,
        retry_in: Duration,
    },
}

/// The wait after the `failures`-th failure in a row (from 1): [`RETRY_FIRST`], doubling, at
/// most [`RETRY_MAX`].
pub(super) fn retry_wait(failures: u32) -> Duration {
    let doublings = failures.saturating_sub(1).min(16);
    (RETRY_FIRST * (1u32 << doublings)).min(RETRY_MAX)
}

/// The camera's state and its transitions.
#[derive(Debug, Default)]
pub(super) struct CameraHealth {
    state: CameraState,
}

/// An outage that ended: how many captures failed and since when.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Recovered {
    pub(super) failures: u32,
    pub(super) since: SystemTime,
}

impl CameraHealth {
    pub(super) fn state(&self) -> &CameraState {
        &self.state
    }

    /// A capture failed at `now` with `error`: the wait before the next attempt.
    pub(super) fn failed(&mut self, error: String, now: SystemTime) -> Duration {
        let (since, failures) = match &self.state {
            CameraState::Ok => (now, 1),
            CameraState::Failing {
                since, failures, ..
            } => (*since, failures.saturating_add(1)),
        };
        let retry_in = retry_wait(failures);
        self.state = CameraState::Failing {
            since,
            failures,
            last_error: error,
            retry_in,
        };
        retry_in
    }

    /// A capture worked: the outage it ends, if it ends one.
    pub(super) fn succeeded(&mut self) -> Option<Recovered> {
        match std::mem::take(&mut self.state) {
            CameraState::Ok => None,
            CameraState::Failing {
                since, failures, ..
            } => Some(Recovered { failures, since }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_double_from_200_ms_to_10_s() {
        let ms: Vec<u128> = (1..=9).map(|f| retry_wait(f).as_millis()).collect();
        assert_eq!(
            ms,
            [200, 400, 800, 1600, 3200, 6400, 10_000, 10_000, 10_000]
        );
        assert_eq!(retry_wait(0), RETRY_FIRST, "never below the first wait");
        assert_eq!(retry_wait(u32::MAX), RETRY_MAX, "no overflow");
    }

    #[test]
    fn failures_accumulate_from_the_first_and_a_success_ends_the_outage_once() {
        let t0 = SystemTime::UNIX_EPOCH + Duration::from_secs(1000);
        let mut health = CameraHealth::default();
        assert_eq!(health.state(), &CameraState::Ok);
        assert_eq!(health.succeeded(), None, "no outage to end");
        assert_eq!(health.failed("gone".into(), t0), RETRY_FIRST);
        let later = t0 + Duration::from_secs(1);
        assert_eq!(
            health.failed("no image within 2s".into(), later),
            RETRY_FIRST * 2
        );
        assert_eq!(
            health.state(),
            &CameraState::Failing {
                since: t0,
                failures: 2,
                last_error: "no image within 2s".into(),
                retry_in: RETRY_FIRST * 2,
            }
        );
        assert_eq!(
            health.succeeded(),
            Some(Recovered {
                failures: 2,
                since: t0
            })
        );
        assert_eq!(health.state(), &CameraState::Ok);
        assert_eq!(health.succeeded(), None);
        // A new outage starts from the first wait again.
        assert_eq!(health.failed("gone".into(), later), RETRY_FIRST);
    }
}
