//! Ground-truth coverage: how much of a world's free space the cameras have seen.
//!
//! [`CoverageGrid`] splits [`World::bounds`] into cubic cells. A cell is *free* when the
//! world's signed distance at its centre is positive; the free cells are the denominator.
//! Each observed pixel ray marks as *explored* every free cell it crosses in front of the
//! first surface (see [`CoverageGrid::observe`]). Results depend only on the inputs, never
//! on thread scheduling.

pub use troupe_algorithms::geometry::VoxelGrid;

use nalgebra::Point3;
use rayon::prelude::*;
use troupe_algorithms::frame::{DepthFrame, check_buffers};

use crate::world::World;

const ROCK: u8 = 0;
const FREE: u8 = 1;
const EXPLORED: u8 = 2;

/// Free and explored cells of a world; see the module documentation.
#[derive(Debug, Clone, PartialEq)]
pub struct CoverageGrid {
    grid: VoxelGrid,
    /// One of `ROCK`, `FREE`, `EXPLORED` per cell.
    state: Vec<u8>,
    free_cells: usize,
    explored_cells: usize,
}

impl CoverageGrid {
    /// Classify every cell of `world.bounds()` with cells of `cell_m` metres (`cell_m` must
    /// be positive). Costs one `sdf_m` per cell, spread over rayon's threads.
    #[must_use]
    pub fn new(world: &dyn World, cell_m: f64) -> Self {
        let grid = VoxelGrid::covering(&world.bounds(), cell_m);
        let mut state = vec![ROCK; grid.cell_count()];
        let slice = grid.dims[0] * grid.dims[1];
        state
            .par_chunks_mut(slice)
            .enumerate()
            .for_each(|(z, cells)| {
                for (i, s) in cells.iter_mut().enumerate() {
                    let c = [i % grid.dims[0], i / grid.dims[0], z];
                    if world.sdf_m(&grid.cell_centre(c)) > 0.0 {
                        *s = FREE;
                    }
                }
            });
        let free_cells = state.iter().filter(|s| **s == FREE).count();
        Self {
            grid,
            state,
            free_cells,
            explored_cells: 0,
        }
    }

    /// The cell geometry.
    #[must_use]
    pub fn grid(&self) -> &VoxelGrid {
        &self.grid
    }

    /// Mark what one frame saw from its pose (body to world, the camera at its origin).
    ///
    /// Every `pixel_stride`-th pixel in both directions (from pixel `(0, 0)`; a stride of 0
    /// counts as 1) casts a ray from the camera. For a pixel with a return at z-depth `d`
    /// the ray runs to the point at z-depth `d`, and every free cell it crosses is marked
    /// except the cell holding that end point (it holds the surface). For a pixel without a
    /// return the ray runs to z-depth `intrinsics.max_depth_m` and every free cell it
    /// crosses is marked, the last one included. Every ray stops at the first rock cell
    /// (a cell whose centre is inside the rock): coverage is ground truth, so a dropout
    /// or a noisy depth past the wall never counts space behind it. Parts of rays outside
    /// the grid are ignored. A frame whose buffers do not fit its intrinsics is ignored.
    pub fn observe(&mut self, frame: &DepthFrame, pixel_stride: usize) {
        self.observe_visiting(frame, pixel_stride, |_| {});
    }

    /// Like [`observe`](Self::observe), and calls `visit` with the linear index
    /// ([`VoxelGrid::linear_index`]) of every free cell a ray marks or crosses again —
    /// explored before or not, once per ray that crosses it, rays in pixel order — for
    /// accounts of who saw what ([`crate::reexploration`]).
    pub fn observe_visiting(
        &mut self,
        frame: &DepthFrame,
        pixel_stride: usize,
        mut visit: impl FnMut(usize),
    ) {
        let k = &frame.intrinsics;
        if check_buffers(k, &frame.depth_m, &frame.intensity).is_err() {
            return;
        }
        let stride = pixel_stride.max(1);
        let origin = Point3::from(frame.pose.translation.vector);
        let width = k.width as usize;
        for row in (0..k.height).step_by(stride) {
            for col in (0..k.width).step_by(stride) {
                // With a unit-depth direction the ray parameter is the z-depth.
                let dir = frame.pose.rotation * k.pixel_ray(col, row);
                let depth = f64::from(frame.depth_m[row as usize * width + col as usize]);
                let (end, hit) = if depth > 0.0 {
                    (depth, true)
                } else {
                    (k.max_depth_m, false)
                };
                let grid = self.grid;
                grid.traverse(&origin, &dir, end, |c, _t_enter, t_exit| {
                    if hit && t_exit >= end {
                        return false;
                    }
                    let index = grid.linear_index(c);
                    let s = &mut self.state[index];
                    if *s == FREE {
                        *s = EXPLORED;
                        self.explored_cells += 1;
                    }
                    if *s == ROCK {
                        return false;
                    }
                    visit(index);
                    true
                });
            }
        }
    }

    /// Explored fraction of the free cells, in `[0, 1]` (0 when nothing is free).
    #[must_use]
    pub fn coverage(&self) -> f64 {
        if self.free_cells == 0 {
            0.0
        } else {
            self.explored_cells as f64 / self.free_cells as f64
        }
    }

    /// Number of free cells.
    #[must_use]
    pub fn free_cells(&self) -> usize {
        self.free_cells
    }

    /// Number of explored (free) cells.
    #[must_use]
    pub fn explored_cells(&self) -> usize {
        self.explored_cells
    }

    /// Whether cell `c` is free space.
    #[must_use]
    pub fn is_free(&self, c: [usize; 3]) -> bool {
        self.state[self.grid.linear_index(c)] != ROCK
    }

    /// Whether cell `c` has been explored.
    #[must_use]
    pub fn is_explored(&self, c: [usize; 3]) -> bool {
        self.state[self.grid.linear_index(c)] == EXPLORED
    }

    /// Volume of one cell, cubic metres.
    #[must_use]
    pub fn cell_volume_m3(&self) -> f64 {
        self.grid.cell_m.powi(3)
    }

    /// Free volume in cubic metres.
    #[must_use]
    pub fn free_volume_m3(&self) -> f64 {
        self.free_cells as f64 * self.grid.cell_m.powi(3)
    }

    /// Explored volume in cubic metres.
    #[must_use]
    pub fn explored_volume_m3(&self) -> f64 {
        self.explored_cells as f64 * self.grid.cell_m.powi(3)
    }
}

#[cfg(test)]
mod tests;
