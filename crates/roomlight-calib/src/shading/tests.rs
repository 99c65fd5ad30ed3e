use super::*;

fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> [f32; 3]) -> LinearImage {
    LinearImage {
        width: w,
        height: h,
        pixels: (0..w * h).map(|i| f(i % w, i / w)).collect(),
    }
}

const W: u32 = 96;
const H: u32 = 64;

/// Where the reference asks twice the red and half the blue over the left half, one full step
/// gives those gains there, 1 on the right, and the bilinear gain passes between them.
#[test]
fn one_full_step_gives_the_ratio_per_channel() {
    let dark = image(W, H, |_, _| [0.01; 3]);
    let current = image(W, H, |_, _| [0.21, 0.31, 0.41]);
    let reference = image(W, H, |x, _| {
        if x < W / 2 {
            [0.41, 0.31, 0.21]
        } else {
            [0.21, 0.31, 0.41]
        }
    });
    let excluded = vec![false; (W * H) as usize];
    let photos = Photographs {
        reference: &reference,
        current: &current,
        dark: &dark,
        excluded: &excluded,
        saturation: 1.0,
    };
    let r = ratios(&photos, &Correspondence::identity(W, H)).expect("ratios");
    assert_eq!(r.read(), (6 * 4, 6 * 4));
    let mut g = Gains::flat(W, H).expect("gains");
    g.step(&r, 1.0).expect("step");
    let left = g.at(8, 30);
    let right = g.at(W - 9, 30);
    for (got, want) in left.iter().zip([2.0, 1.0, 0.5]) {
        // The floor under a channel's sum pulls a ratio towards 1 by a thousandth at most.
        assert!((got - want).abs() < 2e-3 * want, "left {left:?}");
    }
    for got in right {
        assert!((got - 1.0).abs() < 1e-4, "right {right:?}");
    }
    // Between the centres of the last left block (x 40) and the first right one (x 56).
    let mid = g.at(47, 30)[0];
    assert!(
        (1.0..2.0).contains(&mid) && (mid - 1.5).abs() < 0.05,
        "mid {mid}"
    );
    // Half a step: the square root.
    let mut half = Gains::flat(W, H).expect("gains");
    half.step(&r, 0.5).expect("step");
    assert!((half.at(8, 30)[0] - 2f32.sqrt()).abs() < 2e-3);
}

/// A toy room with inter-reflection: every camera pixel gets its projector pixel's light
/// times an albedo plus a fifth of the room's mean light, so one step falls short; passes of
/// the loop bring the whole image within 1% of a reference that is reachable.
#[test]
fn passes_converge_through_inter_reflection() {
    let albedo = |x: u32, y: u32| {
        [
            0.3 + 0.4 * x as f32 / W as f32,
            0.5,
            0.7 - 0.3 * y as f32 / H as f32,
        ]
    };
    // The light the projector shows at each pixel, from its gains on a flat node value.
    let render = |g: &Gains| {
        let direct: Vec<[f32; 3]> = (0..W * H)
            .map(|i| {
                let (x, y) = (i % W, i / W);
                let (a, gain) = (albedo(x, y), g.at(x, y));
                std::array::from_fn(|c| 0.3 * gain[c] * a[c])
            })
            .collect();
        let mean: [f32; 3] =
            std::array::from_fn(|c| direct.iter().map(|p| p[c]).sum::<f32>() / direct.len() as f32);
        LinearImage {
            width: W,
            height: H,
            pixels: direct
                .iter()
                .map(|p| std::array::from_fn(|c| 0.02 + p[c] + 0.2 * mean[c]))
                .collect(),
        }
    };
    // The reference: what smooth gains (within the bounds) would give.
    let mut want = Gains::flat(W, H).expect("gains");
    for (b, g) in want.gains.iter_mut().enumerate() {
        let (bx, by) = ((b % want.across) as f32, (b / want.across) as f32);
        *g = [1.0 + 0.15 * bx, 1.6 - 0.1 * by, 0.6 + 0.05 * (bx + by)];
    }
    let reference = render(&want);
    let dark = image(W, H, |_, _| [0.02; 3]);
    let excluded = vec![false; (W * H) as usize];
    let corr = Correspondence::identity(W, H);
    let mut g = Gains::flat(W, H).expect("gains");
    let worst = |g: &Gains| {
        let now = render(g);
        now.pixels
            .iter()
            .zip(&reference.pixels)
            .flat_map(|(a, b)| (0..3).map(move |c| ((a[c] - b[c]) / b[c]).abs()))
            .fold(0.0f32, f32::max)
    };
    let start = worst(&g);
    for _ in 0..8 {
        let current = render(&g);
        let photos = Photographs {
            reference: &reference,
            current: &current,
            dark: &dark,
            excluded: &excluded,
            saturation: 1.0,
        };
        g.step(&ratios(&photos, &corr).expect("ratios"), 0.8)
            .expect("step");
    }
    let end = worst(&g);
    assert!(start > 0.3, "the start is off by {start}");
    assert!(end < 0.01, "after 8 passes the worst pixel is off by {end}");
}

