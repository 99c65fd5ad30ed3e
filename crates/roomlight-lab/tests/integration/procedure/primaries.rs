//! Groups of projectors coded at once in their primaries (`Settings::primaries`), through the
//! procedure on the simulated room, against white coding and the simulator's truth.

use super::*;
use support::accuracy::accuracy;

/// The small room's three luminaires, whose footprints overlap, coded at once in their
/// primaries, through projectors whose primaries leak into each other's camera channels
/// (crosstalk): one set of slots and a capture of each primary's white instead of a pattern
/// set each, and every standard luminaire decoded as accurately as the graycode tests hold a
/// projector decoded alone (and never off beyond its tolerance + 1 on more than 0.1%).
#[test]
fn overlapping_projectors_are_coded_at_once_in_their_primaries_through_crosstalk() {
    let mut scene = small_scene();
    for p in &mut scene.projectors {
        p.mixing = Some([[0.92, 0.12, 0.03], [0.1, 0.95, 0.12], [0.02, 0.15, 0.9]]);
    }
    let room = Room::build(scene).expect("room");
    let live = ["left", "right", "area"];
    let coded = |primaries: bool| {
        let mut noise = CameraNoise::with_seed(&room, 41);
        let mut rig = rig(&room, &mut noise, &live);
        let (events, progress) = recorder();
        let settings = Settings {
            primaries,
            ..Settings::default()
        };
        let mut procedure = Procedure::new(&mut rig, settings, progress);
        let (_, decoded) = structured_light(&mut procedure);
        let events = events.lock().expect("events").clone();
        (decoded, events)
    };
    let (white, white_events) = coded(false);
    let (coloured, events) = coded(true);
    let sets = events.iter().find_map(|e| match e {
        Event::Primaries { sets } => Some(sets.clone()),
        _ => None,
    });
    let Some(sets) = sets else {
        panic!("no set coded in primaries: {events:?}");
    };
    println!("coded in their primaries: {sets:?}");
    assert_eq!(sets.len(), 1, "three groups, one set");
    assert_eq!(sets[0].len(), 3, "{sets:?}");
    let (in_white, in_primaries) = (
        captured_in(&white_events, Stage::StructuredLight),
        captured_in(&events, Stage::StructuredLight),
    );
    // One capture of each primary's white, then the set's slots: as many as its longest
    // member's pairs (white and black are the dark and primary-white captures).
    let longest = coloured
        .iter()
        .map(|d| d.manifest.shown(false).count() - 2)
        .max()
        .unwrap_or(0);
    println!("structured light: {in_primaries} captures in primaries, {in_white} in white");
    assert!(
        coloured.iter().all(|d| d.second.is_none()),
        "no second pass"
    );
    assert_eq!(in_primaries, 3 + longest);
    assert!(in_primaries < in_white, "{in_primaries} against {in_white}");
    // Each is judged on the noise it was decoded with (`Decoded::decoder`, which decides its
    // placement beside the others): one primary's in the set, white's alone.
    let settings = Settings::default();
    let noise = |c: &roomlight_calib::graycode::DecodeConfig| (c.noise_floor, c.shot_noise);
    for (d, w) in coloured.iter().zip(&white) {
        let alone = settings.decoder(&d.projector);
        let one = alone.in_one_primary();
        assert_eq!(noise(&d.decoder), noise(&one), "{}", d.projector.id);
        assert_eq!(noise(&w.decoder), noise(&alone), "{}", w.projector.id);
        // One channel's read noise against three's, up to 1.5 times it where unmixed.
        assert!(d.decoder.noise_floor < w.decoder.noise_floor);
    }
    for (d, w) in coloured.iter().zip(&white) {
        if d.projector.kind != ProjectorKind::Standard {
            continue;
        }
        assert_accurate(&room, &d.projector.id, &d.corr, d.manifest.tolerance());
        let k = room.projector(&d.projector.id).expect("projector");
        let (close, _, _) = accuracy(&room, k, &d.corr, d.manifest.tolerance());
        let (close_white, _, _) = accuracy(&room, k, &w.corr, w.manifest.tolerance());
        println!(
            "{}: {:.2}% within its tolerance in primaries, {:.2}% in white",
            d.projector.id,
            100.0 * close,
            100.0 * close_white
        );
    }
}
