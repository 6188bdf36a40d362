//! Exact Euclidean distance transform (Felzenszwalb & Huttenlocher, 2012): linear
//! time, separable over the three axes, on squared distances.

use rayon::prelude::*;

use super::{CellState, LocalGrid};

/// Squared-distance transform along one line: `f` holds 0 at sources and `INF`
/// elsewhere on entry, squared distances (in cells², along this and earlier axes) on
/// exit. `v`, `z` and `out` are scratch buffers of at least `f.len()` (+1 for `z`).
fn transform_line(f: &mut [f64], v: &mut [usize], z: &mut [f64], out: &mut [f64]) {
    let n = f.len();
    let mut k = 0usize;
    let mut found = false;
    for q in 0..n {
        if f[q].is_infinite() {
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
            let s =
                ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q as f64 - p as f64));
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
        let d = q as f64 - v[k] as f64;
        *o = d * d + f[v[k]];
    }
    f[..n].copy_from_slice(&out[..n]);
}

/// Squared distance (in cells²) from each cell of a line of `n` cells to the nearest
/// source along it (`INFINITY` when the line has none): the first pass of the
/// transform on the binary input, by one scan each way. Equal to [`transform_line`] on
/// the same line (the squares of small integers are exact).
fn binary_line(sources: impl Fn(usize) -> bool, out: &mut [f64]) {
    let mut last: Option<usize> = None;
    for (q, o) in out.iter_mut().enumerate() {
        if sources(q) {
            last = Some(q);
        }
        *o = last.map_or(f64::INFINITY, |p| ((q - p) * (q - p)) as f64);
    }
    let mut next: Option<usize> = None;
    for (q, o) in out.iter_mut().enumerate().rev() {
        if sources(q) {
            next = Some(q);
        }
        if let Some(p) = next {
            *o = o.min(((p - q) * (p - q)) as f64);
        }
    }
}

/// Distance in metres from each cell centre to the nearest source cell centre
/// (`f64::INFINITY` everywhere if there is no source). `dims` as in
/// [`LocalGrid::dims`], cells row-major with x fastest.
///
/// Lines whose values are all 0 (every cell a source, common in a grid that is mostly
/// unknown) or all infinite (no source yet) are left as they are: the transform maps
/// them to themselves. The lines are transformed on the rayon pool, each on its own, so
/// the result does not depend on the thread count.
#[must_use]
pub fn distance_to(sources: &[bool], dims: [usize; 3], cell_m: f64) -> Vec<f64> {
    let [nx, ny, nz] = dims;
    let mut d = vec![0.0; sources.len()];
    if d.is_empty() {
        return d;
    }
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
    let planes: Vec<Option<Vec<f64>>> = (0..ny)
        .into_par_iter()
        .map_init(
            || Scratch::new(nz, nx),
            |scratch, y| {
                let mut columns = vec![0.0; nx * nz];
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
    d.par_iter_mut().for_each(|x| *x = x.sqrt() * cell_m);
    d
}

/// Scratch buffers for the lines of one plane.
struct Scratch {
    v: Vec<usize>,
    z: Vec<f64>,
    out: Vec<f64>,
    slab: Vec<f64>,
}

impl Scratch {
    /// Buffers for `nx` lines of `n` cells.
    fn new(n: usize, nx: usize) -> Self {
        Scratch {
            v: vec![0; n],
            z: vec![0.0; n + 1],
            out: vec![0.0; n],
            slab: vec![0.0; nx * n],
        }
    }

    /// Transforms the `nx` lines of `plane`, which holds `n` rows of `nx` cells (line
    /// `a` is cell `a` of every row), in place; `false` if no line changed. Lines all
    /// 0 or all infinite map to themselves and are skipped.
    fn transform(&mut self, plane: &mut [f64], n: usize, nx: usize) -> bool {
        for q in 0..n {
            for (a, x) in plane[q * nx..(q + 1) * nx].iter().enumerate() {
                self.slab[a * n + q] = *x;
            }
        }
        let mut changed = false;
        for line in self.slab[..nx * n].chunks_mut(n.max(1)) {
            let all_zero = line.iter().all(|x| *x == 0.0);
            if !all_zero && !line.iter().all(|x| x.is_infinite()) {
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
pub fn unsafe_distance(grid: &LocalGrid) -> Vec<f64> {
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
        let mut d: Vec<f64> = sources
            .iter()
            .map(|s| if *s { 0.0 } else { f64::INFINITY })
            .collect();
        let n = nx.max(ny).max(nz);
        let (mut line, mut v, mut z, mut out) =
            (vec![0.0; n], vec![0; n], vec![0.0; n + 1], vec![0.0; n]);
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
        d.iter().map(|s| s.sqrt() * cell_m).collect()
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
                .iter()
                .zip(&slow)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "case {case} {dims:?} density {density}");
        }
    }
}
