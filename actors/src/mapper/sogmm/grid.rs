//! Uniform 3D grid over a fixed point set, and per-cell lists of the components that can
//! matter in each occupied cell. Used to restrict the E-step to the components that can
//! matter near a point (see [`super::em`] for the bound).

/// Most cells a grid may have; the cell side grows to respect it.
const MAX_CELLS: usize = 1 << 21;

/// No occupied cell.
const EMPTY: u32 = u32::MAX;

/// A uniform grid over the bounding box of a point set. Occupied cells get compact
/// "slots" numbered in increasing cell order, so sorting points by slot sorts them by
/// cell.
#[derive(Clone, Debug)]
pub(crate) struct PointGrid {
    origin: [f64; 3],
    h: f64,
    inv_h: f64,
    dims: [usize; 3],
    /// Slot of each point's cell (same order as the input).
    pub(crate) point_slot: Vec<u32>,
    /// Slot of every cell ([`EMPTY`] where no point lies).
    slot_of_cell: Vec<u32>,
    /// Number of occupied cells.
    slots: usize,
}

impl PointGrid {
    /// Grid of side `h` (or larger, see [`MAX_CELLS`]) over the box of `points`.
    pub(crate) fn new(points: &[[f64; 3]], h: f64) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in points {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        if points.is_empty() {
            lo = [0.0; 3];
            hi = [0.0; 3];
        }
        let extent = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let mut h = if h > 0.0 && h.is_finite() { h } else { 1.0 };
        let dims = loop {
            let d = extent.map(|e| ((e / h).floor() as usize + 1).max(1));
            if d[0].saturating_mul(d[1]).saturating_mul(d[2]) <= MAX_CELLS {
                break d;
            }
            h *= 1.25;
        };
        let mut grid = Self {
            origin: lo,
            h,
            inv_h: 1.0 / h,
            dims,
            point_slot: Vec::with_capacity(points.len()),
            slot_of_cell: vec![EMPTY; dims[0] * dims[1] * dims[2]],
            slots: 0,
        };
        let cells: Vec<usize> = points.iter().map(|p| grid.index(grid.coords(p))).collect();
        for &c in &cells {
            grid.slot_of_cell[c] = 0;
        }
        let mut next = 0u32;
        for s in grid.slot_of_cell.iter_mut() {
            if *s != EMPTY {
                *s = next;
                next += 1;
            }
        }
        grid.slots = next as usize;
        grid.point_slot = cells.iter().map(|&c| grid.slot_of_cell[c]).collect();
        grid
    }

    /// Number of occupied cells (slots).
    pub(crate) fn slots(&self) -> usize {
        self.slots
    }

    /// Clamped integer cell coordinates of a position.
    fn coords(&self, p: &[f64; 3]) -> [usize; 3] {
        let mut c = [0usize; 3];
        for a in 0..3 {
            let v = ((p[a] - self.origin[a]) * self.inv_h).floor();
            c[a] = if v.is_nan() || v < 0.0 {
                0
            } else {
                (v as usize).min(self.dims[a] - 1)
            };
        }
        c
    }

    fn index(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    /// Per-slot component lists (CSR) from axis-aligned boxes `(lo, hi)`: component `m`
    /// is listed in an occupied cell its box overlaps when `keep(m, slot, cell_lo, h)`
    /// holds (`cell_lo` is the cell's lower corner, `h` its side). A component with no
    /// box is in no list. Lists are in increasing component order.
    pub(crate) fn component_lists<F>(
        &self,
        boxes: &[Option<([f64; 3], [f64; 3])>],
        keep: F,
    ) -> CellLists
    where
        F: Fn(usize, usize, [f64; 3], f64) -> bool,
    {
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        for (m, b) in boxes.iter().enumerate() {
            let Some((lo, hi)) = b else { continue };
            let (c0, c1) = (self.coords(lo), self.coords(hi));
            for z in c0[2]..=c1[2] {
                for y in c0[1]..=c1[1] {
                    let row = (z * self.dims[1] + y) * self.dims[0];
                    for x in c0[0]..=c1[0] {
                        let slot = self.slot_of_cell[row + x];
                        if slot == EMPTY {
                            continue;
                        }
                        let cell_lo = [
                            self.origin[0] + x as f64 * self.h,
                            self.origin[1] + y as f64 * self.h,
                            self.origin[2] + z as f64 * self.h,
                        ];
                        if keep(m, slot as usize, cell_lo, self.h) {
                            pairs.push((slot, m as u32));
                        }
                    }
                }
            }
        }
        // Counting sort by slot, stable: each list stays in component order.
        let mut start = vec![0u32; self.slots + 1];
        for &(s, _) in &pairs {
            start[s as usize + 1] += 1;
        }
        for s in 0..self.slots {
            start[s + 1] += start[s];
        }
        let mut fill: Vec<u32> = start[..self.slots].to_vec();
        let mut items = vec![0u32; pairs.len()];
        for &(s, m) in &pairs {
            items[fill[s as usize] as usize] = m;
            fill[s as usize] += 1;
        }
        CellLists { start, items }
    }
}

/// Component lists per occupied cell (slot), CSR layout.
#[derive(Clone, Debug)]
pub(crate) struct CellLists {
    start: Vec<u32>,
    items: Vec<u32>,
}

impl CellLists {
    pub(crate) fn get(&self, slot: u32) -> &[u32] {
        let c = slot as usize;
        &self.items[self.start[c] as usize..self.start[c + 1] as usize]
    }
}
