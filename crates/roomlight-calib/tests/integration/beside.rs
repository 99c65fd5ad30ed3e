//! Which projectors calibrated together are placed beside the others
//! (`procedure::goes_beside`): a standard luminaire whose decode left more than
//! `BESIDE_UNKNOWN` of its reached pixels unknown, "reached" judged on the noise its own
//! decoder was set for. A projector coded in one primary reads about one camera channel's noise,
//! less than white's three: pixels too dim to stand out of white's noise stand out of its own.

use roomlight_calib::graycode::{Correspondence, DecodeConfig, Manifest, SECOND_PASS_SNR};
use roomlight_calib::procedure::{BESIDE_UNKNOWN, Measured, goes_beside};
use roomlight_calib::response::Response;
use roomlight_calib::rig::{Projector, ProjectorKind, ProjectorRole};

/// A 40 × 40 decode, every pixel decoded but a 10 × 10 block lit at `dim` direct light (no
/// global light): reached or not depending on the noise it is judged on.
fn measured(dim: f32, decoder: DecodeConfig, role: ProjectorRole) -> Measured {
    let (w, h) = (40u32, 40u32);
    let n = (w * h) as usize;
    let dark = |i: usize| (15..25).contains(&(i % 40)) && (15..25).contains(&(i / 40));
    let corr = Correspondence {
        width: w,
        height: h,
        projector_width: w,
        projector_height: h,
        map: (0..n)
            .map(|i| (!dark(i)).then_some(((i % 40) as u32, (i / 40) as u32)))
            .collect(),
        confidence: vec![1.0; n],
        direct: (0..n).map(|i| if dark(i) { dim } else { 0.5 }).collect(),
        global: vec![0.0; n],
        reach: 1e-4,
    };
    Measured {
        projector: Projector {
            id: "p".into(),
            width: w,
            height: h,
            kind: ProjectorKind::Standard,
            role,
        },
        manifest: Manifest::new(w, h).expect("manifest"),
        corr,
        decoder,
        response: Response::linear(),
        second: None,
    }
}

/// The direct light at which a pixel with no global light stands `SECOND_PASS_SNR` times out of
/// `config`'s noise of a pattern − inverse difference (solved by bisection: the noise grows
/// with the light).
fn threshold(config: &DecodeConfig) -> f32 {
    let stands_out = |ld: f32| {
        let level = 0.5 * ld;
        let sigma = (2.0
            * (config.noise_floor * config.noise_floor
                + config.shot_noise * config.shot_noise * level))
            .sqrt();
        ld >= SECOND_PASS_SNR * sigma
    };
    let (mut lo, mut hi) = (0.0f32, 1.0f32);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if stands_out(mid) { hi = mid } else { lo = mid }
    }
    hi
}

#[test]
fn a_projector_is_judged_on_the_noise_it_was_decoded_with() {
    let white = DecodeConfig::default();
    let primary = white.in_one_primary();
    let (tw, tp) = (threshold(&white), threshold(&primary));
    assert!(
        tp < tw,
        "one primary's noise is below white's: {tp} against {tw}"
    );
    // Between the two: reached on one primary's noise, not on white's.
    let dim = 0.5 * (tp + tw);
    let coded_in_primary = measured(dim, primary, ProjectorRole::Luminaire);
    let share = coded_in_primary.corr.reached_unknown_share(&primary);
    // The block's 100 pixels, every neighbour of each reached, against 1 500 decoded: 6.67%.
    println!("unknown share on its own noise {share:.4}, threshold {BESIDE_UNKNOWN}");
    assert!(share > BESIDE_UNKNOWN);
    assert!(
        goes_beside(&coded_in_primary),
        "judged on one primary's noise: beside"
    );
    // The same decode judged on white's noise leaves nothing reached unknown: with the others.
    assert!(coded_in_primary.corr.reached_unknown_share(&white) < 1e-12);
    let coded_in_white = measured(dim, white, ProjectorRole::Luminaire);
    assert!(
        !goes_beside(&coded_in_white),
        "judged on white's noise: with the others"
    );
    // Only standard luminaires blend, so only they go beside.
    let texture = measured(dim, primary, ProjectorRole::Texture);
    assert!(!goes_beside(&texture));
}
