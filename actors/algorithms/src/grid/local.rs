//! Log-odds cells around the robot.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use troupe_core::ConfigError;

use crate::geometry::{Aabb, VoxelGrid};

/// Log-odds update and classification rules (the standard inverse sensor model,
/// paper IV-B; defaults follow OctoMap's: hit p = 0.7, miss p = 0.4, clamped to
/// p ∈ [0.12, 0.97]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LogOddsParams {
    /// Added to the cell that holds a ray's end point.
    pub hit: f32,
    /// Added to every other cell a ray crosses (≤ 0).
    pub miss: f32,
    /// Lower clamp.
    pub min: f32,
    /// Upper clamp.
    pub max: f32,
    /// A cell above this log-odds is occupied.
    pub occupied_above: f32,
    /// A cell below this log-odds is free; in between it is unknown (never-seen cells
    /// sit at 0, the prior p = 0.5).
    pub free_below: f32,
}

impl Default for LogOddsParams {
    fn default() -> Self {
        LogOddsParams {
            hit: 0.847_297_9,   // ln(0.7 / 0.3)
            miss: -0.405_465_1, // ln(0.4 / 0.6)
            min: -1.992_430_1,  // ln(0.12 / 0.88)
            max: 3.476_099_6,   // ln(0.97 / 0.03)
            occupied_above: 0.0,
            free_below: 0.0,
        }
    }
}

impl LogOddsParams {
    /// Checks the rules; the error names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (key, value) in [
            ("hit", self.hit),
            ("miss", self.miss),
            ("min", self.min),
            ("max", self.max),
            ("occupied_above", self.occupied_above),
            ("free_below", self.free_below),
        ] {
            if !value.is_finite() {
                return Err(ConfigError::new(key, "must be finite", value));
            }
        }
        ConfigError::positive("hit", f64::from(self.hit))?;
        if self.miss >= 0.0 {
            return Err(ConfigError::new("miss", "must be < 0", self.miss));
        }
        if self.min >= 0.0 {
            return Err(ConfigError::new("min", "must be < 0", self.min));
        }
        if self.max <= 0.0 {
            return Err(ConfigError::new("max", "must be > 0", self.max));
        }
        if self.free_below > self.occupied_above {
            return Err(ConfigError::new(
                "free_below",
                format!("must not exceed occupied_above ({})", self.occupied_above),
                self.free_below,
            ));
        }
        Ok(())
    }
}

/// What a cell is, for planning.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellState {
    /// Never seen, or as likely free as occupied.
    Unknown,
    /// Seen free.
    Free,
    /// Seen occupied.
    Occupied,
}

/// A box of cells in local indices: `min` inclusive, `max` exclusive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CellBox {
    /// First cell.
    pub min: [usize; 3],
    /// One past the last cell.
    pub max: [usize; 3],
}

impl CellBox {
    /// Whether the box holds the cell.
    #[must_use]
    pub fn contains(&self, c: [usize; 3]) -> bool {
        (0..3).all(|i| self.min[i] <= c[i] && c[i] < self.max[i])
    }

    /// Number of cells.
    #[must_use]
    pub fn cell_count(&self) -> usize {
        (0..3)
            .map(|i| self.max[i].saturating_sub(self.min[i]))
            .product()
    }
}

/// Half the extent of the world-fixed lattice, in cells: grids agree on cells as long
/// as they stay within ±2²⁰ cells of the world origin (±210 km at 0.2 m).
const LATTICE_HALF: usize = 1 << 20;

/// A robot-centred log-odds occupancy grid (thesis §3.2.3). Cells are aligned to a
/// world-fixed lattice of the grid's resolution.
#[derive(Clone, Debug, PartialEq)]
pub struct LocalGrid {
    params: LogOddsParams,
    lattice: VoxelGrid,
    /// Lattice index of local cell `[0, 0, 0]`.
    corner: [usize; 3],
    dims: [usize; 3],
    cells: Vec<f32>,
}

