//! What the occupancy-grid baseline would send for a robot's own depth frames at any
//! resolution, without flying it: the thesis post-processes "the depth images collected
//! from the GMM reconstruction trial" with the OG approach at 0.1, 0.05 and 0.025 m
//! (§8.2.6, Table 8.1), so that the map-sharing methods are compared on the same views.
//!
//! [`ChangeSetMeter`] keeps a sparse log-odds map of one robot's observations on the
//! world lattice of its resolution, inserts every frame the way the grid actor does
//! under [`UpdateRule::PerScan`](super::UpdateRule::PerScan) (the frame's returns as one
//! scan, its no-return pixels as a second, [`frame_scans`]), and counts the cells whose
//! value the frame changed: the change set the grid actor's `OwnChanges`
//! (`troupe_actors::grid::changeset`) would send, costed as the thesis does at 8N + 24 bytes per set (§8.2.5). Its map has
//! no window, so it never forgets a cell (the grid actor's sets leave out cells outside
//! its window); at the grid's own resolution and a window that holds the frames, the
//! two count the same cells (tested).

use std::collections::HashMap;
use std::hash::BuildHasherDefault;

use nalgebra::Point3;
use serde::Serialize;

use super::{LocalGrid, LogOddsParams, frame_scans};
use crate::hash::CellHasher;

/// Most changes in one set; larger sets are split (the wire's message limit is
/// 4 MiB, 8 bytes per change).
pub const MAX_CHANGES_PER_SET: usize = 200_000;
use crate::frame::DepthFrame;

/// Bytes of one change set's metadata: grid dimensions (3 × u32) and origin (3 × f32),
/// §8.2.5.
pub const CHANGE_SET_HEADER_BYTES: u64 = 24;
/// Bytes per changed cell: a u32 index and an f32 log-odds, §8.2.5.
pub const CHANGE_SET_CELL_BYTES: u64 = 8;

/// Totals of a [`ChangeSetMeter`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ChangeSetTotals {
    /// Cell edge, metres.
    pub resolution_m: f64,
    /// Frames observed.
    pub frames: u64,
    /// Change sets the frames would make (frames that changed nothing make none; a
    /// set holds at most [`MAX_CHANGES_PER_SET`] cells).
    pub sets: u64,
    /// Cells changed, summed over frames.
    pub changed_cells: u64,
    /// `8 N + 24` per set, summed.
    pub bytes: u64,
    /// Cells ever observed (the size of the robot's OG map).
    pub mapped_cells: u64,
}

/// The OG change sets of one robot's own frames at one resolution (module docs).
#[derive(Clone, Debug)]
pub struct ChangeSetMeter {
    params: LogOddsParams,
    stride: u32,
    /// Walks rays over the world lattice ([`LocalGrid::lattice_corner`]).
    lattice: LocalGrid,
    totals: ChangeSetTotals,
    /// Log-odds per lattice cell ever observed ([`pack`]).
    cells: CellMap<f32>,
    /// This scan's cells: whether a ray ended in it with a hit.
    scan: CellMap<bool>,
    /// This frame's cells and their value before it.
    before: CellMap<f32>,
}

impl ChangeSetMeter {
    /// A meter with cells of `resolution_m` (> 0), the grid's log-odds rules and
    /// pixel stride (every `stride`-th pixel in u and v becomes a ray).
    #[must_use]
    pub fn new(resolution_m: f64, params: LogOddsParams, stride: u32) -> Self {
        ChangeSetMeter {
            params,
            stride,
            lattice: LocalGrid::lattice_corner(resolution_m, params),
            totals: ChangeSetTotals {
                resolution_m,
                ..ChangeSetTotals::default()
            },
            cells: CellMap::default(),
            scan: CellMap::default(),
            before: CellMap::default(),
        }
    }

    /// Inserts one frame and returns the number of cells it changed.
    pub fn observe(&mut self, frame: &DepthFrame) -> usize {
        let resolution_m = self.totals.resolution_m;
        let scans = frame_scans(frame, self.stride, 2.0 * resolution_m);
        self.before.clear();
        self.insert_scan(&scans.origin, &scans.hits, true);
        self.insert_scan(&scans.origin, &scans.misses, false);
        let changed = self
            .before
            .iter()
            .filter(|(cell, before)| self.cells.get(cell) != Some(before))
            .count();
        let sets = changed.div_ceil(MAX_CHANGES_PER_SET) as u64;
        self.totals.frames += 1;
        self.totals.sets += sets;
        self.totals.changed_cells += changed as u64;
        self.totals.bytes +=
            CHANGE_SET_CELL_BYTES * changed as u64 + CHANGE_SET_HEADER_BYTES * sets;
        self.totals.mapped_cells = self.cells.len() as u64;
        changed
    }

    /// What the frames so far add up to.
    #[must_use]
    pub fn totals(&self) -> ChangeSetTotals {
        self.totals
    }

    /// The log-odds of the cell at lattice coordinates `cell` (0 if never observed).
    #[must_use]
    pub fn value(&self, cell: [usize; 3]) -> f32 {
        self.cells.get(&pack(cell)).copied().unwrap_or(0.0)
    }

    /// One scan with the per-scan rule of [`ScanScratch::insert_scan`](super::ScanScratch::insert_scan):
    /// each cell a ray crosses gets one miss, each cell a ray ends in one hit if `hit`
    /// (a hit wins over misses), else one miss.
    fn insert_scan(&mut self, origin: &Point3<f64>, ends: &[Point3<f64>], hit: bool) {
        self.scan.clear();
        for end in ends {
            let Some(walk) = self.lattice.walk(origin, end) else {
                continue;
            };
            for step in walk {
                *self.scan.entry(pack(step.cell)).or_insert(false) |= hit && step.is_end;
            }
        }
        let p = self.params;
        for (&cell, &is_hit) in &self.scan {
            let value = self.cells.entry(cell).or_insert(0.0);
            self.before.entry(cell).or_insert(*value);
            let delta = if is_hit { p.hit } else { p.miss };
            *value = (*value + delta).clamp(p.min, p.max);
        }
    }
}

/// A lattice cell as one key: 21 bits per axis (the lattice spans `2^21` cells).
fn pack(cell: [usize; 3]) -> u64 {
    let [x, y, z] = cell.map(|c| c as u64 & 0x1f_ffff);
    x | y << 21 | z << 42
}

/// Maps keyed by [`pack`]ed cells.
type CellMap<V> = HashMap<u64, V, BuildHasherDefault<CellHasher>>;

#[cfg(test)]
mod tests {
    use super::pack;

    #[test]
    fn packed_cells_are_distinct() {
        let cells = [
            [0, 0, 0],
            [1, 0, 0],
            [0, 1, 0],
            [0, 0, 1],
            [(1 << 21) - 1, 5, 7],
        ];
        let keys: std::collections::BTreeSet<u64> = cells.iter().map(|c| pack(*c)).collect();
        assert_eq!(keys.len(), cells.len());
    }
}
