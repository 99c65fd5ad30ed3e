//! Which projectors can show their structured light at the same time: those whose footprints
//! (the camera pixels each lights directly) do not overlap. It owns the grouping, not how the
//! footprints were measured.

/// Groups projectors whose footprints (camera pixels each lights directly) do not overlap, so
/// that each group shows its patterns at the same time. Greedy, in the given order.
pub fn group_disjoint(footprints: &[Vec<bool>]) -> Vec<Vec<usize>> {
    let mut groups: Vec<(Vec<usize>, Vec<bool>)> = Vec::new();
    for (k, fp) in footprints.iter().enumerate() {
        match groups
            .iter_mut()
            .find(|(_, used)| used.iter().zip(fp).all(|(a, b)| !(*a && *b)))
        {
            Some((members, used)) => {
                members.push(k);
                for (u, f) in used.iter_mut().zip(fp) {
                    *u |= *f;
                }
            }
            None => groups.push((vec![k], fp.clone())),
        }
    }
    groups.into_iter().map(|(m, _)| m).collect()
}