impl LocalGrid {
    /// An all-unknown grid of about `size_m` (rounded to whole cells) centred on
    /// `centre` (snapped to the lattice), with cells of `resolution_m`.
    #[must_use]
    pub fn centred(
        centre: &Point3<f64>,
        size_m: &Vector3<f64>,
        resolution_m: f64,
        params: LogOddsParams,
    ) -> Self {
        let lattice = VoxelGrid {
            origin: Point3::from(Vector3::repeat(-(LATTICE_HALF as f64) * resolution_m)),
            cell_m: resolution_m,
            dims: [2 * LATTICE_HALF; 3],
        };
        let dims = [0, 1, 2].map(|i| ((size_m[i] / resolution_m).round() as usize).max(1));
        let corner = Self::corner_for(&lattice, centre, dims);
        LocalGrid {
            params,
            lattice,
            corner,
            dims,
            cells: vec![0.0; dims[0] * dims[1] * dims[2]],
        }
    }

    fn corner_for(lattice: &VoxelGrid, centre: &Point3<f64>, dims: [usize; 3]) -> [usize; 3] {
        [0, 1, 2].map(|i| {
            let c = ((centre[i] - lattice.origin[i]) / lattice.cell_m).round() as i64
                - (dims[i] / 2) as i64;
            c.clamp(0, (2 * LATTICE_HALF - dims[i]) as i64) as usize
        })
    }

    /// The grid's cells as a [`VoxelGrid`] (local indices).
    #[must_use]
    pub fn geometry(&self) -> VoxelGrid {
        VoxelGrid {
            origin: self.lattice.origin
                + Vector3::from(self.corner.map(|c| c as f64)) * self.lattice.cell_m,
            cell_m: self.lattice.cell_m,
            dims: self.dims,
        }
    }

    /// Cells along x, y, z.
    #[must_use]
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Cell edge, metres.
    #[must_use]
    pub fn resolution_m(&self) -> f64 {
        self.lattice.cell_m
    }

    /// The update rules.
    #[must_use]
    pub fn params(&self) -> &LogOddsParams {
        &self.params
    }

    /// The world-fixed lattice coordinates of a local cell (the same for every grid
    /// of this resolution, wherever its window is).
    #[must_use]
    pub fn lattice_cell(&self, local: [usize; 3]) -> [usize; 3] {
        [0, 1, 2].map(|i| self.corner[i] + local[i])
    }

    /// The local cell at lattice coordinates `cell`, if the window holds it.
    #[must_use]
    pub fn local_of_lattice(&self, cell: [usize; 3]) -> Option<[usize; 3]> {
        let local = [0, 1, 2].map(|i| cell[i].checked_sub(self.corner[i]));
        let local = [local[0]?, local[1]?, local[2]?];
        (0..3).all(|i| local[i] < self.dims[i]).then_some(local)
    }

    /// Lattice coordinates of the cell holding the world point `p`.
    #[must_use]
    pub fn lattice_cell_of(&self, p: &Point3<f64>) -> Option<[usize; 3]> {
        self.lattice.cell_of(p)
    }

    /// The local cell of a row-major index (inverse of [`LocalGrid::index`]).
    #[must_use]
    pub fn cell_at(&self, index: usize) -> [usize; 3] {
        let (nx, ny) = (self.dims[0], self.dims[1]);
        [index % nx, (index / nx) % ny, index / (nx * ny)]
    }

    /// Row-major index (x fastest) of a local cell.
    #[must_use]
    pub fn index(&self, c: [usize; 3]) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    /// All log-odds values, row-major (x fastest).
    #[must_use]
    pub fn values(&self) -> &[f32] {
        &self.cells
    }

    /// Log-odds of a local cell.
    #[must_use]
    pub fn value(&self, c: [usize; 3]) -> f32 {
        self.cells[self.index(c)]
    }

    /// Occupancy probability of a local cell.
    #[must_use]
    pub fn probability(&self, c: [usize; 3]) -> f64 {
        1.0 / (1.0 + (-f64::from(self.value(c))).exp())
    }

    /// Classification of a log-odds value.
    #[must_use]
    pub fn classify(&self, value: f32) -> CellState {
        if value > self.params.occupied_above {
            CellState::Occupied
        } else if value < self.params.free_below {
            CellState::Free
        } else {
            CellState::Unknown
        }
    }

    /// Classification of a local cell.
    #[must_use]
    pub fn state(&self, c: [usize; 3]) -> CellState {
        self.classify(self.value(c))
    }

    /// The local cell holding a world point, if inside.
    #[must_use]
    pub fn cell_of(&self, p: &Point3<f64>) -> Option<[usize; 3]> {
        self.lattice.cell_of(p).and_then(|g| self.local(g))
    }

