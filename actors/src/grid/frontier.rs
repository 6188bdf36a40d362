//! Frontiers (free cells next to unknown space), the frontiers a robot left behind,
//! and map entropy.

use std::collections::BTreeMap;

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

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
    frontier_distance_of(&frontier_mask(grid), grid)
}

/// [`frontier_distance`] from a mask already computed.
#[must_use]
pub fn frontier_distance_of(mask: &[bool], grid: &LocalGrid) -> Vec<f64> {
    distance_to(mask, grid.dims(), grid.resolution_m())
}

/// Settings of the [`FrontierMemory`] (`[robot.grid.frontier_memory]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FrontierMemoryConfig {
    /// Remember frontiers that leave the window.
    pub enabled: bool,
    /// Edge of the coarse cells frontiers are remembered in, metres (one point each).
    pub cell_m: f64,
    /// Frontier cells a coarse cell must hold to be remembered (specks of unknown
    /// space between observed cells are not worth a trip).
    pub min_cells: usize,
}

impl Default for FrontierMemoryConfig {
    fn default() -> Self {
        FrontierMemoryConfig {
            enabled: false,
            cell_m: 2.0,
            min_cells: 8,
        }
    }
}

impl FrontierMemoryConfig {
    /// Checks the numbers; the error names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.cell_m.is_finite() && self.cell_m > 0.0) {
            return Err(format!(
                "frontier_memory.cell_m must be > 0, got {}",
                self.cell_m
            ));
        }
        if self.min_cells == 0 {
            return Err("frontier_memory.min_cells must be ≥ 1".into());
        }
        Ok(())
    }
}

/// Frontiers the robot saw and left behind. The local grid forgets whatever leaves
/// its window (§3.2.3 rebuilds novel boxes only from keyframes, which hold surfaces
/// and the free space in front of them, not the unknown beyond), so a robot whose
/// window holds no frontier any more — at the end of a dead-end tunnel — has nothing
/// to steer by, and wanders. The memory keeps one point (the centroid of the
/// frontier cells) per coarse cell of [`FrontierMemoryConfig::cell_m`]; at every
/// update, the coarse cells inside the window are replaced by what the grid shows now,
/// so a remembered frontier is dropped once the window covers it and it is gone.
#[derive(Clone, Debug)]
pub struct FrontierMemory {
    config: FrontierMemoryConfig,
    points: BTreeMap<[i64; 3], Point3<f64>>,
}

impl FrontierMemory {
    /// An empty memory.
    #[must_use]
    pub fn new(config: FrontierMemoryConfig) -> Self {
        FrontierMemory {
            config,
            points: BTreeMap::new(),
        }
    }

    fn key(&self, p: &Point3<f64>) -> [i64; 3] {
        [0, 1, 2].map(|i| (p[i] / self.config.cell_m).floor() as i64)
    }

    /// Takes the grid's current frontiers (`mask`, from [`frontier_mask`]).
    pub fn update(&mut self, grid: &LocalGrid, mask: &[bool]) {
        let geometry = grid.geometry();
        let low = geometry.origin;
        let high = low + Vector3::from(grid.dims().map(|d| d as f64)) * grid.resolution_m();
        let inside = |p: &Point3<f64>| (0..3).all(|i| p[i] >= low[i] && p[i] < high[i]);
        self.points.retain(|_, p| !inside(p));
        let mut sums: BTreeMap<[i64; 3], (Vector3<f64>, usize)> = BTreeMap::new();
        for (i, _) in mask.iter().enumerate().filter(|(_, f)| **f) {
            let centre = geometry.cell_centre(grid.cell_at(i));
            let entry = sums
                .entry(self.key(&centre))
                .or_insert((Vector3::zeros(), 0));
            entry.0 += centre.coords;
            entry.1 += 1;
        }
        for (key, (sum, n)) in sums {
            if n >= self.config.min_cells {
                self.points.insert(key, Point3::from(sum / n as f64));
            }
        }
    }

    /// Remembered frontiers outside `grid`'s window.
    #[must_use]
    pub fn outside(&self, grid: &LocalGrid) -> Vec<Point3<f64>> {
        self.points
            .values()
            .filter(|p| grid.cell_of(p).is_none())
            .copied()
            .collect()
    }

