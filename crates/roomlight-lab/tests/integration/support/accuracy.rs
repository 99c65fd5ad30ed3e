//! A decode against the simulator's true correspondence: the share of reached camera pixels
//! within a tolerance (±1 projector pixel, or `Manifest::tolerance` over code cells) and the
//! share of decoded ones further than one pixel beyond it.

use roomlight_calib::graycode::Correspondence;
use roomlight_sim::Room;

/// (share of reached pixels decoded within ±`tolerance`, share of decoded pixels off by more
/// than `tolerance + 1`, pixels reached), against the simulator's true correspondence.
pub fn accuracy(
    room: &Room,
    k: usize,
    decoded: &Correspondence,
    tolerance: u32,
) -> (f64, f64, usize) {
    accuracy_where(room, k, decoded, tolerance, |_| true)
}

/// [`accuracy`] over the camera pixels `count` accepts.
pub fn accuracy_where(
    room: &Room,
    k: usize,
    decoded: &Correspondence,
    tolerance: u32,
    count: impl Fn(usize) -> bool,
) -> (f64, f64, usize) {
    let tolerance = i64::from(tolerance);
    let truth = room.true_correspondence(k);
    let pw = room.projectors()[k].pinhole.width;
    let off = |t: u32, (x, y): (u32, u32)| {
        (i64::from(x) - i64::from(t % pw))
            .abs()
            .max((i64::from(y) - i64::from(t / pw)).abs())
    };
    let (mut reached, mut close, mut n, mut far) = (0usize, 0usize, 0usize, 0usize);
    for (i, (t, d)) in truth.iter().zip(&decoded.map).enumerate() {
        if !count(i) {
            continue;
        }
        if let Some(t) = t {
            reached += 1;
            close += usize::from(d.is_some_and(|d| off(*t, d) <= tolerance));
        }
        if let Some(d) = d {
            n += 1;
            far += usize::from(t.is_none_or(|t| off(t, *d) > tolerance + 1));
        }
    }
    (
        close as f64 / reached.max(1) as f64,
        far as f64 / n.max(1) as f64,
        reached,
    )
}

pub fn assert_accurate(room: &Room, id: &str, corr: &Correspondence, tolerance: u32) {
    let k = room.projector(id).expect("projector");
    let (close, far, reached) = accuracy(room, k, corr, tolerance);
    println!(
        "{id}: {reached} pixels reached, {:.2}% within ±{tolerance}, {:.3}% off by > {}",
        100.0 * close,
        100.0 * far,
        tolerance + 1
    );
    // The bar the graycode tests hold the same projectors to when decoded alone.
    assert!(reached > 1000, "{id} reaches {reached} pixels");
    assert!(
        close >= 0.98,
        "{id}: {:.2}% within ±{tolerance}",
        100.0 * close
    );
    assert!(
        far <= 0.001,
        "{id}: {:.3}% off by more than {}",
        100.0 * far,
        tolerance + 1
    );
}
