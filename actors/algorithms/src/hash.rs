//! Spatial hash of mixture components (thesis §6.1.4.3): a sparse uniform grid of cell
//! side `α` mapping a 3D position to the indices of the components registered in its
//! cell.
//!
//! A component is registered under keys at its spatial mean and at points of its 1σ,
//! 2σ and 3σ constant-probability ellipsoids (the thesis' keys). The thesis does not say
//! how many ellipsoid points; here every shell gets its six principal-axis end points
//! plus a Fibonacci lattice on the unit sphere mapped onto the shell, dense enough that
//! neighbouring keys lie at most about `α/2` apart, so a shell leaves no gap of a whole
//! cell. For the flat, surface-like components of a SOGMM the shells cover the
//! component's disc out to 3σ. The cell set of a component is deduplicated, and
//! components are inserted in increasing index order, so every cell list is sorted.
//!
//! Unlike the thesis' bounded grid (extent `[N_x, N_y, N_z]` around an origin), the
//! cells live in a hash map keyed by integer cell coordinates: the map has no extent.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use nalgebra::{Matrix3, Vector3};

/// Most lattice points per shell (a very large component gets sparser keys).
const MAX_SHELL_POINTS: usize = 4096;

/// The constant-probability shells keyed (Mahalanobis radii 1, 2, 3: 68 %, 95 %,
/// 99.7 % along one axis, as the thesis states them).
const SHELLS: [f64; 3] = [1.0, 2.0, 3.0];

/// Integer coordinates of a cell.
pub type CellKey = [i64; 3];

/// A deterministic, fast hasher for cell keys (FNV-1a style mixing of the coordinates).
#[derive(Clone, Copy, Debug)]
pub struct CellHasher(u64);

impl Default for CellHasher {
    fn default() -> Self {
        CellHasher(0xcbf2_9ce4_8422_2325)
    }
}

