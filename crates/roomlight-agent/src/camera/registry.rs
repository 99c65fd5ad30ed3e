//! The registry of live peers: one entry per attached projector (its outbound queue, its nodes,
//! what it shows), admission (checks and insert under one lock), and removal by a guard's
//! `Drop`, so that every way a peer's reader ends cleans up. Waiters are woken on every change.
//! It knows nothing of the model, the camera or the wire's message contents.

use roomlight_proto::v1;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Duration;
use tokio::sync::{Notify, mpsc};
use tonic::Status;

/// The queue of messages to one node agent (the items of its `Attach` response stream).
pub(super) type Outbox = mpsc::Sender<Result<v1::RoomMessage, Status>>;

/// One attached projector.
#[derive(Debug)]
pub(super) struct Peer {
    pub(super) tx: Outbox,
    pub(super) nodes: Vec<u32>,
    /// The last round whose errors this projector has applied and shows (`Some(0)`: its start).
    pub(super) shown: Option<u64>,
    /// The last round sent to it.
    pub(super) awaiting: Option<u64>,
    /// False until its attenuation is known (a hot projector before its calibration): it takes
    /// part in no round.
    pub(super) calibrated: bool,
    /// The last Show pattern it has on its display.
    pub(super) pattern_shown: Option<u64>,
    /// Its resolution and kind, as its Hello said (for calibration over the wire).
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) kind: v1::ProjectorKind,
    /// Which stream this entry belongs to (a reconnected projector gets a new one).
    connection: u64,
}

impl Peer {
    /// A peer as its Hello describes it, before it has shown anything.
    pub(super) fn new(tx: Outbox, nodes: Vec<u32>, calibrated: bool, hello: &v1::Hello) -> Self {
        Self {
            tx,
            nodes,
            shown: None,
            awaiting: None,
            calibrated,
            pattern_shown: None,
            width: hello.width,
            height: hello.height,
            kind: v1::ProjectorKind::try_from(hello.kind).unwrap_or(v1::ProjectorKind::Unspecified),
            connection: 0,
        }
    }

    /// Shows the last frame it was sent (its start at least): it can take the next round.
    pub(super) fn ready(&self) -> bool {
        self.shown.is_some()
            && self
                .awaiting
                .is_none_or(|a| self.shown.is_some_and(|s| s >= a))
    }
}

/// The peers, as seen under the registry's lock.
#[derive(Debug, Default)]
pub(super) struct Peers {
    pub(super) peers: HashMap<String, Peer>,
    next_connection: u64,
}

impl Peers {
    /// The room is still dark: no projector has shown a round's frame yet (bring-up).
    pub(super) fn dark(&self) -> bool {
        self.peers.values().all(|p| p.shown.is_none())
    }

    /// True when every attached, calibrated projector shows the last frame it was sent.
    pub(super) fn all_shown(&self) -> bool {
        self.peers
            .values()
            .filter(|p| p.calibrated)
            .all(Peer::ready)
    }
}

/// The live peers and a notification of every change to them.
#[derive(Debug, Default)]
pub(super) struct Registry {
    peers: Mutex<Peers>,
    changed: Notify,
}

impl Registry {
    /// The peers, locked (never held across an await).
    pub(super) fn lock(&self) -> MutexGuard<'_, Peers> {
        self.peers.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Wakes everyone waiting for a change.
    pub(super) fn notify(&self) {
        self.changed.notify_waiters();
    }

    /// Admits `projector`: refused when it is attached already (one stream per projector: a
    /// reconnecting node is admitted once its old stream has ended or missed its heartbeats);
    /// else inserted, in the same lock. The guard removes it when dropped.
    pub(super) fn admit(
        self: &Arc<Self>,
        projector: &str,
        mut peer: Peer,
    ) -> Result<PeerGuard, Box<Peer>> {
        let mut peers = self.lock();
        if peers.peers.contains_key(projector) {
            return Err(Box::new(peer));
        }
        peers.next_connection += 1;
        peer.connection = peers.next_connection;
        let connection = peer.connection;
        peers.peers.insert(projector.to_string(), peer);
        drop(peers);
        self.notify();
        Ok(PeerGuard {
            registry: self.clone(),
            projector: projector.to_string(),
            connection,
        })
    }

    /// Removes every peer (shutdown); their queues, to say goodbye on.
    pub(super) fn drain(&self) -> Vec<Outbox> {
        let tx: Vec<Outbox> = self.lock().peers.drain().map(|(_, p)| p.tx).collect();
        self.notify();
        tx
    }

