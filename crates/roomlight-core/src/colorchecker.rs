//! The 24-patch ColorChecker: the published sRGB values (8-bit, D65) of its patches, decoded
//! to linear-sRGB reflectances. Used by the synthetic rooms here and by the simulator.

use crate::rgb::LinearRgb;
use palette::{LinSrgb, Srgb};

/// Patch names in chart order (row by row, dark skin first, black last).
pub const NAMES: [&str; 24] = [
    "dark skin",
    "light skin",
    "blue sky",
    "foliage",
    "blue flower",
    "bluish green",
    "orange",
    "purplish blue",
    "moderate red",
    "purple",
    "yellow green",
    "orange yellow",
    "blue",
    "green",
    "red",
    "yellow",
    "magenta",
    "cyan",
    "white 9.5",
    "neutral 8",
    "neutral 6.5",
    "neutral 5",
    "neutral 3.5",
    "black 2",
];

/// sRGB-encoded 8-bit values of the patches, as published by the chart's maker.
pub const SRGB8: [[u8; 3]; 24] = [
    [115, 82, 68],
    [194, 150, 130],
    [98, 122, 157],
    [87, 108, 67],
    [133, 128, 177],
    [103, 189, 170],
    [214, 126, 44],
    [80, 91, 166],
    [193, 90, 99],
    [94, 60, 108],
    [157, 188, 64],
    [224, 163, 46],
    [56, 61, 150],
    [70, 148, 73],
    [175, 54, 60],
    [231, 199, 31],
    [187, 86, 149],
    [8, 133, 161],
    [243, 243, 242],
    [200, 200, 200],
    [160, 160, 160],
    [122, 122, 121],
    [85, 85, 85],
    [52, 52, 52],
];

/// Linear-sRGB reflectance of patch `k` (0..24) in `[0, 1]`.
pub fn reflectance(k: usize) -> LinearRgb {
    let [r, g, b] = SRGB8[k % 24];
    let lin: LinSrgb<f64> = Srgb::new(r, g, b).into_format::<f64>().into_linear();
    LinearRgb([lin.red, lin.green, lin.blue])
}

/// All 24 reflectances in chart order.
pub fn reflectances() -> [LinearRgb; 24] {
    std::array::from_fn(reflectance)
}
