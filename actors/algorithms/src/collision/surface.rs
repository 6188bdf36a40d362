//! A Gaussian surface model as a set of surface ellipsoids (§7.1.1, one per GMM
//! component), with a uniform-grid spatial index: the distance to the surface (Eq. 7.6),
//! its gradient (Eq. 7.7), the K nearest surface ellipsoids and the blended collision
//! probability (Eq. 7.10).
//!
//! # Spatial index
//!
//! Component centres are hashed into cubic cells of side `h` (twice the largest
//! semi-axis by default). A query visits cells in rings of growing Chebyshev radius `ρ`
//! around the robot's cell, clipped to the occupied cells' bounding box. A component at
//! centre distance `r` has a distance estimate of at least `r − a_robot − a_m` (the
//! estimate is an upper bound on the true distance, itself at least that), and every
//! centre in ring `ρ` is at least `(ρ − 1)h` away, so the search stops once
//! `(ρ − 1)h − a_robot − a_max` exceeds the K-th best estimate so far: the cost follows
//! the nearby components only. Components whose own bound exceeds the K-th best are
//! skipped without evaluating Proposition 1.
//!
//! # Blending (Eq. 7.10)
//!
//! The weight of the k-th nearest surface ellipsoid is `w_k = max(0, ∇d_k · n̂_k)`, with
//! `n̂_k` its shortest principal axis signed towards the robot (Fig. 7.1). As written in
//! the thesis, the set of K nearest changes abruptly, so the blended field still jumps
//! (by less than the unblended one) where a component enters or leaves the set.
//! [`Blending::Tapered`] multiplies each weight by `d_{K+1} − d_k`, which vanishes for
//! the component that is about to leave or enter, making the field continuous there; it
//! is an extension, not in the thesis.

use std::collections::HashMap;

use nalgebra::{SMatrix, SVector};

use super::ellipsoid::{Ellipsoid, PairStatus, Proximity};

/// K of Eq. 7.10 in 2D (§7.1.4).
pub const BLEND_K_2D: usize = 3;
/// K of Eq. 7.10 in 3D (§7.1.4).
pub const BLEND_K_3D: usize = 9;

/// How [`SurfaceEllipsoids::collision_probability`] combines surface ellipsoids.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Blending {
    /// Eq. 7.9 against the nearest surface ellipsoid of Eq. 7.6 only (unblended).
    Nearest,
    /// Eq. 7.10 over the `k` nearest surface ellipsoids with `w_k = max(0, ∇d_k · n̂_k)`.
    Weighted {
        /// Number of neighbours K.
        k: usize,
    },
    /// Eq. 7.10 with each weight multiplied by `d_{K+1} − d_k`, so the field is
    /// continuous where the set of the K nearest changes (extension, module docs).
    Tapered {
        /// Number of neighbours K.
        k: usize,
    },
}

/// A surface ellipsoid found near the robot.
#[derive(Clone, Debug, PartialEq)]
pub struct Neighbor<const D: usize> {
    /// Index of the surface ellipsoid in [`SurfaceEllipsoids::ellipsoids`].
    pub index: usize,
    /// Proposition 1 for the robot and that ellipsoid.
    pub proximity: Proximity<D>,
}

/// The surface ellipsoids of a GMM and a spatial index over them.
#[derive(Clone, Debug)]
pub struct SurfaceEllipsoids<const D: usize> {
    ellipsoids: Vec<Ellipsoid<D>>,
    cell: f64,
    cells: HashMap<[i64; D], Vec<u32>>,
    lo: [i64; D],
    hi: [i64; D],
    max_radius: f64,
}

impl<const D: usize> SurfaceEllipsoids<D> {
    /// Indexes `ellipsoids` with cells twice as wide as the largest semi-axis.
    #[must_use]
    pub fn new(ellipsoids: Vec<Ellipsoid<D>>) -> Self {
        let max_radius = ellipsoids
            .iter()
            .map(Ellipsoid::bounding_radius)
            .fold(0.0, f64::max);
        let cell = if max_radius > 0.0 {
            2.0 * max_radius
        } else {
            1.0
        };
        Self::with_cell_size(ellipsoids, cell)
    }

