//! The registry of live peers: per attached projector its outbound queue and what only the wire
//! knows of it (its stream, its resolution, the last calibration pattern it shows, what its
//! node agent says of its display), beside the
//! core's [`Projectors`] (its nodes, what it shows, readiness, node → projector). Admission
//! checks and inserts under one lock; a guard's `Drop` removes a peer, so every way a reader
//! ends cleans up; the nodes of peers that left are kept for the round waiting on them. Waiters
//! are woken on every change. It knows nothing of the model, the camera or message contents.

use super::DisplayLost;
use super::operator::{ProjectorState, ProjectorStatus};
use crate::hardware::DisplayReport;
use roomlight_core::round::Projectors;
use roomlight_proto::v1;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Duration;
use tokio::sync::{Notify, mpsc};
use tokio_util::sync::CancellationToken;
use tonic::Status;

/// The queue of messages to one node agent (the items of its `Attach` response stream).
pub(super) type Outbox = mpsc::Sender<Result<v1::RoomMessage, Status>>;

/// A projector to send to: its id, its queue and its nodes.
pub(super) type Recipient = (String, Outbox, Vec<u32>);

/// What the wire knows of one attached projector.
#[derive(Debug)]
pub(super) struct Peer {
    pub(super) tx: Outbox,
    /// The last Show pattern it has on its display.
    pub(super) pattern_shown: Option<u64>,
    /// Its resolution and kind, as its Hello said (for calibration over the wire).
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) kind: v1::ProjectorKind,
    /// Its display's state as its node agent last reported it (`None`: never reported).
    pub(super) display: Option<DisplayReport>,
    /// Which stream this entry belongs to (a reconnected projector gets a new one).
    connection: u64,
    /// Ends its reader when the peer is dropped by the camera agent (lagging, shutdown).
    cancel: CancellationToken,
}

impl Peer {
    /// A peer as its Hello describes it; its reader stops when `cancel` is.
    pub(super) fn new(tx: Outbox, hello: &v1::Hello, cancel: CancellationToken) -> Self {
        Self {
            tx,
            pattern_shown: None,
            width: hello.width,
            height: hello.height,
            kind: v1::ProjectorKind::try_from(hello.kind).unwrap_or(v1::ProjectorKind::Unspecified),
            display: None,
            connection: 0,
            cancel,
        }
    }
}

/// The peers, as seen under the registry's lock.
#[derive(Debug, Default)]
pub(super) struct Peers {
    /// Nodes, readiness and owners, as the round controller keeps them.
    round: Projectors,
    wire: HashMap<String, Peer>,
    next_connection: u64,
    /// Nodes of the peers that left since the round loop last took them.
    departed: Vec<u32>,
}

impl Peers {
    /// The round controller's view of the live projectors.
    pub(super) fn projectors(&self) -> &Projectors {
        &self.round
    }

    /// A peer's wire side.
    pub(super) fn peer(&self, id: &str) -> Option<&Peer> {
        self.wire.get(id)
    }

    /// The projectors attached now.
    pub(super) fn len(&self) -> usize {
        self.wire.len()
    }

    /// The attached projectors whose display is lost, by projector id.
    pub(super) fn displays_lost(&self) -> Vec<DisplayLost> {
        let mut lost: Vec<DisplayLost> = self
            .wire
            .iter()
            .filter_map(|(id, p)| match &p.display {
                Some(DisplayReport::Lost { output, reason }) => Some(DisplayLost {
                    projector: id.clone(),
                    output: output.clone(),
                    reason: reason.clone(),
                }),
                _ => None,
            })
            .collect();
        lost.sort_by(|a, b| a.projector.cmp(&b.projector));
        lost
    }

    /// The attached projectors' states for the console, by id: `calibrating` are being
    /// measured, `late` were left out of the last round.
    pub(super) fn statuses(&self, calibrating: &[String], late: &[String]) -> Vec<ProjectorStatus> {
        let mut out: Vec<ProjectorStatus> = self
            .wire
            .iter()
            .map(|(id, peer)| {
                let round = self.round.get(id);
                let calibrated = round.is_some_and(|p| p.calibrated());
                let shown = round.and_then(|p| p.shown()).or(peer.pattern_shown);
                let state = if matches!(peer.display, Some(DisplayReport::Lost { .. })) {
                    ProjectorState::DisplayLost
                } else if calibrating.contains(id) {
                    ProjectorState::Calibrating
                } else if calibrated && late.contains(id) {
                    ProjectorState::Late
                } else if calibrated {
                    ProjectorState::Live
                } else if shown.is_none() {
                    ProjectorState::Connecting
                } else {
                    ProjectorState::Waiting
                };
                ProjectorStatus {
                    id: id.clone(),
                    state,
                    nodes: round.map_or(0, |p| p.nodes().len()),
                    shown,
                    width: peer.width,
                    height: peer.height,
                }
            })
            .collect();
        out.sort_by(|a, b| a.id.cmp(&b.id));
        out
    }