/// What the camera cannot use moves nothing: the target's pixels, saturated ones, and blocks
/// too far from any read one keep their gains; a reference brighter than the projector can
/// reach stops at the bound, finite.
#[test]
fn unread_blocks_keep_their_gains_and_bounds_hold() {
    let dark = image(W, H, |_, _| [0.0; 3]);
    let current = image(W, H, |_, _| [0.1; 3]);
    // Wild on the excluded left third, saturated on a band, asks 1000× elsewhere.
    let reference = image(W, H, |x, y| {
        if x < 48 {
            [0.0, 0.5, 0.0]
        } else if y < 16 {
            [2000.0; 3]
        } else {
            [100.0; 3]
        }
    });
    let excluded: Vec<bool> = (0..W * H).map(|i| i % W < 48).collect();
    let photos = Photographs {
        reference: &reference,
        current: &current,
        dark: &dark,
        excluded: &excluded,
        saturation: 1000.0,
    };
    let r = ratios(&photos, &Correspondence::identity(W, H)).expect("ratios");
    let mut g = Gains::flat(W, H).expect("gains");
    for _ in 0..10 {
        g.step(&r, 1.0).expect("step");
    }
    // Block columns 0–2 are excluded, 3.. read: columns 1 and 2 are filled, column 0 is
    // three blocks from a read one.
    // Exact: a gain never stepped stays 1, one stepped past the bound is the bound.
    let is = |g: [f32; 3], v: f32| g.iter().all(|x| x.to_bits() == v.to_bits());
    assert!(is(g.gains[2 * g.across], 1.0), "an unread block moved");
    assert!(
        is(g.gains[2 * g.across + 1], MAX_GAIN),
        "a block two away was not filled"
    );
    assert!(
        g.gains
            .iter()
            .flatten()
            .all(|v| v.is_finite() && (MIN_GAIN..=MAX_GAIN).contains(v))
    );
    assert!(is(g.at(80, 40), MAX_GAIN));
    // The saturated band's blocks were filled from the ones below: one step away.
    assert!(is(g.gains[5], MAX_GAIN));
}

#[test]
fn bad_input_is_refused() {
    let small = image(4, 4, |_, _| [0.1; 3]);
    let big = image(W, H, |_, _| [0.1; 3]);
    let excluded = vec![false; (W * H) as usize];
    let photos = Photographs {
        reference: &big,
        current: &small,
        dark: &big,
        excluded: &excluded,
        saturation: 1.0,
    };
    let e = ratios(&photos, &Correspondence::identity(W, H)).expect_err("sizes differ");
    assert!(e.to_string().contains("current"), "{e}");
    let photos = Photographs {
        current: &big,
        ..photos
    };
    let r = ratios(&photos, &Correspondence::identity(W, H)).expect("ratios");
    let mut other = Gains::flat(W + 1, H).expect("gains");
    assert!(other.step(&r, 1.0).is_err());
    let mut g = Gains::flat(W, H).expect("gains");
    for rate in [0.0, -1.0, 1.5, f64::NAN] {
        assert!(g.step(&r, rate).is_err(), "rate {rate}");
    }
    assert!(Gains::flat(0, 5).is_none());
}

/// A pixel's shaded light: its nodes' light floored per unit weight, times its gains; a pixel
/// no node drives stays dark whatever its gains.
#[test]
fn shaded_light_floors_a_dark_node_and_leaves_undriven_pixels_alone() {
    let close = |a: [f64; 3], b: [f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12);
    assert!(close(
        shaded_light([0.3, 0.0, 0.001], 0.5, [2.0, 4.0, 1.0]),
        [0.6, 4.0 * FLOOR * 0.5, FLOOR * 0.5]
    ));
    assert!(close(shaded_light([0.0; 3], 0.0, [MAX_GAIN; 3]), [0.0; 3]));
    assert!(close(
        shaded_light([0.0; 3], f64::NAN, [MAX_GAIN; 3]),
        [0.0; 3]
    ));
    // A dark node's full-weight pixel reaches full light at the largest gain.
    assert!(shaded_light([0.0; 3], 1.0, [MAX_GAIN; 3])[0] >= 1.0);
}

