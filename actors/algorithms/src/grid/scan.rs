//! Inserting a whole scan at once, as OctoMap's `insertPointCloud` does: collect the
//! cells the scan's rays end in and the cells they cross, then update each cell once —
//! a hit if any ray ends in it (occupied takes precedence), otherwise a miss.
//!
//! Per scan, the result does not depend on the order of the rays, so the rays are
//! walked in parallel (rayon) and the grid is still the same for any thread count.
//! This changes the semantics of [`LocalGrid::insert_ray`] (one update per ray and
//! cell), so it is a separate [`UpdateRule`]: a cell crossed by many rays of one frame
//! gets one miss, not many, and a cell that holds a surface point stays occupied
//! even when other rays of the frame pass through it — which keeps thin walls and the
//! edges of narrow openings from being carved away at coarse resolutions (§5.1).

use std::sync::atomic::{AtomicU8, Ordering};

use nalgebra::Point3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::endvoxel::EndVoxelScratch;
use super::{CellBox, LocalGrid};

/// How the rays of one scan (a depth frame, or the samples of one keyframe) update the
/// grid.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UpdateRule {
    /// Every ray updates every cell it crosses ([`LocalGrid::insert_ray`]).
    #[default]
    PerRay,
    /// Every cell the scan touches is updated once, hits first (OctoMap's
    /// `insertPointCloud`); see [`ScanScratch::insert_scan`].
    PerScan,
    /// As [`UpdateRule::PerScan`], but one ray per distinct end voxel, traced to the
    /// voxel's centre (OctoMap's `discretize`); see [`EndVoxelScratch::insert_scan`].
    PerEndVoxel,
}

/// Rays per rayon task.
const CHUNK_RAYS: usize = 1024;

/// Edge of the bricks the marks are stored in, cells (`4³` bytes = one cache line):
/// a ray's consecutive cells mostly share a brick, where a row-major layout would
/// jump a whole slab on every z step.
const BRICK: usize = 4;

/// Reusable marks for [`ScanScratch::insert_scan`]: one byte per grid cell, in
/// `4 × 4 × 4` bricks.
#[derive(Default)]
pub struct ScanScratch {
    marks: Vec<AtomicU8>,
    /// Bricks along x and y.
    bricks: [usize; 2],
    dims: [usize; 3],
    /// Scan counter: cells marked `2g` this scan are crossed, `2g + 1` hit; the marks
    /// are cleared when it wraps.
    generation: u8,
    /// The scratch of [`UpdateRule::PerEndVoxel`].
    end_voxels: EndVoxelScratch,
}

impl Clone for ScanScratch {
    /// A fresh scratch (marks carry no state between scans).
    fn clone(&self) -> Self {
        ScanScratch::default()
    }
}

impl std::fmt::Debug for ScanScratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScanScratch")
            .field("cells", &self.marks.len())
            .finish_non_exhaustive()
    }
}

/// The cells one chunk of rays touched first: `(crossed, hit)` as (linear index,
/// mark index) pairs.
type Touched = (Vec<(u32, u32)>, Vec<u32>);

/// Position of a cell's mark in the bricked layout.
#[inline]
fn brick_index(c: [usize; 3], bricks: [usize; 2]) -> usize {
    let brick = (c[2] / BRICK * bricks[1] + c[1] / BRICK) * bricks[0] + c[0] / BRICK;
    brick * BRICK * BRICK * BRICK + ((c[2] % BRICK) * BRICK + c[1] % BRICK) * BRICK + c[0] % BRICK
}

impl ScanScratch {
    /// Inserts one scan (rays from `origin` to each of `ends`, surface points if
    /// `hit`) by `rule`, only into `boxes` if given: [`LocalGrid::insert_ray`] for
    /// each point, [`ScanScratch::insert_scan`] or [`EndVoxelScratch::insert_scan`].
    pub fn insert_by(
        &mut self,
        rule: UpdateRule,
        grid: &mut LocalGrid,
        origin: &Point3<f64>,
        ends: &[Point3<f64>],
        hit: bool,
        boxes: Option<&[CellBox]>,
    ) {
        match rule {
            UpdateRule::PerRay => {
                for end in ends {
                    match boxes {
                        None => grid.insert_ray(origin, end, hit, None),
                        Some(b) => grid.insert_ray_boxes(origin, end, hit, b),
                    }
                }
            }
            UpdateRule::PerScan => self.insert_scan(grid, origin, ends, hit, boxes),
            UpdateRule::PerEndVoxel => {
                self.end_voxels.insert_scan(grid, origin, ends, hit, boxes);
            }
        }
    }