    fn local(&self, global: [usize; 3]) -> Option<[usize; 3]> {
        let mut c = [0; 3];
        for i in 0..3 {
            c[i] = global[i].checked_sub(self.corner[i])?;
            if c[i] >= self.dims[i] {
                return None;
            }
        }
        Some(c)
    }

    /// The cells a segment crosses, in order from `origin` to the cell holding `end`
    /// (which comes last, marked [`RayStep::is_end`]); `None` for non-finite input or
    /// points outside the lattice.
    ///
    /// The walk is an exact 3D DDA (Amanatides & Woo) in world-lattice cell units,
    /// started at the origin's cell whatever the window's position, so every grid
    /// visits the same lattice cells for the same segment; cells outside the window
    /// come with `index: None`.
    #[must_use]
    pub fn walk(&self, origin: &Point3<f64>, end: &Point3<f64>) -> Option<RayWalk> {
        let g0 = self.lattice_coords(origin)?;
        let g1 = self.lattice_coords(end)?;
        Some(self.walk_lattice(&g0, &g1))
    }

    /// A one-cell grid at the corner of the world lattice of `resolution_m`: its local
    /// cells are lattice cells ([`LocalGrid::lattice_cell`]), so the steps of its
    /// [`LocalGrid::walk`]s name lattice cells in `cell` (their `index` is meaningless) —
    /// walks with no window, as [`ChangeSetMeter`](super::meter::ChangeSetMeter) needs.
    #[must_use]
    pub fn lattice_corner(resolution_m: f64, params: LogOddsParams) -> Self {
        let corner = Point3::from(Vector3::repeat(-(LATTICE_HALF as f64) * resolution_m));
        LocalGrid::centred(
            &corner,
            &Vector3::repeat(resolution_m),
            resolution_m,
            params,
        )
    }

    /// `p` in world-lattice cell units (cell `c` spans `[c, c + 1)` along each axis),
    /// as [`LocalGrid::walk`] sees it; `None` if not finite or outside the lattice.
    pub(super) fn lattice_coords(&self, p: &Point3<f64>) -> Option<Vector3<f64>> {
        let g = (p.coords - self.lattice.origin.coords) * (1.0 / self.lattice.cell_m);
        let span = 2.0 * LATTICE_HALF as f64;
        // `contains` is false for NaN, so this also rejects non-finite points.
        (0..3).all(|i| (0.0..span).contains(&g[i])).then_some(g)
    }

    /// Lattice index of local cell `[0, 0, 0]`.
    pub(super) fn corner(&self) -> [usize; 3] {
        self.corner
    }

    /// [`LocalGrid::walk`] between two points already in lattice cell units (from
    /// [`LocalGrid::lattice_coords`], or a cell centre `c + 0.5`).
    pub(super) fn walk_lattice(&self, g0: &Vector3<f64>, g1: &Vector3<f64>) -> RayWalk {
        let dir = g1 - g0;
        let cell = [0, 1, 2].map(|i| g0[i].floor() as i64);
        let end_cell = [0, 1, 2].map(|i| g1[i].floor() as i64);
        let mut step = [0i64; 3];
        let mut t_next = [f64::INFINITY; 3];
        let mut t_delta = [f64::INFINITY; 3];
        for i in 0..3 {
            if dir[i] > 0.0 {
                step[i] = 1;
                t_next[i] = ((cell[i] + 1) as f64 - g0[i]) / dir[i];
                t_delta[i] = 1.0 / dir[i];
            } else if dir[i] < 0.0 {
                step[i] = -1;
                t_next[i] = (cell[i] as f64 - g0[i]) / dir[i];
                t_delta[i] = -1.0 / dir[i];
            }
        }
        let dims = self.dims.map(|d| d as i64);
        let stride = [1, dims[0], dims[0] * dims[1]];
        let local = [0, 1, 2].map(|i| cell[i] - self.corner[i] as i64);
        RayWalk {
            index: local[0] + stride[1] * local[1] + stride[2] * local[2],
            local,
            end_local: [0, 1, 2].map(|i| end_cell[i] - self.corner[i] as i64),
            step,
            stride,
            dims,
            t_next,
            t_delta,
            t_enter: 0.0,
            // The segment crosses exactly this many faces on its way to the end cell;
            // taking that many steps bounds the walk even if rounding at a corner sends
            // it past a neighbour of the end cell (the end cell comes last either way).
            remaining: (0..3).map(|i| (end_cell[i] - cell[i]).abs()).sum(),
            finished: false,
        }
    }

