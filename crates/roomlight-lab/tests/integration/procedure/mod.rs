//! The one calibration procedure (roomlight_calib::procedure) on the simulated room as a rig
//! (the lab's `SimRig`, the rig the demo and the benches calibrate through), against the
//! simulator's truth: correspondences, simultaneous coding of disjoint projectors, the second
//! pass, partition of unity, attenuation, and a projector joining a lit room hot.

use roomlight_calib::charts::SampleConfig;
use roomlight_calib::nodes::{Partition, add_claim};
use roomlight_calib::procedure::{
    BringUp, Decoded, Event, Placed, Procedure, Settings, Setup, Stage,
};
use roomlight_calib::rig::{Frame, Projector, ProjectorKind, Rig, block_on};
use roomlight_core::LinearRgb;
use roomlight_lab::pipeline::{SimRig, chart_corners};
use roomlight_sim::{CameraNoise, Room, scenes};
use std::sync::{Arc, Mutex};
use support::accuracy::{accuracy, accuracy_where, assert_accurate};
use support::{apart_scene, small_scene};

use crate::support;

mod primaries;

/// The lab at a small camera resolution (320 × 240).
fn small_lab() -> Room {
    let mut scene = scenes::lab().expect("lab");
    scene.camera.resolution = [320, 240];
    Room::build(scene).expect("room")
}

/// The simulated room as a rig with only `live` projectors, captures exposed through `noise`.
fn rig<'a>(room: &'a Room, noise: &'a mut CameraNoise, live: &[&str]) -> SimRig<'a> {
    SimRig::new(room, noise)
        .with_live(live)
        .expect("live projectors")
}

fn setup(room: &Room) -> Setup {
    Setup {
        corners: chart_corners(room).expect("charts in view"),
        sample: SampleConfig::default(),
        target_mask: room.pixels().iter().map(|p| p.target).collect(),
        target_patches: Vec::new(),
        wall_patches: Vec::new(),
        reference: None,
    }
}

/// Every event the procedure reported.
fn recorder() -> (Arc<Mutex<Vec<Event>>>, impl FnMut(Event) + Send + 'static) {
    let events = Arc::new(Mutex::new(Vec::new()));
    let sink = events.clone();
    (events, move |e| sink.lock().expect("events").push(e))
}

fn captured_in(events: &[Event], stage: Stage) -> usize {
    events
        .iter()
        .filter(|e| **e == Event::Captured { stage })
        .count()
}

/// The partition of unity of placed standard luminaires through the true correspondence,
/// away from the target (its margin is black), as the nodes tests measure it.
fn partition(room: &Room, placed: &[&Placed]) -> Partition {
    roomlight_lab::pipeline::placed_partition(room, placed).expect("partition")
}

/// The simulator's noiseless patch values with every projector showing `frames` (by id;
/// the others black) drawn as the rig draws them.
fn truth_values(rig: &SimRig, frames: &[(&str, Frame)]) -> (Vec<LinearRgb>, Vec<LinearRgb>) {
    let room = rig.room();
    let mut all = vec![roomlight_sim::Frame::Black; room.projectors().len()];
    for (id, f) in frames {
        let k = room.projector(id).expect("projector");
        all[k] = rig.sim_frame_of(id, f).expect("frame");
    }
    room.patch_values_and_spread(&all, None).expect("truth")
}

/// Compares measured columns with the truth (noiseless, node alone at white minus all black,
/// on patches the light is uniform over): within 2% beyond 3σ where the truth is above 20σ,
/// as the attenuation tests hold both schemes to. Returns the entries checked.
fn check_columns(
    measured: &[Vec<LinearRgb>],
    sigma: &[Vec<LinearRgb>],
    usable: &[bool],
    truth: &[(Vec<LinearRgb>, Vec<bool>)],
) -> usize {
    let mut checked = 0;
    for ((m, s), (t, uniform)) in measured.iter().zip(sigma).zip(truth) {
        for i in 0..t.len() {
            for c in 0..3 {
                if usable[i] && uniform[i] && t[i][c] > 20.0 * s[i][c] {
                    let excess = ((m[i][c] - t[i][c]).abs() - 3.0 * s[i][c]).max(0.0);
                    assert!(
                        excess < 0.02 * t[i][c],
                        "patch {i}: {} vs {} (σ {})",
                        m[i][c],
                        t[i][c],
                        s[i][c]
                    );
                    checked += 1;
                }
            }
        }
    }
    checked
}

