//! The round controller on its own: readiness and late projectors, a round's contributions with
//! a deadline and a projector leaving mid-round, the settle rule, and the calibration backoff.
//! No clocks: time is a `Duration` the test chooses.

use roomlight_core::round::{Backoff, Collection, Projectors, Received, Settle};
use std::time::Duration;

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

/// Two calibrated projectors of two nodes each, both showing their start.
fn two_lit() -> Projectors {
    let mut room = Projectors::default();
    room.join("a", vec![0, 1], true);
    room.join("b", vec![2, 3], true);
    room.shown("a", 0);
    room.shown("b", 0);
    room
}

#[test]
fn a_round_is_sent_to_the_ready_and_waits_for_their_acknowledgements() {
    let mut room = two_lit();
    assert!(room.all_shown() && !room.dark() && room.any_running());
    let (mut sent, late) = room.start_round(1);
    sent.sort();
    assert_eq!(sent, ["a", "b"]);
    assert!(late.is_empty());
    assert!(!room.all_shown(), "both now owe the frame of round 1");
    room.shown("a", 1);
    assert!(!room.all_shown());
    // An older acknowledgement arriving late does not undo a newer one.
    room.shown("b", 1);
    room.shown("b", 0);
    assert!(room.all_shown());
    assert_eq!(room.get("b").and_then(|p| p.shown()), Some(1));
}

#[test]
fn a_late_projector_is_left_out_of_the_round_and_taken_back_once_it_shows() {
    let mut room = two_lit();
    room.start_round(1);
    room.shown("a", 1);
    // The deadline passed with b still on round 0: round 2 goes to a alone.
    let (sent, late) = room.start_round(2);
    assert_eq!(sent, ["a"]);
    assert_eq!(late, ["b"]);
    room.shown("b", 1);
    room.shown("a", 2);
    let (mut sent, late) = room.start_round(3);
    sent.sort();
    assert_eq!(sent, ["a", "b"]);
    assert!(late.is_empty());
}

#[test]
fn an_uncalibrated_projector_takes_part_in_no_round_until_it_is_calibrated() {
    let mut room = two_lit();
    room.join("hot", vec![], false);
    assert!(room.any_uncalibrated() && room.all_shown());
    assert_eq!(room.uncalibrated(), ["hot"]);
    let (sent, _) = room.start_round(1);
    assert!(!sent.contains(&"hot".to_string()));
    room.set_nodes("hot", vec![4, 5]);
    assert_eq!(room.owner(5), Some("hot"));
    room.calibrated("hot");
    assert!(!room.any_uncalibrated());
    assert!(room.any_unlit(), "measured but not lit yet");
    assert!(!room.all_shown());
    room.shown("hot", 0);
    assert!(!room.any_unlit());
}

#[test]
fn leaving_forgets_a_projector_its_nodes_and_its_counts() {
    let mut room = two_lit();
    room.start_round(1);
    assert!(!room.all_shown());
    let gone = room.leave("b").expect("b was live");
    assert_eq!(gone.nodes(), [2, 3]);
    assert_eq!(room.owner(2), None);
    room.shown("a", 1);
    assert!(room.all_shown(), "no one waits for a projector that left");
    room.leave("a");
    assert!(room.is_empty() && room.dark() && !room.any_present());
    // Rejoining under the same id starts afresh: nothing shown, so the rounds wait for it.
    room.join("a", vec![0], true);
    assert!(room.dark() && !room.all_shown() && room.any_unlit());
}

#[test]
fn a_round_collects_each_awaited_contribution_once() {
    let mut round = Collection::new(7, [0, 1, 2], ms(100), ms(500));
    assert_eq!(round.receive(6, 0), Received::OtherRound);
    assert_eq!(round.receive(7, 0), Received::Counted);
    assert_eq!(round.receive(7, 0), Received::NotAwaited, "a duplicate");
    assert_eq!(round.receive(7, 9), Received::NotAwaited, "never sent");
    assert_eq!(round.missing(), 2);
    assert!(!round.done());
    assert_eq!(round.receive(7, 1), Received::Counted);
    assert_eq!(round.receive(7, 2), Received::Counted);
    assert!(round.done());
}