    /// Indexes `ellipsoids` with cells of side `cell` (metres; replaced by 1 when not
    /// positive and finite).
    #[must_use]
    pub fn with_cell_size(ellipsoids: Vec<Ellipsoid<D>>, cell: f64) -> Self {
        let cell = if cell > 0.0 && cell.is_finite() {
            cell
        } else {
            1.0
        };
        let max_radius = ellipsoids
            .iter()
            .map(Ellipsoid::bounding_radius)
            .fold(0.0, f64::max);
        let mut cells: HashMap<[i64; D], Vec<u32>> = HashMap::new();
        let mut lo = [i64::MAX; D];
        let mut hi = [i64::MIN; D];
        for (i, e) in ellipsoids.iter().enumerate() {
            let key = cell_of(e.center(), cell);
            for d in 0..D {
                lo[d] = lo[d].min(key[d]);
                hi[d] = hi[d].max(key[d]);
            }
            // Index fits in u32: a GMM with 2³² components is not a use case.
            cells.entry(key).or_default().push(i as u32);
        }
        Self {
            ellipsoids,
            cell,
            cells,
            lo,
            hi,
            max_radius,
        }
    }

    /// The surface ellipsoids of the `level`-th isocontours (§7.1.1) of the Gaussian
    /// components `(mean, covariance)`; `None` if a covariance is not positive definite.
    #[must_use]
    pub fn from_gaussians<I>(components: I, level: f64) -> Option<Self>
    where
        I: IntoIterator<Item = (SVector<f64, D>, SMatrix<f64, D, D>)>,
    {
        let ellipsoids = components
            .into_iter()
            .map(|(mean, cov)| Ellipsoid::from_gaussian(mean, &cov, level))
            .collect::<Option<Vec<_>>>()?;
        Some(Self::new(ellipsoids))
    }

    /// The surface ellipsoids, in input order.
    #[must_use]
    pub fn ellipsoids(&self) -> &[Ellipsoid<D>] {
        &self.ellipsoids
    }

    /// Number of surface ellipsoids.
    #[must_use]
    pub fn len(&self) -> usize {
        self.ellipsoids.len()
    }

