//! Exact Euclidean distance transform (Felzenszwalb & Huttenlocher, 2012): linear
//! time, separable over the three axes, on squared distances.
//!
//! The squared distances between cell centres are integers (in cells²), so the
//! transform runs on `u32`s and a [`DistanceField`] keeps them, as `u16`s when the
//! grid is small enough (the default 100 × 100 × 60 window is): a quarter of the
//! memory of metres in `f64`, and no pass over the grid to take square roots.
//! Reading a cell gives `sqrt(d²) · cell_m`, the same number a transform in metres
//! would give.

use rayon::prelude::*;

use super::{CellState, LocalGrid};

/// The squared distance of a cell with no source on its lines so far (∞).
const NO_SOURCE: u32 = u32::MAX;

/// Squared-distance transform along one line: `f` holds 0 at sources and
/// [`NO_SOURCE`] elsewhere on entry, squared distances (in cells², along this and
/// earlier axes) on exit. `v`, `z` and `out` are scratch buffers of at least
/// `f.len()` (+1 for `z`). The parabolas' intersections are computed in `f64` from
/// the same exact integers a transform in `f64` would hold, so the envelope and the
/// result are the same.
fn transform_line(f: &mut [u32], v: &mut [usize], z: &mut [f64], out: &mut [u32]) {
    let n = f.len();
    let mut k = 0usize;
    let mut found = false;
    let height = |q: usize, fq: u32| f64::from(fq) + (q * q) as f64;
    for q in 0..n {
        if f[q] == NO_SOURCE {
            continue;
        }
        if !found {
            v[0] = q;
            z[0] = f64::NEG_INFINITY;
            z[1] = f64::INFINITY;
            found = true;
            continue;
        }
        // z[0] = −∞, so the loop never pops the first parabola.
        loop {
            let p = v[k];
            let s = (height(q, f[q]) - height(p, f[p])) / (2.0 * (q as f64 - p as f64));
            if s <= z[k] {
                k -= 1;
            } else {
                k += 1;
                v[k] = q;
                z[k] = s;
                z[k + 1] = f64::INFINITY;
                break;
            }
        }
    }
    if !found {
        return;
    }
    k = 0;
    for (q, o) in out.iter_mut().enumerate().take(n) {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let d = q.abs_diff(v[k]) as u64;
        *o = saturate(d * d + u64::from(f[v[k]]));
    }
    f[..n].copy_from_slice(&out[..n]);
}

/// A squared distance as stored: beyond `u32` (lines of over 46 000 cells) it
/// saturates just below [`NO_SOURCE`].
fn saturate(d2: u64) -> u32 {
    u32::try_from(d2)
        .unwrap_or(NO_SOURCE - 1)
        .min(NO_SOURCE - 1)
}

/// Squared distance (in cells²) from each cell of a line of `n` cells to the nearest
/// source along it ([`NO_SOURCE`] when the line has none): the first pass of the
/// transform on the binary input, by one scan each way. Equal to [`transform_line`] on
/// the same line.
fn binary_line(sources: impl Fn(usize) -> bool, out: &mut [u32]) {
    let square = |a: usize| saturate((a as u64) * (a as u64));
    let mut last: Option<usize> = None;
    for (q, o) in out.iter_mut().enumerate() {
        if sources(q) {
            last = Some(q);
        }
        *o = last.map_or(NO_SOURCE, |p| square(q - p));
    }
    let mut next: Option<usize> = None;
    for (q, o) in out.iter_mut().enumerate().rev() {
        if sources(q) {
            next = Some(q);
        }
        if let Some(p) = next {
            *o = (*o).min(square(p - q));
        }
    }
}

/// Distance from each cell centre of a grid to the nearest source cell centre
/// ([`distance_to`]), kept as exact squared distances in cells and read in metres.
#[derive(Clone, Debug, PartialEq)]
pub struct DistanceField {
    squared_cells: SquaredCells,
    cell_m: f64,
}

/// Squared distances in cells², `MAX` for no source.
#[derive(Clone, Debug, PartialEq)]
enum SquaredCells {
    /// Every finite value is below `u16::MAX`.
    Narrow(Vec<u16>),
    Wide(Vec<u32>),
}

