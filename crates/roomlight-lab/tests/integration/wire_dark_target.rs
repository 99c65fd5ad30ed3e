//! A dark target over the wire (issue 22 item 3 in a real room): the camera agent measures
//! patches on the target beside the charts' and weighs their light in the objective
//! (`camera::Survey`), so that the node agents' rounds keep the luminaires' light, direct and
//! reflected, off it. Judged against the simulator's noiseless truth of what the projectors
//! show: the light on the target as a share of the LEDs', and the charts' ΔE00. A camera agent
//! restarted from its model file keeps the target dark.

use crate::support::{brought_up_two, small_scene};
use roomlight_lab::wire_room::{Judged, Options};
use roomlight_sim::{Room, Scene};
use std::sync::Arc;
use std::time::Duration;

/// The small room with its two standard luminaires only (the large aperture and the texture
/// projector left out, for time), its target kept.
fn scene() -> Scene {
    let mut scene = small_scene();
    scene.projectors.truncate(2);
    scene
}

/// Brings the room up at `dark_weight`, lets the rounds settle on the survey's preset, and
/// judges it; with `restart`, restarts the camera agent from its files and judges the room
/// once the resumed rounds have settled again.
async fn run(room: &Arc<Room>, dark_weight: f64, restart: bool) -> (Judged, Option<Judged>) {
    let options = Options {
        shading_passes: 0,
        model_rounds: 2,
        seed: 11,
        survey_photographs: true,
        model_file: restart,
        dark_weight,
    };
    let (mut wire, up) = brought_up_two(room, options).await;
    wire.until(Duration::from_secs(300), "settling", |s| {
        s.settled && s.captures > up.captures + 4
    })
    .await
    .expect("settled");
    let judged = wire.judge(0).expect("judged");
    // The rounds reach the weighed model's optimum (an independent solver's): the captures'
    // target patches are scaled as the columns and the reference are, or they would settle
    // elsewhere.
    let best = roomlight_core::optimum::optimum(&wire.problem()).expect("optimum");
    let measured = wire.status().measured_objective;
    eprintln!(
        "weight {dark_weight}: G {measured:.4e} measured, G* {:.4e}",
        best.objective
    );
    assert!(
        (measured - best.objective).abs() < 0.1 * best.objective,
        "weight {dark_weight}: G {measured:.4e} against G* {:.4e}",
        best.objective
    );
    let mut resumed = None;
    if restart {
        wire.restart_camera().await.expect("restarted");
        let at = wire.status().captures;
        wire.until(Duration::from_secs(300), "the resumed rounds", |s| {
            s.live_projectors == 2 && s.settled && s.captures > at + 4
        })
        .await
        .expect("resumed");
        assert_eq!(wire.status().calibrated_hot, 0, "nothing calibrated again");
        resumed = Some(wire.judge(0).expect("judged"));
    }
    wire.stop().await.expect("every agent stopped cleanly");
    (judged, resumed)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dark_target_over_the_wire_keeps_the_luminaires_light_off_it() {
    let room = Arc::new(Room::build(scene()).expect("room"));
    let (plain, _) = run(&room, 0.0, false).await;
    let (dark, resumed) = run(&room, 10.0, true).await;
    let resumed = resumed.expect("judged after the restart");
    let share = |j: &Judged| j.target_share.expect("the LEDs light the target");
    eprintln!(
        "over the wire, light on the target (share of the LEDs') and charts' ΔE00: weight 0 \
         {:.0}% / {:.2}; weight 10 {:.0}% / {:.2}; restarted {:.0}% / {:.2}",
        100.0 * share(&plain),
        plain.charts_de00,
        100.0 * share(&dark),
        dark.charts_de00,
        100.0 * share(&resumed),
        resumed.charts_de00
    );
    assert!(
        share(&dark) < share(&plain) - 0.08,
        "the target keeps {:.0}% of the LEDs' light at weight 10, {:.0}% at 0",
        100.0 * share(&dark),
        100.0 * share(&plain)
    );
    // What it costs is the optimum's (asserted above), printed, not bounded: on this room most
    // of the target's light comes off the table and the wall that the charts need lit
    // (measured 2026-12-07: 38% → 24% at charts' ΔE00 0.86 → 5.92; at weight 3, 33% at 2.09).
    // Resumed from its model file the camera agent keeps the target's patches weighed (they
    // are at the black level by design, not left out).
    assert!(
        share(&resumed) < share(&plain) - 0.08,
        "restarted, the target keeps {:.0}% of the LEDs' light",
        100.0 * share(&resumed)
    );
}
