//! Uniform 3D grid over a fixed point set, and per-cell lists of the components whose
//! reach box overlaps the cell. Used to restrict the E-step to the components that can
//! matter near a point (see [`super::em`] for the bound).

/// Most cells a grid may have; the cell side grows to respect it.
const MAX_CELLS: usize = 1 << 21;

/// A uniform grid over the bounding box of a point set.
#[derive(Clone, Debug)]
pub(crate) struct PointGrid {
    origin: [f64; 3],
    inv_h: f64,
    dims: [usize; 3],
    /// Cell of each point (same order as the input).
    pub(crate) point_cell: Vec<u32>,
    occupied: Vec<bool>,
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
            inv_h: 1.0 / h,
            dims,
            point_cell: Vec::with_capacity(points.len()),
            occupied: vec![false; dims[0] * dims[1] * dims[2]],
        };
        for p in points {
            let c = grid.index(grid.coords(p));
            grid.occupied[c] = true;
            grid.point_cell.push(c as u32);
        }
        grid
    }

    pub(crate) fn n_cells(&self) -> usize {
        self.occupied.len()
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

    /// Per-cell component lists (CSR) from axis-aligned reach boxes `(lo, hi)`; a
    /// component with no box is in no list. Only occupied cells get entries; lists are
    /// in increasing component order.
    pub(crate) fn component_lists(&self, boxes: &[Option<([f64; 3], [f64; 3])>]) -> CellLists {
        let n_cells = self.n_cells();
        let mut count = vec![0u32; n_cells + 1];
        let ranges: Vec<Option<([usize; 3], [usize; 3])>> = boxes
            .iter()
            .map(|b| b.map(|(lo, hi)| (self.coords(&lo), self.coords(&hi))))
            .collect();
        let for_cells = |r: &([usize; 3], [usize; 3]), f: &mut dyn FnMut(usize)| {
            for z in r.0[2]..=r.1[2] {
                for y in r.0[1]..=r.1[1] {
                    let row = (z * self.dims[1] + y) * self.dims[0];
                    for x in r.0[0]..=r.1[0] {
                        if self.occupied[row + x] {
                            f(row + x);
                        }
                    }
                }
            }
        };
        for r in ranges.iter().flatten() {
            for_cells(r, &mut |c| count[c + 1] += 1);
        }
        for c in 0..n_cells {
            count[c + 1] += count[c];
        }
        let start = count;
        let mut fill: Vec<u32> = start[..n_cells].to_vec();
        let mut items = vec![0u32; start[n_cells] as usize];
        for (m, r) in ranges.iter().enumerate() {
            if let Some(r) = r {
                for_cells(r, &mut |c| {
                    items[fill[c] as usize] = m as u32;
                    fill[c] += 1;
                });
            }
        }
        CellLists { start, items }
    }
}

/// Component lists per cell, CSR layout.
#[derive(Clone, Debug)]
pub(crate) struct CellLists {
    start: Vec<u32>,
    items: Vec<u32>,
}

impl CellLists {
    pub(crate) fn get(&self, cell: u32) -> &[u32] {
        let c = cell as usize;
        &self.items[self.start[c] as usize..self.start[c + 1] as usize]
    }
}