impl DistanceField {
    /// The field of `squared` (in cells², [`NO_SOURCE`] for none), narrowed when a
    /// grid of `dims` cannot hold a squared distance of `u16::MAX` or more.
    fn new(squared: Vec<u32>, dims: [usize; 3], cell_m: f64) -> Self {
        let widest = dims
            .iter()
            .map(|n| n.saturating_sub(1).pow(2))
            .sum::<usize>();
        let squared_cells = if widest < usize::from(u16::MAX) {
            SquaredCells::Narrow(
                squared
                    .iter()
                    .map(|d2| u16::try_from(*d2).unwrap_or(u16::MAX))
                    .collect(),
            )
        } else {
            SquaredCells::Wide(squared)
        };
        DistanceField {
            squared_cells,
            cell_m,
        }
    }

    /// Cells in the field.
    #[must_use]
    pub fn len(&self) -> usize {
        match &self.squared_cells {
            SquaredCells::Narrow(d) => d.len(),
            SquaredCells::Wide(d) => d.len(),
        }
    }

    /// Whether the field has no cells.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Distance from cell `i` to the nearest source, metres (`f64::INFINITY` when
    /// there is no source). Panics if `i` is not a cell of the field.
    #[inline]
    #[must_use]
    pub fn metres(&self, i: usize) -> f64 {
        let d2 = match &self.squared_cells {
            SquaredCells::Narrow(d) => match d[i] {
                u16::MAX => return f64::INFINITY,
                d2 => u32::from(d2),
            },
            SquaredCells::Wide(d) => match d[i] {
                NO_SOURCE => return f64::INFINITY,
                d2 => d2,
            },
        };
        f64::from(d2).sqrt() * self.cell_m
    }

    /// [`metres`](Self::metres), or `None` if `i` is not a cell of the field.
    #[must_use]
    pub fn get(&self, i: usize) -> Option<f64> {
        (i < self.len()).then(|| self.metres(i))
    }

    /// Every cell's distance in metres, in cell order.
    pub fn iter_m(&self) -> impl ExactSizeIterator<Item = f64> + '_ {
        (0..self.len()).map(|i| self.metres(i))
    }

    /// Bytes the field holds.
    #[must_use]
    pub fn heap_bytes(&self) -> usize {
        match &self.squared_cells {
            SquaredCells::Narrow(d) => 2 * d.len(),
            SquaredCells::Wide(d) => 4 * d.len(),
        }
    }
}

/// Distance in metres from each cell centre to the nearest source cell centre
/// (infinite everywhere if there is no source). `dims` as in [`LocalGrid::dims`],
/// cells row-major with x fastest.
///
/// Only the box around the cells that are not sources, one cell wider, is
/// transformed: every cell outside that box is a source (distance 0), and for a cell
/// inside it a source beyond the box is never nearer than the box's border cell
/// between them (clamping the source's coordinates into the box moves it closer on
/// every axis, onto a cell outside the inner box, a source). In a window that is
/// mostly unknown, the unsafe-distance field's box is the free space's, often a
/// fraction of the window.
#[must_use]
pub fn distance_to(sources: &[bool], dims: [usize; 3], cell_m: f64) -> DistanceField {
    let squared = match non_source_box(sources, dims) {
        None => vec![0; sources.len()],
        Some((lo, hi)) => {
            let lo = lo.map(|v| v.saturating_sub(1));
            let hi = [0, 1, 2].map(|k| (hi[k] + 1).min(dims[k] - 1));
            if lo == [0; 3] && hi == dims.map(|n| n - 1) {
                squared_distances(sources, dims)
            } else {
                let sub = [0, 1, 2].map(|k| hi[k] - lo[k] + 1);
                // Where each of the box's rows starts in the grid, in the box's order.
                let rows: Vec<usize> = (lo[2]..=hi[2])
                    .flat_map(|z| (lo[1]..=hi[1]).map(move |y| lo[0] + dims[0] * (y + dims[1] * z)))
                    .collect();
                let inner: Vec<bool> = rows
                    .iter()
                    .flat_map(|&at| &sources[at..at + sub[0]])
                    .copied()
                    .collect();
                let mut d = vec![0; sources.len()];
                for (&at, row) in rows
                    .iter()
                    .zip(squared_distances(&inner, sub).chunks(sub[0]))
                {
                    d[at..at + sub[0]].copy_from_slice(row);
                }
                d
            }
        }
    };
    DistanceField::new(squared, dims, cell_m)
}

