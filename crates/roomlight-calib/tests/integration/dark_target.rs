//! The dark target's pieces in calibration: patches on the target's camera mask, sampled like
//! chart patches, and the model's rows on them scaled by √w with the black level as reference.

use roomlight_calib::charts::{PatchSample, PatchStatus, SampleConfig, sample_region};
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::procedure::{Target, target_patches};
use roomlight_core::LinearRgb;

fn ok(mean: f64) -> PatchSample {
    PatchSample {
        mean: LinearRgb::splat(mean),
        std_error: LinearRgb::splat(0.01),
        pixels: 100,
        status: PatchStatus::Ok,
    }
}

#[test]
fn target_patches_split_the_eroded_mask_and_sample_like_chart_patches() {
    // A 10 × 10 target at (4, 6) in a 20 × 20 image: eroded by one pixel, 8 × 8 = 64 pixels,
    // four patches of 16 in a 2 × 2 grid.
    let (w, h) = (20u32, 20u32);
    let mask: Vec<bool> = (0..w * h)
        .map(|i| (4..14).contains(&(i % w)) && (6..16).contains(&(i / w)))
        .collect();
    let patches = target_patches(&mask, w, 2);
    assert_eq!(patches.len(), 4);
    for p in &patches {
        assert_eq!(p.len(), 16);
        for &i in p {
            let (x, y) = (i % w, i / w);
            assert!(
                (5..13).contains(&x) && (7..15).contains(&y),
                "pixel {x},{y}"
            );
        }
    }
    // Each pixel's value is its column: a patch's mean is the mean of its columns.
    let image = LinearImage {
        width: w,
        height: h,
        pixels: (0..w * h).map(|i| [(i % w) as f32 / 100.0; 3]).collect(),
    };
    let config = SampleConfig::default();
    let s = sample_region(&image, &patches[0], &config);
    assert_eq!(s.status, PatchStatus::Ok);
    assert!((s.mean[0] - 0.065).abs() < 1e-6, "{}", s.mean[0]); // columns 5..=8
    assert!(s.std_error[0] > 0.0);
    let mut bright = image.clone();
    bright.pixels[patches[1][0] as usize] = [0.99; 3];
    assert_eq!(
        sample_region(&bright, &patches[1], &config).status,
        PatchStatus::Saturated
    );
    assert_eq!(
        sample_region(&image, &[w * h], &config).status,
        PatchStatus::OutOfImage
    );
    assert!(target_patches(&vec![false; 400], w, 2).is_empty());
}

#[test]
fn a_dark_target_scales_its_rows_and_weight_zero_leaves_it_out() {
    // Room patches 0 and 1 on charts, 2 on the target.
    let black = [LinearRgb::splat(0.01); 3];
    let lit = [ok(0.5), ok(0.4), ok(0.3)];
    let columns = vec![vec![
        (0u32, LinearRgb::splat(0.2)),
        (1, LinearRgb::splat(0.1)),
        (2, LinearRgb::splat(0.05)),
    ]];
    let plain = Target::new(&black, &[true, true, false], &lit).expect("charts only");
    let all = Target::new(&black, &[true; 3], &lit).expect("all");
    let zero = all.clone().with_dark(2..3, 0.0).expect("w = 0");
    assert_eq!(zero, plain, "weight 0 is the model over the charts alone");
    assert_eq!(
        zero.problem(zero.columns(&columns).expect("ok"))
            .expect("ok"),
        plain
            .problem(plain.columns(&columns).expect("ok"))
            .expect("ok")
    );
    let dark = all.clone().with_dark(2..3, 4.0).expect("w = 4");
    let problem = dark
        .problem(dark.columns(&columns).expect("ok"))
        .expect("ok");
    // The target patch: reference = black level, row × √4 = 2.
    assert_eq!(problem.target()[2], LinearRgb::splat(0.02));
    assert_eq!(problem.black()[2], LinearRgb::splat(0.02));
    assert_eq!(problem.noise()[2], LinearRgb::splat(0.02));
    assert_eq!(problem.columns()[0].get(2), LinearRgb::splat(0.1));
    // Chart patches untouched.
    assert_eq!(problem.target()[0], LinearRgb::splat(0.5));
    assert_eq!(problem.columns()[0].get(0), LinearRgb::splat(0.2));
    // G weighs the target patch's squared error by w: at x = 1 its error is 0.05 above black.
    let x = [LinearRgb::ONE];
    let e = problem.errors(&x);
    assert!((e[2][0].abs() - 2.0 * 0.05).abs() < 1e-12, "{:?}", e[2]);
    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        let err = all
            .clone()
            .with_dark(2..3, bad)
            .expect_err("refused")
            .to_string();
        assert!(err.contains("dark target weight"), "{err}");
    }
}
