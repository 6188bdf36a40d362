//! Frontiers (free cells next to unknown space) and map entropy.

use super::distance::distance_to;
use super::{CellState, LocalGrid};

/// Frontier cells: free cells with at least one unknown face neighbour inside the grid.
#[must_use]
pub fn frontier_mask(grid: &LocalGrid) -> Vec<bool> {
    let d = grid.dims();
    let states: Vec<CellState> = grid.values().iter().map(|v| grid.classify(*v)).collect();
    let mut mask = vec![false; states.len()];
    for z in 0..d[2] {
        for y in 0..d[1] {
            for x in 0..d[0] {
                let i = grid.index([x, y, z]);
                if states[i] != CellState::Free {
                    continue;
                }
                let c = [x, y, z];
                mask[i] = (0..3).any(|axis| {
                    let below = c[axis].checked_sub(1).map(|v| {
                        let mut n = c;
                        n[axis] = v;
                        n
                    });
                    let above = (c[axis] + 1 < d[axis]).then(|| {
                        let mut n = c;
                        n[axis] += 1;
                        n
                    });
                    [below, above]
                        .into_iter()
                        .flatten()
                        .any(|n| states[grid.index(n)] == CellState::Unknown)
                });
            }
        }
    }
    mask
}

/// Distance from each cell to the nearest frontier cell, metres (infinite when there
/// is no frontier): the field behind the frontier reward V = d(ξ0) − d(ξτ) (paper V-B).
#[must_use]
pub fn frontier_distance(grid: &LocalGrid) -> Vec<f64> {
    distance_to(&frontier_mask(grid), grid.dims(), grid.resolution_m())
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
