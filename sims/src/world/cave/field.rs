//! The cave's smooth-free "base" distance field: a union of capsules and chambers behind
//! a coarse grid index.
//!
//! `base(p) = max(-ROCK_CLAMP_M, max_i f_i(p))`, where `f_i` is the exact signed distance
//! into primitive `i` (positive inside). Every `f_i` is 1-Lipschitz, and so are max and the
//! clamp, so `base` is 1-Lipschitz. Each grid cell lists every primitive whose region grown
//! by `ROCK_CLAMP_M` reaches the cell; primitives left out are below the clamp everywhere
//! in the cell, so the indexed evaluation equals the brute-force one exactly.
//!
//! [`Field::base_m`] reads a finer second index built from the first: each fine cell keeps
//! only the primitives that can be the maximum somewhere in it. With `h` the cell's half
//! diagonal and `c` its centre, primitive `i` is dropped when
//! `f_i(c) + h < max(-ROCK_CLAMP_M, max_j f_j(c) - h)`: by 1-Lipschitz continuity it is
//! below another primitive (or the clamp) everywhere in the cell. The maximum over the
//! kept primitives is the same number as over all of them, bit for bit.

use nalgebra::{Point3, Vector3};

use crate::world::Aabb;
use crate::world::gpu_scene::{GpuCaveField, GpuNoise, GpuPrimitive};

/// Depth below which rock distances are clamped (a conservative rock distance).
pub(super) const ROCK_CLAMP_M: f64 = 1.0;

/// Edge of the index cells (the GPU camera's index).
const INDEX_CELL_M: f64 = 2.0;

/// Fine index cells per coarse cell edge (fine cells of 0.5 m).
const FINE_PER_COARSE: usize = 4;

/// Slack added to the pruning bound for rounding in `free_m` (far above its error).
const PRUNE_SLACK_M: f64 = 1e-9;

/// One convex piece of free space.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Primitive {
    /// Points within `radius` of the segment `a`–`a + ab`.
    Capsule {
        a: Point3<f64>,
        ab: Vector3<f64>,
        inv_len2: f64,
        radius: f64,
    },
    /// A ball cut by a horizontal floor at `floor_z`.
    Chamber {
        centre: Point3<f64>,
        radius: f64,
        floor_z: f64,
    },
}

impl Primitive {
    /// A capsule from `a` to `b`.
    pub(super) fn capsule(a: Point3<f64>, b: Point3<f64>, radius: f64) -> Self {
        let ab = b - a;
        let len2 = ab.norm_squared();
        let inv_len2 = if len2 > 0.0 { 1.0 / len2 } else { 0.0 };
        Primitive::Capsule {
            a,
            ab,
            inv_len2,
            radius,
        }
    }

    /// Signed distance into the primitive (positive inside), 1-Lipschitz.
    #[inline]
    pub(super) fn free_m(&self, p: &Point3<f64>) -> f64 {
        match self {
            Primitive::Capsule {
                a,
                ab,
                inv_len2,
                radius,
            } => {
                let ap = p - a;
                let t = (ap.dot(ab) * inv_len2).clamp(0.0, 1.0);
                radius - (ap - ab * t).norm()
            }
            Primitive::Chamber {
                centre,
                radius,
                floor_z,
            } => (radius - (p - centre).norm()).min(p.z - floor_z),
        }
    }

    /// A box holding the primitive's free region.
    pub(super) fn aabb(&self) -> Aabb {
        match self {
            Primitive::Capsule { a, ab, radius, .. } => Aabb::new(*a, a + ab).expanded(*radius),
            Primitive::Chamber { centre, radius, .. } => {
                Aabb::from_point(*centre).expanded(*radius)
            }
        }
    }
}

/// Primitives plus a uniform grid listing, per cell, the primitives that matter there.
#[derive(Debug, Clone)]
pub(super) struct Field {
    prims: Vec<Primitive>,
    origin: Point3<f64>,
    dims: [usize; 3],
    /// `cell_items[cell_start[c]..cell_start[c + 1]]` are the primitives of cell `c`.
    cell_start: Vec<u32>,
    cell_items: Vec<u32>,
    /// The fine index (see the module doc): cells of `INDEX_CELL_M / FINE_PER_COARSE`
    /// from the same origin, laid out as the coarse one.
    fine_dims: [usize; 3],
    fine_start: Vec<u32>,
    fine_items: Vec<u32>,
}

