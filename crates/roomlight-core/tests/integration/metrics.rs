//! Metrics against published data and constructed images with known answers.

use roomlight_core::LinearRgb;
use roomlight_core::metrics::{
    GrayImage, MetricError, Rect, ansi_contrast, ciede2000, lab_from_linear_rgb, patch_delta_e,
    rms_contrast,
};

/// Table 1 of Sharma, Wu & Dalal (2005), "The CIEDE2000 colour-difference formula:
/// implementation notes, supplementary test data, and mathematical observations".
const SHARMA: [([f64; 3], [f64; 3], f64); 34] = [
    (
        [50.0000, 2.6772, -79.7751],
        [50.0000, 0.0000, -82.7485],
        2.0425,
    ),
    (
        [50.0000, 3.1571, -77.2803],
        [50.0000, 0.0000, -82.7485],
        2.8615,
    ),
    (
        [50.0000, 2.8361, -74.0200],
        [50.0000, 0.0000, -82.7485],
        3.4412,
    ),
    (
        [50.0000, -1.3802, -84.2814],
        [50.0000, 0.0000, -82.7485],
        1.0000,
    ),
    (
        [50.0000, -1.1848, -84.8006],
        [50.0000, 0.0000, -82.7485],
        1.0000,
    ),
    (
        [50.0000, -0.9009, -85.5211],
        [50.0000, 0.0000, -82.7485],
        1.0000,
    ),
    (
        [50.0000, 0.0000, 0.0000],
        [50.0000, -1.0000, 2.0000],
        2.3669,
    ),
    (
        [50.0000, -1.0000, 2.0000],
        [50.0000, 0.0000, 0.0000],
        2.3669,
    ),
    (
        [50.0000, 2.4900, -0.0010],
        [50.0000, -2.4900, 0.0009],
        7.1792,
    ),
    (
        [50.0000, 2.4900, -0.0010],
        [50.0000, -2.4900, 0.0010],
        7.1792,
    ),
    (
        [50.0000, 2.4900, -0.0010],
        [50.0000, -2.4900, 0.0011],
        7.2195,
    ),
    (
        [50.0000, 2.4900, -0.0010],
        [50.0000, -2.4900, 0.0012],
        7.2195,
    ),
    (
        [50.0000, -0.0010, 2.4900],
        [50.0000, 0.0009, -2.4900],
        4.8045,
    ),
    (
        [50.0000, -0.0010, 2.4900],
        [50.0000, 0.0010, -2.4900],
        4.8045,
    ),
    (
        [50.0000, -0.0010, 2.4900],
        [50.0000, 0.0011, -2.4900],
        4.7461,
    ),
    (
        [50.0000, 2.5000, 0.0000],
        [50.0000, 0.0000, -2.5000],
        4.3065,
    ),
    (
        [50.0000, 2.5000, 0.0000],
        [73.0000, 25.0000, -18.0000],
        27.1492,
    ),
    (
        [50.0000, 2.5000, 0.0000],
        [61.0000, -5.0000, 29.0000],
        22.8977,
    ),
    (
        [50.0000, 2.5000, 0.0000],
        [56.0000, -27.0000, -3.0000],
        31.9030,
    ),
    (
        [50.0000, 2.5000, 0.0000],
        [58.0000, 24.0000, 15.0000],
        19.4535,
    ),
    ([50.0000, 2.5000, 0.0000], [50.0000, 3.1736, 0.5854], 1.0000),
    ([50.0000, 2.5000, 0.0000], [50.0000, 3.2972, 0.0000], 1.0000),
    ([50.0000, 2.5000, 0.0000], [50.0000, 1.8634, 0.5757], 1.0000),
    ([50.0000, 2.5000, 0.0000], [50.0000, 3.2592, 0.3350], 1.0000),
    (
        [60.2574, -34.0099, 36.2677],
        [60.4626, -34.1751, 39.4387],
        1.2644,
    ),
    (
        [63.0109, -31.0961, -5.8663],
        [62.8187, -29.7946, -4.0864],
        1.2630,
    ),
    (
        [61.2901, 3.7196, -5.3901],
        [61.4292, 2.2480, -4.9620],
        1.8731,
    ),
    (
        [35.0831, -44.1164, 3.7933],
        [35.0232, -40.0716, 1.5901],
        1.8645,
    ),
    (
        [22.7233, 20.0904, -46.6940],
        [23.0331, 14.9730, -42.5619],
        2.0373,
    ),
    (
        [36.4612, 47.8580, 18.3852],
        [36.2715, 50.5065, 21.2231],
        1.4146,
    ),
    (
        [90.8027, -2.0831, 1.4410],
        [91.1528, -1.6435, 0.0447],
        1.4441,
    ),
    (
        [90.9257, -0.5406, -0.9208],
        [88.6381, -0.8985, -0.7239],
        1.5381,
    ),
    (
        [6.7747, -0.2908, -2.4247],
        [5.8714, -0.0985, -2.2286],
        0.6377,
    ),
    (
        [2.0776, 0.0795, -1.1350],
        [0.9033, -0.0636, -0.5514],
        0.9082,
    ),
];

