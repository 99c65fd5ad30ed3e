//! The process's last warnings, for the console: a `tracing` layer keeps the last
//! [`KEPT`] events at WARN or ERROR (message and fields, as the log prints them, cut to
//! [`MAX_LEN`] characters) in a process-wide ring. The binary adds the layer to its subscriber;
//! without it the ring stays empty. Fields a peer chose are already escaped by the code that
//! logs them, and the page shows them as text, never as HTML.

use std::collections::VecDeque;
use std::fmt::Write as _;
use std::sync::{Mutex, PoisonError};
use std::time::{SystemTime, UNIX_EPOCH};
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::layer::Context;

/// Warnings kept.
pub const KEPT: usize = 50;
/// Characters kept of one warning.
pub const MAX_LEN: usize = 500;

/// One warning.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Warning {
    pub unix_ms: u64,
    pub level: String,
    pub message: String,
}

static RING: Mutex<VecDeque<Warning>> = Mutex::new(VecDeque::new());

/// The warnings kept, oldest first.
pub fn recent() -> Vec<Warning> {
    RING.lock()
        .unwrap_or_else(PoisonError::into_inner)
        .iter()
        .cloned()
        .collect()
}

/// Keeps a warning (the layer's work, public for tests and for events the log does not see).
pub fn keep(level: &str, message: String) {
    let mut message = message;
    if message.chars().count() > MAX_LEN {
        message = message.chars().take(MAX_LEN).collect::<String>() + "…";
    }
    let unix_ms = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX));
    let mut ring = RING.lock().unwrap_or_else(PoisonError::into_inner);
    if ring.len() >= KEPT {
        ring.pop_front();
    }
    ring.push_back(Warning {
        unix_ms,
        level: level.to_string(),
        message,
    });
}

/// The layer that fills the ring.
#[derive(Debug, Default, Clone, Copy)]
pub struct Layer;

impl<S: Subscriber> tracing_subscriber::Layer<S> for Layer {
    fn on_event(&self, event: &Event<'_>, _ctx: Context<'_, S>) {
        let level = *event.metadata().level();
        if level > Level::WARN {
            return;
        }
        let mut text = Text::default();
        event.record(&mut text);
        keep(level.as_str(), text.0);
    }
}

/// An event's message, then its fields as `name=value`.
#[derive(Default)]
struct Text(String);

impl Visit for Text {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if self.0.len() > 4 * MAX_LEN {
            return;
        }
        if field.name() == "message" {
            let fields = std::mem::take(&mut self.0);
            let _ = write!(self.0, "{value:?}");
            self.0.push_str(&fields);
        } else {
            let _ = write!(self.0, " {}={value:?}", field.name());
        }
    }

    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            let fields = std::mem::take(&mut self.0);
            self.0.push_str(value);
            self.0.push_str(&fields);
        } else {
            self.record_debug(field, &value);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tracing_subscriber::layer::SubscriberExt;

    /// Warnings and errors are kept with their fields, infos are not, the ring is bounded.
    #[test]
    fn the_layer_keeps_the_last_warnings() {
        let subscriber = tracing_subscriber::registry().with(Layer);
        tracing::subscriber::with_default(subscriber, || {
            tracing::info!("not kept");
            tracing::warn!(projector = "p1", "late: left out of this round");
            for i in 0..KEPT + 5 {
                tracing::error!(i, "burst");
            }
            tracing::warn!(projector = "p2", "last one");
        });
        let kept = recent();
        assert_eq!(kept.len(), KEPT);
        let last = kept.last().expect("a warning");
        assert_eq!(last.level, "WARN");
        assert_eq!(last.message, "last one projector=\"p2\"");
        assert!(kept.iter().all(|w| w.message != "not kept"));
    }
}