    /// Whether there is no surface ellipsoid.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.ellipsoids.is_empty()
    }

    /// The surface ellipsoid closest to `robot` by Eq. 7.6 (ties to the lower index);
    /// `None` for an empty set.
    #[must_use]
    pub fn nearest(&self, robot: &Ellipsoid<D>) -> Option<Neighbor<D>> {
        let mut out = Vec::with_capacity(1);
        self.k_nearest(robot, 1, &mut out);
        out.pop()
    }

    /// Distance estimate to the surface (Eq. 7.6) and its gradient (Eq. 7.7, the zero
    /// vector in contact); `None` for an empty set.
    #[must_use]
    pub fn distance(&self, robot: &Ellipsoid<D>) -> Option<(f64, SVector<f64, D>)> {
        self.nearest(robot)
            .map(|n| (n.proximity.distance(), n.proximity.gradient()))
    }

    /// Fills `out` with the `k` surface ellipsoids of smallest distance estimate to
    /// `robot`, closest first (ties to the lower index), through the spatial index.
    #[allow(clippy::needless_range_loop)] // per-axis arithmetic on several arrays
    pub fn k_nearest(&self, robot: &Ellipsoid<D>, k: usize, out: &mut Vec<Neighbor<D>>) {
        out.clear();
        if k == 0 || self.ellipsoids.is_empty() {
            return;
        }
        let b = robot.center();
        let q = cell_of(b, self.cell);
        let mut rho_start = 0;
        let mut rho_end = 0;
        for d in 0..D {
            rho_start = rho_start.max(self.lo[d] - q[d]).max(q[d] - self.hi[d]);
            rho_end = rho_end
                .max((q[d] - self.lo[d]).abs())
                .max((q[d] - self.hi[d]).abs());
        }
        let slack = robot.bounding_radius() + self.max_radius;
        for rho in rho_start..=rho_end {
            let ring_bound = ((rho - 1).max(0) as f64) * self.cell - slack;
            if out.len() == k && ring_bound > out[k - 1].proximity.distance() {
                break;
            }
            let mut first = [0i64; D];
            let mut last = [0i64; D];
            for d in 0..D {
                first[d] = (q[d] - rho).max(self.lo[d]);
                last[d] = (q[d] + rho).min(self.hi[d]);
            }
            if (0..D).any(|d| first[d] > last[d]) {
                continue;
            }
            let volume = (0..D).fold(1.0, |v, d| v * (last[d] - first[d] + 1) as f64);
            if volume > self.ellipsoids.len() as f64 {
                // Sparse map or far query: a full scan is cheaper than this ring.
                out.clear();
                for m in 0..self.ellipsoids.len() {
                    self.consider(robot, m, k, out);
                }
                return;
            }
            let mut key = first;
            loop {
                let on_ring = (0..D).any(|d| (key[d] - q[d]).abs() == rho);
                if on_ring && let Some(members) = self.cells.get(&key) {
                    for &m in members {
                        self.consider(robot, m as usize, k, out);
                    }
                }
                // Odometer over the clipped cube.
                let mut d = 0;
                while d < D {
                    key[d] += 1;
                    if key[d] <= last[d] {
                        break;
                    }
                    key[d] = first[d];
                    d += 1;
                }
                if d == D {
                    break;
                }
            }
        }
    }

    fn consider(&self, robot: &Ellipsoid<D>, m: usize, k: usize, out: &mut Vec<Neighbor<D>>) {
        let e = &self.ellipsoids[m];
        if out.len() == k {
            let bound = (e.center() - robot.center()).norm()
                - robot.bounding_radius()
                - e.bounding_radius();
            if bound > out[k - 1].proximity.distance() {
                return;
            }
        }
        let proximity = Proximity::between(robot, e);
        let d = proximity.distance();
        let pos = out
            .iter()
            .position(|n| (d, m) < (n.proximity.distance(), n.index))
            .unwrap_or(out.len());
        if pos < k {
            if out.len() == k {
                out.pop();
            }
            out.insert(
                pos,
                Neighbor {
                    index: m,
                    proximity,
                },
            );
        }
    }

    /// Collision probability of `robot` whose centre is `N(robot.center(),
    /// position_covariance)` against the surface: Eq. 7.9 against the nearest surface
    /// ellipsoid, or the blend of Eq. 7.10, per `blending`.
    ///
    /// Returns 0 for an empty set and 1 when the robot at its mean position touches a
    /// considered surface ellipsoid. A blend whose weights are all zero (every
    /// neighbour faces away, §7.1.4) falls back to the nearest ellipsoid's Eq. 7.9.
    #[must_use]
    pub fn collision_probability(
        &self,
        robot: &Ellipsoid<D>,
        position_covariance: &SMatrix<f64, D, D>,
        blending: Blending,
    ) -> f64 {
        let mut buf = Vec::new();
        self.collision_probability_with(robot, position_covariance, blending, &mut buf)
    }

    /// [`collision_probability`](Self::collision_probability) reusing `scratch` for the
    /// neighbours (no allocation once it has grown).
    #[must_use]
    pub fn collision_probability_with(
        &self,
        robot: &Ellipsoid<D>,
        position_covariance: &SMatrix<f64, D, D>,
        blending: Blending,
        scratch: &mut Vec<Neighbor<D>>,
    ) -> f64 {
        let (k, tapered) = match blending {
            Blending::Nearest => (1, false),
            Blending::Weighted { k } => (k.max(1), false),
            Blending::Tapered { k } => (k.max(1), true),
        };
        let want = if tapered { k + 1 } else { k };
        self.k_nearest(robot, want, scratch);
        let Some(first) = scratch.first() else {
            return 0.0;
        };
        let considered = &scratch[..scratch.len().min(k)];
        if considered
            .iter()
            .any(|n| n.proximity.status() != PairStatus::Separated)
        {
            return 1.0;
        }
        let nearest = first
            .proximity
            .collision_probability(position_covariance)
            .probability;
        if k == 1 && !tapered {
            return nearest;
        }
        let next_distance = if tapered {
            scratch.get(k).map(|n| n.proximity.distance())
        } else {
            None
        };
        let mut weight_sum = 0.0;
        let mut acc = 0.0;
        for n in considered {
            let normal = self.ellipsoids[n.index].normal_towards(robot.center());
            let mut w = n.proximity.gradient().dot(&normal).max(0.0);
            if let Some(next) = next_distance {
                w *= (next - n.proximity.distance()).max(0.0);
            }
            if w > 0.0 {
                weight_sum += w;
                acc += w * n
                    .proximity
                    .collision_probability(position_covariance)
                    .probability;
            }
        }
        if weight_sum > 0.0 {
            (acc / weight_sum).clamp(0.0, 1.0)
        } else {
            nearest
        }
    }
}

fn cell_of<const D: usize>(p: &SVector<f64, D>, cell: f64) -> [i64; D] {
    // Clamped (and NaN → 0 by the saturating cast) so that cell arithmetic cannot
    // overflow; far points share edge cells, which only costs pruning.
    const LIMIT: f64 = (1u64 << 40) as f64;
    std::array::from_fn(|d| (p[d] / cell).floor().clamp(-LIMIT, LIMIT) as i64)
}
