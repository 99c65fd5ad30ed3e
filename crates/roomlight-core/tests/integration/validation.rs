//! Bad input is rejected with an error that says what was wrong, and leaves state untouched.

use roomlight_core::aggregator::ErrorAggregator;
use roomlight_core::conventional::{conventional_start, conventional_value};
use roomlight_core::{AttenuationColumn, LinearRgb, ModelError, NodeState, Problem, StepRule};

fn rgb(r: f64, g: f64, b: f64) -> LinearRgb {
    LinearRgb([r, g, b])
}

#[test]
fn columns_reject_nan_negative_unsorted_and_mismatched() {
    let nan = AttenuationColumn::new(
        vec![0, 1],
        vec![rgb(0.1, 0.1, 0.1), rgb(f64::NAN, 0.0, 0.0)],
    );
    assert!(matches!(
        nan,
        Err(ModelError::NotFinite {
            index: 1,
            channel: 0,
            ..
        })
    ));
    let neg = AttenuationColumn::new(vec![0], vec![rgb(0.1, -0.2, 0.1)]);
    assert!(matches!(
        neg,
        Err(ModelError::Negative {
            index: 0,
            channel: 1,
            ..
        })
    ));
    let unsorted = AttenuationColumn::new(vec![3, 3], vec![LinearRgb::ONE; 2]);
    assert!(matches!(
        unsorted,
        Err(ModelError::Unsorted {
            previous: 3,
            next: 3,
            ..
        })
    ));
    let short = AttenuationColumn::new(vec![0, 1], vec![LinearRgb::ONE]);
    assert!(matches!(
        short,
        Err(ModelError::Length {
            got: 1,
            expected: 2,
            ..
        })
    ));
    let inf = AttenuationColumn::new(vec![0], vec![rgb(f64::INFINITY, 0.0, 0.0)]);
    let message = inf.expect_err("infinite value").to_string();
    assert!(
        message.contains("attenuation column") && message.contains("finite"),
        "{message}"
    );
}

#[test]
fn problems_reject_bad_targets_and_out_of_range_supports() {
    let col = AttenuationColumn::new(vec![0, 5], vec![LinearRgb::ONE; 2]).expect("column");
    let two = vec![LinearRgb::ZERO; 2];
    let err = Problem::new(vec![col], two.clone(), two.clone(), two.clone());
    assert!(matches!(
        err,
        Err(ModelError::PatchOutOfRange {
            patch: 5,
            patches: 2,
            ..
        })
    ));
    let err = Problem::new(
        vec![],
        two.clone(),
        vec![rgb(f64::NAN, 0.0, 0.0), LinearRgb::ZERO],
        two.clone(),
    );
    assert!(matches!(
        err,
        Err(ModelError::NotFinite {
            what: "targets",
            ..
        })
    ));
    let err = Problem::new(
        vec![],
        vec![rgb(-1.0, 0.0, 0.0), LinearRgb::ZERO],
        two.clone(),
        two.clone(),
    );
    assert!(matches!(
        err,
        Err(ModelError::Negative {
            what: "black offsets",
            ..
        })
    ));
    let err = Problem::new(vec![], two.clone(), two.clone(), vec![LinearRgb::ZERO]);
    assert!(matches!(err, Err(ModelError::Length { what: "noise", .. })));
}

#[test]
fn nodes_reject_bad_errors_and_keep_their_state() {
    let col = AttenuationColumn::new(vec![0, 1], vec![rgb(0.5, 0.5, 0.5), rgb(0.2, 0.2, 0.2)])
        .expect("column");
    let s = [rgb(0.6, 0.6, 0.6), rgb(0.2, 0.2, 0.2)];
    let mut node = NodeState::new(
        col,
        &s,
        StepRule::Momentum { theta: 1.0 },
        LinearRgb::splat(0.4),
    )
    .expect("node");
    let before = node.shown();
    assert!(
        node.update(&[rgb(f64::NAN, 0.0, 0.0), LinearRgb::ZERO], false)
            .is_err()
    );
    assert!(node.update(&[LinearRgb::ZERO], false).is_err());
    assert_eq!(node.shown(), before);
    assert!(matches!(
        NodeState::new(
            AttenuationColumn::default(),
            &[],
            StepRule::Safe { theta: 2.0 },
            LinearRgb::ZERO
        ),
        Err(ModelError::Parameter { what: "theta", .. })
    ));
    assert!(
        NodeState::new(
            AttenuationColumn::default(),
            &[],
            StepRule::Fixed {
                epsilon: rgb(f64::NAN, 0.0, 0.0)
            },
            LinearRgb::ZERO
        )
        .is_err()
    );
    assert!(
        NodeState::new(
            AttenuationColumn::default(),
            &[LinearRgb::ONE],
            StepRule::paper(),
            LinearRgb::ZERO
        )
        .is_err()
    );
}

