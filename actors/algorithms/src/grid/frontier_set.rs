//! The frontier cells of a snapshot, and the exact distance from any cell to the
//! nearest of them, found on demand.
//!
//! The planner reads the distance to the nearest frontier at a few hundred points a
//! round (the frontier reward V = d(ξ0) − d(ξτ), paper V-B), while a distance
//! transform of the whole window costs several milliseconds at every snapshot.
//! Frontier cells are few and sparse, so [`FrontierSet`] keeps them in blocks of
//! [`BLOCK_CELLS`]³ and searches the blocks around a query outwards, stopping once no
//! block left can hold a nearer cell. The result is the exact squared distance
//! between cell centres in cells², the same integer an exact Euclidean transform
//! ([`distance_to`](super::distance::distance_to)) gives, read in metres the same
//! way.

use super::LocalGrid;
use super::frontier::frontier_mask;

/// Edge of the search blocks, in cells.
const BLOCK_CELLS: usize = 8;

/// A grid's frontier cells ([`frontier_mask`]) and nearest-frontier queries.
#[derive(Clone, Debug, PartialEq)]
pub struct FrontierSet {
    cell_m: f64,
    /// One bit per cell, set for a frontier cell.
    bits: Vec<u64>,
    /// Blocks per axis.
    blocks: [usize; 3],
    /// `cells[block_start[b]..block_start[b + 1]]` are the frontier cells of block `b`.
    block_start: Vec<u32>,
    cells: Vec<[u32; 3]>,
}

impl FrontierSet {
    /// The frontier cells of `grid`.
    #[must_use]
    pub fn of(grid: &LocalGrid) -> Self {
        Self::from_mask(&frontier_mask(grid), grid.dims(), grid.resolution_m())
    }

    /// The cells set in `mask` (`dims` as in [`LocalGrid::dims`], cells row-major
    /// with x fastest) of a grid of `cell_m` cells; entries of `mask` beyond the grid's
    /// cells are ignored.
    #[must_use]
    pub fn from_mask(mask: &[bool], dims: [usize; 3], cell_m: f64) -> Self {
        let mask = &mask[..mask.len().min(dims.iter().product())];
        let blocks = dims.map(|n| n.div_ceil(BLOCK_CELLS));
        let block_of = |c: [usize; 3]| {
            let b = c.map(|v| v / BLOCK_CELLS);
            b[0] + blocks[0] * (b[1] + blocks[1] * b[2])
        };
        let mut bits = vec![0u64; mask.len().div_ceil(64)];
        let mut frontier = Vec::new();
        for (i, _) in mask.iter().enumerate().filter(|(_, f)| **f) {
            bits[i / 64] |= 1 << (i % 64);
            let c = [
                i % dims[0],
                (i / dims[0]) % dims[1],
                i / (dims[0] * dims[1]),
            ];
            frontier.push((block_of(c), c.map(|v| v as u32)));
        }
        // Stable: within a block, cells stay in cell order.
        frontier.sort_by_key(|(b, _)| *b);
        let mut block_start = vec![0u32; blocks.iter().product::<usize>() + 1];
        for (b, _) in &frontier {
            block_start[b + 1] += 1;
        }
        for b in 1..block_start.len() {
            block_start[b] += block_start[b - 1];
        }
        FrontierSet {
            cell_m,
            bits,
            blocks,
            block_start,
            cells: frontier.into_iter().map(|(_, c)| c).collect(),
        }
    }

    /// Number of frontier cells.
    #[must_use]
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether the grid has no frontier cell.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Whether cell `i` (row-major, x fastest) is a frontier cell; `false` outside
    /// the grid.
    #[must_use]
    pub fn contains(&self, i: usize) -> bool {
        self.bits
            .get(i / 64)
            .is_some_and(|word| word & (1 << (i % 64)) != 0)
    }

