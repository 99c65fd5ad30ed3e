//! The round controller on its own: captures and model rounds, restarts on a rising `G` and on
//! a change of the live projectors, settling; readiness and late projectors, a round's
//! contributions with a deadline and a projector leaving mid-round, the settle rule, and the
//! calibration backoff. Plain values: no network, no clocks (time is a `Duration` the test
//! chooses).

use roomlight_core::LinearRgb;
use roomlight_core::aggregator::ErrorKind;
use roomlight_core::round::{
    Backoff, Collection, Controller, Next, Projectors, Received, STALE_CAPTURES, Settle,
    objective_noise,
};
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

/// A room of three patches whose captures have noise σ = `sigma` on every channel.
fn controller(sigma: f64, model_rounds: usize) -> Controller {
    Controller::new(vec![LinearRgb::splat(sigma); 3], model_rounds)
}

fn errors(v: f64) -> Vec<LinearRgb> {
    vec![LinearRgb::splat(v); 3]
}

#[test]
fn after_a_capture_come_k_model_rounds_then_a_capture() {
    let mut c = controller(0.0, 3);
    assert_eq!(c.next(), Next::Capture, "nothing to predict from yet");
    assert_eq!(c.predicted(), None);
    assert!(!c.has_measured());
    for cycle in 0..2u64 {
        let measured = c.measured(errors(1.0)).expect("valid errors");
        assert_eq!(measured.kind, ErrorKind::Measured);
        assert_eq!(measured.round, 4 * cycle + 1);
        let mut rounds = Vec::new();
        while c.next() == Next::Model {
            let predicted = c.predicted().expect("a model round is due");
            assert_eq!(predicted.kind, ErrorKind::Predicted);
            rounds.push(predicted.round);
        }
        assert_eq!(rounds, [2, 3, 4].map(|r| r + 4 * cycle));
        assert_eq!(c.predicted(), None, "a capture is due");
    }
    assert!(c.has_measured());
    // Without model rounds every round is a capture.
    let mut c = controller(0.0, 0);
    c.measured(errors(1.0)).expect("valid");
    assert_eq!(c.next(), Next::Capture);
}

#[test]
fn model_rounds_predict_the_errors_from_the_contributions() {
    let mut c = controller(0.0, 1);
    c.measured(errors(1.0)).expect("valid");
    c.contribution([(0, LinearRgb::splat(0.25)), (2, LinearRgb::splat(0.5))])
        .expect("a valid contribution");
    c.contribution([(0, LinearRgb::splat(0.25))])
        .expect("another node's");
    // Refused whole: nothing of it is applied.
    assert!(
        c.contribution([(1, LinearRgb::splat(9.0)), (7, LinearRgb::ZERO)])
            .is_err()
    );
    assert!(
        c.contribution([(1, LinearRgb([f64::NAN, 0.0, 0.0]))])
            .is_err()
    );
    let predicted = c.predicted().expect("one model round");
    assert_eq!(c.errors(), [0.5, 1.0, 0.5].map(LinearRgb::splat));
    // G = ½ Σ e² over patches and channels.
    assert!((predicted.objective - 1.5 * (0.25 + 1.0 + 0.25)).abs() < 1e-12);
}

#[test]
fn a_capture_whose_errors_are_malformed_is_refused_and_changes_nothing() {
    let mut c = controller(0.0, 2);
    assert!(c.measured(vec![LinearRgb::ZERO; 2]).is_err(), "two patches");
    assert!(c.measured(errors(f64::INFINITY)).is_err());
    assert_eq!(c.next(), Next::Capture);
    assert!(!c.has_measured());
    assert_eq!(c.measured(errors(1.0)).expect("valid").round, 1);
}

#[test]
fn the_restart_flag_follows_a_rising_objective() {
    let mut c = controller(0.0, 1);
    assert!(
        !c.measured(errors(1.0)).expect("valid").restart,
        "first round"
    );
    // G rises in the model round: the nodes' contributions overshot.
    c.contribution([(0, LinearRgb::splat(3.0))]).expect("valid");
    assert!(c.predicted().expect("model round").restart);
    assert!(!c.measured(errors(0.5)).expect("valid").restart, "G fell");
}