/// The smallest box (first and last cell on each axis) holding every cell that is
/// not a source; `None` if every cell is one.
fn non_source_box(sources: &[bool], dims: [usize; 3]) -> Option<([usize; 3], [usize; 3])> {
    let nx = dims[0].max(1);
    let mut bounds: Option<([usize; 3], [usize; 3])> = None;
    for (r, row) in sources.chunks(nx).enumerate() {
        let Some(first) = row.iter().position(|s| !s) else {
            continue;
        };
        let last = row.iter().rposition(|s| !s).unwrap_or(first);
        let (y, z) = (r % dims[1], r / dims[1]);
        let (lo, hi) = bounds.get_or_insert(([first, y, z], [last, y, z]));
        *lo = [lo[0].min(first), lo[1].min(y), lo[2].min(z)];
        *hi = [hi[0].max(last), hi[1].max(y), hi[2].max(z)];
    }
    bounds
}

/// Squared distances in cells² ([`NO_SOURCE`] for none) by the separable transform.
///
/// Lines whose values are all 0 (every cell a source) or all [`NO_SOURCE`] (no
/// source yet) are left as they are: the transform maps them to themselves. The lines
/// are transformed on the rayon pool, each on its own, so the result does not depend
/// on the thread count.
fn squared_distances(sources: &[bool], dims: [usize; 3]) -> Vec<u32> {
    let [nx, ny, nz] = dims;
    let mut d = vec![0u32; sources.len()];
    if !d.is_empty() {
        // Along x: each row on its own.
        d.par_chunks_mut(nx)
            .zip(sources.par_chunks(nx))
            .for_each(|(out, src)| binary_line(|q| src[q], out));
        // Along y: each z-slab (contiguous) on its own.
        d.par_chunks_mut(nx * ny).for_each_init(
            || Scratch::new(ny, nx),
            |scratch, plane| {
                scratch.transform(plane, ny, nx);
            },
        );
        // Along z: each y-row of the volume is gathered, transformed and written back.
        let planes: Vec<Option<Vec<u32>>> = (0..ny)
            .into_par_iter()
            .map_init(
                || Scratch::new(nz, nx),
                |scratch, y| {
                    let mut columns = vec![0; nx * nz];
                    for q in 0..nz {
                        let row = y * nx + q * nx * ny;
                        columns[q * nx..(q + 1) * nx].copy_from_slice(&d[row..row + nx]);
                    }
                    scratch.transform(&mut columns, nz, nx).then_some(columns)
                },
            )
            .collect();
        for (y, columns) in planes.into_iter().enumerate() {
            if let Some(columns) = columns {
                for q in 0..nz {
                    let row = y * nx + q * nx * ny;
                    d[row..row + nx].copy_from_slice(&columns[q * nx..(q + 1) * nx]);
                }
            }
        }
    }
    d
}

/// Scratch buffers for the lines of one plane.
struct Scratch {
    v: Vec<usize>,
    z: Vec<f64>,
    out: Vec<u32>,
    slab: Vec<u32>,
}

impl Scratch {
    /// Buffers for `nx` lines of `n` cells.
    fn new(n: usize, nx: usize) -> Self {
        Scratch {
            v: vec![0; n],
            z: vec![0.0; n + 1],
            out: vec![0; n],
            slab: vec![0; nx * n],
        }
    }

