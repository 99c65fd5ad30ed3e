//! The live projectors, their readiness and node owners ([`Projectors`]).

use std::collections::HashMap;

/// One live projector, as the rounds see it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Projector {
    nodes: Vec<u32>,
    calibrated: bool,
    /// The last round whose errors it has applied and shows (`Some(0)`: its start).
    shown: Option<u64>,
    /// The last round sent to it.
    awaiting: Option<u64>,
}

impl Projector {
    /// Its nodes.
    pub fn nodes(&self) -> &[u32] {
        &self.nodes
    }

    /// False until its attenuation is known: it takes part in no round.
    pub fn calibrated(&self) -> bool {
        self.calibrated
    }

    /// The last round's frame it shows (`Some(0)`: its start), `None` before any.
    pub fn shown(&self) -> Option<u64> {
        self.shown
    }

    /// It shows the last frame it was sent (its start at least): it can take the next round.
    pub fn ready(&self) -> bool {
        self.shown.is_some()
            && self
                .awaiting
                .is_none_or(|a| self.shown.is_some_and(|s| s >= a))
    }

    /// Which of the counted states it is in: (calibrated and not ready, lit, uncalibrated,
    /// calibrated and unlit, calibrated and lit).
    fn counts(&self) -> [usize; 5] {
        let c = self.calibrated;
        let lit = self.shown.is_some();
        [
            usize::from(c && !self.ready()),
            usize::from(lit),
            usize::from(!c),
            usize::from(c && !lit),
            usize::from(c && lit),
        ]
    }
}

/// The live projectors, their nodes' owners and readiness counts, so that every question a
/// round asks is answered in O(1) (a room of thousands of nodes asks them on every message).
#[derive(Debug, Clone, Default)]
pub struct Projectors {
    projectors: HashMap<String, Projector>,
    /// Node → the projector that owns it.
    owner: HashMap<u32, String>,
    /// See [`Projector::counts`].
    counts: [usize; 5],
    /// Counts the changes of the projectors taking part in the rounds (calibrated and lit).
    generation: u64,
}

impl Projectors {
    /// Adds a projector (replacing one of the same id): not yet showing anything.
    pub fn join(&mut self, id: &str, nodes: Vec<u32>, calibrated: bool) {
        self.leave(id);
        let p = Projector {
            nodes,
            calibrated,
            shown: None,
            awaiting: None,
        };
        for &n in &p.nodes {
            self.owner.insert(n, id.to_string());
        }
        self.add_counts(&p, 1);
        self.projectors.insert(id.to_string(), p);
    }

    /// Removes a projector; what it was.
    pub fn leave(&mut self, id: &str) -> Option<Projector> {
        let p = self.projectors.remove(id)?;
        if p.counts()[4] > 0 {
            self.generation += 1;
        }
        self.add_counts(&p, -1);
        for n in &p.nodes {
            if self.owner.get(n).is_some_and(|o| o == id) {
                self.owner.remove(n);
            }
        }
        Some(p)
    }

    /// Removes every projector; their ids.
    pub fn clear(&mut self) -> Vec<String> {
        self.owner.clear();
        if self.counts[4] > 0 {
            self.generation += 1;
        }
        self.counts = [0; 5];
        let mut ids: Vec<String> = self.projectors.drain().map(|(id, _)| id).collect();
        ids.sort_unstable();
        ids
    }

    /// A projector by id.
    pub fn get(&self, id: &str) -> Option<&Projector> {
        self.projectors.get(id)
    }

    /// The projectors.
    pub fn iter(&self) -> impl Iterator<Item = (&String, &Projector)> {
        self.projectors.iter()
    }

    /// How many are live.
    pub fn len(&self) -> usize {
        self.projectors.len()
    }

    /// None is live.
    pub fn is_empty(&self) -> bool {
        self.projectors.is_empty()
    }

    /// The projector that owns `node`.
    pub fn owner(&self, node: u32) -> Option<&str> {
        self.owner.get(&node).map(String::as_str)
    }

    /// It acknowledged showing round `seq`'s frame (acknowledgements may come out of order: the
    /// latest counts).
    pub fn shown(&mut self, id: &str, seq: u64) {
        self.update(id, |p| {
            p.shown = Some(p.shown.map_or(seq, |old| old.max(seq)))
        });
    }