#[test]
fn ciede2000_matches_all_sharma_pairs() {
    for (k, (a, b, want)) in SHARMA.iter().enumerate() {
        let got = ciede2000(*a, *b);
        assert!(
            (got - want).abs() <= 1e-4,
            "pair {}: got {got:.5}, want {want}",
            k + 1
        );
        let back = ciede2000(*b, *a);
        assert!(
            (got - back).abs() <= 1e-9,
            "pair {} is not symmetric",
            k + 1
        );
    }
}

#[test]
fn lab_of_white_and_grey() {
    let white = lab_from_linear_rgb(LinearRgb::splat(0.5), 0.5);
    assert!(
        (white[0] - 100.0).abs() < 1e-6 && white[1].abs() < 1e-3 && white[2].abs() < 1e-3,
        "{white:?}"
    );
    // 18% grey is L* ≈ 49.5 (CIE 1976: 116·0.18^(1/3) − 16).
    let grey = lab_from_linear_rgb(LinearRgb::splat(0.18), 1.0);
    assert!(
        (grey[0] - (116.0 * 0.18f64.cbrt() - 16.0)).abs() < 1e-3,
        "{grey:?}"
    );
}

#[test]
fn patch_delta_e_is_zero_on_a_perfect_match_and_grows_with_error() {
    let target = vec![LinearRgb([0.2, 0.3, 0.4]), LinearRgb([0.5, 0.5, 0.5])];
    let same = patch_delta_e(&target, &target).expect("metric");
    assert!(same.max.abs() < 1e-12);
    let off = vec![target[0] * 1.1, target[1]];
    let de = patch_delta_e(&target, &off).expect("metric");
    assert!(de.per_patch[0] > 1.0 && de.per_patch[1].abs() < 1e-12);
    assert!(
        (de.mean - de.per_patch[0] / 2.0).abs() < 1e-12 && (de.max - de.per_patch[0]).abs() < 1e-15
    );
    assert!(matches!(
        patch_delta_e(&target, &off[..1]),
        Err(MetricError::Length { .. })
    ));
    let nan = vec![LinearRgb([f64::NAN, 0.0, 0.0]), target[1]];
    assert!(matches!(
        patch_delta_e(&target, &nan),
        Err(MetricError::NotFinite { .. })
    ));
}