/// `lit` brought up in the dark (with `settings`) and lit at mid grey, then `joiner` live
/// beside them: the rig, the bring-up, and the share of the light the lit ones give at each
/// camera pixel.
fn lit_then_joining<'a>(
    room: &'a Room,
    noise: &'a mut CameraNoise,
    (setup, settings): (&Setup, Settings),
    lit: &[&str],
    joiner: &str,
) -> (SimRig<'a>, BringUp, Vec<f32>) {
    let mut rig = rig(room, noise, lit);
    let up =
        block_on(Procedure::new(&mut rig, settings, |_| {}).bring_up(setup)).expect("bring-up");
    block_on(rig.show(&frames_of(&up.placed, &[], LinearRgb::splat(0.5)))).expect("lit");
    rig.go_live(joiner).expect("joiner");
    let pixels = room.camera().width as usize * room.camera().height as usize;
    let claimed = roomlight_calib::procedure::claimed_by(&up.placed, pixels);
    (rig, up, claimed)
}

/// Node values of `placed` as frames: node ids in `on` at white, the others at `rest`.
fn frames_of<'p>(placed: &'p [Placed], on: &[u32], rest: LinearRgb) -> Vec<(&'p str, Frame)> {
    placed
        .iter()
        .map(|p| {
            let values = p
                .nodes
                .iter()
                .map(|n| {
                    (
                        n.id,
                        if on.contains(&n.id) {
                            LinearRgb::ONE
                        } else {
                            rest
                        },
                    )
                })
                .collect();
            (p.projector.id.as_str(), Frame::Nodes(values))
        })
        .collect()
}

/// Every live projector of the procedure's rig through its black offset, whites and structured
/// light: the projectors and what they decoded.
fn structured_light(procedure: &mut Procedure<'_, SimRig<'_>>) -> (Vec<Projector>, Vec<Decoded>) {
    let live = procedure.rig().projectors();
    let decoded = block_on(async {
        let dark = procedure.dark(&live).await?;
        let whites = procedure.whites(&live).await?;
        procedure
            .structured_light(&live, &dark, &whites, None)
            .await
    })
    .expect("structured light");
    (live, decoded)
}