/// Ratios from the wire: the blocks of a pass round-trip, and a wrong count, a NaN, an
/// infinite or an out-of-bound ratio are refused naming the block.
#[test]
fn ratios_from_blocks_round_trip_and_refuse_what_a_pass_cannot_give() {
    let dark = image(W, H, |_, _| [0.01; 3]);
    let current = image(W, H, |_, _| [0.2; 3]);
    let reference = image(W, H, |x, _| [0.1 + 0.002 * x as f32; 3]);
    let excluded = vec![false; (W * H) as usize];
    let photos = Photographs {
        reference: &reference,
        current: &current,
        dark: &dark,
        excluded: &excluded,
        saturation: 1.0,
    };
    let r = ratios(&photos, &Correspondence::identity(W, H)).expect("ratios");
    let back = Ratios::from_blocks(W, H, r.blocks().to_vec())
        .and_then(|b| b.with_light(r.light().to_vec()))
        .expect("the same blocks");
    assert_eq!(back, r);
    assert_eq!(back.size(), (W, H));
    let mut blocks = r.blocks().to_vec();
    blocks.pop();
    let e = Ratios::from_blocks(W, H, blocks).expect_err("a block short");
    assert!(e.to_string().contains("23 blocks"), "{e}");
    for bad in [f64::NAN, f64::INFINITY, 0.0, MAX_STEP * 1.01] {
        let mut blocks = r.blocks().to_vec();
        blocks[5] = Some([1.0, bad, 1.0]);
        let e = Ratios::from_blocks(W, H, blocks).expect_err("refused");
        assert!(e.to_string().contains("block 5"), "{bad}: {e}");
    }
    assert!(Ratios::from_blocks(0, H, Vec::new()).is_err());
}

/// ΔE00 between the LEDs' light and the current light stepped by `step`, white 1.
fn de_after(reference: [f64; 3], current: [f64; 3], step: [f64; 3]) -> f64 {
    ciede2000(
        lab_from_linear_rgb(LinearRgb(reference), 1.0),
        lab_from_linear_rgb(
            LinearRgb(std::array::from_fn(|c| current[c] * step[c])),
            1.0,
        ),
    )
}

/// With headroom for the plain ratio, the closest colour is the plain ratio; where red is short
/// of it (a warm wall one projector reaches at full red), red takes all it has and green
/// comes down with it: closer in ΔE00 than matching them channel by channel, and than
/// keeping the hue exactly, within the bounds; inputs that are not light give bounded steps.
#[test]
fn short_of_headroom_the_closest_colour_beats_channel_by_channel() {
    let (reference, current) = ([0.36, 0.14, 0.03], [0.21, 0.11, 0.029]);
    let plain: [f64; 3] = std::array::from_fn(|c| reference[c] / current[c]);
    let roomy = closest_within(reference, current, [4.0; 3]);
    for c in 0..3 {
        assert!(
            (roomy[c] - plain[c]).abs() < 2e-3 * plain[c],
            "{roomy:?} {plain:?}"
        );
    }
    // Red can give 1.2 times what it gives, not the 1.71 asked.
    let most = [1.2, 4.0, 4.0];
    let best = closest_within(reference, current, most);
    assert!(
        (best[0] - 1.2).abs() < 1e-6,
        "red takes all it has: {best:?}"
    );
    assert!(
        best[1] < 0.9 * plain[1],
        "green comes down: {best:?} {plain:?}"
    );
    let by_channel = [1.2, plain[1], plain[2]];
    let same_hue = [1.2, plain[1] * 1.2 / plain[0], plain[2] * 1.2 / plain[0]];
    let (b, c, h) = (
        de_after(reference, current, best),
        de_after(reference, current, by_channel),
        de_after(reference, current, same_hue),
    );
    assert!(
        b < c - 0.5 && b <= h,
        "closest {b:.2}, by channel {c:.2}, same hue {h:.2}"
    );
    for bad in [
        closest_within([f64::NAN; 3], current, most),
        closest_within(reference, [0.0; 3], most),
        closest_within(reference, current, [f64::NAN, -1.0, f64::INFINITY]),
    ] {
        assert!(
            bad.iter()
                .all(|v| v.is_finite() && (1.0 / MAX_STEP..=MAX_STEP).contains(v)),
            "{bad:?}"
        );
    }
}