#[test]
fn a_join_or_a_leave_sets_restart_on_the_next_round_only() {
    let mut room = two_lit();
    let mut c = controller(0.0, 1);
    c.live(room.generation());
    assert!(
        !c.measured(errors(1.0)).expect("valid").restart,
        "the first projectors seen are no change"
    );
    // A projector joins and lights up before the model round: that round restarts.
    room.join("c", vec![4], true);
    c.live(room.generation());
    room.shown("c", 0);
    c.live(room.generation());
    assert!(c.predicted().expect("model round").restart);
    c.live(room.generation());
    assert!(
        !c.measured(errors(0.5)).expect("valid").restart,
        "once is enough"
    );
    // A projector that leaves: the next round restarts too.
    room.leave("a");
    c.live(room.generation());
    assert!(c.predicted().expect("model round").restart);
    // Acknowledgements and rounds are no change.
    let g = room.generation();
    room.start_round(5);
    room.shown("b", 5);
    assert_eq!(room.generation(), g);
    c.live(g);
    assert!(!c.measured(errors(0.25)).expect("valid").restart);
}

#[test]
fn the_generation_counts_projectors_entering_and_leaving_the_rounds() {
    let mut room = Projectors::default();
    let g0 = room.generation();
    room.join("hot", vec![], false);
    room.shown("hot", 0);
    assert_eq!(room.generation(), g0, "uncalibrated: not in the rounds");
    room.set_nodes("hot", vec![1, 2]);
    assert_eq!(room.generation(), g0);
    room.calibrated("hot");
    assert_eq!(room.generation(), g0 + 1, "calibrated and lit: in");
    room.set_nodes("hot", vec![1, 2, 3]);
    assert_eq!(room.generation(), g0 + 2, "its nodes changed while in");
    room.join("dark", vec![5], true);
    room.leave("dark");
    assert_eq!(room.generation(), g0 + 2, "never lit: never in");
    room.leave("hot");
    assert_eq!(room.generation(), g0 + 3);
}

#[test]
fn the_controller_settles_after_two_quiet_captures() {
    // σ = 0.1 per channel: with e = 1 everywhere σ_G = sqrt(9 · 0.01) = 0.3.
    let mut c = controller(0.1, 2);
    assert!((objective_noise(&errors(1.0), &errors(0.1)) - 0.3).abs() < 1e-12);
    c.measured(errors(2.0)).expect("valid");
    assert!(!c.settled());
    c.measured(errors(1.0)).expect("valid");
    assert!(!c.settled(), "G moved by 13.5, far beyond its noise");
    c.measured(errors(1.01)).expect("valid");
    assert!(!c.settled(), "one quiet capture");
    // Model rounds do not count: only captures are judged.
    while c.predicted().is_some() {}
    assert!(!c.settled());
    c.measured(errors(1.0)).expect("valid");
    assert!(c.settled(), "two quiet captures running");
    c.measured(errors(3.0)).expect("valid");
    assert!(!c.settled(), "a real change unsettles it");
}

/// Captures of a room of `patches` patches whose errors are `truth(patch)` on every channel,
/// each with Gaussian noise σ = `sigma` (seeded).
fn noisy_room(
    sigma: f64,
    patches: usize,
    seed: u64,
) -> impl FnMut(&dyn Fn(usize) -> f64) -> Vec<LinearRgb> {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, sigma).expect("normal");
    move |truth| {
        (0..patches)
            .map(|i| LinearRgb([0, 1, 2].map(|_| truth(i) + normal.sample(&mut rng))))
            .collect()
    }
}