    /// Waits until `ready` holds or the deadline passes; true when it holds.
    pub(super) async fn wait_for(
        &self,
        deadline: Duration,
        ready: impl Fn(&Peers) -> bool,
    ) -> bool {
        let until = tokio::time::Instant::now() + deadline;
        loop {
            let notified = self.changed.notified();
            if ready(&self.lock()) {
                return true;
            }
            if tokio::time::timeout_at(until, notified).await.is_err() {
                return ready(&self.lock());
            }
        }
    }

    /// A future that completes at the next change (create it before checking a condition).
    pub(super) fn changed(&self) -> tokio::sync::futures::Notified<'_> {
        self.changed.notified()
    }
}

/// A peer's place in the registry, held by its reader: dropping it removes the peer (unless a
/// newer stream of the same projector has replaced it) and wakes the waiters.
#[derive(Debug)]
pub(super) struct PeerGuard {
    registry: Arc<Registry>,
    projector: String,
    connection: u64,
}

impl PeerGuard {
    /// The projector this guard holds.
    pub(super) fn projector(&self) -> &str {
        &self.projector
    }

    /// Runs `f` on this peer's entry, if it is still this stream's.
    pub(super) fn with<T>(&self, f: impl FnOnce(&mut Peer) -> T) -> Option<T> {
        let mut peers = self.registry.lock();
        peers
            .peers
            .get_mut(&self.projector)
            .filter(|p| p.connection == self.connection)
            .map(f)
    }
}

impl Drop for PeerGuard {
    fn drop(&mut self) {
        let removed = {
            let mut peers = self.registry.lock();
            let mine = peers
                .peers
                .get(&self.projector)
                .is_some_and(|p| p.connection == self.connection);
            mine && peers.peers.remove(&self.projector).is_some()
        };
        if removed {
            tracing::info!(projector = %self.projector, "left");
        }
        self.registry.notify();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peer(nodes: Vec<u32>) -> (Peer, mpsc::Receiver<Result<v1::RoomMessage, Status>>) {
        let (tx, rx) = mpsc::channel(4);
        (Peer::new(tx, nodes, true, &v1::Hello::default()), rx)
    }

    #[test]
    fn a_second_stream_of_an_attached_projector_is_refused() {
        let registry = Arc::new(Registry::default());
        let (a, _ra) = peer(vec![0, 1]);
        let (b, _rb) = peer(vec![0, 1]);
        let guard = registry.admit("p0", a).expect("first");
        assert!(registry.admit("p0", b).is_err());
        assert_eq!(guard.projector(), "p0");
        assert_eq!(registry.lock().peers.len(), 1);
    }

    #[test]
    fn dropping_the_guard_removes_the_peer_but_not_a_newer_stream() {
        let registry = Arc::new(Registry::default());
        let (a, _ra) = peer(vec![0]);
        let old = registry.admit("p0", a).expect("first");
        drop(old);
        assert!(registry.lock().peers.is_empty());
        let (b, _rb) = peer(vec![0]);
        let new = registry.admit("p0", b).expect("again after it left");
        // The old stream's entry was replaced (drained at shutdown, say) and re-admitted: a
        // stale guard of another connection must not remove the new entry.
        let (c, _rc) = peer(vec![0]);
        registry.drain();
        let newer = registry.admit("p0", c).expect("after the drain");
        drop(new);
        assert_eq!(registry.lock().peers.len(), 1);
        drop(newer);
        assert!(registry.lock().peers.is_empty());
    }

    #[test]
    fn readiness_follows_what_each_calibrated_peer_shows() {
        let registry = Arc::new(Registry::default());
        let (a, _ra) = peer(vec![0]);
        let (mut b, _rb) = peer(vec![1]);
        b.calibrated = false;
        let ga = registry.admit("a", a).expect("a");
        let _gb = registry.admit("b", b).expect("b");
        assert!(registry.lock().dark());
        assert!(!registry.lock().all_shown());
        ga.with(|p| p.shown = Some(0));
        assert!(!registry.lock().dark());
        // The uncalibrated one takes part in no round: the room is ready without it.
        assert!(registry.lock().all_shown());
        ga.with(|p| p.awaiting = Some(3));
        assert!(!registry.lock().all_shown());
        ga.with(|p| p.shown = Some(3));
        assert!(registry.lock().all_shown());
    }
}