    /// Transforms the `nx` lines of `plane`, which holds `n` rows of `nx` cells (line
    /// `a` is cell `a` of every row), in place; `false` if no line changed. Lines all
    /// 0 or all [`NO_SOURCE`] map to themselves and are skipped.
    fn transform(&mut self, plane: &mut [u32], n: usize, nx: usize) -> bool {
        for q in 0..n {
            for (a, x) in plane[q * nx..(q + 1) * nx].iter().enumerate() {
                self.slab[a * n + q] = *x;
            }
        }
        let mut changed = false;
        for line in self.slab[..nx * n].chunks_mut(n.max(1)) {
            let all_zero = line.iter().all(|x| *x == 0);
            if !all_zero && !line.iter().all(|x| *x == NO_SOURCE) {
                transform_line(line, &mut self.v, &mut self.z, &mut self.out);
                changed = true;
            }
        }
        if changed {
            for q in 0..n {
                for (a, x) in plane[q * nx..(q + 1) * nx].iter_mut().enumerate() {
                    *x = self.slab[a * n + q];
                }
            }
        }
        changed
    }
}

/// Distance from each cell to the nearest unsafe (occupied or unknown) cell, metres
/// — what the planner and the collision checker read (DESIGN §6).
#[must_use]
pub fn unsafe_distance(grid: &LocalGrid) -> DistanceField {
    let sources: Vec<bool> = grid
        .values()
        .iter()
        .map(|v| grid.classify(*v) != CellState::Free)
        .collect();
    distance_to(&sources, grid.dims(), grid.resolution_m())
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::{distance_to, transform_line};

    /// The plain separable transform: [`transform_line`] along every line of every axis.
    fn plain(sources: &[bool], dims: [usize; 3], cell_m: f64) -> Vec<f64> {
        let [nx, ny, nz] = dims;
        let mut d: Vec<u32> = sources
            .iter()
            .map(|s| if *s { 0 } else { super::NO_SOURCE })
            .collect();
        let n = nx.max(ny).max(nz);
        let (mut line, mut v, mut z, mut out) =
            (vec![0; n], vec![0; n], vec![0.0; n + 1], vec![0; n]);
        let index = |x: usize, y: usize, zz: usize| x + nx * (y + ny * zz);
        for axis in 0..3 {
            let (len, others) = [(nx, [ny, nz]), (ny, [nx, nz]), (nz, [nx, ny])][axis];
            for b in 0..others[1] {
                for a in 0..others[0] {
                    let at = |q| [index(q, a, b), index(a, q, b), index(a, b, q)][axis];
                    for q in 0..len {
                        line[q] = d[at(q)];
                    }
                    transform_line(&mut line[..len], &mut v, &mut z, &mut out);
                    for q in 0..len {
                        d[at(q)] = line[q];
                    }
                }
            }
        }
        d.iter()
            .map(|s| match *s {
                super::NO_SOURCE => f64::INFINITY,
                s => f64::from(s).sqrt() * cell_m,
            })
            .collect()
    }

    /// A grid too long for `u16` squared distances keeps `u32`s, with the same
    /// metres.
    #[test]
    fn a_long_grid_keeps_wide_squared_distances() {
        let dims = [300, 1, 1];
        let mut sources = vec![false; 300];
        sources[0] = true;
        let field = distance_to(&sources, dims, 0.1);
        assert_eq!(field.heap_bytes(), 4 * 300);
        assert_eq!(field.metres(299).to_bits(), (299.0f64 * 0.1).to_bits());
        let short = distance_to(&sources[..200], [200, 1, 1], 0.1);
        assert_eq!(short.heap_bytes(), 2 * 200);
        assert_eq!(short.metres(199).to_bits(), (199.0f64 * 0.1).to_bits());
        let none = distance_to(&[false; 4], [2, 2, 1], 0.1);
        assert!(none.iter_m().all(f64::is_infinite));
    }

    #[test]
    fn equals_the_plain_transform_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for case in 0..200 {
            let dims = [0, 1, 2].map(|_| rng.random_range(1..14));
            let density = [0.0, 0.01, 0.2, 0.7, 0.97, 1.0][case % 6];
            let n = dims.iter().product();
            let mut sources: Vec<bool> = (0..n).map(|_| rng.random_bool(density)).collect();
            // Whole planes of sources, as unknown space makes them.
            if case % 4 == 1 {
                let plane = dims[0] * dims[1];
                sources[..plane.min(n)].fill(true);
            }
            let fast = distance_to(&sources, dims, 0.2);
            let slow = plain(&sources, dims, 0.2);
            let same = fast
                .iter_m()
                .zip(&slow)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "case {case} {dims:?} density {density}");
        }
    }
}
