//! Exact Euclidean distance transform (Felzenszwalb & Huttenlocher, 2012): linear
//! time, separable over the three axes, on squared distances.

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

/// Distance in metres from each cell centre to the nearest source cell centre
/// (`f64::INFINITY` everywhere if there is no source). `dims` as in
/// [`LocalGrid::dims`], cells row-major with x fastest.
#[must_use]
pub fn distance_to(sources: &[bool], dims: [usize; 3], cell_m: f64) -> Vec<f64> {
    let [nx, ny, nz] = dims;
    let mut d: Vec<f64> = sources
        .iter()
        .map(|s| if *s { 0.0 } else { f64::INFINITY })
        .collect();
    let longest = nx.max(ny).max(nz);
    let (mut line, mut v, mut z, mut out) = (
        vec![0.0; longest],
        vec![0usize; longest],
        vec![0.0; longest + 1],
        vec![0.0; longest],
    );
    let index = |x: usize, y: usize, zz: usize| x + nx * (y + ny * zz);
    for axis in 0..3 {
        let (n, others) = match axis {
            0 => (nx, [ny, nz]),
            1 => (ny, [nx, nz]),
            _ => (nz, [nx, ny]),
        };
        for b in 0..others[1] {
            for a in 0..others[0] {
                let at = |q: usize| match axis {
                    0 => index(q, a, b),
                    1 => index(a, q, b),
                    _ => index(a, b, q),
                };
                for q in 0..n {
                    line[q] = d[at(q)];
                }
                transform_line(&mut line[..n], &mut v, &mut z, &mut out);
                for q in 0..n {
                    d[at(q)] = line[q];
                }
            }
        }
    }
    d.iter().map(|s| s.sqrt() * cell_m).collect()
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
