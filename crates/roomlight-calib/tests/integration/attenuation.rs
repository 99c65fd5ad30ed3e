//! Responses and attenuation measured from simulated captures against the true transport.

use crate::common;

use common::{chart_corners, small_scene, to_image};
use roomlight_calib::attenuation::{Scheme, differential, plan, s_order, solve, white_response};
use roomlight_calib::charts::{ChartCorners, PatchSample, SampleConfig, sample_charts};
use roomlight_calib::response::{fit_response, ramp_codes};
use roomlight_core::LinearRgb;
use roomlight_sim::{CameraNoise, Frame, ProjectorImage, Room};

/// Nodes: the top and bottom halves of the two standard projectors (their boundary runs between
/// the charts, as the nearest-chart segmentation places it), and the large-aperture projector.
const NODES: usize = 5;

/// The node of pixel `i` of projector `k`; the texture projector (3) is no luminaire.
fn node_of(k: usize, i: u32, w: u32, h: u32) -> Option<usize> {
    match k {
        0 | 1 => Some(2 * k + usize::from(i / w >= h / 2)),
        2 => Some(4),
        _ => None,
    }
}

fn node_frames(room: &Room, on: &[bool], level: f32) -> Vec<Frame> {
    room.projectors()
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let (w, h) = (p.pinhole.width, p.pinhole.height);
            let pixels = (0..w * h)
                .map(|i| {
                    if node_of(k, i, w, h).is_some_and(|n| on[n]) {
                        [level; 3]
                    } else {
                        [0.0; 3]
                    }
                })
                .collect();
            Frame::Image(ProjectorImage {
                width: w,
                height: h,
                pixels,
            })
        })
        .collect()
}

fn measure(
    room: &Room,
    frames: &[Frame],
    noise: &mut CameraNoise,
    charts: &[ChartCorners],
) -> Vec<PatchSample> {
    let cap = noise.expose(&room.render(frames, None).expect("render"));
    sample_charts(&to_image(&cap), charts, &SampleConfig::default()).expect("samples")
}

#[test]
fn the_hidden_gamma_is_recovered_within_two_percent() {
    let room = Room::build(small_scene()).expect("room");
    let charts = chart_corners(&room);
    let mut noise = CameraNoise::new(&room);
    let k = 1; // gamma [2.0, 2.2, 2.4]
    let codes = ramp_codes(9).expect("codes");
    let samples: Vec<Vec<PatchSample>> = codes
        .iter()
        .map(|&c| {
            let mut frames = vec![Frame::Black; room.projectors().len()];
            frames[k] = Frame::Uniform([c as f32; 3]);
            measure(&room, &frames, &mut noise, &charts)
        })
        .collect();
    // The white patch (index 18) of the chart this projector lights most.
    let patch = (0..charts.len())
        .map(|m| 24 * m + 18)
        .max_by(|&a, &b| samples[8][a].mean[1].total_cmp(&samples[8][b].mean[1]))
        .expect("a chart");
    let measured: Vec<LinearRgb> = samples.iter().map(|s| s[patch].mean).collect();
    let sigma: Vec<LinearRgb> = samples.iter().map(|s| s[patch].std_error).collect();
    let response = fit_response(&codes, &measured, &sigma).expect("fit");
    for (c, truth) in [2.0, 2.2, 2.4].into_iter().enumerate() {
        assert!(
            (response.gamma[c] / truth - 1.0).abs() < 0.02,
            "channel {c}: {} vs {truth}",
            response.gamma[c]
        );
    }
    // The inverse gives linear light: half the light needs code 0.5^(1/γ).
    let code = response.to_code(LinearRgb::splat(0.5));
    assert!((f64::from(code[1]) - 0.5f64.powf(1.0 / 2.2)).abs() < 0.01);
    // Too few levels, or a patch the projector does not light, are refused.
    assert!(ramp_codes(3).is_err());
    // The ends and two levels between (the procedure's ramp) recover it too.
    let four: Vec<usize> = vec![0, 3, 6, 8];
    let pick = |v: &[LinearRgb]| four.iter().map(|&j| v[j]).collect::<Vec<_>>();
    let coarse = fit_response(
        &four.iter().map(|&j| codes[j]).collect::<Vec<_>>(),
        &pick(&measured),
        &pick(&sigma),
    );
    // Codes 3/8 and 6/8 are not the procedure's 1/3 and 2/3, but fit the same one exponent.
    for (c, truth) in [2.0, 2.2, 2.4].into_iter().enumerate() {
        let g = coarse.as_ref().expect("fit from four levels").gamma[c];
        assert!(
            (g / truth - 1.0).abs() < 0.02,
            "channel {c}: {g} vs {truth}"
        );
    }
    let dark: Vec<LinearRgb> = vec![LinearRgb::splat(0.01); 9];
    assert!(fit_response(&codes, &dark, &sigma).is_err());
}

