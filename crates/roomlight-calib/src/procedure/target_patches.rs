//! The projection-mapping target's camera pixels split into patches, measured like chart
//! patches after them so that the light the luminaires throw on the target can enter the
//! objective ([`super::Target::with_dark`]).

/// Target patches per side of the grid over the target ([`target_patches`]): the lab's bust
/// is about 25 camera pixels across, so 2 × 2 patches of some 100 pixels each.
pub const TARGET_PATCH_GRID: u32 = 2;

/// The target's camera pixels (`mask`, `width` wide), eroded by one pixel (its rim mixes in
/// the background), split into up to `side × side` patches by a grid over their bounding box;
/// patches of fewer than 4 pixels are left out. Empty when the mask is.
pub fn target_patches(mask: &[bool], width: u32, side: u32) -> Vec<Vec<u32>> {
    let w = width as usize;
    if w == 0 || side == 0 {
        return Vec::new();
    }
    let h = mask.len() / w;
    let inner: Vec<bool> = (0..mask.len())
        .map(|i| {
            let (x, y) = (i % w, i / w);
            mask[i]
                && x > 0
                && y > 0
                && x + 1 < w
                && y + 1 < h
                && mask[i - 1]
                && mask[i + 1]
                && mask[i - w]
                && mask[i + w]
        })
        .collect();
    let pixels: Vec<usize> = (0..inner.len()).filter(|&i| inner[i]).collect();
    let (Some(x0), Some(x1)) = (
        pixels.iter().map(|i| i % w).min(),
        pixels.iter().map(|i| i % w).max(),
    ) else {
        return Vec::new();
    };
    let (y0, y1) = (pixels[0] / w, pixels[pixels.len() - 1] / w);
    let side = side as usize;
    let (bw, bh) = (x1 - x0 + 1, y1 - y0 + 1);
    let mut cells = vec![Vec::new(); side * side];
    for &i in &pixels {
        let (cx, cy) = (((i % w) - x0) * side / bw, ((i / w) - y0) * side / bh);
        cells[cy * side + cx].push(i as u32);
    }
    cells.retain(|c| c.len() >= 4);
    cells
}