#[test]
fn a_node_with_an_empty_or_dark_support_stays_where_it_is() {
    for rule in [
        StepRule::paper(),
        StepRule::Safe { theta: 1.0 },
        StepRule::Momentum { theta: 1.0 },
    ] {
        let mut empty = NodeState::new(
            AttenuationColumn::default(),
            &[],
            rule,
            LinearRgb::splat(0.3),
        )
        .expect("node");
        assert_eq!(empty.update(&[], true).expect("update"), LinearRgb::ZERO);
        assert_eq!(empty.shown(), LinearRgb::splat(0.3));
        let dark = AttenuationColumn::new(vec![2], vec![LinearRgb::ZERO]).expect("column");
        let mut node =
            NodeState::new(dark, &[LinearRgb::ZERO], rule, LinearRgb::splat(0.3)).expect("node");
        for _ in 0..3 {
            let d = node.update(&[rgb(1.0, -1.0, 5.0)], false).expect("update");
            assert_eq!(d, LinearRgb::ZERO);
        }
        assert_eq!(node.shown(), LinearRgb::splat(0.3));
    }
}

#[test]
fn the_safe_step_is_the_exact_minimiser_for_a_lone_node() {
    // One node alone: h = ‖p‖², so θ = 1 lands on the one-dimensional optimum in one step.
    let p = [rgb(0.5, 0.4, 0.3), rgb(0.2, 0.1, 0.6)];
    let col = AttenuationColumn::new(vec![0, 1], p.to_vec()).expect("column");
    let mut node =
        NodeState::new(col, &p, StepRule::Safe { theta: 1.0 }, LinearRgb::ZERO).expect("node");
    let x_star = rgb(0.3, 0.6, 0.2);
    let errors: Vec<LinearRgb> = p.iter().map(|pi| pi.hadamard(x_star)).collect();
    node.update(&errors, false).expect("update");
    assert!(
        (node.shown() - x_star).max_abs() < 1e-12,
        "{:?}",
        node.shown()
    );
}

#[test]
fn aggregator_rejects_bad_contributions_whole() {
    let mut agg = ErrorAggregator::new(3);
    agg.measured(vec![LinearRgb::ONE; 3]).expect("errors");
    let before = agg.errors().to_vec();
    assert!(
        agg.add_contribution([(0, LinearRgb::ONE), (7, LinearRgb::ONE)])
            .is_err()
    );
    assert!(
        agg.add_contribution([(0, LinearRgb::ONE), (1, rgb(f64::NAN, 0.0, 0.0))])
            .is_err()
    );
    assert_eq!(agg.errors(), &before[..]);
    assert!(agg.measured(vec![LinearRgb::ONE; 2]).is_err());
    agg.add_contribution([(1, LinearRgb::splat(0.25))])
        .expect("contribution");
    let summary = agg.predicted();
    assert!(!summary.restart && summary.round == 2);
    assert_eq!(agg.errors()[1], LinearRgb::splat(0.75));
    agg.add_contribution([(1, LinearRgb::splat(-3.0))])
        .expect("contribution");
    assert!(agg.predicted().restart, "G rose: restart");
}

#[test]
fn conventional_start_equals_its_closed_form() {
    let p0 = [
        rgb(0.5, 0.4, 0.3),
        rgb(0.2, 0.1, 0.6),
        rgb(0.05, 0.05, 0.05),
    ];
    let col = AttenuationColumn::new(vec![0, 1, 2], p0.to_vec()).expect("column");
    let other =
        AttenuationColumn::new(vec![1, 2, 3], vec![LinearRgb::splat(0.3); 3]).expect("column");
    let target = vec![
        rgb(0.3, 0.3, 0.3),
        rgb(0.2, 0.25, 0.4),
        rgb(0.1, 0.1, 0.1),
        rgb(0.9, 0.9, 0.9),
    ];
    let black = vec![LinearRgb::splat(0.01); 4];
    let problem = Problem::new(
        vec![col.clone(), other],
        black.clone(),
        target.clone(),
        vec![LinearRgb::splat(1e-3); 4],
    )
    .expect("problem");
    // Node 0's own chart is patches 0 and 1; node 1 has none in view.
    let x =
        conventional_start(&problem, &[vec![0, 1], vec![]], LinearRgb::splat(0.5)).expect("start");
    for c in 0..3 {
        let num = p0[0][c] * (target[0][c] - 0.01) + p0[1][c] * (target[1][c] - 0.01);
        let den = p0[0][c] * p0[0][c] + p0[1][c] * p0[1][c];
        assert!((x[0][c] - (num / den).clamp(0.0, 1.0)).abs() < 1e-15);
    }
    assert_eq!(
        x[1],
        LinearRgb::splat(0.5),
        "no chart: the fallback, lights on"
    );
    // Clipping: a target far too bright gives 1.
    let bright = vec![LinearRgb::splat(100.0); 4];
    let v = conventional_value(&col, &[0, 1], &bright, &black, LinearRgb::ZERO).expect("value");
    assert_eq!(v, LinearRgb::ONE);
    assert!(conventional_value(&col, &[9], &bright, &black, LinearRgb::ZERO).is_err());
}