/// The true `p` of each node (noiseless patch values with the node white, minus black), and
/// whether the light is uniform over each patch in that capture (spread under 5%): where an
/// edge crosses a patch its value depends on where one samples, so it is not compared.
fn truth(room: &Room, nodes: usize) -> (Vec<Vec<LinearRgb>>, Vec<Vec<bool>>) {
    let black = room
        .patch_values(&node_frames(room, &vec![false; nodes], 1.0), None)
        .expect("truth");
    (0..nodes)
        .map(|n| {
            let on: Vec<bool> = (0..nodes).map(|j| j == n).collect();
            let (y, spread) = room
                .patch_values_and_spread(&node_frames(room, &on, 1.0), None)
                .expect("truth");
            (
                y.iter().zip(&black).map(|(a, b)| *a - *b).collect(),
                spread.iter().map(|s| s.max_abs() < 0.05).collect(),
            )
        })
        .unzip()
}

fn run(
    room: &Room,
    scheme: Scheme,
    nodes: usize,
    seed: u64,
    charts: &[ChartCorners],
) -> roomlight_calib::attenuation::Attenuation {
    let mut noise = CameraNoise::with_seed(room, seed);
    let black = measure(
        room,
        &node_frames(room, &vec![false; nodes], 1.0),
        &mut noise,
        charts,
    );
    let caps: Vec<Vec<PatchSample>> = plan(nodes, scheme)
        .iter()
        .map(|on| measure(room, &node_frames(room, on, 1.0), &mut noise, charts))
        .collect();
    solve(scheme, nodes, &black, &caps).expect("solve")
}

#[test]
fn attenuation_matches_the_true_transport_for_both_schemes() {
    let room = Room::build(small_scene()).expect("room");
    let charts = chart_corners(&room);
    let nodes = NODES;
    let (truth, uniform) = truth(&room, nodes);
    for scheme in [Scheme::OneAtATime, Scheme::Hadamard] {
        let att = run(&room, scheme, nodes, 11, &charts);
        let (mut checked, mut worst) = (0, 0.0f64);
        for n in 0..nodes {
            for i in 0..truth[n].len() {
                let (tn, mn, sn) = (truth[n][i], att.dense[n][i], att.sigma[n][i]);
                for c in 0..3 {
                    let (t, m, s) = (tn[c], mn[c], sn[c]);
                    // Entries above the noise floor: within 2% beyond three standard deviations.
                    if att.usable[i] && uniform[n][i] && t > 20.0 * s {
                        let e = ((m - t).abs() - 3.0 * s).max(0.0) / t;
                        worst = worst.max(e);
                        checked += 1;
                    }
                }
            }
        }
        assert!(
            checked > 100,
            "{scheme:?}: only {checked} entries above the noise"
        );
        assert!(
            worst < 0.02,
            "{scheme:?}: worst relative error beyond 3σ {worst}"
        );
        // The support keeps entries above 3σ and drops the rest.
        let columns = att.columns(3.0).expect("columns");
        for (n, col) in columns.iter().enumerate() {
            for (i, p) in col.iter() {
                assert!((0..3).any(|c| p[c] > 3.0 * att.sigma[n][i as usize][c]));
            }
        }
    }
    assert_eq!(s_order(NODES), 7);
    assert_eq!(plan(NODES, Scheme::Hadamard).len(), 7);
}

