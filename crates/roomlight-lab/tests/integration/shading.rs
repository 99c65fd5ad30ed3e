//! Per-pixel shading (issue 22 item 2) on the small room: from its measured model's optimum,
//! passes of gains stepped towards the LEDs' photograph (noisy, as a camera gives it, through
//! the measured decodes) bring the whole room's mean much closer to the LEDs, judged against
//! the simulator's noiseless truth, its 95th percentile too, at a small cost at the charts; the
//! gains stay within their bounds.

use crate::support;

use roomlight_calib::procedure::Settings;
use roomlight_calib::shading::{MAX_GAIN, MIN_GAIN};
use roomlight_lab::pipeline::{self, Nodes};
use roomlight_lab::shaded::{self, Preset};
use roomlight_lab::whole_room::ReachMap;
use roomlight_lab::whole_room_best;
use roomlight_sim::{CameraNoise, Frame, Room};

#[test]
fn shading_passes_bring_the_whole_room_to_the_leds() {
    let room = Room::build(support::small_scene()).expect("room");
    let bar = indicatif::ProgressBar::hidden();
    let mut noise = CameraNoise::with_seed(&room, 5);
    let cal = pipeline::calibrate_configured(
        &room,
        false,
        Settings::default(),
        Nodes::Flat,
        &mut noise,
        &bar,
        |_| {},
    )
    .expect("calibration");
    let reach = ReachMap::new(&room, &cal.regions).expect("reach");
    let (lit, photograph) = pipeline::photograph_lit(&room, &cal, 0, &mut noise).expect("lit");
    let model = pipeline::Model::for_weight(&cal, &lit, 0.0).expect("model");
    let x = roomlight_core::optimum::optimum(&model.problem)
        .expect("optimum")
        .x;
    let black = vec![Frame::Black; room.projectors().len()];
    let dark = noise.expose(&room.render(&black, None).expect("dark"));
    let preset = Preset {
        index: 0,
        reference: &photograph,
        dark: &dark,
    };
    let s = shaded::shade(&room, &cal, &reach, preset, &x, &mut noise, 4).expect("shading");
    // Pass 0 is the nodes' light as the report measures it: flat gains change nothing.
    let truth = room.render(&black, Some(0)).expect("reference");
    let plain = whole_room_best::of_values(&room, &cal, &reach, &truth, &x).expect("plain");
    let (start, end) = (s.first(), s.last());
    assert!((start.whole_room_de00_mean - plain.de00_mean).abs() < 1e-9);
    assert!((start.whole_room_de00_p95 - plain.de00_p95).abs() < 1e-9);
    for p in s.passes() {
        println!(
            "after {} passes: whole room ΔE00 {:.2} / p95 {:.2}, charts {:.2}",
            p.captures, p.whole_room_de00_mean, p.whole_room_de00_p95, p.chart_de00_mean
        );
    }
    println!("gains (5th, 95th percentile) {:?}", s.gains);
    assert_eq!(s.passes().len(), 5);
    // Measured (2026-12-07): 8.41 / 18.49 → 2.72 / 8.71, charts 2.27 → 2.54. The small room's
    // left projector is all but off at its model's optimum (its nodes under 0.04): without the
    // floor under a shaded pixel's light its half of the room stayed dark (4.48 / 17.66).
    assert!(
        end.whole_room_de00_mean < 0.5 * start.whole_room_de00_mean,
        "mean {:.2} → {:.2}",
        start.whole_room_de00_mean,
        end.whole_room_de00_mean
    );
    assert!(
        end.whole_room_de00_p95 < 0.7 * start.whole_room_de00_p95,
        "p95 {:.2} → {:.2}",
        start.whole_room_de00_p95,
        end.whole_room_de00_p95
    );
    // The charts lose a little here (the lab's gain: docs/results.md).
    assert!(
        end.chart_de00_mean < start.chart_de00_mean + 0.5,
        "charts {:.2} → {:.2}",
        start.chart_de00_mean,
        end.chart_de00_mean
    );
    assert!(!s.gains.is_empty());
    for (name, lo, hi) in &s.gains {
        assert!(
            MIN_GAIN <= *lo && lo <= hi && *hi <= MAX_GAIN,
            "{name}: gains {lo}..{hi}"
        );
    }
}