#[test]
fn rms_contrast_of_a_two_level_image() {
    // Half the pixels at a, half at b: σ = |a − b|/2, mean = (a + b)/2.
    let (a, b) = (0.8, 0.2);
    let pixels: Vec<f64> = (0..1000).map(|k| if k % 2 == 0 { a } else { b }).collect();
    let c = rms_contrast(&pixels).expect("contrast");
    assert!((c - (a - b) / (a + b)).abs() < 1e-12, "got {c}");
    // Ambient light adds to both levels and lowers the contrast.
    let lit: Vec<f64> = pixels.iter().map(|v| v + 0.5).collect();
    assert!(rms_contrast(&lit).expect("contrast") < c);
    assert!(matches!(rms_contrast(&[]), Err(MetricError::Empty { .. })));
    assert!(matches!(
        rms_contrast(&[0.0, 0.0]),
        Err(MetricError::NonPositive { .. })
    ));
    assert!(matches!(
        rms_contrast(&[1.0, f64::NAN]),
        Err(MetricError::NotFinite { .. })
    ));
}

/// A 4×4 checker of `white`/`black` squares on a grey surround, edges blurred over a few pixels.
fn checker(width: usize, height: usize, board: Rect, white: f32, black: f32) -> Vec<f32> {
    let mut img = vec![0.3f32; width * height];
    for y in 0..height {
        for x in 0..width {
            let (fx, fy) = (x as f64 + 0.5 - board.x, y as f64 + 0.5 - board.y);
            if fx < 0.0 || fy < 0.0 || fx >= board.width || fy >= board.height {
                continue;
            }
            let (col, row) = (
                (fx / board.width * 4.0) as usize,
                (fy / board.height * 4.0) as usize,
            );
            img[y * width + x] = if (row + col) % 2 == 0 { white } else { black };
        }
    }
    // A box blur of radius 2 smears the square edges, as a defocused camera would.
    let src = img.clone();
    for y in 2..height - 2 {
        for x in 2..width - 2 {
            let mut s = 0.0;
            for dy in 0..5 {
                for dx in 0..5 {
                    s += src[(y + dy - 2) * width + (x + dx - 2)];
                }
            }
            img[y * width + x] = s / 25.0;
        }
    }
    img
}

#[test]
fn ansi_contrast_of_a_constructed_checker() {
    let (w, h) = (200, 160);
    let board = Rect {
        x: 20.0,
        y: 16.0,
        width: 160.0,
        height: 128.0,
    };
    let img = checker(w, h, board, 0.9, 0.005);
    let image = GrayImage {
        width: w,
        height: h,
        pixels: &img,
    };
    let c = ansi_contrast(image, board, true).expect("contrast");
    assert!((c.ratio - 180.0).abs() < 1e-3, "got {}", c.ratio);
    // The other phase swaps white and black.
    let swapped = ansi_contrast(image, board, false).expect("contrast");
    assert!((swapped.ratio - 1.0 / 180.0).abs() < 1e-6);
    // Ambient light on both: (0.9 + a) / (0.005 + a).
    let lit: Vec<f32> = img.iter().map(|v| v + 0.025).collect();
    let c = ansi_contrast(
        GrayImage {
            width: w,
            height: h,
            pixels: &lit,
        },
        board,
        true,
    )
    .expect("contrast");
    assert!((c.ratio - 0.925 / 0.03).abs() < 1e-3, "got {}", c.ratio);
}

#[test]
fn ansi_contrast_rejects_bad_input() {
    let img = vec![0.5f32; 100];
    let image = GrayImage {
        width: 10,
        height: 10,
        pixels: &img,
    };
    let outside = Rect {
        x: 5.0,
        y: 5.0,
        width: 10.0,
        height: 10.0,
    };
    assert!(matches!(
        ansi_contrast(image, outside, true),
        Err(MetricError::OutOfImage { .. })
    ));
    let dark = vec![0.0f32; 100];
    let all = Rect {
        x: 0.0,
        y: 0.0,
        width: 10.0,
        height: 10.0,
    };
    let image = GrayImage {
        width: 10,
        height: 10,
        pixels: &dark,
    };
    assert!(matches!(
        ansi_contrast(image, all, true),
        Err(MetricError::NonPositive { .. })
    ));
    let image = GrayImage {
        width: 10,
        height: 9,
        pixels: &dark,
    };
    assert!(matches!(
        ansi_contrast(image, all, true),
        Err(MetricError::Length { .. })
    ));
}
