//! Uniform voxel grids and ray traversal through them (Amanatides & Woo, 1987).

use nalgebra::{Point3, Vector3};

use super::Aabb;

/// Geometry of a uniform grid of cubic cells: cell `[i, j, k]` spans
/// `origin + [i, j, k] * cell_m` to `origin + [i + 1, j + 1, k + 1] * cell_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoxelGrid {
    /// Lowest corner of cell `[0, 0, 0]`.
    pub origin: Point3<f64>,
    /// Cell edge length in metres.
    pub cell_m: f64,
    /// Number of cells along x, y, z (each at least 1).
    pub dims: [usize; 3],
}

impl VoxelGrid {
    /// The grid of `cell_m` cells starting at `bounds.min` and covering `bounds`.
    #[must_use]
    pub fn covering(bounds: &Aabb, cell_m: f64) -> Self {
        let size = bounds.size();
        let dims = [0, 1, 2].map(|i| ((size[i] / cell_m).ceil() as usize).max(1));
        Self {
            origin: bounds.min,
            cell_m,
            dims,
        }
    }

    /// Total number of cells.
    #[must_use]
    pub fn cell_count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// The box the cells cover.
    #[must_use]
    pub fn aabb(&self) -> Aabb {
        let size = Vector3::new(
            self.dims[0] as f64,
            self.dims[1] as f64,
            self.dims[2] as f64,
        );
        Aabb {
            min: self.origin,
            max: self.origin + size * self.cell_m,
        }
    }

    /// The cell holding `p`, if `p` lies in the grid (cells are half-open intervals).
    #[must_use]
    pub fn cell_of(&self, p: &Point3<f64>) -> Option<[usize; 3]> {
        let mut c = [0usize; 3];
        for (i, ci) in c.iter_mut().enumerate() {
            let f = ((p[i] - self.origin[i]) / self.cell_m).floor();
            if !(f >= 0.0 && f < self.dims[i] as f64) {
                return None;
            }
            *ci = f as usize;
        }
        Some(c)
    }

    /// Row-major linear index (x fastest) of a cell.
    #[must_use]
    pub fn linear_index(&self, c: [usize; 3]) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    /// Centre of a cell.
    #[must_use]
    pub fn cell_centre(&self, c: [usize; 3]) -> Point3<f64> {
        self.origin
            + Vector3::new(c[0] as f64 + 0.5, c[1] as f64 + 0.5, c[2] as f64 + 0.5) * self.cell_m
    }

    /// Visit, in order, every cell that the segment `origin + t * dir`, `t ∈ [0, t_end]`,
    /// crosses for a positive length, with the parameter interval `(t_enter, t_exit)` it
    /// spends there; `visit` returns `false` to stop early. Parts outside the grid are
    /// skipped; `dir` need not be a unit vector.
    pub fn traverse(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        t_end: f64,
        mut visit: impl FnMut([usize; 3], f64, f64) -> bool,
    ) {
        if t_end.is_nan() || t_end <= 0.0 || dir.norm_squared() == 0.0 {
            return;
        }
        let Some((t0, t1)) = self.aabb().clip_ray(origin, dir, 0.0, t_end) else {
            return;
        };
        if t1 <= t0 {
            return;
        }
        // The entry cell; an entry point on a cell face belongs to the cell the segment
        // goes on into.
        let entry = origin + dir * t0;
        let mut cell = [0usize; 3];
        let mut step = [0isize; 3];
        let mut t_next = [f64::INFINITY; 3];
        let mut t_delta = [f64::INFINITY; 3];
        for i in 0..3 {
            let rel = (entry[i] - self.origin[i]) / self.cell_m;
            let mut c = rel.floor();
            // On a face while moving down: the crossed cell is the lower one.
            if dir[i] < 0.0 && c == rel {
                c -= 1.0;
            }
            let c = c.clamp(0.0, (self.dims[i] - 1) as f64) as usize;
            cell[i] = c;
            if dir[i] > 0.0 {
                step[i] = 1;
                let face = self.origin[i] + (c + 1) as f64 * self.cell_m;
                t_next[i] = (face - origin[i]) / dir[i];
                t_delta[i] = self.cell_m / dir[i];
            } else if dir[i] < 0.0 {
                step[i] = -1;
                let face = self.origin[i] + c as f64 * self.cell_m;
                t_next[i] = (face - origin[i]) / dir[i];
                t_delta[i] = -self.cell_m / dir[i];
            }
        }
        let mut t = t0;
        loop {
            let axis = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
                0
            } else if t_next[1] <= t_next[2] {
                1
            } else {
                2
            };
            let exit = t_next[axis].min(t1);
            if exit > t && !visit(cell, t, exit) {
                return;
            }
            if t_next[axis] >= t1 {
                return;
            }
            t = exit;
            let moved = cell[axis] as isize + step[axis];
            if moved < 0 || moved >= self.dims[axis] as isize {
                return;
            }
            cell[axis] = moved as usize;
            t_next[axis] += t_delta[axis];
        }
    }
}