/// Captures of a static room are averaged with what the last ones predict: the held errors'
/// spread falls as 1/√k up to the cap, a capture the prediction does not explain (the room
/// changed) starts the average afresh, and so does a change of the live projectors; model
/// rounds' contributions move the prediction the capture is averaged with.
#[test]
fn captures_are_averaged_with_the_prediction_until_the_room_disagrees() {
    let sigma = 0.01;
    let patches = 300;
    let mut room = noisy_room(sigma, patches, 7);
    let mut noisy = |truth: f64| room(&|_| truth);
    // The held errors' RMS deviation from `truth`, in units of σ.
    let spread = |c: &mut Controller, truth: f64| {
        let e = c.errors();
        let sum: f64 = e
            .iter()
            .flat_map(|v| (0..3).map(move |k| (v[k] - truth).powi(2)))
            .sum();
        (sum / (3 * e.len()) as f64).sqrt() / sigma
    };
    let mut c = Controller::new(vec![LinearRgb::splat(sigma); patches], 0).averaging(4);
    c.measured(noisy(0.5)).expect("first");
    let first = spread(&mut c, 0.5);
    assert!((first - 1.0).abs() < 0.1, "one capture: {first} σ");
    for _ in 0..5 {
        c.measured(noisy(0.5)).expect("static");
    }
    // Four captures averaged (the cap), then a moving average of gain 1/4: its variance falls
    // towards 1/7 of a capture's, and the count says so (6 after six captures, 7 at last).
    let averaged = spread(&mut c, 0.5);
    assert!(
        (0.33..0.52).contains(&averaged),
        "six captures: {averaged} σ (0.42 expected)"
    );
    assert_eq!(c.averaged(), 6);
    for _ in 0..20 {
        c.measured(noisy(0.5)).expect("static");
    }
    assert_eq!(
        c.averaged(),
        7,
        "the moving average's noise: 1/7 of a capture's"
    );
    let moving = spread(&mut c, 0.5);
    assert!(
        (0.3..0.46).contains(&moving),
        "a moving average of gain 1/4: {moving} σ (0.38 expected)"
    );
    // The room changed by 5σ everywhere: the prediction is refused, the capture stands alone.
    c.measured(noisy(0.55)).expect("changed");
    let fresh = spread(&mut c, 0.55);
    assert!((fresh - 1.0).abs() < 0.1, "afresh: {fresh} σ");
    // A model round's contributions are the prediction: the nodes took 0.05 off every error,
    // and the room followed; the capture is averaged, not refused.
    c.contribution((0..patches as u32).map(|i| (i, LinearRgb::splat(0.05))))
        .expect("contribution");
    c.measured(noisy(0.5)).expect("predicted");
    let followed = spread(&mut c, 0.5);
    assert!(
        followed < 0.85,
        "averaged with the prediction: {followed} σ"
    );
    // A projector joined: afresh.
    c.live(1);
    c.live(2);
    c.measured(noisy(0.5)).expect("joined");
    let joined = spread(&mut c, 0.5);
    assert!((joined - 1.0).abs() < 0.1, "a projector joined: {joined} σ");
    // Without any noise known nothing is averaged.
    let mut quiet = controller(0.0, 0);
    quiet.measured(errors(1.0)).expect("first");
    quiet.measured(errors(2.0)).expect("second");
    assert_eq!(quiet.errors(), errors(2.0));
}

/// A camera that hands over its frames late shows, after the nodes stepped, the room as it was
/// at the last capture: such a capture is refused (nothing changes), the fresh one after it is
/// measured; a step the room followed is never refused, nor one it followed only in part (a
/// model 40% off), nor a room that changed otherwise; and after `STALE_CAPTURES` refusals in a
/// row the capture is measured whatever it shows (a display that shows nothing is not waited
/// for forever).
#[test]
fn a_capture_that_shows_the_values_before_the_last_step_is_stale() {
    let (sigma, patches) = (0.01, 200);
    let mut room = noisy_room(sigma, patches, 11);
    let mut noisy = |truth: f64| room(&|_| truth);
    let step = |c: &mut Controller, by: f64| {
        c.contribution((0..patches as u32).map(|i| (i, LinearRgb::splat(by))))
            .expect("contribution");
    };
    let mut c = Controller::new(vec![LinearRgb::splat(sigma); patches], 0);
    // Nothing to judge by before the first capture.
    assert!(!c.stale(&noisy(0.5)));
    c.measured(noisy(0.5)).expect("first");
    // The nodes take 0.1 (10σ) off every error; the camera shows the old room twice.
    step(&mut c, 0.1);
    let before = c.errors().to_vec();
    assert!(c.stale(&noisy(0.5)), "the room before the step");
    assert!(c.stale(&noisy(0.5)), "still before the step");
    assert_eq!(c.errors(), before, "a stale verdict changes nothing");
    assert!(!c.stale(&noisy(0.4)), "the room after the step");
    c.measured(noisy(0.4)).expect("fresh");
    assert_eq!(
        c.averaged(),
        2,
        "the fresh capture agrees with the prediction"
    );
    // A step the room follows in part (the model 40% off): measured, not refused.
    step(&mut c, 0.1);
    assert!(!c.stale(&noisy(0.34)));
    c.measured(noisy(0.34)).expect("partial");
    // A room that changed otherwise (a door opened: everything 0.2 brighter) is not stale.
    step(&mut c, 0.1);
    assert!(!c.stale(&noisy(0.04)));
    c.measured(noisy(0.04)).expect("changed");
    // A display that shows nothing: refused STALE_CAPTURES times, then measured.
    step(&mut c, 0.02);
    let refused = (0..10).take_while(|_| c.stale(&noisy(0.04))).count();
    assert_eq!(refused, STALE_CAPTURES);
    c.measured(noisy(0.04)).expect("measured at last");
    assert_eq!(
        c.averaged(),
        1,
        "the disagreement starts the average afresh"
    );
    // After a change of the live projectors nothing is judged stale.
    step(&mut c, 0.1);
    c.live(1);
    c.live(2);
    assert!(!c.stale(&noisy(0.04)));
    // Without any noise known nothing is judged.
    let mut quiet = controller(0.0, 0);
    quiet.measured(errors(1.0)).expect("first");
    quiet
        .contribution([(0, LinearRgb::splat(0.5))])
        .expect("contribution");
    assert!(!quiet.stale(&errors(1.0)));
}

