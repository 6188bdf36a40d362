//! [`UpdateRule::PerEndVoxel`]: a whole scan inserted with one ray per end voxel
//! (OctoMap's `insertPointCloud(…, discretize = true)` idea, on top of the per-scan
//! rule of [`super::scan`]).
//!
//! The rule, for a scan of end points `ends` seen from `origin` (thesis §3.2.3,
//! paper IV-B):
//!
//! 1. The *end voxels* are the world-lattice cells that hold at least one finite end
//!    point (each point's cell as [`LocalGrid::walk`] computes it).
//! 2. For each end voxel, exactly one segment is traced with the grid's 3D DDA, from
//!    `origin` to the **centre** of that voxel (not to the points in it).
//! 3. Every end voxel inside the window gets one hit if `hit` (surface points), one
//!    miss otherwise (free-space points, no-return pixels).
//! 4. Every other window cell that one of those segments crosses gets one miss.
//!
//! Each cell changes at most once per scan, and hits win over misses as in
//! [`UpdateRule::PerScan`] — unlike [`UpdateRule::PerRay`], where a cell crossed by
//! `k` rays of the scan gets `k` misses and a hit cell can also get misses. The only
//! difference from `PerScan` is which cells are free (occupied cells are the same):
//! the segment to a voxel centre stays within half a cell per axis of the segments to
//! the voxel's points (closest near the origin, furthest at the end voxel), yet it can
//! clip other cells at the edges of the swept volume, mostly in the last cells before
//! the end voxel. The result does not depend on the order of the points, and a window
//! anywhere on the lattice gets the same cells for what it holds, because the traced
//! segments are fixed by the lattice.
//!
//! With a box filter (the novel boxes of a window move), a component the store skips
//! stays skippable: the segment to a voxel centre lies within half a cell per axis of
//! the segment to any point in the voxel, inside the two-cell margin of
//! [`super::ComponentStore::rebuild`]'s ray–box test.
//!
//! Cost: binning the points is one pass; the walks are as many as the distinct end
//! voxels (far fewer than the pixels of a 160×120 frame at 0.2 m); the update visits
//! only the touched cells. One thread, no atomics, no allocation once the scratch has
//! grown.

use nalgebra::{Point3, Vector3};

#[cfg(doc)]
use super::UpdateRule;
use super::{CellBox, LocalGrid};

/// Mark of a cell a segment crossed this scan.
const CROSSED: u8 = 1;
/// Mark of an end voxel this scan (wins over [`CROSSED`]).
const ENDED: u8 = 2;

/// Reusable state for [`EndVoxelScratch::insert_scan`]: one mark byte per grid cell,
/// all zero between scans, and the lists of cells the current scan touched.
#[derive(Default)]
pub struct EndVoxelScratch {
    /// Per cell (row-major, as the grid): 0, [`CROSSED`] or [`ENDED`].
    marks: Vec<u8>,
    /// Distinct end voxels inside the window, as linear indices.
    ends_inside: Vec<u32>,
    /// End voxels outside the window, as lattice cells (with repeats until deduped).
    ends_outside: Vec<[u32; 3]>,
    /// Cells crossed and not end voxels, as linear indices, each once.
    crossed: Vec<u32>,
}

impl Clone for EndVoxelScratch {
    /// A fresh scratch (marks carry no state between scans).
    fn clone(&self) -> Self {
        EndVoxelScratch::default()
    }
}

impl std::fmt::Debug for EndVoxelScratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EndVoxelScratch")
            .field("cells", &self.marks.len())
            .finish_non_exhaustive()
    }
}

impl EndVoxelScratch {
    /// Inserts one scan by the [`UpdateRule::PerEndVoxel`] rule (see the module
    /// docs): one hit (or, if not `hit`, one miss) for each end voxel, one miss for
    /// each other cell crossed by a segment from `origin` to an end voxel's centre.
    /// Only cells inside one of `boxes` change (all cells if `None`). Points that are
    /// not finite or lie off the lattice are skipped; a bad `origin` skips the scan.
    /// Returns the number of segments traced (distinct end voxels).
    pub fn insert_scan(
        &mut self,
        grid: &mut LocalGrid,
        origin: &Point3<f64>,
        ends: &[Point3<f64>],
        hit: bool,
        boxes: Option<&[CellBox]>,
    ) -> usize {
        let Some(g0) = grid.lattice_coords(origin) else {
            return 0;
        };
        let n_cells = grid.values().len();
        if self.marks.len() != n_cells {
            self.marks = vec![0; n_cells];
        }
        let dims = grid.dims();
        let corner = grid.corner();
        let stride = [1, dims[0], dims[0] * dims[1]];
        // 1. Bin the points by end voxel.
        for end in ends {
            let Some(g) = grid.lattice_coords(end) else {
                continue;
            };
            // `g` lies in [0, 2²¹) (the lattice check above), where truncation is
            // `floor` without the libm call.
            let cell = [0, 1, 2].map(|a| g[a] as usize);
            let local = [0, 1, 2].map(|a| cell[a].wrapping_sub(corner[a]));
            if (0..3).all(|a| local[a] < dims[a]) {
                let i = local[0] + stride[1] * local[1] + stride[2] * local[2];
                if self.marks[i] == 0 {
                    self.marks[i] = ENDED;
                    self.ends_inside.push(i as u32);
                }
            } else {
                self.ends_outside.push(cell.map(|v| v as u32));
            }
        }
        self.ends_outside.sort_unstable();
        self.ends_outside.dedup();
        // 2. One segment per end voxel, to its centre.
        let inside_centres = self.ends_inside.iter().map(|&i| {
            let i = i as usize;
            let local = [i % dims[0], (i / dims[0]) % dims[1], i / stride[2]];
            Vector3::from([0, 1, 2].map(|a| (corner[a] + local[a]) as f64 + 0.5))
        });
        let outside_centres = self
            .ends_outside
            .iter()
            .map(|cell| Vector3::from(cell.map(|v| f64::from(v) + 0.5)));
        let (marks, crossed) = (&mut self.marks, &mut self.crossed);
        for centre in inside_centres.chain(outside_centres) {
            // The visit is written out here (not a shared `&mut` closure) so that it
            // inlines into the walk.
            grid.walk_lattice(&g0, &centre)
                .for_each_inside(|i, _, is_end| {
                    if !is_end && marks[i] == 0 {
                        marks[i] = CROSSED;
                        crossed.push(i as u32);
                    }
                });
        }
        let traced = self.ends_inside.len() + self.ends_outside.len();
        // 3. Each touched cell once, then the marks back to zero.
        let params = *grid.params();
        let inside = |i: usize| {
            boxes.is_none_or(|bs| {
                let c = [i % dims[0], (i / dims[0]) % dims[1], i / stride[2]];
                bs.iter().any(|b| b.contains(c))
            })
        };
        let end_delta = if hit { params.hit } else { params.miss };
        let cells = grid.values_mut();
        for &i in &self.ends_inside {
            let i = i as usize;
            if inside(i) {
                cells[i] = (cells[i] + end_delta).clamp(params.min, params.max);
            }
            self.marks[i] = 0;
        }
        for &i in &self.crossed {
            let i = i as usize;
            if inside(i) {
                cells[i] = (cells[i] + params.miss).clamp(params.min, params.max);
            }
            self.marks[i] = 0;
        }
        self.ends_inside.clear();
        self.ends_outside.clear();
        self.crossed.clear();
        traced
    }
}
