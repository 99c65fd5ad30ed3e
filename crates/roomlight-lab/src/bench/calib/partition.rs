//! The partition of unity of the lab's nodes as the bench reads it, through the simulator's
//! true correspondence: all segmented together, one after the other, and (with
//! `ROOMLIGHT_DIAG` set) where it misses in overlaps.

use roomlight_calib::charts::ChartCorners;
use roomlight_calib::graycode::Correspondence;
use roomlight_calib::nodes::{
    NodeConfig, Segmentation, add_claim, partition_of_unity, projector_weights, segment_beside,
};
use roomlight_sim::Room;

/// Partition of unity on the surface points, through the simulator's true correspondence,
/// away from the target (its margin is black): the standard luminaires (`luminaires`, room
/// indices, decoded as `corr`) all segmented together (`seg`; the cold start's line gives
/// the bring-up's own placement), and one after the other as projectors joining a lit room
/// over the wire are.
pub(super) fn report(
    room: &Room,
    luminaires: &[usize],
    corr: &[Correspondence],
    seg: &Segmentation,
    charts: &[ChartCorners],
    mask: &[bool],
) {
    let truth: Vec<Vec<Option<u32>>> = luminaires
        .iter()
        .map(|&k| room.true_correspondence(k))
        .collect();
    let (cw, ch) = (room.camera().width as usize, room.camera().height as usize);
    let away = roomlight_calib::nodes::dilate(mask, cw, ch, 8);
    let weights: Vec<Vec<f32>> = (0..corr.len())
        .map(|k| projector_weights(&seg.nodes, k))
        .collect();
    println!(
        "  partition of unity, all segmented together (a bring-up places those that left over {:.0}% unknown beside the others): {}",
        100.0 * roomlight_calib::procedure::BESIDE_UNKNOWN,
        partition_of_unity(&truth, &weights, &seg.excluded, &away)
    );
    if std::env::var_os("ROOMLIGHT_DIAG").is_some() {
        partition_misses(&truth, corr, &weights, &seg.excluded, &away, cw);
    }
    let mut claimed = vec![0.0f32; cw * ch];
    let (mut weights, mut dark) = (Vec::new(), Vec::new());
    for c in corr {
        let one = segment_beside(
            std::slice::from_ref(c),
            charts,
            Some(mask),
            &NodeConfig::default(),
            Some(&claimed),
        );
        // A projector that lights no chart alone: no nodes, no light.
        let Ok(one) = one else {
            weights.push(Vec::new());
            dark.push(Vec::new());
            continue;
        };
        add_claim(&mut claimed, &one.claims[0]);
        weights.push(projector_weights(&one.nodes, 0));
        dark.extend(one.excluded);
    }
    println!(
        "  partition of unity, one after the other: {}",
        partition_of_unity(&truth, &weights, &dark, &away)
    );
}

/// Where the partition of unity misses in overlaps (with `ROOMLIGHT_DIAG` set): each overlap
/// point off by more than 1e-3, by what the decode says about its contributors.
fn partition_misses(
    truth: &[Vec<Option<u32>>],
    corr: &[Correspondence],
    weights: &[Vec<f32>],
    dark: &[Vec<bool>],
    skip: &[bool],
    cw: usize,
) {
    let (mut undecoded, mut off_pixel, mut exact) = ([0usize; 2], [0usize; 2], [0usize; 2]);
    let mut samples = Vec::new();
    for i in 0..skip.len() {
        let reaching: Vec<(usize, u32)> = truth
            .iter()
            .enumerate()
            .filter_map(|(k, t)| t[i].map(|p| (k, p)))
            .collect();
        if skip[i] || reaching.len() < 2 || reaching.iter().any(|&(k, p)| dark[k][p as usize]) {
            continue;
        }
        let sum: f32 = reaching.iter().map(|&(k, p)| weights[k][p as usize]).sum();
        let miss = (sum - 1.0).abs();
        if miss <= 1e-3 {
            continue;
        }
        let big = usize::from(miss > 0.05);
        let decoded: Vec<Option<u32>> = reaching
            .iter()
            .map(|&(k, _)| corr[k].map[i].map(|(x, y)| y * corr[k].projector_width + x))
            .collect();
        if decoded.iter().any(Option::is_none) {
            undecoded[big] += 1;
        } else if reaching
            .iter()
            .zip(&decoded)
            .any(|((_, t), d)| Some(*t) != *d)
        {
            off_pixel[big] += 1;
        } else {
            exact[big] += 1;
        }
        if samples.len() < 12 && big == 1 {
            samples.push(format!(
                "({}, {}) sum {sum:.3} truth {:?} decoded {:?}",
                i % cw,
                i / cw,
                reaching,
                decoded
            ));
        }
    }
    println!(
        "  misses in overlaps (> 1e-3 / > 0.05): a contributor not decoded there {undecoded:?}, decoded off its true pixel {off_pixel:?}, all decoded exactly {exact:?}"
    );
    for s in samples {
        println!("    {s}");
    }
}