impl Hasher for CellHasher {
    fn finish(&self) -> u64 {
        // Final avalanche (splitmix64) so that nearby cells spread over the buckets.
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 = (self.0 ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    fn write_i64(&mut self, v: i64) {
        self.0 = (self.0 ^ v as u64).wrapping_mul(0x0000_0100_0000_01b3);
    }

    fn write_u64(&mut self, v: u64) {
        self.write_i64(v as i64);
    }

    fn write_usize(&mut self, v: usize) {
        self.write_i64(v as i64);
    }
}

/// The spatial hash `H` of §6.1.4.3.
#[derive(Clone, Debug)]
pub struct SpatialHash {
    cell_m: f64,
    inv_cell: f64,
    cells: HashMap<CellKey, Vec<u32>, BuildHasherDefault<CellHasher>>,
    entries: usize,
}

impl SpatialHash {
    /// An empty hash with cell side `cell_m` (the thesis' `α`, 0.2 m there); `None`
    /// unless `cell_m` is positive and finite.
    #[must_use]
    pub fn new(cell_m: f64) -> Option<Self> {
        (cell_m.is_finite() && cell_m > 0.0).then(|| SpatialHash {
            cell_m,
            inv_cell: 1.0 / cell_m,
            cells: HashMap::default(),
            entries: 0,
        })
    }

    /// Cell side `α`, metres.
    #[must_use]
    pub fn cell_m(&self) -> f64 {
        self.cell_m
    }

    /// Occupied cells.
    #[must_use]
    pub fn cells(&self) -> usize {
        self.cells.len()
    }

    /// Total (cell, component) entries.
    #[must_use]
    pub fn entries(&self) -> usize {
        self.entries
    }

    /// The cell of a position: `⌊p / α⌋` per axis (saturating for huge values; a
    /// non-finite coordinate maps to 0).
    #[must_use]
    pub fn key(&self, p: &[f64; 3]) -> CellKey {
        p.map(|v| {
            let c = (v * self.inv_cell).floor();
            if c.is_nan() { 0 } else { c as i64 }
        })
    }

    /// The cells of component `component` (mean `mean`, spatial covariance `cov`): the
    /// cells of its keys (see the module doc), sorted and deduplicated.
    #[must_use]
    pub fn component_cells(&self, mean: &Vector3<f64>, cov: &Matrix3<f64>) -> Vec<CellKey> {
        let mut cells: Vec<CellKey> = ellipsoid_keys(mean, cov, self.cell_m)
            .iter()
            .map(|p| self.key(p))
            .collect();
        cells.sort_unstable();
        cells.dedup();
        cells
    }

    /// Register component `component` under its keys. Components must be inserted in
    /// increasing index order for the cell lists to stay sorted (the global map does).
    pub fn insert(&mut self, component: u32, mean: &Vector3<f64>, cov: &Matrix3<f64>) {
        for cell in self.component_cells(mean, cov) {
            self.cells.entry(cell).or_default().push(component);
            self.entries += 1;
        }
    }

    /// The components registered in the cell of `p` (sorted; empty if none).
    #[must_use]
    pub fn query(&self, p: &[f64; 3]) -> &[u32] {
        self.cells.get(&self.key(p)).map_or(&[], Vec::as_slice)
    }

    /// The union `B` of the components returned for all of `points` (sorted, unique):
    /// the subset of §6.1.4.1.
    #[must_use]
    pub fn query_union(&self, points: &[[f64; 3]]) -> Vec<u32> {
        let mut keys: Vec<CellKey> = points.iter().map(|p| self.key(p)).collect();
        keys.sort_unstable();
        keys.dedup();
        let mut out: Vec<u32> = keys
            .iter()
            .filter_map(|k| self.cells.get(k))
            .flatten()
            .copied()
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    }
}

/// Key points of a 3D Gaussian (§6.1.4.3): its mean and points on its 1σ, 2σ and 3σ
/// ellipsoids, spaced at most about `spacing_m / 2` apart (see the module doc). A
/// covariance that is not symmetric positive semi-definite yields the mean only.
#[must_use]
pub fn ellipsoid_keys(mean: &Vector3<f64>, cov: &Matrix3<f64>, spacing_m: f64) -> Vec<[f64; 3]> {
    let mut keys = vec![[mean.x, mean.y, mean.z]];
    if !(cov.iter().all(|v| v.is_finite()) && spacing_m.is_finite() && spacing_m > 0.0) {
        return keys;
    }
    let eig = cov.symmetric_eigen();
    if eig.eigenvalues.iter().any(|l| *l < 0.0) {
        return keys;
    }
    // Columns: principal axes scaled by the standard deviations.
    let mut axes = eig.eigenvectors;
    for (a, l) in eig.eigenvalues.iter().enumerate() {
        let s = l.sqrt();
        for r in 0..3 {
            axes[(r, a)] *= s;
        }
    }
    let sd_max = eig.eigenvalues.max().sqrt();
    for k in SHELLS {
        for a in 0..3 {
            for sign in [-1.0, 1.0] {
                let p = mean + axes.column(a) * (k * sign);
                keys.push([p.x, p.y, p.z]);
            }
        }
        // n Fibonacci points on the unit sphere are about sqrt(4π / n) apart; the shell
        // stretches them by at most k·sd_max.
        let ratio = 2.0 * k * sd_max / spacing_m;
        let n = (4.0 * std::f64::consts::PI * ratio * ratio).ceil();
        let n = if n.is_finite() {
            (n as usize).clamp(0, MAX_SHELL_POINTS)
        } else {
            MAX_SHELL_POINTS
        };
        for u in fibonacci_sphere(n) {
            let p = mean + axes * (u * k);
            keys.push([p.x, p.y, p.z]);
        }
    }
    keys
}

/// `n` nearly uniform unit vectors (golden-angle spiral); empty for `n = 0`.
fn fibonacci_sphere(n: usize) -> impl Iterator<Item = Vector3<f64>> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n).map(move |i| {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let (s, c) = (golden * i as f64).sin_cos();
        Vector3::new(r * c, r * s, z)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_lie_on_their_shells() {
        let mean = Vector3::new(1.0, -2.0, 0.5);
        let cov = Matrix3::new(0.04, 0.01, 0.0, 0.01, 0.02, 0.0, 0.0, 0.0, 1e-5);
        let inv = cov.try_inverse().unwrap();
        let keys = ellipsoid_keys(&mean, &cov, 0.2);
        assert_eq!(keys[0], [mean.x, mean.y, mean.z]);
        for p in &keys[1..] {
            let d = Vector3::from(*p) - mean;
            let m = (d.transpose() * inv * d)[0].sqrt();
            assert!(
                SHELLS.iter().any(|k| (m - k).abs() < 1e-6),
                "Mahalanobis radius {m}"
            );
        }
        // Every shell has its six axis end points and a lattice.
        assert!(keys.len() > 1 + 3 * 6);
    }

    #[test]
    fn shells_leave_no_gap_of_a_cell() {
        // A flat disc of 0.3 m standard deviation: every point of its 3σ disc must be
        // within α of a key (the lattice spacing is about α/2).
        let alpha = 0.2;
        let mean = Vector3::zeros();
        let cov = Matrix3::from_diagonal(&Vector3::new(0.09, 0.09, 1e-6));
        let keys = ellipsoid_keys(&mean, &cov, alpha);
        for i in 0..40 {
            for j in 0..40 {
                let p = Vector3::new(
                    -0.9 + 1.8 * i as f64 / 39.0,
                    -0.9 + 1.8 * j as f64 / 39.0,
                    0.0,
                );
                if p.norm() > 0.9 {
                    continue;
                }
                let nearest = keys
                    .iter()
                    .map(|k| (Vector3::from(*k) - p).norm())
                    .fold(f64::INFINITY, f64::min);
                assert!(nearest < 0.6 * alpha, "{p}: {nearest}");
            }
        }
    }

    #[test]
    fn query_matches_brute_force_over_components() {
        let mut hash = SpatialHash::new(0.25).unwrap();
        let comps: Vec<(Vector3<f64>, Matrix3<f64>)> = (0..30)
            .map(|i| {
                let f = f64::from(i);
                (
                    Vector3::new((f * 0.37).sin() * 2.0, (f * 0.71).cos() * 2.0, f * 0.05),
                    Matrix3::from_diagonal(&Vector3::new(
                        0.01 + 0.002 * f,
                        0.02,
                        0.0001 + 0.0005 * f,
                    )),
                )
            })
            .collect();
        for (k, (m, c)) in comps.iter().enumerate() {
            hash.insert(k as u32, m, c);
        }
        let cells: Vec<Vec<CellKey>> = comps
            .iter()
            .map(|(m, c)| hash.component_cells(m, c))
            .collect();
        let mut queries = Vec::new();
        for i in 0..2000 {
            let t = f64::from(i);
            let p = [
                (t * 0.013).sin() * 2.6,
                (t * 0.029).cos() * 2.6,
                (t * 0.0007) * 1.5 - 0.2,
            ];
            let brute: Vec<u32> = (0..comps.len() as u32)
                .filter(|&k| cells[k as usize].contains(&hash.key(&p)))
                .collect();
            assert_eq!(hash.query(&p), brute.as_slice());
            queries.push(p);
        }
        let mut union: Vec<u32> = queries
            .iter()
            .flat_map(|p| hash.query(p).to_vec())
            .collect();
        union.sort_unstable();
        union.dedup();
        assert_eq!(hash.query_union(&queries), union);
        assert_eq!(hash.entries(), cells.iter().map(Vec::len).sum::<usize>());
    }

    #[test]
    fn rejects_bad_cell_sizes_and_bad_covariances() {
        assert!(SpatialHash::new(0.0).is_none());
        assert!(SpatialHash::new(f64::NAN).is_none());
        let nan = Matrix3::from_element(f64::NAN);
        assert_eq!(ellipsoid_keys(&Vector3::zeros(), &nan, 0.2).len(), 1);
        let mut h = SpatialHash::new(0.2).unwrap();
        assert_eq!(h.key(&[f64::NAN, 0.1, -0.1]), [0, 0, -1]);
        h.insert(0, &Vector3::zeros(), &nan);
        assert_eq!(h.query(&[0.05, 0.05, 0.05]), &[0]);
    }
}
