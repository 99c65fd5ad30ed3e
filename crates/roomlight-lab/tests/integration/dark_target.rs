//! A dark target (issue 22): patches on the projection-mapping target measured through the
//! same attenuation captures as the charts, weighed into the objective. At weight 0 the model
//! is today's to the last bit; a positive weight lowers the light the model's optimum throws
//! on the target and raises the board's ANSI contrast, both measured on the simulator's
//! noiseless renders.

#[allow(dead_code)]
use crate::support;

use roomlight_lab::dark_target::{curve, target_light};
use roomlight_lab::pipeline::{self, Model};
use roomlight_lab::pm::{self, Lighting};
use roomlight_lab::whole_room::ReachMap;
use roomlight_sim::{CameraNoise, Frame, Room};

const SEED: u64 = 11;

#[test]
fn a_weight_darkens_the_target_at_a_cost_and_weight_zero_is_todays_model() {
    let room = Room::build(support::small_scene()).expect("room");
    let bar = indicatif::ProgressBar::hidden();
    let calibrate = |patches: bool| {
        let mut noise = CameraNoise::with_seed(&room, SEED);
        let cal = pipeline::calibrate_with(&room, patches, &mut noise, &bar, |_| {})
            .expect("calibration");
        (cal, noise)
    };
    let (plain, mut plain_noise) = calibrate(false);
    let (cal, mut noise) = calibrate(true);
    assert_eq!(plain.target_patch_range().len(), 0);
    let patches = cal.target_patch_range().len();
    assert!(patches >= 2, "{patches} target patches");
    // Weight 0: the model is the one calibrated without target patches, bit for bit.
    let today = pipeline::measure_target(&room, &plain, 0, &mut plain_noise).expect("model");
    let lit = pipeline::measure_lit(&room, &cal, 0, &mut noise).expect("lit");
    let zero = Model::for_weight(&cal, &lit, 0.0).expect("w = 0");
    assert_eq!(zero.problem, today.problem);
    assert_eq!(zero.patches, today.patches);
    assert_eq!(zero.conventional, today.conventional);
    let heavy = Model::for_weight(&cal, &lit, 10.0).expect("w = 10");
    assert_eq!(heavy.patches.len(), today.patches.len() + patches);
    // The optimum at each weight, rendered: less light on the target as the weight grows, a
    // room further from the LEDs in exchange.
    let reach = ReachMap::new(&room, &cal.regions).expect("reach");
    let points = curve(&room, &cal, &reach, 0, &lit, &[0.0, 10.0, 100.0]).expect("curve");
    let shares: Vec<f64> = points.iter().map(|p| p.target_light_share).collect();
    assert!(
        shares[1] < 0.8 * shares[0] && shares[2] < shares[1],
        "light on the target {shares:?}"
    );
    // The share is the simulator's: re-render the heaviest optimum independently.
    let frames =
        pipeline::FrameBuilder::new(&room, &cal.regions, cal.responses.clone()).expect("frames");
    let black = vec![Frame::Black; room.projectors().len()];
    let mask: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let dark = room.render(&black, None).expect("ok");
    let led = target_light(&room.render(&black, Some(0)).expect("ok"), &dark, &mask).expect("ok");
    let lit_heavy = target_light(
        &room.render(&frames.frames(&points[2].x), None).expect("ok"),
        &dark,
        &mask,
    )
    .expect("ok");
    assert!((lit_heavy / led - shares[2]).abs() < 1e-9);
    assert!(
        points[2].room_de00_mean > points[0].room_de00_mean,
        "darkening the target costs the room: {:?}",
        points.iter().map(|p| p.room_de00_mean).collect::<Vec<_>>()
    );
    // The board's ANSI contrast under projector lighting with each optimum.
    let name = room.scene().presets[0].name.clone();
    let lightings: Vec<Lighting<'_>> = points
        .iter()
        .map(|p| Lighting {
            gains: &[],
            preset: 0,
            name: &name,
            x: &p.x,
        })
        .collect();
    let dir = std::env::temp_dir().join(format!("roomlight-dark-target-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let result = pm::run(&room, &cal, &lightings[..1], &lightings, SEED, &dir, |_| {});
    std::fs::remove_dir_all(&dir).ok();
    let ansi = result.expect("projection mapping").tradeoff_ansi;
    assert_eq!(ansi.len(), 3);
    assert!(
        ansi[1] > 1.1 * ansi[0] && ansi[2] > ansi[1],
        "ANSI contrast {ansi:?}"
    );
}

/// The agents' rounds with the target weighed in (issue 22 item 3): the simulated camera's
/// measurements of the target patches scaled as their rows are, the truth asking for the
/// black level there. At weight 10 the rounds leave less light on the target than at 0, and
/// end within 5% of the weighted model's optimum `G*` (from 10 or more times that at the
/// conventional start), as the rounds over the charts alone do of theirs.
#[test]
fn the_rounds_with_a_dark_weight_darken_the_target_and_reach_their_optimum() {
    let room = std::sync::Arc::new(Room::build(support::small_scene()).expect("room"));
    let bar = indicatif::ProgressBar::hidden();
    let mut noise = CameraNoise::with_seed(&room, SEED);
    let cal = pipeline::calibrate_with(&room, true, &mut noise, &bar, |_| {}).expect("cal");
    let lit = pipeline::measure_lit(&room, &cal, 0, &mut noise).expect("lit");
    let transport = pipeline::Transport::new(&room, &cal.regions, cal.setup()).expect("transport");
    let frames =
        pipeline::FrameBuilder::new(&room, &cal.regions, cal.responses.clone()).expect("frames");
    let black = vec![Frame::Black; room.projectors().len()];
    let mask: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let dark = room.render(&black, None).expect("dark");
    let on_target = |x: &[roomlight_core::LinearRgb]| {
        target_light(
            &room.render(&frames.frames(x), None).expect("render"),
            &dark,
            &mask,
        )
        .expect("target")
    };
    let run = |weight: f64| {
        let model = Model::for_weight(&cal, &lit, weight).expect("model");
        let truth = pipeline::Truth::new(&room, &transport, &model, 0).expect("truth");
        let options = pipeline::RunOptions {
            max_captures: 12,
            ..pipeline::RunOptions::default_rule(3)
        };
        let result = pipeline::run_agents(&room, &cal, &model, &transport, &truth, options, &bar)
            .expect("run");
        let start = result.trace.first().expect("start").model_excess;
        assert!(
            result.final_excess < 0.05 && result.final_excess < start / 10.0,
            "w {weight}: excess over the model's optimum {start} at the start, {} at the end",
            result.final_excess
        );
        on_target(&result.x)
    };
    let (plain, weighed) = (run(0.0), run(10.0));
    assert!(
        weighed < 0.8 * plain,
        "light on the target: {plain} at w = 0, {weighed} at w = 10"
    );
}

/// The contrast board in place of the target: the luminaires' nodes re-placed for it
/// ([`pm::board_regions`]) also keep dark where their light fell on the target during
/// calibration, so less direct light reaches the board than with the board's own mask alone
/// (what projection mapping used before; on the lab the direct light on the board grew with
/// the weight, as the nodes behind the target were turned up). Measured on the small room
/// (2026-11-28): 0.0395 kept dark, 0.0557 with the board's own mask, 0.364 unmasked. The 11%
/// of the unmasked light left falls where neither mask is (not investigated: likely parts of
/// the board the room camera does not see).
#[test]
fn the_luminaires_throw_no_direct_light_on_the_board() {
    use roomlight_core::metrics::luminance;
    let scene = support::small_scene();
    let room = Room::build(scene.clone()).expect("room");
    let bar = indicatif::ProgressBar::hidden();
    let mut noise = CameraNoise::with_seed(&room, SEED);
    let cal = pipeline::calibrate_with(&room, true, &mut noise, &bar, |_| {}).expect("cal");
    let board = Room::build(pm::evaluation_scene(&scene, true, true).expect("scene")).expect("b");
    let board_mask: Vec<bool> = board.pixels().iter().map(|p| p.target).collect();
    let direct = |regions: &[roomlight_sim::NodeRegion]| {
        let frames = pipeline::FrameBuilder::new(&board, regions, cal.responses.clone())
            .expect("frames")
            .frames(&vec![roomlight_core::LinearRgb::splat(1.0); regions.len()]);
        (0..frames.len())
            .map(|k| luminance(board.target_irradiance(k, &frames[k]).expect("direct")))
            .sum::<f64>()
    };
    let unmasked = direct(&cal.regions);
    let own = direct(&cal.regions_with_mask(&room, &board_mask).expect("own mask"));
    let kept = direct(&pm::board_regions(&room, &cal).expect("board regions"));
    println!("direct light on the board: {unmasked} unmasked, {own} with its own mask, {kept}");
    assert!(unmasked > 0.0, "the luminaires do not reach the board");
    assert!(
        kept < 0.8 * own && kept < 0.15 * unmasked,
        "direct light on the board: {kept} kept dark, {own} with its own mask, {unmasked} unmasked"
    );
}