    /// Projector `id` is to be measured again (it keeps its nodes and light meanwhile).
    pub(super) fn recalibrate(&mut self, id: &str) -> bool {
        if self.round.get(id).is_none() {
            return false;
        }
        self.round.recalibrate(id);
        true
    }

    /// Its queue and nodes.
    pub(super) fn outbox(&self, id: &str) -> Option<(Outbox, Vec<u32>)> {
        let tx = self.wire.get(id)?.tx.clone();
        Some((tx, self.round.get(id)?.nodes().to_vec()))
    }

    /// Every calibrated projector's id, queue and nodes.
    pub(super) fn calibrated(&self) -> Vec<Recipient> {
        self.round
            .iter()
            .filter(|(_, p)| p.calibrated())
            .filter_map(|(id, p)| {
                Some((
                    id.clone(),
                    self.wire.get(id)?.tx.clone(),
                    p.nodes().to_vec(),
                ))
            })
            .collect()
    }

    /// Its attenuation is known: it takes part in the rounds.
    pub(super) fn mark_calibrated(&mut self, id: &str) {
        self.round.calibrated(id);
    }

    /// Its nodes, once segmented over the wire.
    pub(super) fn set_nodes(&mut self, id: &str, nodes: Vec<u32>) {
        self.round.set_nodes(id, nodes);
    }

    /// Starts `round` (see [`Projectors::start_round`]): the ready projectors' ids, queues and
    /// nodes; the late ones' ids. The nodes that left before are forgotten: this round was not
    /// sent to them.
    pub(super) fn start_round(&mut self, round: u64) -> (Vec<Recipient>, Vec<String>) {
        self.departed.clear();
        let (sent, late) = self.round.start_round(round);
        let sent = sent
            .into_iter()
            .filter_map(|id| {
                let tx = self.wire.get(&id)?.tx.clone();
                let nodes = self.round.get(&id)?.nodes().to_vec();
                Some((id, tx, nodes))
            })
            .collect();
        (sent, late)
    }

    /// The nodes of the peers that left since the last call.
    pub(super) fn take_departed(&mut self) -> Vec<u32> {
        std::mem::take(&mut self.departed)
    }