#[test]
fn a_round_waits_until_its_deadline_and_no_longer() {
    let round = Collection::new(1, [0], ms(1_000), ms(250));
    assert_eq!(round.deadline(), ms(1_250));
    assert!(!round.expired(ms(1_249)));
    assert!(round.expired(ms(1_250)));
    // A deadline past the end of time saturates instead of wrapping.
    let forever = Collection::new(1, [0], Duration::MAX, ms(1));
    assert!(!forever.expired(ms(1)));
}

#[test]
fn a_projector_leaving_mid_round_is_not_waited_for() {
    let mut room = two_lit();
    let (sent, _) = room.start_round(1);
    let awaited: Vec<u32> = sent
        .iter()
        .filter_map(|id| room.get(id))
        .flat_map(|p| p.nodes().to_vec())
        .collect();
    let mut round = Collection::new(1, awaited, ms(0), ms(500));
    assert_eq!(round.receive(1, 0), Received::Counted);
    assert_eq!(round.receive(1, 1), Received::Counted);
    let gone = room.leave("b").expect("b");
    round.left(gone.nodes());
    assert!(round.done(), "b's nodes left with it");
    // Its contribution, should one still arrive, is not counted.
    assert_eq!(round.receive(1, 2), Received::NotAwaited);
}

#[test]
fn the_room_settles_after_two_quiet_captures() {
    let mut settle = Settle::default();
    assert!(!settle.measured());
    // σ_G = 1: a change within 3√2 ≈ 4.24 is quiet.
    assert!(
        !settle.observe(100.0, 1.0),
        "the first capture has nothing to compare"
    );
    assert!(!settle.observe(90.0, 1.0), "a change of 10 is not noise");
    assert!(!settle.observe(87.0, 1.0), "one quiet capture");
    assert!(settle.observe(84.0, 1.0), "two quiet captures running");
    assert!(settle.settled());
    assert!(!settle.observe(70.0, 1.0), "a real change unsettles it");
    assert!(!settle.observe(70.0, 1.0));
    assert!(settle.observe(70.0, 1.0));
}

#[test]
fn a_noiseless_room_settles_when_its_objective_stops_changing_to_rounding() {
    let mut settle = Settle::default();
    settle.observe(1.0, 0.0);
    assert!(!settle.observe(1.0 - 1e-9, 0.0), "still moving");
    settle.observe(1.0 - 1e-9 - 1e-14, 0.0);
    assert!(settle.observe(1.0 - 1e-9 - 2e-14, 0.0));
}

#[test]
fn a_failed_calibration_backs_off_doubling_to_3_2_s() {
    let mut backoff = Backoff::default();
    let waiting = vec!["p".to_string(), "q".to_string()];
    assert_eq!(backoff.next_due(&waiting, ms(0)), Some(&waiting[0]));
    let mut now = ms(0);
    let mut waits = Vec::new();
    for _ in 0..6 {
        let at = backoff.failed("p", now);
        waits.push(at - now);
        assert!(!backoff.due("p", at - ms(1)));
        assert!(backoff.due("p", at));
        now = at;
    }
    assert_eq!(
        waits,
        [ms(400), ms(800), ms(1_600), ms(3_200), ms(3_200), ms(3_200)]
    );
    // While p backs off, q is tried first.
    assert_eq!(backoff.next_due(&waiting, now), Some(&waiting[0]));
    backoff.failed("p", now);
    assert_eq!(backoff.next_due(&waiting, now), Some(&waiting[1]));
    assert_eq!(backoff.earliest(), Some(now + ms(3_200)));
    // Calibrated, or gone: its failures are forgotten.
    backoff.forget("p");
    assert!(backoff.due("p", now));
    backoff.failed("q", now);
    backoff.retain(&["p".to_string()]);
    assert_eq!(backoff.earliest(), None);
}