#[test]
fn bring_up_decodes_segments_and_measures_the_small_room() {
    let room = Room::build(small_scene()).expect("room");
    let setup = setup(&room);
    let mut noise = CameraNoise::with_seed(&room, 21);
    let mut rig = rig(&room, &mut noise, &["left", "right", "area", "texture"]);
    let (events, progress) = recorder();
    let up = block_on(Procedure::new(&mut rig, Settings::default(), progress).bring_up(&setup))
        .expect("bring-up");
    let events = events.lock().expect("events").clone();
    assert_eq!(up.captures, rig.captures());
    assert_eq!(
        events
            .iter()
            .filter(|e| matches!(e, Event::Captured { .. }))
            .count(),
        up.captures
    );
    println!("bring-up: {} captures", up.captures);
    // The texture projector is kept dark, not calibrated.
    let ids: Vec<&str> = up
        .measured
        .iter()
        .map(|m| m.projector.id.as_str())
        .collect();
    assert_eq!(ids, ["left", "right", "area"]);
    for m in up
        .measured
        .iter()
        .filter(|m| m.projector.kind == ProjectorKind::Standard)
    {
        assert_accurate(&room, &m.projector.id, &m.corr, m.manifest.tolerance());
    }
    // Every projector's hidden gamma (right's is [2.0, 2.2, 2.4]), from the ramp levels the
    // three showed at once (one capture a level): the small room's footprints overlap.
    assert_eq!(captured_in(&events, Stage::Responses), 2);
    assert!(
        !events.iter().any(|e| matches!(e, Event::RampApart { .. })),
        "the ramp was shown apart"
    );
    for m in &up.measured {
        let truth =
            room.scene().projectors[room.projector(&m.projector.id).expect("projector")].gamma;
        let gamma = m.response.gamma;
        println!("{}: γ {gamma:?}, true {truth:?}", m.projector.id);
        for c in 0..3 {
            assert!(
                (gamma[c] / truth[c] - 1.0).abs() < 0.03,
                "{}: γ {gamma:?}",
                m.projector.id
            );
        }
    }
    // Segmented together: the bar the nodes tests set (measured 98.76% within 1e-3).
    let standard: Vec<&Placed> = up.placed.iter().take(2).collect();
    let joint = partition(&room, &standard);
    println!("segmented together: {joint}");
    assert!(joint.points > 1000 && joint.overlap > 200, "{joint}");
    assert!(
        joint.within_1e3 > 0.98 && joint.within_0_05 > 0.99,
        "{joint}"
    );
    // The area light is one node over its frame.
    assert_eq!(up.placed[2].nodes.len(), 1);
    // Attenuation against the simulator's transport, through the nodes as the rig draws them.
    let black = truth_values(&rig, &frames_of(&up.placed, &[], LinearRgb::ZERO)).0;
    let truth: Vec<(Vec<LinearRgb>, Vec<bool>)> = up
        .columns
        .ids
        .iter()
        .map(|&n| {
            let (y, spread) = truth_values(&rig, &frames_of(&up.placed, &[n], LinearRgb::ZERO));
            (
                y.iter().zip(&black).map(|(a, b)| *a - *b).collect(),
                spread.iter().map(|s| s.max_abs() < 0.05).collect(),
            )
        })
        .collect();
    let att = &up.columns.attenuation;
    let checked = check_columns(&att.dense, &att.sigma, &att.usable, &truth);
    println!("attenuation: {checked} entries checked against the truth");
    assert!(checked > 100, "only {checked} entries above the noise");
    // The target stays dark: luminaire light on it is at most 1% of the table's beside it.
    for p in &standard {
        let k = room.projector(&p.projector.id).expect("projector");
        let all_on: Vec<u32> = p.ids();
        let frame = rig
            .sim_frame_of(
                &p.projector.id,
                &frames_of(std::slice::from_ref(*p), &all_on, LinearRgb::ZERO)[0].1,
            )
            .expect("frame");
        let on_target = room.target_irradiance(k, &frame).expect("target")[1];
        let table = room
            .direct_irradiance_at(k, &frame, [0.75, 0.62, 0.32], [0.0, 0.0, 1.0])
            .expect("table")[1];
        assert!(
            on_target <= 0.01 * table,
            "{}: {on_target} vs {table}",
            p.projector.id
        );
    }
}

#[test]
fn projectors_whose_footprints_do_not_overlap_are_coded_in_one_pass() {
    let room = Room::build(apart_scene()).expect("room");
    let mut noise = CameraNoise::with_seed(&room, 31);
    let mut rig = rig(&room, &mut noise, &["left", "right"]);
    let (events, progress) = recorder();
    // At full resolution. Right lights its wall at a grazing angle, so one axis is far more
    // foreshortened than the other; cells sized from its footprint's average (4) leave 3.9%
    // of its reached pixels unknown shown once (none at full resolution in this sharp
    // simulated camera), and the group then takes its inverses: 26 captures instead of 13.
    // Cells per axis would fit it; they are not done (2026-11-29).
    let settings = Settings {
        cells: false,
        ..Settings::default()
    };
    let mut procedure = Procedure::new(&mut rig, settings, progress);
    let (live, decoded) = structured_light(&mut procedure);
    let events = events.lock().expect("events").clone();
    assert!(
        events.contains(&Event::Grouped {
            groups: vec![vec!["left".into(), "right".into()]]
        }),
        "{events:?}"
    );
    for d in &decoded {
        assert_accurate(&room, &d.projector.id, &d.corr, d.manifest.tolerance());
    }
    // One pattern set for both instead of one each (their bit patterns, without inverses as
    // both are XOR-coded: white and black are the dark and footprint captures).
    let coded = captured_in(&events, Stage::StructuredLight);
    let alone: usize = live
        .iter()
        .zip(&decoded)
        .map(|(p, d)| {
            assert!(settings.shows_once(p), "{} is shown once", p.id);
            (d.manifest.column_bits + d.manifest.row_bits) as usize
        })
        .sum();
    println!("structured light: {coded} captures together, {alone} one at a time");
    assert_eq!(2 * coded, alone);
}