/// A step whose prediction is off by a tenth (the room follows 90% of it) on half the patches:
/// the capture disagrees with the prediction beyond its noise, and is fused with it by the
/// model's error on the step instead of starting the average afresh. The patches the step left
/// alone keep their average (σ/√5 after five captures, not σ); those it moved follow the
/// capture and come out closer to the truth than the capture alone. A model off by more than
/// half the step starts afresh.
#[test]
fn a_step_the_model_predicts_in_part_keeps_the_average_where_it_did_not_step() {
    /// Captures of a room whose errors are `truth(patch)`, with noise.
    type Sampler<'a> = dyn FnMut(&dyn Fn(usize) -> f64) -> Vec<LinearRgb> + 'a;
    let (sigma, patches) = (0.01, 400);
    let mut noisy = noisy_room(sigma, patches, 5);
    // RMS deviation from `truth` over `which` patches, in units of σ.
    let spread = |e: &[LinearRgb], truth: &dyn Fn(usize) -> f64, which: &dyn Fn(usize) -> bool| {
        let (sum, n) = e
            .iter()
            .enumerate()
            .filter(|(i, _)| which(*i))
            .flat_map(|(i, v)| (0..3).map(move |k| (v[k] - truth(i)).powi(2)))
            .fold((0.0, 0usize), |(s, n), d| (s + d, n + 1));
        (sum / n as f64).sqrt() / sigma
    };
    let stepped = |i: usize| i.is_multiple_of(2);
    let run = |follows: f64, noisy: &mut Sampler| {
        let mut c = Controller::new(vec![LinearRgb::splat(sigma); patches], 0);
        for _ in 0..4 {
            c.measured(noisy(&|_| 0.5)).expect("static");
        }
        assert_eq!(c.averaged(), 4);
        // The nodes take 0.1 (10σ) off the even patches' errors; the room follows `follows`.
        c.contribution(
            (0..patches as u32)
                .filter(|&i| stepped(i as usize))
                .map(|i| (i, LinearRgb::splat(0.1))),
        )
        .expect("contribution");
        let truth = move |i: usize| if stepped(i) { 0.5 - 0.1 * follows } else { 0.5 };
        c.measured(noisy(&truth)).expect("after the step");
        let e = c.errors().to_vec();
        (
            spread(&e, &truth, &|i| !stepped(i)),
            spread(&e, &truth, &stepped),
            c.averaged(),
        )
    };
    let (still, moved, averaged) = run(0.9, &mut noisy);
    assert!(
        (0.35..0.6).contains(&still),
        "unstepped patches: {still} σ (five captures averaged: 0.45)"
    );
    assert!(
        moved < 0.95,
        "stepped patches: {moved} σ (the capture alone: 1)"
    );
    assert!((2..=4).contains(&averaged), "averaged {averaged}");
    // A model off by 60% of the step: the room changed in a way the step does not explain.
    let (still, moved, averaged) = run(0.4, &mut noisy);
    assert!((still - 1.0).abs() < 0.12, "afresh: {still} σ");
    assert!((moved - 1.0).abs() < 0.12, "afresh: {moved} σ");
    assert_eq!(averaged, 1);
}