    /// Inserts a ray from `origin` to `end`: every cell it crosses before the end cell
    /// gets a miss; the end cell gets a hit if `hit` (a surface point), or a miss too
    /// if not (a free-space point, e.g. from the free-space GMM). Only cells inside
    /// `region` (all cells if `None`) change. Non-finite input is ignored.
    pub fn insert_ray(
        &mut self,
        origin: &Point3<f64>,
        end: &Point3<f64>,
        hit: bool,
        region: Option<&CellBox>,
    ) {
        match region {
            None => self.insert_ray_where(origin, end, hit, |_| true),
            Some(r) => self.insert_ray_where(origin, end, hit, |c| r.contains(c)),
        }
    }

    /// [`LocalGrid::insert_ray`] changing only the cells inside one of `boxes` (the
    /// novel boxes of a window move, thesis Fig. 3.2); nothing changes for no boxes.
    pub fn insert_ray_boxes(
        &mut self,
        origin: &Point3<f64>,
        end: &Point3<f64>,
        hit: bool,
        boxes: &[CellBox],
    ) {
        // A ray that passes no box (grown by a cell for the walk's rounding) changes
        // nothing: skip its walk. Most sample rays of a rebuild miss the thin slabs a
        // window move uncovers.
        let (Some(g0), Some(g1)) = (self.lattice_coords(origin), self.lattice_coords(end)) else {
            return;
        };
        let corner = Vector3::from(self.corner.map(|c| c as f64));
        let meets = |b: &CellBox| {
            let lattice_box = Aabb {
                min: Point3::from(corner + Vector3::from(b.min.map(|v| v as f64))),
                max: Point3::from(corner + Vector3::from(b.max.map(|v| v as f64))),
            };
            lattice_box
                .expanded(1.0)
                .clip_ray(&Point3::from(g0), &(g1 - g0), 0.0, 1.0)
                .is_some()
        };
        if !boxes.iter().any(meets) {
            return;
        }
        self.insert_ray_where(origin, end, hit, |c| boxes.iter().any(|b| b.contains(c)));
    }

    fn insert_ray_where(
        &mut self,
        origin: &Point3<f64>,
        end: &Point3<f64>,
        hit: bool,
        keep: impl Fn([usize; 3]) -> bool,
    ) {
        let Some(walk) = self.walk(origin, end) else {
            return;
        };
        let (min, max) = (self.params.min, self.params.max);
        let (hit_delta, miss_delta) = (self.params.hit, self.params.miss);
        let cells = &mut self.cells;
        walk.for_each_inside(|i, cell, is_end| {
            if keep(cell) {
                let delta = if is_end && hit { hit_delta } else { miss_delta };
                let v = &mut cells[i];
                *v = (*v + delta).clamp(min, max);
            }
        });
    }

    /// Adds `delta` to the log-odds of the cell at linear `index`, clamped to the
    /// rules' bounds; an index outside the grid is ignored.
    pub fn update(&mut self, index: usize, delta: f32) {
        let (min, max) = (self.params.min, self.params.max);
        if let Some(v) = self.cells.get_mut(index) {
            *v = (*v + delta).clamp(min, max);
        }
    }

    /// Replaces all values (tests only; the length must match).
    #[cfg(test)]
    pub(super) fn set_values_for_test(&mut self, values: Vec<f32>) {
        assert_eq!(values.len(), self.cells.len());
        self.cells = values;
    }

    /// Mutable log-odds values, row-major (x fastest), for the scan update.
    pub(super) fn values_mut(&mut self) -> &mut [f32] {
        &mut self.cells
    }

    /// Marks the unknown cells whose centres lie within `radius_m` of `centre` as free
    /// (one miss each); cells already observed keep their values. Used for space the
    /// robot's body occupies, which cannot be rock, without overriding what the sensor
    /// saw.
    pub fn clear_unknown_sphere(&mut self, centre: &Point3<f64>, radius_m: f64) {
        if !(radius_m > 0.0 && centre.coords.iter().all(|v| v.is_finite())) {
            return;
        }
        let geometry = self.geometry();
        let n = (radius_m / self.lattice.cell_m).ceil() as i64 + 1;
        let Some(middle) = geometry.cell_of(centre) else {
            return;
        };
        let (miss, min, max) = (self.params.miss, self.params.min, self.params.max);
        for dz in -n..=n {
            for dy in -n..=n {
                for dx in -n..=n {
                    let offset = [dx, dy, dz];
                    let cell = [0, 1, 2].map(|i| middle[i] as i64 + offset[i]);
                    if (0..3).any(|i| cell[i] < 0 || cell[i] >= self.dims[i] as i64) {
                        continue;
                    }
                    let cell = cell.map(|v| v as usize);
                    if (geometry.cell_centre(cell) - centre).norm() > radius_m {
                        continue;
                    }
                    let i = self.index(cell);
                    if self.classify(self.cells[i]) == CellState::Unknown {
                        self.cells[i] = (self.cells[i] + miss).clamp(min, max);
                    }
                }
            }
        }
    }