#[test]
fn a_second_pass_decodes_the_labs_grazing_face() {
    // The lab at a small camera resolution with only floor-right live: the floor's reflected
    // light hides the grazing face's code from the first pass (graycode tests: 93.70% within
    // ±1 alone, 99.61% after the second pass).
    let room = small_lab();
    let mut noise = CameraNoise::with_seed(&room, 7);
    let mut rig = rig(&room, &mut noise, &["floor-right"]);
    let (events, progress) = recorder();
    let mut procedure = Procedure::new(&mut rig, Settings::default(), progress);
    let (live, decoded) = structured_light(&mut procedure);
    drop(procedure);
    let pass = decoded[0].second.expect("a second pass");
    assert!(pass.taken > 0, "{pass:?}");
    assert_eq!(
        captured_in(&events.lock().expect("events"), Stage::SecondPass),
        pass.captures
    );
    assert_accurate(
        &room,
        "floor-right",
        &decoded[0].corr,
        decoded[0].manifest.tolerance(),
    );
    // A rig that cannot show images skips it.
    rig.set_shows_masks(false);
    let mut procedure = Procedure::new(&mut rig, Settings::default(), |_| {});
    let mut corr = decoded[0].corr.clone();
    corr.map.iter_mut().enumerate().for_each(|(i, m)| {
        if i % 3 == 0 {
            *m = None;
        }
    });
    let manifest = roomlight_calib::graycode::Manifest::with_coding(
        live[0].width,
        live[0].height,
        roomlight_calib::graycode::Coding::Xor04,
    )
    .expect("manifest");
    let skipped =
        block_on(procedure.second_pass(&live[0], &manifest, &mut corr, None)).expect("skip");
    assert_eq!(skipped, None);
    assert_eq!(procedure.captures(), 0);
}

#[test]
fn a_bring_up_places_a_projector_that_left_a_face_unknown_beside_the_others() {
    // The lab at a small camera resolution, wall-front, floor-left and floor-right brought up
    // together. floor-right's first pass leaves its grazing face unknown (the test above),
    // where the other two are decoded: they take the light there, so it is shown neither its
    // inverses nor a second pass, and is placed beside them as a joiner would be.
    let room = small_lab();
    let setup = setup(&room);
    let mut noise = CameraNoise::with_seed(&room, 43);
    let mut rig = rig(
        &room,
        &mut noise,
        &["wall-front", "floor-left", "floor-right"],
    );
    let (events, progress) = recorder();
    // At full resolution: this 320 × 240 camera sees some nine projector pixels a side in each
    // of its own, more than cells of 4 (the largest) resolve in a single shot, so over cells
    // wall-front's group takes its inverses (no earlier projector decoded beside it), which is
    // not what this test is about. Cells are tested at the lab's own camera (`roomlight bench
    // calib`), on the apart room below and on photographs (roomlight-calib). In white, one
    // group at a time: groups in their primaries are shown pairs, not once (the lab's
    // floor-right is placed beside the others that way too: `roomlight bench calib`).
    let settings = Settings {
        cells: false,
        primaries: false,
        ..Settings::default()
    };
    let up =
        block_on(Procedure::new(&mut rig, settings, progress).bring_up(&setup)).expect("bring-up");
    let events = events.lock().expect("events").clone();
    let groups = events
        .iter()
        .find_map(|e| match e {
            Event::Grouped { groups } => Some(groups.clone()),
            _ => None,
        })
        .expect("grouped");
    // Every group shown once (20 bits of a 1024 × 768 projector each), no second pass.
    assert_eq!(
        captured_in(&events, Stage::StructuredLight),
        20 * groups.len()
    );
    assert_eq!(captured_in(&events, Stage::SecondPass), 0, "{events:?}");
    let ids: Vec<&str> = up
        .measured
        .iter()
        .map(|m| m.projector.id.as_str())
        .collect();
    assert_eq!(ids, ["wall-front", "floor-left", "floor-right"]);
    let unknown = up.measured[2]
        .corr
        .reached_unknown_share(&up.measured[2].decoder);
    println!("floor-right left {:.2}% unknown", 100.0 * unknown);
    assert!(unknown > roomlight_calib::procedure::BESIDE_UNKNOWN);
    let placed: Vec<&str> = up.placed.iter().map(|p| p.projector.id.as_str()).collect();
    assert_eq!(placed, ["wall-front", "floor-left", "floor-right"]);
    let ids: Vec<u32> = up.placed.iter().flat_map(Placed::ids).collect();
    assert_eq!(ids, (0..ids.len() as u32).collect::<Vec<_>>());
    // Against the same decodes segmented all together: the weights sum to one better.
    let together = roomlight_calib::procedure::place(
        &setup,
        &up.measured,
        None,
        0,
        &Settings::default().nodes,
        &mut |_| {},
    )
    .expect("placed");
    let beside = partition(&room, &up.placed.iter().collect::<Vec<_>>());
    let all = partition(&room, &together.iter().collect::<Vec<_>>());
    println!("beside: {beside}\ntogether: {all}");
    assert!(beside.overlap > 1000, "{beside}");
    assert!(beside.overlap_within_0_05 >= 0.995, "{beside}");
    assert!(
        beside.overlap_within_0_05 > all.overlap_within_0_05,
        "{beside} against {all}"
    );
}