#[test]
fn hadamard_multiplexing_lowers_the_variance() {
    let room = Room::build(small_scene()).expect("room");
    let charts = chart_corners(&room);
    let nodes = NODES;
    let runs = 12;
    let estimates = |scheme| {
        (0..runs)
            .map(|r| run(&room, scheme, nodes, 100 + r, &charts))
            .collect::<Vec<_>>()
    };
    let (single, multiplexed) = (estimates(Scheme::OneAtATime), estimates(Scheme::Hadamard));
    let variance = |runs: &[roomlight_calib::attenuation::Attenuation], n: usize, i: usize| {
        let m = runs.iter().map(|a| a.dense[n][i][1]).sum::<f64>() / runs.len() as f64;
        runs.iter()
            .map(|a| (a.dense[n][i][1] - m).powi(2))
            .sum::<f64>()
            / (runs.len() - 1) as f64
    };
    let (mut num, mut den) = (0.0, 0.0);
    for n in 0..nodes {
        for i in 0..single[0].dense[n].len() {
            if single[0].usable[i] && multiplexed[0].usable[i] {
                num += variance(&single, n, i);
                den += variance(&multiplexed, n, i);
            }
        }
    }
    let gain = num / den;
    let theory = (7.0f64 + 1.0).powi(2) / (4.0 * 7.0);
    println!(
        "Hadamard variance gain over one-at-a-time: measured {gain:.2}, theory {theory:.2} for read noise alone (shot noise grows with the extra light and eats into it)"
    );
    assert!(gain > 1.0, "measured gain {gain}");
}

#[test]
fn hot_calibration_measures_one_node_while_the_others_stay_lit() {
    let room = Room::build(small_scene()).expect("room");
    let charts = chart_corners(&room);
    let nodes = NODES;
    let (truth, uniform) = truth(&room, nodes);
    let mut noise = CameraNoise::with_seed(&room, 5);
    let n = 2;
    // Everyone else at mid grey; node n at white and at black, in the same frames.
    let frames_with = |level_n: f32| {
        room.projectors()
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let (w, h) = (p.pinhole.width, p.pinhole.height);
                let pixels = (0..w * h)
                    .map(|i| {
                        [if node_of(k, i, w, h) == Some(n) {
                            level_n
                        } else {
                            0.7
                        }; 3]
                    })
                    .collect();
                Frame::Image(ProjectorImage {
                    width: w,
                    height: h,
                    pixels,
                })
            })
            .collect::<Vec<_>>()
    };
    let at_one = measure(&room, &frames_with(1.0), &mut noise, &charts);
    let at_zero = measure(&room, &frames_with(0.0), &mut noise, &charts);
    let (p, sigma) = differential(&at_one, &at_zero).expect("differential");
    let mut checked = 0;
    for i in 0..p.len() {
        for c in 0..3 {
            if at_one[i].status == roomlight_calib::charts::PatchStatus::Ok
                && at_zero[i].status == roomlight_calib::charts::PatchStatus::Ok
                && uniform[n][i]
                && truth[n][i][c] > 20.0 * sigma[i][c]
            {
                let excess = ((p[i][c] - truth[n][i][c]).abs() - 3.0 * sigma[i][c]).max(0.0);
                assert!(
                    excess < 0.02 * truth[n][i][c],
                    "patch {i}: {} vs {} (σ {})",
                    p[i][c],
                    truth[n][i][c],
                    sigma[i][c]
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 20);
    // s from one all-white capture equals the sum of the columns.
    let black = measure(
        &room,
        &node_frames(&room, &vec![false; nodes], 1.0),
        &mut noise,
        &charts,
    );
    let white = measure(
        &room,
        &node_frames(&room, &vec![true; nodes], 1.0),
        &mut noise,
        &charts,
    );
    let s = white_response(&black, &white).expect("s");
    let ok = |i: usize| {
        white[i].status == roomlight_calib::charts::PatchStatus::Ok
            && black[i].status == roomlight_calib::charts::PatchStatus::Ok
    };
    for i in (0..s.len()).filter(|&i| ok(i) && (0..nodes).all(|n| uniform[n][i])) {
        let sum: f64 = (0..nodes).map(|n| truth[n][i][1]).sum();
        assert!(
            (s[i][1] - sum).abs() < 0.02 * sum + 0.01,
            "patch {i}: s {} vs Σp {}",
            s[i][1],
            sum
        );
    }
}
