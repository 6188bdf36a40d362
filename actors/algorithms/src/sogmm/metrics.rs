//! Reconstruction measures of §6.2.4: mean reconstruction error, precision and recall
//! within a radius, and intensity PSNR, from nearest neighbours between a predicted and
//! a ground-truth 4D point cloud.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use nalgebra::Vector4;

/// Scores of a reconstruction against ground truth (§6.2.4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReconstructionMetrics {
    /// Mean distance from each predicted point to its nearest ground-truth point, metres.
    pub mre_m: f64,
    /// Fraction of predicted points within the radius of a ground-truth point.
    pub precision: f64,
    /// Fraction of ground-truth points within the radius of a predicted point.
    pub recall: f64,
    /// `10 log10(1 / MSE)` of the intensity of each predicted point against its nearest
    /// ground-truth point (intensities in [0, 1]).
    pub psnr_db: f64,
}

/// Nearest-neighbour search over 3D positions on a hashed uniform grid.
pub struct NearestGrid<'a> {
    points: &'a [Vector4<f64>],
    h: f64,
    cells: HashMap<[i64; 3], Vec<u32>, BuildHasherDefault<CellHasher>>,
    max_ring: i64,
}

impl<'a> NearestGrid<'a> {
    /// Index the (x, y, z) of `points` with cell side `h` metres.
    #[must_use]
    pub fn new(points: &'a [Vector4<f64>], h: f64) -> Self {
        let mut cells: HashMap<[i64; 3], Vec<u32>, BuildHasherDefault<CellHasher>> =
            HashMap::default();
        let mut lo = [i64::MAX; 3];
        let mut hi = [i64::MIN; 3];
        for (i, p) in points.iter().enumerate() {
            let k = key(p, h);
            for a in 0..3 {
                lo[a] = lo[a].min(k[a]);
                hi[a] = hi[a].max(k[a]);
            }
            cells.entry(k).or_default().push(i as u32);
        }
        let max_ring = (0..3)
            .map(|a| hi[a].saturating_sub(lo[a]))
            .max()
            .unwrap_or(0)
            + 2;
        Self {
            points,
            h,
            cells,
            max_ring,
        }
    }

    /// Index and distance of the nearest point to `q` (spatial part), if any.
    #[must_use]
    pub fn nearest(&self, q: &Vector4<f64>) -> Option<(usize, f64)> {
        self.nearest_up_to(q, self.max_ring)
    }

    /// Whether some point lies within `radius` of `q`.
    #[must_use]
    pub fn any_within(&self, q: &Vector4<f64>, radius: f64) -> bool {
        let rings = (radius / self.h).ceil() as i64;
        self.nearest_up_to(q, rings)
            .is_some_and(|(_, d)| d <= radius)
    }

    fn nearest_up_to(&self, q: &Vector4<f64>, max_ring: i64) -> Option<(usize, f64)> {
        let c = key(q, self.h);
        let mut best: Option<(usize, f64)> = None;
        let mut r = 0i64;
        while r <= max_ring {
            for dz in -r..=r {
                for dy in -r..=r {
                    // Only the shell of the (2r+1)³ cube: full rows on its faces, the two
                    // end cells elsewhere.
                    let full = dz.abs() == r || dy.abs() == r;
                    let step = if full || r == 0 { 1 } else { (2 * r) as usize };
                    for dx in (-r..=r).step_by(step) {
                        if let Some(list) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                            for &i in list {
                                let d = (self.points[i as usize].xyz() - q.xyz()).norm();
                                if best.is_none_or(|(_, b)| d < b) {
                                    best = Some((i as usize, d));
                                }
                            }
                        }
                    }
                }
            }
            // Cells beyond ring r are at least r·h away.
            if best.is_some_and(|(_, b)| b <= r as f64 * self.h) {
                break;
            }
            r += 1;
        }
        best
    }
}

/// Multiply–rotate hasher for integer cell keys (the default SipHash dominates the
/// nearest-neighbour queries).
#[derive(Default)]
struct CellHasher(u64);

impl Hasher for CellHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.write_u64(u64::from(*b));
        }
    }

    fn write_i64(&mut self, v: i64) {
        self.write_u64(v as u64);
    }

    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(23) ^ v).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

fn key(p: &Vector4<f64>, h: f64) -> [i64; 3] {
    [
        (p[0] / h).floor() as i64,
        (p[1] / h).floor() as i64,
        (p[2] / h).floor() as i64,
    ]
}

/// Scores `predicted` against `truth` (both `(x, y, z, intensity)`) with the precision /
/// recall radius `radius_m` (0.01 in the thesis). Empty inputs give NaN scores.
#[must_use]
pub fn reconstruction_metrics(
    predicted: &[Vector4<f64>],
    truth: &[Vector4<f64>],
    radius_m: f64,
) -> ReconstructionMetrics {
    // Cells of 2.5 radii keep the ring search short for points a few radii off.
    let truth_grid = NearestGrid::new(truth, 2.5 * radius_m.max(1e-4));
    let pred_grid = NearestGrid::new(predicted, radius_m.max(1e-4));
    let (mut sum_d, mut within, mut se, mut n) = (0.0, 0usize, 0.0, 0usize);
    for p in predicted {
        if let Some((i, d)) = truth_grid.nearest(p) {
            sum_d += d;
            within += usize::from(d <= radius_m);
            se += (p[3] - truth[i][3]).powi(2);
            n += 1;
        }
    }
    let recalled = truth
        .iter()
        .filter(|t| pred_grid.any_within(t, radius_m))
        .count();
    let nf = n as f64;
    ReconstructionMetrics {
        mre_m: sum_d / nf,
        precision: within as f64 / nf,
        recall: recalled as f64 / truth.len() as f64,
        psnr_db: 10.0 * (nf / se).log10(),
    }
}