#[test]
fn a_projector_joining_a_lit_room_decodes_again_only_where_it_is_needed() {
    // The lab at a small camera resolution, wall-front and floor-left brought up and lit at
    // mid grey; then floor-right joins. Its first pass leaves its grazing face unknown (the
    // test above), but the other two already give all the light there: a second pass would
    // cost its captures and change no weight.
    let room = small_lab();
    let setup = setup(&room);
    let mut noise = CameraNoise::with_seed(&room, 43);
    // At full resolution, as the bring-up test above and for the same reason: this camera
    // sees more projector pixels in one of its own than cells of 4 resolve.
    let full = Settings {
        cells: false,
        ..Settings::default()
    };
    let (mut rig, up, claimed) = lit_then_joining(
        &room,
        &mut noise,
        (&setup, full),
        &["wall-front", "floor-left"],
        "floor-right",
    );
    let first = up.placed.iter().map(|p| p.nodes.len() as u32).sum();
    let (events, progress) = recorder();
    let joined = block_on(Procedure::new(&mut rig, full, progress).join(
        &setup,
        "floor-right",
        Some(&claimed),
        first,
    ))
    .expect("join");
    let events = events.lock().expect("events").clone();
    assert_eq!(captured_in(&events, Stage::SecondPass), 0, "{events:?}");
    assert_eq!(joined.measured.second, None);
    // Without the room's claims the same first pass would have had its second pass.
    let config = Settings::default().decode;
    let corr = &joined.measured.corr;
    assert!(
        roomlight_calib::graycode::SecondPassPlan::new(&config, corr, None).is_some(),
        "unknown where the room is lit: {:.2}% of decoded",
        100.0 * corr.reached_unknown_share(&config)
    );
    // Decoded where it is needed, and the room's weights still sum to one.
    let needed = roomlight_calib::procedure::needed(&claimed);
    let k = room.projector("floor-right").expect("floor-right");
    let tolerance = joined.measured.manifest.tolerance();
    let (close, far, reached) = accuracy_where(&room, k, corr, tolerance, |i| needed[i]);
    println!(
        "floor-right where needed: {reached} pixels reached, {:.2}% within ±1, {:.3}% off by > 2",
        100.0 * close,
        100.0 * far
    );
    let blended: Vec<&Placed> = up
        .placed
        .iter()
        .chain(std::iter::once(&joined.placed))
        .filter(|p| p.claim.is_some())
        .collect();
    let after = partition(&room, &blended);
    println!("after the join: {after}");
    // The same join with the second pass it skipped (on the same first pass, in the same
    // lit room), placed beside the same claims: the weights are no better for it.
    let mut fuller = joined.measured.clone();
    let manifest = roomlight_calib::graycode::Manifest::with_coding(
        fuller.projector.width,
        fuller.projector.height,
        roomlight_calib::procedure::coding(&fuller.projector),
    )
    .expect("manifest");
    let mut procedure = Procedure::new(&mut rig, full.lit_room(), |_| {});
    let pass = block_on(procedure.second_pass(
        &fuller.projector.clone(),
        &manifest,
        &mut fuller.corr,
        None,
    ))
    .expect("second pass")
    .expect("a second pass without the claims");
    let replaced = roomlight_calib::procedure::place(
        &setup,
        std::slice::from_ref(&fuller),
        Some(&claimed),
        first,
        &Settings::default().nodes,
        &mut |_| {},
    )
    .expect("placed");
    let with_pass = partition(
        &room,
        &up.placed
            .iter()
            .chain(&replaced)
            .filter(|p| p.claim.is_some())
            .collect::<Vec<_>>(),
    );
    let (close_with, ..) = accuracy_where(&room, k, &fuller.corr, tolerance, |i| needed[i]);
    println!(
        "with the second pass ({} captures): {:.2}% within ±1 where needed; {with_pass}",
        pass.captures,
        100.0 * close_with
    );
    // Measured (seed 43): 96.50% against 96.93% within ±1 where needed, none off by more than
    // 2; in overlaps 99.82% against 99.80% within 0.05.
    assert!(
        reached > 1000 && far <= 0.001,
        "{reached} reached, {far} off"
    );
    assert!(close >= close_with - 0.01, "{close} against {close_with}");
    assert!(
        after.overlap_within_0_05 >= with_pass.overlap_within_0_05 - 0.001
            && after.overlap_within_0_05 >= 0.99,
        "{after}"
    );
}