impl Field {
    /// Index `prims`.
    pub(super) fn new(prims: Vec<Primitive>) -> Self {
        let reach = ROCK_CLAMP_M + 1e-6;
        let boxes: Vec<Aabb> = prims.iter().map(|p| p.aabb().expanded(reach)).collect();
        let all = boxes.iter().skip(1).fold(
            boxes
                .first()
                .copied()
                .unwrap_or(Aabb::from_point(Point3::origin())),
            |acc, b| acc.union(b),
        );
        let origin = all.min;
        let size = all.size();
        let dims = [0, 1, 2].map(|i| ((size[i] / INDEX_CELL_M).ceil() as usize).max(1));
        let ncells = dims[0] * dims[1] * dims[2];
        let half_diag = INDEX_CELL_M * 3f64.sqrt() / 2.0;
        // Cells of prim `i`: those overlapping its grown box whose centre is near enough.
        let cells_of = |i: usize, visit: &mut dyn FnMut(usize)| {
            let b = &boxes[i];
            let lo = [0, 1, 2]
                .map(|k| (((b.min[k] - origin[k]) / INDEX_CELL_M).floor().max(0.0)) as usize);
            let hi = [0, 1, 2].map(|k| {
                ((((b.max[k] - origin[k]) / INDEX_CELL_M).floor().max(0.0)) as usize)
                    .min(dims[k] - 1)
            });
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        let c = origin
                            + Vector3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5)
                                * INDEX_CELL_M;
                        if prims[i].free_m(&c) > -(reach + half_diag) {
                            visit(x + dims[0] * (y + dims[1] * z));
                        }
                    }
                }
            }
        };
        let mut counts = vec![0u32; ncells + 1];
        for i in 0..prims.len() {
            cells_of(i, &mut |c| counts[c + 1] += 1);
        }
        for c in 0..ncells {
            counts[c + 1] += counts[c];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; counts[ncells] as usize];
        for i in 0..prims.len() {
            cells_of(i, &mut |c| {
                items[fill[c] as usize] = i as u32;
                fill[c] += 1;
            });
        }
        let mut field = Self {
            prims,
            origin,
            dims,
            cell_start: counts,
            cell_items: items,
            fine_dims: dims.map(|d| d * FINE_PER_COARSE),
            fine_start: Vec::new(),
            fine_items: Vec::new(),
        };
        field.build_fine_index();
        field
    }

    /// Fills the fine index from the coarse one (see the module doc).
    fn build_fine_index(&mut self) {
        let fine_m = INDEX_CELL_M / FINE_PER_COARSE as f64;
        let half_diag = fine_m * 3f64.sqrt() / 2.0;
        let [nx, ny, nz] = self.fine_dims;
        let mut start = Vec::with_capacity(nx * ny * nz + 1);
        let mut items = Vec::new();
        let mut values: Vec<(u32, f64)> = Vec::new();
        start.push(0u32);
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let coarse = x / FINE_PER_COARSE
                        + self.dims[0]
                            * (y / FINE_PER_COARSE + self.dims[1] * (z / FINE_PER_COARSE));
                    let (s, e) = (
                        self.cell_start[coarse] as usize,
                        self.cell_start[coarse + 1] as usize,
                    );
                    let centre = self.origin
                        + Vector3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5) * fine_m;
                    values.clear();
                    values.extend(
                        self.cell_items[s..e]
                            .iter()
                            .map(|&i| (i, self.prims[i as usize].free_m(&centre))),
                    );
                    let floor = values
                        .iter()
                        .map(|(_, v)| v - half_diag)
                        .fold(-ROCK_CLAMP_M, f64::max);
                    items.extend(
                        values
                            .iter()
                            .filter(|(_, v)| v + half_diag + PRUNE_SLACK_M >= floor)
                            .map(|(i, _)| *i),
                    );
                    start.push(u32::try_from(items.len()).unwrap_or(u32::MAX));
                }
            }
        }
        self.fine_start = start;
        self.fine_items = items;
    }

    /// The indexed base field (see the module doc).
    #[inline]
    pub(super) fn base_m(&self, p: &Point3<f64>) -> f64 {
        let mut best = -ROCK_CLAMP_M;
        let rel = (p - self.origin) * (FINE_PER_COARSE as f64 / INDEX_CELL_M);
        let mut cell = 0usize;
        let mut stride = 1usize;
        for k in 0..3 {
            let r = rel[k];
            // For r >= 0 truncation is the floor; false for NaN.
            if !(r >= 0.0 && r < self.fine_dims[k] as f64) {
                return best;
            }
            cell += r as usize * stride;
            stride *= self.fine_dims[k];
        }
        let (s, e) = (
            self.fine_start[cell] as usize,
            self.fine_start[cell + 1] as usize,
        );
        for &i in &self.fine_items[s..e] {
            best = best.max(self.prims[i as usize].free_m(p));
        }
        best
    }

    /// The field, index included, as tables for the GPU camera, with the cave's wall
    /// roughness `amplitude_m * wall_noise(p / wavelength_m)` and Lipschitz bound.
    pub(super) fn to_gpu(
        &self,
        wall_noise: GpuNoise,
        amplitude_m: f64,
        wavelength_m: f64,
        lipschitz: f64,
    ) -> GpuCaveField {
        let primitives = self
            .prims
            .iter()
            .map(|p| match *p {
                Primitive::Capsule {
                    a,
                    ab,
                    inv_len2,
                    radius,
                } => GpuPrimitive::Capsule {
                    a,
                    ab,
                    inv_len2,
                    radius_m: radius,
                },
                Primitive::Chamber {
                    centre,
                    radius,
                    floor_z,
                } => GpuPrimitive::Chamber {
                    centre,
                    radius_m: radius,
                    floor_z_m: floor_z,
                },
            })
            .collect();
        GpuCaveField {
            primitives,
            grid_origin: self.origin,
            cell_m: INDEX_CELL_M,
            dims: self.dims.map(|d| u32::try_from(d).unwrap_or(u32::MAX)),
            cell_start: self.cell_start.clone(),
            cell_items: self.cell_items.clone(),
            rock_clamp_m: ROCK_CLAMP_M,
            wall_noise,
            amplitude_m,
            wavelength_m,
            lipschitz,
        }
    }

    /// The field through the coarse index alone (the evaluation before the fine index).
    #[cfg(test)]
    pub(super) fn base_coarse_m(&self, p: &Point3<f64>) -> f64 {
        let mut best = -ROCK_CLAMP_M;
        let rel = (p - self.origin) / INDEX_CELL_M;
        let mut cell = 0usize;
        let mut stride = 1usize;
        for k in 0..3 {
            let f = rel[k].floor();
            if !(f >= 0.0 && f < self.dims[k] as f64) {
                return best;
            }
            cell += f as usize * stride;
            stride *= self.dims[k];
        }
        let (s, e) = (
            self.cell_start[cell] as usize,
            self.cell_start[cell + 1] as usize,
        );
        for &i in &self.cell_items[s..e] {
            best = best.max(self.prims[i as usize].free_m(p));
        }
        best
    }

    /// The same field without the index (slow reference for tests).
    #[cfg(test)]
    pub(super) fn base_brute_m(&self, p: &Point3<f64>) -> f64 {
        self.prims
            .iter()
            .map(|q| q.free_m(p))
            .fold(-ROCK_CLAMP_M, f64::max)
    }

    /// A box holding every primitive's free region.
    pub(super) fn free_aabb(&self) -> Aabb {
        let mut it = self.prims.iter().map(Primitive::aabb);
        let first = it.next().unwrap_or(Aabb::from_point(Point3::origin()));
        it.fold(first, |acc, b| acc.union(&b))
    }

    /// Mean number of primitives listed per non-empty cell, coarse and fine index (for
    /// diagnostics).
    #[cfg(test)]
    pub(super) fn mean_items_per_busy_cell(&self) -> [f64; 2] {
        let mean = |start: &[u32], items: &[u32]| {
            let busy = start.windows(2).filter(|w| w[1] > w[0]).count();
            items.len() as f64 / busy.max(1) as f64
        };
        [
            mean(&self.cell_start, &self.cell_items),
            mean(&self.fine_start, &self.fine_items),
        ]
    }
}
