//! Frontiers (free cells next to unknown space) and map entropy.

use super::{CellState, LocalGrid};

/// Frontier cells: free cells with an unknown neighbour across a vertical face (in x
/// or y) and no occupied cell among their 26 neighbours, in clusters of at least
/// [`MIN_FRONTIER_CLUSTER_CELLS`].
///
/// The restrictions are ours (the paper's frontier, V-B, is any free cell next to
/// unknown space); each stops the frontier reward V = d(ξ0) − d(ξτ) from holding a
/// robot in place, which a diagnosis of stalled runs in the default cave showed:
/// - a free cell beside a surface whose unknown neighbour lies behind it is a gap in
///   the surface's occupied layer (rays end at the surface, the rock behind stays
///   unknown), not an opening. Such specks — a few to ~30 cells along rough walls —
///   were within a metre of the robot wherever it was, and ground truth put nearly
///   all their unknown neighbours inside the rock: robots hovered at dead ends (run
///   seed 3 stalled at 35 % coverage for 500 s);
/// - unknown space only above or below a free cell is floor or ceiling out of the
///   forward camera's vertical field of view (±30°). Flying towards it puts it out of
///   sight, so a robot drawn to the cells under it hovered there for 350 s.
///
/// - clusters of fewer than [`MIN_FRONTIER_CLUSTER_CELLS`] frontier cells (26-connected)
///   are pockets in floors and walls, not openings: a robot drawn to a 3-cell pocket
///   a metre below it hovered there for 200 s.
///
/// Openings into unexplored space — tunnels continuing, side passages, the edge of
/// what was seen — have horizontal unknown neighbours away from surfaces and keep
/// their bulk.
#[must_use]
pub fn frontier_mask(grid: &LocalGrid) -> Vec<bool> {
    let d = grid.dims();
    let states: Vec<CellState> = grid.values().iter().map(|v| grid.classify(*v)).collect();
    let state = |c: [usize; 3]| states[grid.index(c)];
    let neighbour = |c: [usize; 3], offset: [i64; 3]| -> Option<[usize; 3]> {
        let mut n = [0usize; 3];
        for axis in 0..3 {
            let v = c[axis] as i64 + offset[axis];
            if v < 0 || v >= d[axis] as i64 {
                return None;
            }
            n[axis] = v as usize;
        }
        Some(n)
    };
    const SIDES: [[i64; 3]; 4] = [[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0]];
    let mut mask = vec![false; states.len()];
    for z in 0..d[2] {
        for y in 0..d[1] {
            for x in 0..d[0] {
                let c = [x, y, z];
                if state(c) != CellState::Free {
                    continue;
                }
                let opens = SIDES
                    .iter()
                    .filter_map(|o| neighbour(c, *o))
                    .any(|n| state(n) == CellState::Unknown);
                if !opens {
                    continue;
                }
                let walled = (-1..=1).any(|dz| {
                    (-1..=1).any(|dy| {
                        (-1..=1).any(|dx| {
                            neighbour(c, [dx, dy, dz])
                                .is_some_and(|n| state(n) == CellState::Occupied)
                        })
                    })
                });
                mask[grid.index(c)] = !walled;
            }
        }
    }
    drop_small_clusters(&mut mask, d, MIN_FRONTIER_CLUSTER_CELLS);
    mask
}

/// Frontier clusters (26-connected) smaller than this are dropped from the mask.
pub const MIN_FRONTIER_CLUSTER_CELLS: usize = 10;

/// Clears every 26-connected cluster of `mask` with fewer than `min_cells` cells.
fn drop_small_clusters(mask: &mut [bool], d: [usize; 3], min_cells: usize) {
    let index = |c: [usize; 3]| c[0] + d[0] * (c[1] + d[1] * c[2]);
    let cell = |i: usize| [i % d[0], (i / d[0]) % d[1], i / (d[0] * d[1])];
    let mut seen = vec![false; mask.len()];
    let (mut cluster, mut stack) = (Vec::new(), Vec::new());
    for start in 0..mask.len() {
        if !mask[start] || seen[start] {
            continue;
        }
        cluster.clear();
        seen[start] = true;
        stack.push(start);
        while let Some(i) = stack.pop() {
            cluster.push(i);
            let c = cell(i);
            for dz in -1i64..=1 {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let n = [c[0] as i64 + dx, c[1] as i64 + dy, c[2] as i64 + dz];
                        if (0..3).any(|a| n[a] < 0 || n[a] >= d[a] as i64) {
                            continue;
                        }
                        let j = index([n[0] as usize, n[1] as usize, n[2] as usize]);
                        if mask[j] && !seen[j] {
                            seen[j] = true;
                            stack.push(j);
                        }
                    }
                }
            }
        }
        if cluster.len() < min_cells {
            for &i in &cluster {
                mask[i] = false;
            }
        }
    }
}

/// Shannon entropy of the grid in bits: Σ H(p) with H(p) = −p log₂ p − (1−p) log₂(1−p).
#[must_use]
pub fn entropy_bits(grid: &LocalGrid) -> f64 {
    grid.values()
        .iter()
        .map(|l| {
            let p = 1.0 / (1.0 + (-f64::from(*l)).exp());
            if p <= 0.0 || p >= 1.0 {
                0.0
            } else {
                -(p * p.log2() + (1.0 - p) * (1.0 - p).log2())
            }
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::drop_small_clusters;

    #[test]
    fn small_clusters_are_dropped_and_large_ones_kept_whole() {
        let d = [8, 8, 2];
        let index = |x: usize, y: usize, z: usize| x + d[0] * (y + d[1] * z);
        let mut mask = vec![false; 128];
        // A 2-cell pocket and a diagonal chain of 4 (26-connected across layers).
        mask[index(0, 0, 0)] = true;
        mask[index(1, 0, 0)] = true;
        for k in 0..4 {
            mask[index(3 + k, 3 + k, k % 2)] = true;
        }
        let mut kept = mask.clone();
        drop_small_clusters(&mut kept, d, 3);
        assert!(
            !kept[index(0, 0, 0)] && !kept[index(1, 0, 0)],
            "the pocket goes"
        );
        assert_eq!(
            kept.iter().filter(|m| **m).count(),
            4,
            "the chain stays whole"
        );
        drop_small_clusters(&mut mask, d, 5);
        assert!(mask.iter().all(|m| !m));
    }
}