    /// Removes `id` if `keep` holds for its entry; true when removed. Its reader is stopped and
    /// its nodes are recorded as departed.
    fn remove_if(&mut self, id: &str, keep: impl FnOnce(&Peer) -> bool) -> bool {
        if !self.wire.get(id).is_some_and(keep) {
            return false;
        }
        if let Some(peer) = self.wire.remove(id) {
            peer.cancel.cancel();
        }
        if let Some(p) = self.round.leave(id) {
            self.departed.extend_from_slice(p.nodes());
        }
        true
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

    /// Admits `projector` with these nodes: refused (the peer handed back) when it is attached
    /// already (one stream per projector: a reconnecting node is admitted once its old stream
    /// has ended or missed its heartbeats); else inserted, in the same lock. The guard removes
    /// it when dropped.
    pub(super) fn admit(
        self: &Arc<Self>,
        projector: &str,
        mut peer: Peer,
        nodes: Vec<u32>,
        calibrated: bool,
    ) -> Result<PeerGuard, Box<Peer>> {
        let mut peers = self.lock();
        if peers.wire.contains_key(projector) {
            return Err(Box::new(peer));
        }
        peers.next_connection += 1;
        peer.connection = peers.next_connection;
        let connection = peer.connection;
        let cancel = peer.cancel.clone();
        peers.wire.insert(projector.to_string(), peer);
        peers.round.join(projector, nodes, calibrated);
        drop(peers);
        self.notify();
        Ok(PeerGuard {
            registry: self.clone(),
            projector: projector.to_string(),
            connection,
            cancel,
        })
    }

    /// Drops the peer whose queue is `tx` (lagging); true when it was still attached.
    pub(super) fn drop_peer(&self, id: &str, tx: &Outbox) -> bool {
        let removed = self.lock().remove_if(id, |p| p.tx.same_channel(tx));
        self.notify();
        removed
    }

    /// Removes every peer (shutdown); their queues, to say goodbye on.
    pub(super) fn drain(&self) -> Vec<Outbox> {
        let tx: Vec<Outbox> = {
            let mut peers = self.lock();
            peers.round.clear();
            peers
                .wire
                .drain()
                .map(|(_, p)| {
                    p.cancel.cancel();
                    p.tx
                })
                .collect()
        };
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
    cancel: CancellationToken,
}

impl PeerGuard {
    /// The projector this guard holds.
    pub(super) fn projector(&self) -> &str {
        &self.projector
    }

    /// Cancelled when the camera agent drops this peer.
    pub(super) fn cancelled(&self) -> &CancellationToken {
        &self.cancel
    }

    /// It acknowledged showing a round's frame (`pattern`: a calibration pattern) `seq`.
    pub(super) fn shown(&self, seq: u64, pattern: bool) {
        {
            let mut peers = self.registry.lock();
            let Some(peer) = peers
                .wire
                .get_mut(&self.projector)
                .filter(|p| p.connection == self.connection)
            else {
                return;
            };
            if pattern {
                peer.pattern_shown = Some(peer.pattern_shown.map_or(seq, |old| old.max(seq)));
            } else {
                peers.round.shown(&self.projector, seq);
            }
        }
        self.registry.notify();
    }

    /// Its node agent reported its display's state: recorded (the projector stays attached);
    /// the state it replaces, or `None` when this stream is no longer the projector's.
    pub(super) fn display(&self, report: DisplayReport) -> Option<Option<DisplayReport>> {
        let previous = {
            let mut peers = self.registry.lock();
            let peer = peers
                .wire
                .get_mut(&self.projector)
                .filter(|p| p.connection == self.connection)?;
            peer.display.replace(report)
        };
        self.registry.notify();
        Some(previous)
    }

    /// Tells the peer on this stream why it is dropped, best effort (a full queue loses it).
    pub(super) fn goodbye(&self, reason: String) {
        let tx = {
            let peers = self.registry.lock();
            peers
                .wire
                .get(&self.projector)
                .filter(|p| p.connection == self.connection)
                .map(|p| p.tx.clone())
        };
        if let Some(tx) = tx {
            let goodbye = v1::room_message::Body::Goodbye(v1::Goodbye { reason });
            let _ = tx.try_send(Ok(v1::RoomMessage {
                body: Some(goodbye),
            }));
        }
    }

    /// Which of `nodes` this stream's projector owns (O(1) each: the controller's node →
    /// projector index), under one lock (a batched message names all a projector's nodes).
    pub(super) fn owned(&self, nodes: impl Iterator<Item = u32>) -> Vec<u32> {
        let peers = self.registry.lock();
        let current = peers
            .wire
            .get(&self.projector)
            .is_some_and(|p| p.connection == self.connection);
        if !current {
            return Vec::new();
        }
        nodes
            .filter(|&n| peers.round.owner(n) == Some(self.projector.as_str()))
            .collect()
    }
}

impl Drop for PeerGuard {
    fn drop(&mut self) {
        let connection = self.connection;
        let removed = self
            .registry
            .lock()
            .remove_if(&self.projector, |p| p.connection == connection);
        if removed {
            tracing::info!(projector = %self.projector, "left");
        }
        self.registry.notify();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peer() -> (Peer, mpsc::Receiver<Result<v1::RoomMessage, Status>>) {
        let (tx, rx) = mpsc::channel(4);
        let p = Peer::new(tx, &v1::Hello::default(), CancellationToken::new());
        (p, rx)
    }

    #[test]
    fn a_second_stream_of_an_attached_projector_is_refused() {
        let registry = Arc::new(Registry::default());
        let (a, _ra) = peer();
        let (b, _rb) = peer();
        let guard = registry.admit("p0", a, vec![0, 1], true).expect("first");
        assert!(registry.admit("p0", b, vec![0, 1], true).is_err());
        assert_eq!(guard.projector(), "p0");
        assert_eq!(registry.lock().len(), 1);
        assert_eq!(guard.owned([1, 2].into_iter()), [1]);
    }

    #[test]
    fn dropping_the_guard_removes_the_peer_but_not_a_newer_stream() {
        let registry = Arc::new(Registry::default());
        let (a, _ra) = peer();
        let old = registry.admit("p0", a, vec![0], true).expect("first");
        drop(old);
        assert_eq!(registry.lock().len(), 0);
        assert_eq!(registry.lock().take_departed(), vec![0]);
        let (b, _rb) = peer();
        let new = registry
            .admit("p0", b, vec![0], true)
            .expect("again after it left");
        // Its entry drained (shutdown) and the projector admitted anew: the stale guard of the
        // old connection must not remove the new entry.
        let (c, _rc) = peer();
        registry.drain();
        assert!(
            new.cancelled().is_cancelled(),
            "the drained reader is stopped"
        );
        let newer = registry
            .admit("p0", c, vec![0], true)
            .expect("after the drain");
        drop(new);
        assert_eq!(registry.lock().len(), 1);
        assert_eq!(newer.owned([0].into_iter()), [0]);
        drop(newer);
        assert_eq!(registry.lock().len(), 0);
    }

    #[test]
    fn readiness_follows_what_each_calibrated_peer_shows() {
        let registry = Arc::new(Registry::default());
        let (a, _ra) = peer();
        let (b, _rb) = peer();
        let ga = registry.admit("a", a, vec![0], true).expect("a");
        let _gb = registry.admit("b", b, vec![1], false).expect("b");
        let ready = |r: &Registry| r.lock().projectors().all_shown();
        assert!(registry.lock().projectors().dark());
        assert!(!ready(&registry));
        ga.shown(0, false);
        assert!(!registry.lock().projectors().dark());
        // The uncalibrated one takes part in no round: the room is ready without it.
        assert!(ready(&registry));
        let (sent, late) = registry.lock().start_round(3);
        assert_eq!((sent.len(), late.len()), (1, 0));
        assert!(!ready(&registry));
        // A calibration pattern is not a round's frame.
        ga.shown(3, true);
        assert!(!ready(&registry));
        ga.shown(3, false);
        assert!(ready(&registry));
    }

    #[test]
    fn a_lagging_peer_is_dropped_its_reader_stopped_and_its_nodes_departed() {
        let registry = Arc::new(Registry::default());
        let (a, _ra) = peer();
        let tx = a.tx.clone();
        let guard = registry.admit("a", a, vec![4, 5], true).expect("a");
        let (other, _) = mpsc::channel(1);
        assert!(
            !registry.drop_peer("a", &other),
            "another queue is not this peer"
        );
        assert!(registry.drop_peer("a", &tx));
        assert!(guard.cancelled().is_cancelled());
        assert!(guard.owned([4].into_iter()).is_empty());
        let mut departed = registry.lock().take_departed();
        departed.sort_unstable();
        assert_eq!(departed, vec![4, 5]);
        drop(guard);
        assert!(registry.lock().take_departed().is_empty(), "removed once");
    }

    #[test]
    fn a_lost_display_is_recorded_per_projector_and_forgotten_when_it_leaves() {
        let registry = Arc::new(Registry::default());
        let (a, _ra) = peer();
        let (b, _rb) = peer();
        let ga = registry.admit("a", a, vec![0], true).expect("a");
        let gb = registry.admit("b", b, vec![1], true).expect("b");
        let lost = DisplayReport::Lost {
            output: "HDMI-1".into(),
            reason: "output HDMI-1 is gone".into(),
        };
        assert_eq!(ga.display(lost.clone()), Some(None));
        assert_eq!(
            gb.display(DisplayReport::Showing {
                output: "HDMI-2".into()
            }),
            Some(None)
        );
        let expected = vec![DisplayLost {
            projector: "a".into(),
            output: "HDMI-1".into(),
            reason: "output HDMI-1 is gone".into(),
        }];
        assert_eq!(registry.lock().displays_lost(), expected);
        assert_eq!(registry.lock().len(), 2, "a lost display stays attached");
        let back = DisplayReport::Showing {
            output: "HDMI-1".into(),
        };
        assert_eq!(ga.display(back), Some(Some(lost.clone())));
        assert!(registry.lock().displays_lost().is_empty());
        ga.display(lost);
        drop(ga);
        assert!(
            registry.lock().displays_lost().is_empty(),
            "left: forgotten"
        );
    }
}