#[test]
fn a_projector_joins_hot_beside_a_lit_one() {
    let room = Room::build(small_scene()).expect("room");
    let setup = setup(&room);
    let mut noise = CameraNoise::with_seed(&room, 41);
    let mut rig = rig(&room, &mut noise, &["left"]);
    let up = block_on(Procedure::new(&mut rig, Settings::default(), |_| {}).bring_up(&setup))
        .expect("bring-up");
    // "left" lit at mid grey, then "right" switched on and calibrated hot.
    let lit = frames_of(&up.placed, &[], LinearRgb::splat(0.5));
    block_on(rig.show(&lit)).expect("lit");
    rig.go_live("right").expect("right");
    let claimed = up.placed[0].claim.clone().expect("a charted projector");
    let first = up.placed[0].nodes.len() as u32;
    let (events, progress) = recorder();
    let joined = block_on(
        Procedure::new(&mut rig, Settings::default(), progress).join(
            &setup,
            "right",
            Some(&claimed),
            first,
        ),
    )
    .expect("join");
    assert_accurate(
        &room,
        "right",
        &joined.measured.corr,
        joined.measured.manifest.tolerance(),
    );
    assert_eq!(joined.placed.nodes[0].id, first);
    // No footprint grouping for one projector: its white is the top of its ramp.
    let events = events.lock().expect("events").clone();
    assert_eq!(joined.captures, rig.captures() - up.captures);
    // Its black is the dark capture it took first (the room in the same state).
    assert_eq!(captured_in(&events, Stage::Hot), joined.placed.nodes.len());
    // One after the other: the bar the nodes tests set.
    let both = partition(&room, &[&up.placed[0], &joined.placed]);
    println!("segmented one after the other: {both}");
    assert!(both.within_1e3 > 0.95 && both.within_0_05 > 0.99, "{both}");
    let mut sum = claimed.clone();
    add_claim(&mut sum, joined.placed.claim.as_deref().expect("claim"));
    // Its columns against the truth with "left" lit.
    let with_right = |on: &[u32]| {
        let mut frames = lit.clone();
        frames.extend(frames_of(
            std::slice::from_ref(&joined.placed),
            on,
            LinearRgb::ZERO,
        ));
        truth_values(&rig, &frames)
    };
    let black = with_right(&[]).0;
    let truth: Vec<(Vec<LinearRgb>, Vec<bool>)> = joined
        .placed
        .ids()
        .iter()
        .map(|&n| {
            let (y, spread) = with_right(&[n]);
            (
                y.iter().zip(&black).map(|(a, b)| *a - *b).collect(),
                spread.iter().map(|s| s.max_abs() < 0.05).collect(),
            )
        })
        .collect();
    let measured: Vec<Vec<LinearRgb>> = joined.hot.columns.iter().map(|c| c.1.clone()).collect();
    let checked = check_columns(&measured, &joined.hot.sigma, &joined.hot.measurable, &truth);
    println!("hot: {checked} entries checked against the truth");
    assert!(checked > 20, "only {checked} entries above the noise");
}