    /// Moves the window so that it is centred on `centre` (snapped to the lattice):
    /// cells in the overlap keep their values, the rest become unknown. Returns the
    /// novel boxes (at most three, disjoint) that must be rebuilt from the maps
    /// (thesis Fig. 3.2).
    pub fn shift_to(&mut self, centre: &Point3<f64>) -> Vec<CellBox> {
        let corner = Self::corner_for(&self.lattice, centre, self.dims);
        if corner == self.corner {
            return Vec::new();
        }
        let shift = [0, 1, 2].map(|i| corner[i] as i64 - self.corner[i] as i64);
        let mut cells = vec![0.0; self.cells.len()];
        let d = self.dims;
        let kept = |i: usize| kept_range(d[i], shift[i]);
        let ((x0, x1), (y0, y1), (z0, z1)) = (kept(0), kept(1), kept(2));
        if x0 < x1 {
            let old_x0 = (x0 as i64 + shift[0]) as usize;
            for z in z0..z1 {
                for y in y0..y1 {
                    let old_y = (y as i64 + shift[1]) as usize;
                    let old_z = (z as i64 + shift[2]) as usize;
                    let from = self.index([old_x0, old_y, old_z]);
                    let to = x0 + d[0] * (y + d[1] * z);
                    cells[to..to + (x1 - x0)].copy_from_slice(&self.cells[from..from + (x1 - x0)]);
                }
            }
        }
        self.cells = cells;
        self.corner = corner;
        novel_boxes(d, shift)
    }
}

/// Along one axis of `n` cells moved by `shift`, the new indices `lo..hi` whose old cell
/// (`new + shift`) lies in the old box.
fn kept_range(n: usize, shift: i64) -> (usize, usize) {
    let n = n as i64;
    (
        (-shift).clamp(0, n) as usize,
        (n - shift).clamp(0, n) as usize,
    )
}

/// The part of a box of `dims` cells, moved by `shift` cells, that the old box did
/// not cover, as at most three disjoint boxes: a slab across x, then one across y
/// outside it, then one across z outside both.
fn novel_boxes(dims: [usize; 3], shift: [i64; 3]) -> Vec<CellBox> {
    let mut boxes = Vec::new();
    // The range of the old box along each axis, in new local indices, clamped.
    let kept = |i: usize| kept_range(dims[i], shift[i]);
    let mut lo = [0usize; 3];
    let mut hi = dims;
    for axis in 0..3 {
        let (k_lo, k_hi) = kept(axis);
        if k_lo > lo[axis] {
            let mut max = hi;
            max[axis] = k_lo;
            boxes.push(CellBox { min: lo, max });
        }
        if k_hi < hi[axis] {
            let mut min = lo;
            min[axis] = k_hi;
            boxes.push(CellBox { min, max: hi });
        }
        lo[axis] = k_lo.max(lo[axis]);
        hi[axis] = k_hi.min(hi[axis]);
        if lo[axis] >= hi[axis] {
            // No overlap at all: the whole box was covered by the boxes above.
            break;
        }
    }
    boxes.retain(|b| b.cell_count() > 0);
    boxes
}

/// One cell on a [`RayWalk`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayStep {
    /// Local cell coordinates (meaningful only when `index` is `Some`).
    pub cell: [usize; 3],
    /// Linear index into [`LocalGrid::values`], `None` outside the window.
    pub index: Option<usize>,
    /// Fraction of the segment at which the walk entered the cell (0 for the first).
    pub t_enter: f64,
    /// Whether this is the cell holding the segment's end point.
    pub is_end: bool,
}