/// The headroom of a block is 1 over its mean drawn light (clipped at full light) over the
/// pixels that draw any, infinite where it is black; a frame of the wrong size has none.
#[test]
fn headroom_is_one_over_a_blocks_mean_light() {
    let (w, h) = (2 * BLOCK, BLOCK);
    let shares: Vec<[f64; 3]> = (0..w * h)
        .map(|i| {
            if i % w < BLOCK {
                // Half the pixels asked for twice full light (drawn at full), half at a half.
                if i % 2 == 0 {
                    [2.0, 0.5, 0.0]
                } else {
                    [0.5, 0.5, 0.0]
                }
            } else if i / w < BLOCK / 2 {
                [0.25, 0.0, f64::NAN]
            } else {
                // Undriven: counted for nothing.
                [0.0; 3]
            }
        })
        .collect();
    let room = headroom(&shares, w, h).expect("headroom");
    assert_eq!(room.len(), 2);
    assert!((room[0][0] - 1.0 / 0.75).abs() < 1e-9 && (room[0][1] - 2.0).abs() < 1e-9);
    assert!(room[0][2].is_infinite() && room[1][1].is_infinite());
    assert!((room[1][0] - 4.0).abs() < 1e-9, "{room:?}");
    // A pixel that is not a number counts as full light: no headroom promised.
    assert!((room[1][2] - 1.0).abs() < 1e-9, "{room:?}");
    assert!(headroom(&shares[1..], w, h).is_none());
}

/// A pass's ratios carry each read block's light; a block short of headroom steps by the
/// closest colour, the others by their ratios; light from the wire is checked.
#[test]
fn a_step_within_headroom_changes_only_the_blocks_short_of_it() {
    let dark = image(W, H, |_, _| [0.0; 3]);
    let current = image(W, H, |_, _| [0.21, 0.11, 0.029]);
    let reference = image(W, H, |_, _| [0.36, 0.14, 0.03]);
    let excluded = vec![false; (W * H) as usize];
    let photos = Photographs {
        reference: &reference,
        current: &current,
        dark: &dark,
        excluded: &excluded,
        saturation: 1.0,
    };
    let want = luminance(LinearRgb([0.36, 0.14, 0.03]));
    // A camera without a saturation level (not a number) leaves nothing out, as `ratios` does.
    for saturation in [1.0, f32::NAN] {
        let white = white(&Photographs {
            saturation,
            ..photos
        });
        assert!(
            (white - want).abs() < 1e-6,
            "white {white}, expected {want}"
        );
    }
    let white = white(&photos);
    let r = ratios(&photos, &Correspondence::identity(W, H))
        .expect("ratios")
        .relative_to(white);
    let [lr, lc] = r.light()[0].expect("read blocks carry their light");
    assert!((lr[0] - 0.36 / white).abs() < 1e-6 && (lc[1] - 0.11 / white).abs() < 1e-6);
    let blocks = r.blocks().len();
    // The first block has red for 1.2 times its light, the others room for anything.
    let mut room = vec![[f64::INFINITY; 3]; blocks];
    room[0] = [1.2, 4.0, 4.0];
    let (mut plain, mut within) = (
        Gains::flat(W, H).expect("gains"),
        Gains::flat(W, H).expect("gains"),
    );
    plain.step(&r, 1.0).expect("step");
    within.step_within(&r, 1.0, Some(&room)).expect("step");
    assert_eq!(plain.gains[1..], within.gains[1..]);
    assert!((within.gains[0][0] - 1.2).abs() < 1e-5 && within.gains[0][1] < plain.gains[0][1]);
    // Headroom of another length is ignored.
    let mut ignored = Gains::flat(W, H).expect("gains");
    ignored
        .step_within(&r, 1.0, Some(&room[1..]))
        .expect("step");
    assert_eq!(ignored, plain);
    // Light is checked: a count, a value out of range.
    let fresh = || Ratios::from_blocks(W, H, r.blocks().to_vec()).expect("blocks");
    let e = fresh()
        .with_light(vec![None; blocks - 1])
        .expect_err("count")
        .to_string();
    assert!(e.contains(&format!("{blocks}")), "{e}");
    let mut bad = vec![None; blocks];
    bad[3] = Some([[0.1, f64::NAN, 0.1], [0.1; 3]]);
    let e = fresh()
        .with_light(bad)
        .expect_err("not a number")
        .to_string();
    assert!(e.contains("block 3"), "{e}");
    assert!(fresh().light().iter().all(Option::is_none));
    assert!(
        r.clone()
            .relative_to(0.0)
            .light()
            .iter()
            .all(Option::is_none)
    );
}