    /// How many frontier points are remembered (inside the window and out).
    #[must_use]
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether nothing is remembered.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
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
    use super::*;
    use crate::grid::LogOddsParams;
    use crate::msgs::GridSnapshot;
    use crate::runtime::Time;

    /// A 10 m × 10 m × 4 m window at 0.5 m centred on `centre`, every cell free but
    /// those within `unknown_m` of `hole` (left unknown).
    fn grid(centre: Point3<f64>, hole: Option<(Point3<f64>, f64)>) -> LocalGrid {
        let mut g = LocalGrid::centred(
            &centre,
            &Vector3::new(10.0, 10.0, 4.0),
            0.5,
            LogOddsParams::default(),
        );
        let geometry = g.geometry();
        for i in 0..g.values().len() {
            let c = geometry.cell_centre(g.cell_at(i));
            if hole.is_none_or(|(h, r)| (c - h).norm() > r) {
                g.update(i, -1.0);
            }
        }
        g
    }

    fn snapshot(grid: LocalGrid, memory: &mut FrontierMemory) -> GridSnapshot {
        let mask = frontier_mask(&grid);
        memory.update(&grid, &mask);
        GridSnapshot {
            stamp: Time::ZERO,
            unsafe_distance_m: vec![0.0; grid.values().len()],
            frontier_distance_m: frontier_distance_of(&mask, &grid),
            remembered_frontiers_m: memory.outside(&grid),
            grid,
        }
    }

    #[test]
    fn frontiers_left_behind_are_remembered_steered_by_and_forgotten_once_seen() {
        let config = FrontierMemoryConfig {
            enabled: true,
            ..FrontierMemoryConfig::default()
        };
        let mut memory = FrontierMemory::new(config);
        let hole = Point3::new(3.0, 3.0, 0.0);
        // A window with an unknown pocket: its rim is a frontier, known in the window.
        let first = snapshot(grid(Point3::origin(), Some((hole, 1.2))), &mut memory);
        assert!(!memory.is_empty());
        assert!(
            first.remembered_frontiers_m.is_empty(),
            "all inside the window"
        );
        let near_hole = first.frontier_distance(&Point3::new(1.0, 1.0, 0.0));
        assert!(near_hole.is_finite() && near_hole < 2.5, "{near_hole}");
        // 30 m on, no frontier in the window: the pocket's rim is remembered and the
        // distance to it is the straight line.
        let away = Point3::new(30.0, 0.0, 0.0);
        let second = snapshot(grid(away, None), &mut memory);
        assert!(!second.remembered_frontiers_m.is_empty());
        for f in &second.remembered_frontiers_m {
            assert!((f - hole).norm() < 2.0, "{f} is not at the pocket");
        }
        let d = second.frontier_distance(&away);
        let nearest = second
            .remembered_frontiers_m
            .iter()
            .map(|f| (f - away).norm())
            .fold(f64::INFINITY, f64::min);
        assert_eq!(d, nearest);
        assert!(second.frontier_distance(&(away - Vector3::new(1.0, 0.0, 0.0))) < d);
        // Back over the pocket, now observed: forgotten.
        let third = snapshot(grid(Point3::origin(), None), &mut memory);
        assert!(memory.is_empty());
        assert!(third.frontier_distance(&Point3::origin()).is_infinite());
    }

    #[test]
    fn specks_are_not_remembered_and_memory_is_off_by_default() {
        assert!(!FrontierMemoryConfig::default().enabled);
        let mut memory = FrontierMemory::new(FrontierMemoryConfig {
            min_cells: 1000,
            ..FrontierMemoryConfig::default()
        });
        let g = grid(Point3::origin(), Some((Point3::new(3.0, 3.0, 0.0), 1.2)));
        memory.update(&g, &frontier_mask(&g));
        assert!(memory.is_empty());
        assert!(
            FrontierMemoryConfig {
                cell_m: 0.0,
                ..FrontierMemoryConfig::default()
            }
            .validate()
            .is_err()
        );
    }
}