/// The cells along a segment; see [`LocalGrid::walk`].
#[derive(Clone, Debug)]
pub struct RayWalk {
    local: [i64; 3],
    index: i64,
    end_local: [i64; 3],
    step: [i64; 3],
    stride: [i64; 3],
    dims: [i64; 3],
    t_next: [f64; 3],
    t_delta: [f64; 3],
    t_enter: f64,
    remaining: i64,
    finished: bool,
}

impl RayWalk {
    /// Visits the cells of the walk that lie inside the window, in order, as
    /// `(linear index, local cell, is_end)`: the same cells as the iterator, in a
    /// tight loop without the per-step [`RayStep`].
    #[inline]
    pub fn for_each_inside(self, mut visit: impl FnMut(usize, [usize; 3], bool)) {
        // When the start and end cells lie two cells or more inside the window, so
        // does every cell between (rounding at a corner strays at most one cell from
        // their bounding box), and no step needs the bounds check.
        let interior = |c: &[i64; 3]| (0..3).all(|a| c[a] >= 2 && c[a] + 2 < self.dims[a]);
        if interior(&self.local) && interior(&self.end_local) {
            self.walk_cells::<false>(&mut visit);
        } else {
            self.walk_cells::<true>(&mut visit);
        }
        let c = self.end_local;
        if self.inside(&c) {
            let i = c[0] + self.stride[1] * c[1] + self.stride[2] * c[2];
            visit(i as usize, c.map(|v| v as usize), true);
        }
    }

    /// The cells before the end cell, bounds-checked against the window when `CHECK`.
    /// The walk's state is kept in scalars (not arrays indexed by the axis) so that it
    /// stays in registers; the comparisons and sums are the iterator's.
    #[inline]
    fn walk_cells<const CHECK: bool>(&self, visit: &mut impl FnMut(usize, [usize; 3], bool)) {
        let [wx, wy, wz] = self.dims.map(|d| d as u64);
        let [mut lx, mut ly, mut lz] = self.local;
        let [mut tx, mut ty, mut tz] = self.t_next;
        let [dx, dy, dz] = self.t_delta;
        let [sx, sy, sz] = self.step;
        let [ix, iy, iz] = [0, 1, 2].map(|a| self.step[a] * self.stride[a]);
        let mut index = self.index;
        for _ in 0..self.remaining {
            if !CHECK || ((lx as u64) < wx && (ly as u64) < wy && (lz as u64) < wz) {
                visit(
                    index as usize,
                    [lx as usize, ly as usize, lz as usize],
                    false,
                );
            }
            if tx <= ty && tx <= tz {
                lx += sx;
                index += ix;
                tx += dx;
            } else if ty <= tz {
                ly += sy;
                index += iy;
                ty += dy;
            } else {
                lz += sz;
                index += iz;
                tz += dz;
            }
        }
    }

    fn inside(&self, c: &[i64; 3]) -> bool {
        (c[0] as u64) < self.dims[0] as u64
            && (c[1] as u64) < self.dims[1] as u64
            && (c[2] as u64) < self.dims[2] as u64
    }
}

impl Iterator for RayWalk {
    type Item = RayStep;

    #[inline]
    fn next(&mut self) -> Option<RayStep> {
        if self.remaining > 0 {
            let c = self.local;
            let step = RayStep {
                cell: c.map(|v| v as usize),
                index: self.inside(&c).then_some(self.index as usize),
                t_enter: self.t_enter,
                is_end: false,
            };
            // Branch-free choice of the axis whose face comes first.
            let x_first = self.t_next[0] <= self.t_next[1] && self.t_next[0] <= self.t_next[2];
            let y_not_z = self.t_next[1] <= self.t_next[2];
            let axis = usize::from(!x_first) * (1 + usize::from(!y_not_z));
            self.t_enter = self.t_next[axis];
            self.local[axis] += self.step[axis];
            self.index += self.step[axis] * self.stride[axis];
            self.t_next[axis] += self.t_delta[axis];
            self.remaining -= 1;
            return Some(step);
        }
        if self.finished {
            return None;
        }
        self.finished = true;
        let c = self.end_local;
        let inside = self.inside(&c);
        let stride = self.stride;
        Some(RayStep {
            cell: c.map(|v| v as usize),
            index: inside.then(|| (c[0] + stride[1] * c[1] + stride[2] * c[2]) as usize),
            t_enter: self.t_enter.min(1.0),
            is_end: true,
        })
    }
}
