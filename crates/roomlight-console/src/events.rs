//! Server-Sent Events: one task serialises the status once per update (on every change, at
//! most [`MAX_RATE`] times a second, and at least every [`HEARTBEAT`]: 2.5 a second) and offers it to every
//! open stream without waiting; a stream whose queue is full (its browser does not read) is
//! dropped, and at most [`MAX_STREAMS`] are open at once.

use crate::Console;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

/// Streams open at once.
pub const MAX_STREAMS: usize = 32;
/// Updates queued for one stream before it counts as lagging.
pub const QUEUE: usize = 8;
/// An update at least this often (the page's liveness).
pub const HEARTBEAT: Duration = Duration::from_millis(400);
/// At most this many updates a second.
pub const MAX_RATE: u32 = 5;

/// The open streams.
#[derive(Debug, Default)]
pub struct Hub {
    streams: Mutex<Vec<mpsc::Sender<Arc<str>>>>,
}

impl Hub {
    fn streams(&self) -> std::sync::MutexGuard<'_, Vec<mpsc::Sender<Arc<str>>>> {
        self.streams.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// A new stream, starting with `first`; `None` when [`MAX_STREAMS`] are open.
    pub fn subscribe(&self, first: Arc<str>) -> Option<mpsc::Receiver<Arc<str>>> {
        let mut streams = self.streams();
        streams.retain(|s| !s.is_closed());
        if streams.len() >= MAX_STREAMS {
            return None;
        }
        let (tx, rx) = mpsc::channel(QUEUE);
        let _ = tx.try_send(first);
        streams.push(tx);
        Some(rx)
    }

    /// Offers `update` to every stream; returns how many were dropped for lagging.
    fn offer(&self, update: &Arc<str>) -> usize {
        let mut dropped = 0;
        self.streams().retain(|s| match s.try_send(update.clone()) {
            Ok(()) => true,
            Err(mpsc::error::TrySendError::Full(_)) => {
                dropped += 1;
                false
            }
            Err(mpsc::error::TrySendError::Closed(_)) => false,
        });
        dropped
    }

    /// Streams open now.
    pub fn len(&self) -> usize {
        self.streams().iter().filter(|s| !s.is_closed()).count()
    }
}

/// Publishes the status to the streams until `cancel`.
pub async fn publish(console: Arc<Console>, cancel: CancellationToken) {
    let mut status = console.status.clone();
    let mut overview = console.overview.clone();
    let pause = Duration::from_secs(1) / MAX_RATE;
    let mut heartbeat = tokio::time::interval(HEARTBEAT);
    heartbeat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            changed = status.changed() => if changed.is_err() { return },
            changed = overview.changed() => if changed.is_err() { return },
            _ = heartbeat.tick() => {}
            () = cancel.cancelled() => return,
        }
        status.borrow_and_update();
        overview.borrow_and_update();
        if console.events.len() > 0 {
            let update: Arc<str> = crate::api::status_json(&console).to_string().into();
            let dropped = console.events.offer(&update);
            if dropped > 0 {
                tracing::info!(
                    dropped,
                    "console: event streams dropped (their browsers did not read)"
                );
            }
        }
        tokio::time::sleep(pause).await;
    }
}