    /// Its attenuation is known: it takes part in the rounds.
    pub fn calibrated(&mut self, id: &str) {
        self.update(id, |p| p.calibrated = true);
    }

    /// It is to be measured again: it leaves the rounds (keeping its nodes and its light)
    /// until it is [`Projectors::calibrated`] again.
    pub fn recalibrate(&mut self, id: &str) {
        self.update(id, |p| {
            p.calibrated = false;
            p.awaiting = None;
        });
    }

    /// Its nodes (segmented over the wire).
    pub fn set_nodes(&mut self, id: &str, nodes: Vec<u32>) {
        let Some(old) = self.projectors.get(id).map(|p| p.nodes.clone()) else {
            return;
        };
        for n in &old {
            if self.owner.get(n).is_some_and(|o| o == id) {
                self.owner.remove(n);
            }
        }
        for &n in &nodes {
            self.owner.insert(n, id.to_string());
        }
        if self.projectors.get(id).is_some_and(|p| p.counts()[4] > 0) {
            self.generation += 1;
        }
        self.update(id, |p| p.nodes = nodes);
    }

    /// True when every calibrated projector shows the last frame it was sent.
    pub fn all_shown(&self) -> bool {
        self.counts[0] == 0
    }

    /// The room is still dark: no projector has shown a round's frame yet (bring-up).
    pub fn dark(&self) -> bool {
        self.counts[1] == 0
    }

    /// Some projector waits for its calibration.
    pub fn any_uncalibrated(&self) -> bool {
        self.counts[2] > 0
    }

    /// Some calibrated projector has not lit up yet.
    pub fn any_unlit(&self) -> bool {
        self.counts[3] > 0
    }

    /// Some calibrated projector runs rounds.
    pub fn any_running(&self) -> bool {
        self.counts[4] > 0
    }

    /// Changes whenever a projector enters the rounds (calibrated and lit), leaves them, or
    /// has its nodes changed while in them; for [`Controller::live`](super::Controller::live).
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// There is something to do: a projector shows a frame or waits for its calibration.
    pub fn any_present(&self) -> bool {
        !self.dark() || self.any_uncalibrated()
    }

    /// The projectors waiting for their calibration, by id (O(projectors): asked once per
    /// cycle). Sorted, so that which is calibrated first does not depend on a hash's order.
    pub fn uncalibrated(&self) -> Vec<String> {
        if !self.any_uncalibrated() {
            return Vec::new();
        }
        let mut ids: Vec<String> = self
            .projectors
            .iter()
            .filter(|(_, p)| !p.calibrated)
            .map(|(id, _)| id.clone())
            .collect();
        ids.sort_unstable();
        ids
    }

    /// Starts `round`: every calibrated projector that is ready is sent it (and awaited);
    /// `(sent, late)` by id, each sorted (messages leave in the same order on every run).
    pub fn start_round(&mut self, round: u64) -> (Vec<String>, Vec<String>) {
        let mut sent = Vec::new();
        let mut late = Vec::new();
        for (id, p) in &self.projectors {
            if !p.calibrated {
                continue;
            }
            if p.ready() {
                sent.push(id.clone());
            } else {
                late.push(id.clone());
            }
        }
        sent.sort_unstable();
        late.sort_unstable();
        for id in &sent {
            self.update(id, |p| p.awaiting = Some(round));
        }
        (sent, late)
    }

    fn update(&mut self, id: &str, f: impl FnOnce(&mut Projector)) {
        let Some(p) = self.projectors.get_mut(id) else {
            return;
        };
        let before = p.counts();
        f(p);
        let after = p.counts();
        if before[4] != after[4] {
            self.generation += 1;
        }
        for k in 0..5 {
            self.counts[k] = self.counts[k] + after[k] - before[k];
        }
    }

    fn add_counts(&mut self, p: &Projector, sign: isize) {
        for (c, k) in self.counts.iter_mut().zip(p.counts()) {
            *c = c.saturating_add_signed(sign * k as isize);
        }
    }
}
