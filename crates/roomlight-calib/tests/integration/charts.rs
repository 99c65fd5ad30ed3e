//! Chart sampling against the simulator's true patch values.

use crate::common;

use common::{chart_corners, small_scene, to_image};
use roomlight_calib::charts::{ChartCorners, PatchStatus, SampleConfig, sample_charts};
use roomlight_sim::{CameraNoise, Frame, Room};

#[test]
fn patch_means_match_the_true_patch_values_within_their_noise() {
    let room = Room::build(small_scene()).expect("room");
    let n = room.projectors().len();
    let frames = vec![Frame::Uniform([0.6; 3]); n];
    let preset = Some(room.preset("on").expect("preset"));
    let capture = CameraNoise::new(&room).expose(&room.render(&frames, preset).expect("render"));
    let (truth, spread) = room
        .patch_values_and_spread(&frames, preset)
        .expect("truth");
    let samples = sample_charts(
        &to_image(&capture),
        &chart_corners(&room),
        &SampleConfig::default(),
    )
    .expect("samples");
    assert_eq!(samples.len(), truth.len());
    let mut measured = 0;
    for (k, (s, t)) in samples.iter().zip(&truth).enumerate() {
        // Where an edge crosses the patch (the light varies by more than 5% over its inner
        // half) the patch value depends on where one samples: not compared.
        if s.status == PatchStatus::NonUniform || spread[k].max_abs() > 0.05 {
            continue;
        }
        assert_eq!(s.status, PatchStatus::Ok, "patch {k}");
        assert!(s.pixels >= 4, "patch {k}: {} pixels", s.pixels);
        for c in 0..3 {
            let err = (s.mean[c] - t[c]).abs();
            assert!(
                err <= 0.02 * t[c] + 4.0 * s.std_error[c] + 1e-4,
                "patch {k} channel {c}: {} vs {} (σ {})",
                s.mean[c],
                t[c],
                s.std_error[c]
            );
            assert!(
                s.std_error[c] > 0.0 && s.std_error[c].is_finite(),
                "patch {k}: {s:?}"
            );
        }
        measured += 1;
    }
    assert!(measured >= 30, "{measured} of 48 patches measured");
}

#[test]
fn saturated_and_out_of_image_patches_are_reported_not_averaged() {
    let mut scene = small_scene();
    scene.camera.exposure *= 6.0;
    let room = Room::build(scene).expect("room");
    let frames = vec![Frame::Uniform([1.0; 3]); room.projectors().len()];
    let capture = CameraNoise::new(&room).expose(&room.render(&frames, None).expect("render"));
    let samples = sample_charts(
        &to_image(&capture),
        &chart_corners(&room),
        &SampleConfig {
            saturation: 1.0,
            ..SampleConfig::default()
        },
    )
    .expect("samples");
    let saturated = samples
        .iter()
        .filter(|s| s.status == PatchStatus::Saturated)
        .count();
    assert!(
        saturated > 0,
        "bright patches must saturate at six times the exposure"
    );
    assert!(
        samples
            .iter()
            // A non-uniform patch keeps its mean (the caller judges it across captures).
            .filter(|s| !matches!(s.status, PatchStatus::Ok | PatchStatus::NonUniform))
            .all(|s| s.mean == roomlight_core::LinearRgb::ZERO)
    );
    let mut charts = chart_corners(&room);
    // Corners outside the image are refused, naming the chart.
    charts[1].corners[2] = [10_000.0, 5.0];
    let err = sample_charts(
        &to_image(&capture),
        &charts,
        &SampleConfig {
            saturation: 1.0,
            ..SampleConfig::default()
        },
    )
    .expect_err("corner outside");
    let message = err.to_string();
    assert!(
        message.contains("chart floor") && message.contains("outside the 640x480 image"),
        "{message}"
    );
    let degenerate = ChartCorners {
        name: "flat".into(),
        corners: [[5.0, 5.0]; 4],
    };
    assert!(sample_charts(&to_image(&capture), &[degenerate], &SampleConfig::default()).is_err());
}