/// Two projectors on one stand, aimed alike: their whites cannot tell their shares of a ramp
/// shown together apart, so the procedure says so and shows each one's levels alone (one
/// capture spent on the refused level), and both exponents still come out right.
#[test]
fn projectors_that_cannot_be_told_apart_show_their_ramps_alone() {
    let mut scene = small_scene();
    scene.projectors.truncate(2);
    let left = scene.projectors[0].clone();
    let twin = &mut scene.projectors[1];
    (twin.position_mm, twin.look_at_mm, twin.up, twin.fov_deg) =
        (left.position_mm, left.look_at_mm, left.up, left.fov_deg);
    let room = Room::build(scene).expect("room");
    let mut noise = CameraNoise::with_seed(&room, 41);
    let mut rig = rig(&room, &mut noise, &["left", "right"]);
    let (events, progress) = recorder();
    let mut procedure = Procedure::new(&mut rig, Settings::default(), progress);
    let live = procedure.rig().projectors();
    let measured = block_on(async {
        let dark = procedure.dark(&live).await?;
        let whites = procedure.whites(&live).await?;
        let decoded = procedure
            .structured_light(&live, &dark, &whites, None)
            .await?;
        procedure.responses(decoded, &live, &dark, &whites).await
    })
    .expect("responses");
    let events = events.lock().expect("events").clone();
    let apart: Vec<&Event> = events
        .iter()
        .filter(|e| matches!(e, Event::RampApart { .. }))
        .collect();
    assert_eq!(apart.len(), 1, "{events:?}");
    // Named by id, and why.
    assert!(
        matches!(apart[0], Event::RampApart { reason } if reason.contains("left: its white cannot be told apart")),
        "{apart:?}"
    );
    // The refused level, then the two middle levels of each projector alone.
    assert_eq!(captured_in(&events, Stage::Responses), 1 + 2 * 2);
    assert_eq!(measured.len(), 2);
    for m in &measured {
        let truth =
            room.scene().projectors[room.projector(&m.projector.id).expect("projector")].gamma;
        let gamma = m.response.gamma;
        for c in 0..3 {
            assert!(
                (gamma[c] / truth[c] - 1.0).abs() < 0.03,
                "{}: γ {gamma:?}, true {truth:?}",
                m.projector.id
            );
        }
    }
}

#[test]
fn a_single_shot_beside_lit_projectors_is_never_wrong_where_it_clips() {
    // The small room at its own camera (256×192), left and the large aperture brought up and
    // lit at mid grey: near right's frame edge their light and its own reach the camera's
    // ceiling under every pattern. Shown once and read against its white there, right took a
    // code from the clipping alone at 0.27% of its decoded pixels (off by more than 2, at
    // full confidence); each clipped pixel is now read from its own lit and unlit patterns.
    // Decoded as a projector joining the room is, where the room needs it: counted over every
    // pixel, the clipped ones are unknown to a pair as well, and they bring the inverses
    // (which hid the wrong codes).
    let room = Room::build(scenes::small().expect("small")).expect("room");
    let setup = setup(&room);
    let mut noise = CameraNoise::with_seed(&room, 41);
    let (mut rig, _, claimed) = lit_then_joining(
        &room,
        &mut noise,
        (&setup, Settings::default()),
        &["left", "area"],
        "right",
    );
    let needed = roomlight_calib::procedure::needed(&claimed);
    let k = room.projector("right").expect("right");
    // At full resolution never wrong; over the cells of 4 its footprint gets (the default),
    // measured (2026-11-29): 2 of 7480 decoded pixels 25 rows off, at a quarter confidence,
    // within the 0.1% of gross errors.
    for (cells, most) in [(false, 0.0), (true, 0.001)] {
        let settings = Settings {
            cells,
            ..Settings::default()
        };
        let mut procedure = Procedure::new(&mut rig, settings, |_| {});
        let right: Vec<Projector> = procedure
            .rig()
            .projectors()
            .into_iter()
            .filter(|p| p.id == "right")
            .collect();
        assert!(settings.shows_once(&right[0]));
        let decoded = block_on(async {
            let dark = procedure.dark(&right).await?;
            let whites = procedure.whites(&right).await?;
            procedure
                .structured_light(&right, &dark, &whites, Some(&needed))
                .await
        })
        .expect("decoded");
        let tolerance = decoded[0].manifest.tolerance();
        let (close, far, reached) = accuracy(&room, k, &decoded[0].corr, tolerance);
        println!(
            "right shown once beside lit projectors, cells {}: {reached} reached, {:.2}% within ±{tolerance}, {:.3}% off by > {}",
            decoded[0].manifest.cell,
            100.0 * close,
            100.0 * far,
            tolerance + 1
        );
        assert!(
            far <= most,
            "cells {cells}: {far} off by more than {}",
            tolerance + 1
        );
        assert!(close >= 0.98, "{close}");
    }
}