    /// Every frontier cell's index, in cell order.
    pub fn indices(&self) -> impl Iterator<Item = usize> + '_ {
        self.bits.iter().enumerate().flat_map(|(w, &word)| {
            (0..64)
                .filter(move |bit| word & (1 << bit) != 0)
                .map(move |bit| w * 64 + bit)
        })
    }

    /// Bytes the set holds.
    #[must_use]
    pub fn heap_bytes(&self) -> usize {
        8 * self.bits.len() + 4 * self.block_start.len() + 12 * self.cells.len()
    }

    /// Distance from the centre of cell `c` to the nearest frontier cell's centre,
    /// metres (`f64::INFINITY` without a frontier).
    #[must_use]
    pub fn distance_m(&self, c: [usize; 3]) -> f64 {
        self.nearest_squared_cells(c)
            .map_or(f64::INFINITY, |d2| (d2 as f64).sqrt() * self.cell_m)
    }

    /// Squared distance in cells² from cell `c` to the nearest frontier cell, by
    /// blocks in shells of growing Chebyshev radius around `c`'s block: a block `r`
    /// shells out is at least `(r − 1)·B + 1` cells away along some axis, so the
    /// search stops once that bound reaches the best distance found.
    #[must_use]
    pub fn nearest_squared_cells(&self, c: [usize; 3]) -> Option<u64> {
        if self.cells.is_empty() {
            return None;
        }
        let home = c.map(|v| (v / BLOCK_CELLS) as i64);
        let nb = self.blocks.map(|n| n as i64);
        let last_shell = (0..3)
            .map(|k| home[k].max(nb[k] - 1 - home[k]))
            .max()
            .unwrap_or(0);
        let c = c.map(|v| v as i64);
        let mut best = u64::MAX;
        for r in 0..=last_shell {
            if r > 0 {
                let gap = ((r - 1) * BLOCK_CELLS as i64 + 1) as u64;
                if gap * gap >= best {
                    break;
                }
            }
            let range = |k: usize| (home[k] - r).max(0)..=(home[k] + r).min(nb[k] - 1);
            for bz in range(2) {
                for by in range(1) {
                    let on_shell_yz = (bz - home[2]).abs() == r || (by - home[1]).abs() == r;
                    for bx in range(0) {
                        if !on_shell_yz && (bx - home[0]).abs() != r {
                            continue;
                        }
                        let b = (bx + nb[0] * (by + nb[1] * bz)) as usize;
                        let (s, e) = (
                            self.block_start[b] as usize,
                            self.block_start[b + 1] as usize,
                        );
                        for f in &self.cells[s..e] {
                            let d2 = (0..3)
                                .map(|k| (i64::from(f[k]) - c[k]).unsigned_abs().pow(2))
                                .sum::<u64>();
                            best = best.min(d2);
                        }
                    }
                }
            }
        }
        Some(best)
    }
}

#[cfg(test)]
mod tests {
    use super::super::distance::distance_to;
    use super::*;

    /// A deterministic pseudo-random mask with about one cell in `one_in` set.
    fn mask(dims: [usize; 3], one_in: u64, seed: u64) -> Vec<bool> {
        let mut state = seed;
        (0..dims.iter().product::<usize>())
            .map(|_| {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                (state >> 33).is_multiple_of(one_in)
            })
            .collect()
    }

    #[test]
    fn nearest_frontier_is_the_exact_transform_bit_for_bit() {
        // Sparse and dense sets, odd sizes (partial blocks), one cell, none.
        let cases: [([usize; 3], u64); 5] = [
            ([37, 23, 11], 400),
            ([20, 20, 20], 7),
            ([9, 50, 3], 1_000),
            ([64, 64, 16], 20_000),
            ([5, 5, 5], u64::MAX),
        ];
        for (n, (dims, one_in)) in cases.into_iter().enumerate() {
            let m = mask(dims, one_in, n as u64 + 1);
            let set = FrontierSet::from_mask(&m, dims, 0.1);
            let field = distance_to(&m, dims, 0.1);
            assert_eq!(set.len(), m.iter().filter(|f| **f).count());
            assert!(set.indices().eq((0..m.len()).filter(|i| m[*i])));
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let i = x + dims[0] * (y + dims[1] * z);
                        assert_eq!(set.contains(i), m[i]);
                        let (got, want) = (set.distance_m([x, y, z]), field.metres(i));
                        assert_eq!(got.to_bits(), want.to_bits(), "{dims:?} at {x},{y},{z}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_lone_far_frontier_is_found_across_the_grid() {
        let dims = [40, 30, 20];
        let mut m = vec![false; 40 * 30 * 20];
        m[39 + 40 * (29 + 30 * 19)] = true;
        let set = FrontierSet::from_mask(&m, dims, 1.0);
        assert_eq!(
            set.nearest_squared_cells([0, 0, 0]),
            Some(39 * 39 + 29 * 29 + 19 * 19)
        );
        assert!(!set.contains(m.len()));
        assert!(
            FrontierSet::from_mask(&[false; 8], [2, 2, 2], 1.0)
                .distance_m([0, 0, 0])
                .is_infinite()
        );
    }
}