    /// Inserts one scan: rays from `origin` to each of `ends`. Every cell in which a
    /// ray ends gets one hit if `hit` (surface points); every other cell a ray crosses
    /// (and, if not `hit`, the end cells too) gets one miss. Only cells inside one of
    /// `boxes` change (all cells if `None`). Points that are not finite are skipped.
    /// The result is independent of the order of `ends` and of the thread count.
    pub fn insert_scan(
        &mut self,
        grid: &mut LocalGrid,
        origin: &Point3<f64>,
        ends: &[Point3<f64>],
        hit: bool,
        boxes: Option<&[CellBox]>,
    ) {
        let dims = grid.dims();
        if self.dims != dims || self.generation >= u8::MAX / 2 - 1 {
            let bricks = dims.map(|d| d.div_ceil(BRICK));
            let n = bricks.iter().product::<usize>() * BRICK * BRICK * BRICK;
            if self.marks.len() == n {
                self.marks
                    .iter()
                    .for_each(|m| m.store(0, Ordering::Relaxed));
            } else {
                self.marks = (0..n).map(|_| AtomicU8::new(0)).collect();
            }
            self.bricks = [bricks[0], bricks[1]];
            self.dims = dims;
            self.generation = 0;
        }
        self.generation += 1;
        let crossed = 2 * self.generation;
        let ended = if hit { crossed + 1 } else { crossed };
        let (marks, bricks) = (&self.marks, self.bricks);
        let shared: &LocalGrid = grid;
        // On one thread the marks are read and written plainly (no atomic
        // read-modify-write); in parallel, `fetch_max` decides which thread saw a cell
        // first.
        let exclusive = ends.len() <= CHUNK_RAYS || rayon::current_num_threads() == 1;
        let walk_chunk = |chunk: &[Point3<f64>]| -> Touched {
            let (mut cross, mut hits) = (Vec::new(), Vec::new());
            for end in chunk {
                let Some(walk) = shared.walk(origin, end) else {
                    continue;
                };
                walk.for_each_inside(|i, c, is_end| {
                    let mark = if is_end { ended } else { crossed };
                    let b = brick_index(c, bricks);
                    // Most visits repeat a cell already marked this scan: a plain load
                    // settles them without a read-modify-write.
                    let seen = marks[b].load(Ordering::Relaxed);
                    if seen >= mark {
                        return;
                    }
                    let before = if exclusive {
                        marks[b].store(mark, Ordering::Relaxed);
                        seen
                    } else {
                        marks[b].fetch_max(mark, Ordering::Relaxed)
                    };
                    if before < crossed {
                        cross.push((i as u32, b as u32));
                    }
                    if mark > crossed && before < mark {
                        hits.push(i as u32);
                    }
                });
            }
            (cross, hits)
        };
        let touched: Vec<Touched> = if exclusive {
            vec![walk_chunk(ends)]
        } else {
            ends.par_chunks(CHUNK_RAYS).map(walk_chunk).collect()
        };
        let params = *grid.params();
        let inside = |i: usize| {
            boxes.is_none_or(|bs| {
                let c = [
                    i % dims[0],
                    (i / dims[0]) % dims[1],
                    i / (dims[0] * dims[1]),
                ];
                bs.iter().any(|b| b.contains(c))
            })
        };
        let cells = grid.values_mut();
        for (cross, hits) in &touched {
            for &i in hits {
                let i = i as usize;
                if inside(i) {
                    cells[i] = (cells[i] + params.hit).clamp(params.min, params.max);
                }
            }
            for &(i, b) in cross {
                let i = i as usize;
                if marks[b as usize].load(Ordering::Relaxed) == crossed && inside(i) {
                    cells[i] = (cells[i] + params.miss).clamp(params.min, params.max);
                }
            }
        }
    }
}
