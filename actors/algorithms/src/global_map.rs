//! Incremental global SOGMM map (thesis §6.1.4, Fig. 6.3).
//!
//! For every new point cloud `Z`:
//!
//! 1. **Relevant subset** (§6.1.4.1, Eq. 6.9): a point is relevant (not yet explained
//!    by the global model `G_G`) when its marginal spatial log-likelihood is below the
//!    threshold φ. Only the components that the spatial hash returns for the point's
//!    cell enter the sum (§6.1.4.3), which is what makes the step independent of the map
//!    size. Points held in the cache from earlier frames are tested again together with
//!    the new frame.
//! 2. **Local model** (§6.1.4.1): when at least `min_relevant_points` points are relevant
//!    they are fitted with the SOGMM pipeline (mean shift → k-means++ → EM); otherwise
//!    they are cached for later frames (the cache keeps the newest `max_cached_points`).
//! 3. **Merge** (§6.1.4.2): the local components are appended and all weights
//!    renormalised by support, `τ_k = n_k / Σ n`, where `n_k` is the number of points a
//!    component was fitted to (`π_j · |Z^r|` for a local component).
//! 4. **Hash** (§6.1.4.3): the local components are inserted into the spatial hash.
//!
//! **The threshold.** The weights of `G_G` are renormalised at every merge, so its
//! density at a surface point already mapped falls as the map grows (∝ 1/ΣN), and a
//! fixed φ on `ln G_G(x)` (Eq. 6.10) would slowly declare old surfaces relevant again.
//! The test here is Eq. 6.9 on the support-scaled density
//! `ℓ(x) = ln Σ_k n_k N(x | ν_k^x, Λ_k^xx) = L(x) + ln Σ_k n_k` (points per m³), i.e.
//! Eq. 6.9 with `φ_t = φ − ln Σ_k n_k`, which leaves the decision for a given surface
//! unchanged as other parts of the map grow.
//!
//! Determinism: the local fit of the `f`-th fit uses seed `config.sogmm.seed + f`; all
//! other steps are deterministic and independent of the rayon thread count, so the same
//! frames and seed give a bit-identical map.

use std::time::Instant;

use nalgebra::{Matrix3, Vector3, Vector4};
use rayon::prelude::*;

use crate::hash::SpatialHash;
use crate::mixture::{Chol3, MixtureError, log_sum_exp};
use crate::sogmm::{FramePoints, Gmm4, SogmmConfig, SogmmError, fit_points};

/// Points per rayon task in the relevance test (values are per point: the split does
/// not change any result).
const BATCH: usize = 512;

/// Bytes of the parameters of one component as held (weight, 4 mean entries and the
/// 10 distinct covariance entries, f64).
pub const COMPONENT_BYTES: usize = (1 + 4 + 10) * 8;

/// Settings of the incremental map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlobalMapConfig {
    /// Cell side `α` of the spatial hash, metres (thesis §6.2.3: 0.2 m).
    pub cell_m: f64,
    /// Relevance threshold φ on the support-scaled spatial log-density
    /// `ln Σ n_k N(x | ν_k^x, Λ_k^xx)` (ln of points per m³, see the module doc): a
    /// point below it is relevant.
    pub relevance_threshold: f64,
    /// Fit a local model once at least this many relevant points are at hand.
    pub min_relevant_points: usize,
    /// Most relevant points kept in the cache between frames (the newest are kept).
    pub max_cached_points: usize,
    /// Settings of the local fits (σ, EM, base seed).
    pub sogmm: SogmmConfig,
}

impl Default for GlobalMapConfig {
    /// α = 0.2 m, φ = 4 (see [`GlobalMapConfig::relevance_threshold`]), fit from 500
    /// points, cache up to 20 000, σ = 0.02.
    fn default() -> Self {
        Self {
            cell_m: 0.2,
            relevance_threshold: 4.0,
            min_relevant_points: 500,
            max_cached_points: 20_000,
            sogmm: SogmmConfig::default(),
        }
    }
}

impl GlobalMapConfig {
    /// Checks the numbers.
    pub fn validate(&self) -> Result<(), SogmmError> {
        if !(self.cell_m.is_finite() && self.cell_m > 0.0) {
            return Err(SogmmError::InvalidInput(
                "hash cell size must be positive and finite",
            ));
        }
        if self.relevance_threshold.is_nan() {
            return Err(SogmmError::InvalidInput(
                "relevance threshold must not be NaN",
            ));
        }
        if self.min_relevant_points == 0 {
            return Err(SogmmError::InvalidInput(
                "min_relevant_points must be at least 1",
            ));
        }
        if !(self.sogmm.bandwidth.is_finite() && self.sogmm.bandwidth > 0.0) {
            return Err(SogmmError::InvalidInput(
                "bandwidth must be positive and finite",
            ));
        }
        Ok(())
    }
}

/// What one [`GlobalMap::insert_frame`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameUpdate {
    /// Points of the new frame.
    pub frame_points: usize,
    /// Points tested (cached + new).
    pub tested_points: usize,
    /// Relevant points among them.
    pub relevant_points: usize,
    /// Points fitted into a local model (0 when the relevant points were cached).
    pub fitted_points: usize,
    /// Components added to the global model.
    pub new_components: usize,
    /// Points in the cache afterwards.
    pub cached_points: usize,
    /// Components the hash returned for the tested points (`|B|`, §6.1.4.1).
    pub queried_components: usize,
    /// Seconds spent on the relevant subset (Eq. 6.9 through the hash).
    pub relevant_s: f64,
    /// Seconds spent on the local SOGMM fit.
    pub fit_s: f64,
    /// Seconds spent merging and hashing.
    pub merge_s: f64,
}

/// The incremental global map: the global model `G_G` with each component's support,
/// the spatial hash `H`, and the cache of relevant points not yet fitted (§6.1.4).
#[derive(Clone, Debug)]
pub struct GlobalMap {
    config: GlobalMapConfig,
    gmm: Option<Gmm4>,
    support: Vec<f64>,
    total_support: f64,
    spatial: Vec<Chol3>,
    log_c: Vec<f64>,
    hash: SpatialHash,
    cache_points: Vec<Vector4<f64>>,
    cache_depth_intensity: Vec<[f64; 2]>,
    fits: u64,
}

impl GlobalMap {
    /// An empty map.
    pub fn new(config: GlobalMapConfig) -> Result<Self, SogmmError> {
        config.validate()?;
        let hash = SpatialHash::new(config.cell_m).ok_or(SogmmError::InvalidInput(
            "hash cell size must be positive and finite",
        ))?;
        Ok(Self {
            config,
            gmm: None,
            support: Vec::new(),
            total_support: 0.0,
            spatial: Vec::new(),
            log_c: Vec::new(),
            hash,
            cache_points: Vec::new(),
            cache_depth_intensity: Vec::new(),
            fits: 0,
        })
    }

    /// The settings.
    #[must_use]
    pub fn config(&self) -> &GlobalMapConfig {
        &self.config
    }

    /// The global model `G_G`; `None` before the first local model.
    #[must_use]
    pub fn gmm(&self) -> Option<&Gmm4> {
        self.gmm.as_ref()
    }

    /// Number of components `|K|`.
    #[must_use]
    pub fn len(&self) -> usize {
        self.support.len()
    }

    /// True before the first local model.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.support.is_empty()
    }

    /// Support `n_k` of every component: the points it was fitted to.
    #[must_use]
    pub fn support(&self) -> &[f64] {
        &self.support
    }

    /// `Σ n_k`: points represented by the map.
    #[must_use]
    pub fn total_support(&self) -> f64 {
        self.total_support
    }

    /// Bytes of the model parameters ([`COMPONENT_BYTES`] per component).
    #[must_use]
    pub fn parameter_bytes(&self) -> usize {
        self.len() * COMPONENT_BYTES
    }

    /// Relevant points waiting in the cache.
    #[must_use]
    pub fn cached_points(&self) -> usize {
        self.cache_points.len()
    }

    /// Local models fitted so far.
    #[must_use]
    pub fn fits(&self) -> u64 {
        self.fits
    }

    /// The spatial hash.
    #[must_use]
    pub fn hash(&self) -> &SpatialHash {
        &self.hash
    }

    /// `ln n_k + ln N(x | ν_k^x, Λ_k^xx)` of component `k` at `x`.
    #[inline]
    fn log_term(&self, k: usize, x: &[f64; 3]) -> f64 {
        self.log_c[k] - 0.5 * self.spatial[k].mahalanobis2(x)
    }

    /// The support-scaled spatial log-density `ℓ(x)` (module doc) over the components
    /// the hash returns for the cell of `x` (§6.1.4.3); `−∞` where none is registered.
    #[must_use]
    pub fn log_density(&self, x: &[f64; 3]) -> f64 {
        let list = self.hash.query(x);
        let mut buf = [0.0f64; 64];
        if list.len() <= buf.len() {
            for (b, &k) in buf.iter_mut().zip(list) {
                *b = self.log_term(k as usize, x);
            }
            log_sum_exp(&buf[..list.len()])
        } else {
            let v: Vec<f64> = list.iter().map(|&k| self.log_term(k as usize, x)).collect();
            log_sum_exp(&v)
        }
    }

    /// `ℓ(x)` over all components: the reference the hash approximates (Eq. 6.10
    /// shifted by `ln Σ n_k`). It is never below [`GlobalMap::log_density`].
    #[must_use]
    pub fn log_density_all(&self, x: &[f64; 3]) -> f64 {
        let v: Vec<f64> = (0..self.len()).map(|k| self.log_term(k, x)).collect();
        log_sum_exp(&v)
    }

    /// Relevance (Eq. 6.9) of each point through the hash: `ℓ(x) < φ`. All points are
    /// relevant while the map is empty.
    #[must_use]
    pub fn relevant(&self, points: &[Vector4<f64>]) -> Vec<bool> {
        self.relevance_with(points, |x| self.log_density(x))
    }

    /// Relevance over all components (the reference of [`GlobalMap::relevant`]); every
    /// point relevant here is relevant there too, since fewer summands give a smaller
    /// density.
    #[must_use]
    pub fn relevant_all(&self, points: &[Vector4<f64>]) -> Vec<bool> {
        self.relevance_with(points, |x| self.log_density_all(x))
    }

    fn relevance_with<F>(&self, points: &[Vector4<f64>], density: F) -> Vec<bool>
    where
        F: Fn(&[f64; 3]) -> f64 + Sync,
    {
        if self.is_empty() {
            return vec![true; points.len()];
        }
        let phi = self.config.relevance_threshold;
        points
            .par_chunks(BATCH)
            .flat_map_iter(|chunk| {
                chunk
                    .iter()
                    .map(|p| density(&[p[0], p[1], p[2]]) < phi)
                    .collect::<Vec<_>>()
            })
            .collect()
    }

    /// Process one point cloud (module doc, steps 1–4). On a fit error the map is left
    /// as it was, except that the relevant points stay cached.
    pub fn insert_frame(&mut self, frame: &FramePoints) -> Result<FrameUpdate, SogmmError> {
        if frame.points.len() != frame.depth_intensity.len() {
            return Err(SogmmError::InvalidInput(
                "points and depth-intensity data differ in length",
            ));
        }
        let mut update = FrameUpdate {
            frame_points: frame.points.len(),
            ..FrameUpdate::default()
        };
        let t0 = Instant::now();
        let mut points = std::mem::take(&mut self.cache_points);
        let mut depth_intensity = std::mem::take(&mut self.cache_depth_intensity);
        points.extend_from_slice(&frame.points);
        depth_intensity.extend_from_slice(&frame.depth_intensity);
        update.tested_points = points.len();
        let mask = self.relevant(&points);
        if !self.is_empty() {
            let xyz: Vec<[f64; 3]> = points.iter().map(|p| [p[0], p[1], p[2]]).collect();
            update.queried_components = self.hash.query_union(&xyz).len();
        }
        let mut keep = mask.iter();
        points.retain(|_| keep.next().copied().unwrap_or(false));
        let mut keep = mask.iter();
        depth_intensity.retain(|_| keep.next().copied().unwrap_or(false));
        update.relevant_points = points.len();
        update.relevant_s = t0.elapsed().as_secs_f64();

        if points.len() >= self.config.min_relevant_points {
            let t1 = Instant::now();
            let config = SogmmConfig {
                seed: self.config.sogmm.seed.wrapping_add(self.fits),
                ..self.config.sogmm
            };
            let fitted = fit_points(&points, &depth_intensity, &config);
            update.fit_s = t1.elapsed().as_secs_f64();
            let fit = match fitted {
                Ok(fit) => fit,
                Err(e) => {
                    self.keep_cache(points, depth_intensity);
                    return Err(e);
                }
            };
            self.fits += 1;
            let t2 = Instant::now();
            if let Err(e) = self.merge(&fit.gmm, points.len() as f64) {
                self.keep_cache(points, depth_intensity);
                return Err(e);
            }
            update.merge_s = t2.elapsed().as_secs_f64();
            update.fitted_points = points.len();
            update.new_components = fit.gmm.len();
        } else {
            self.keep_cache(points, depth_intensity);
        }
        update.cached_points = self.cache_points.len();
        Ok(update)
    }

    fn keep_cache(&mut self, mut points: Vec<Vector4<f64>>, mut depth_intensity: Vec<[f64; 2]>) {
        let excess = points.len().saturating_sub(self.config.max_cached_points);
        points.drain(..excess);
        depth_intensity.drain(..excess);
        self.cache_points = points;
        self.cache_depth_intensity = depth_intensity;
    }

    /// Merge a local model fitted to `support_points` points (§6.1.4.2) and hash its
    /// components (§6.1.4.3): component `j` gets support `π_j · support_points`, and all
    /// weights become `n_k / Σ n`. On error the map is unchanged.
    pub fn merge(&mut self, local: &Gmm4, support_points: f64) -> Result<(), SogmmError> {
        if !(support_points.is_finite() && support_points > 0.0) {
            return Err(SogmmError::InvalidInput(
                "support of a local model must be positive and finite",
            ));
        }
        let mut spatial = Vec::with_capacity(local.len());
        let mut marginals = Vec::with_capacity(local.len());
        for (component, (mean, cov)) in local.means().iter().zip(local.covariances()).enumerate() {
            let m: Vector3<f64> = mean.xyz();
            let c: Matrix3<f64> = cov.fixed_view::<3, 3>(0, 0).into_owned();
            spatial
                .push(Chol3::new(&m, &c).ok_or(MixtureError::NotPositiveDefinite { component })?);
            marginals.push((m, c));
        }
        let new_support: Vec<f64> = local.weights().iter().map(|w| w * support_points).collect();
        let mut support = self.support.clone();
        support.extend_from_slice(&new_support);
        let total: f64 = support.iter().sum();
        match self.gmm.as_mut() {
            None => self.gmm = Some(local.clone()),
            Some(gmm) => {
                let weights = support.iter().map(|n| n / total).collect();
                gmm.append_reweighted(local, weights)?;
            }
        }
        let first = self.support.len();
        for (j, ((c, (m, cov)), n)) in spatial.iter().zip(&marginals).zip(&new_support).enumerate()
        {
            self.log_c.push(n.ln() + c.log_norm);
            self.hash.insert((first + j) as u32, m, cov);
        }
        self.spatial.extend(spatial);
        self.support = support;
        self.total_support = total;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sogmm::{frame_points, synthetic};

    const LENGTH_M: f64 = 12.0;

    fn flight(n: usize, w: u32, h: u32) -> Vec<FramePoints> {
        let scene = synthetic::Scene::corridor(LENGTH_M);
        let intr = synthetic::intrinsics(w, h);
        (0..n)
            .map(|i| {
                let pose = synthetic::flight_pose(i, n, LENGTH_M);
                let (d, g) = scene.render(&intr, &pose);
                frame_points(&d, &g, &intr, &pose).unwrap()
            })
            .collect()
    }

    fn config() -> GlobalMapConfig {
        GlobalMapConfig {
            min_relevant_points: 150,
            sogmm: SogmmConfig {
                bandwidth: 0.03,
                seed: 7,
                ..SogmmConfig::default()
            },
            ..GlobalMapConfig::default()
        }
    }

    fn build(frames: &[FramePoints], config: GlobalMapConfig) -> GlobalMap {
        let mut map = GlobalMap::new(config).unwrap();
        for f in frames {
            map.insert_frame(f).unwrap();
        }
        map
    }

    #[test]
    fn merges_keep_a_valid_support_weighted_mixture() {
        let frames = flight(24, 40, 30);
        let mut map = GlobalMap::new(config()).unwrap();
        let mut fitted = 0;
        for f in &frames {
            let before = map.len();
            let up = map.insert_frame(f).unwrap();
            fitted += up.fitted_points;
            assert_eq!(map.len(), before + up.new_components);
            assert!(up.cached_points <= map.config().max_cached_points);
            let Some(gmm) = map.gmm() else { continue };
            gmm.validate().unwrap();
            let sum: f64 = gmm.weights().iter().sum();
            assert!((sum - 1.0).abs() < 1e-12, "weights sum to {sum}");
            for (w, n) in gmm.weights().iter().zip(map.support()) {
                assert!((w - n / map.total_support()).abs() < 1e-15);
            }
            for c in gmm.covariances() {
                assert!(c.symmetric_eigenvalues().min() > 0.0);
                assert!(c.fixed_view::<3, 3>(0, 0).into_owned().cholesky().is_some());
            }
        }
        assert!(map.fits() > 2, "{} fits", map.fits());
        // Support counts the fitted points exactly (π_j |Z^r| summed over j).
        assert!((map.total_support() - fitted as f64).abs() < 1e-6 * fitted as f64);
        assert_eq!(map.parameter_bytes(), map.len() * COMPONENT_BYTES);
    }

    #[test]
    fn hash_query_matches_brute_force() {
        let frames = flight(16, 40, 30);
        let map = build(&frames[..15], config());
        let gmm = map.gmm().unwrap();
        // Brute force: the components whose key cells contain the query's cell.
        let cells: Vec<Vec<[i64; 3]>> = gmm
            .means()
            .iter()
            .zip(gmm.covariances())
            .map(|(m, c)| {
                map.hash()
                    .component_cells(&m.xyz(), &c.fixed_view::<3, 3>(0, 0).into_owned())
            })
            .collect();
        let probe = &frames[15].points;
        for p in probe.iter().step_by(7) {
            let x = [p[0], p[1], p[2]];
            let key = map.hash().key(&x);
            let brute: Vec<u32> = (0..map.len() as u32)
                .filter(|&k| cells[k as usize].binary_search(&key).is_ok())
                .collect();
            assert_eq!(map.hash().query(&x), brute.as_slice());
            // Fewer summands: never a larger density than the sum over all components.
            assert!(map.log_density(&x) <= map.log_density_all(&x) + 1e-9);
        }
        // Same relevant set up to the points near φ, and never fewer relevant points.
        let (hash, all) = (map.relevant(probe), map.relevant_all(probe));
        let differ = hash.iter().zip(&all).filter(|(a, b)| a != b).count();
        for (h, a) in hash.iter().zip(&all) {
            assert!(
                *h || !*a,
                "relevant over all components but not through the hash"
            );
        }
        assert!(
            differ * 50 <= probe.len(),
            "{differ} of {} points differ",
            probe.len()
        );
    }

    #[test]
    fn same_seed_gives_identical_map_on_any_thread_count() {
        let frames = flight(10, 40, 30);
        let run = |threads: usize, seed: u64| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut c = config();
            c.sogmm.seed = seed;
            pool.install(|| build(&frames, c))
        };
        let (a, b, c) = (run(1, 7), run(3, 7), run(1, 8));
        assert_eq!(a.gmm(), b.gmm());
        assert_eq!(a.support(), b.support());
        assert_eq!(a.cached_points(), b.cached_points());
        assert_ne!(a.gmm(), c.gmm());
    }

    #[test]
    fn a_frame_seen_again_is_explained_and_small_subsets_are_cached() {
        let frames = flight(3, 40, 30);
        let mut map = GlobalMap::new(config()).unwrap();
        let first = map.insert_frame(&frames[0]).unwrap();
        assert_eq!(first.relevant_points, frames[0].len());
        assert_eq!(first.fitted_points, frames[0].len());
        let again = map.insert_frame(&frames[0]).unwrap();
        assert!(
            again.relevant_points * 20 < frames[0].len(),
            "{} of {} relevant on a second look",
            again.relevant_points,
            frames[0].len()
        );
        // With a high minimum, relevant points wait in the cache, bounded by its size.
        let mut c = config();
        c.min_relevant_points = 1_000_000;
        c.max_cached_points = 500;
        let mut map = GlobalMap::new(c).unwrap();
        let up = map.insert_frame(&frames[0]).unwrap();
        assert_eq!((up.fitted_points, up.new_components), (0, 0));
        assert_eq!(map.cached_points(), 500);
        assert!(map.is_empty() && map.gmm().is_none());
        let up = map.insert_frame(&frames[1]).unwrap();
        assert_eq!(up.tested_points, 500 + frames[1].len());
    }

    #[test]
    fn bad_settings_and_input_are_errors() {
        let bad = |f: fn(&mut GlobalMapConfig)| {
            let mut c = GlobalMapConfig::default();
            f(&mut c);
            GlobalMap::new(c).is_err()
        };
        assert!(bad(|c| c.cell_m = 0.0));
        assert!(bad(|c| c.cell_m = f64::INFINITY));
        assert!(bad(|c| c.relevance_threshold = f64::NAN));
        assert!(bad(|c| c.min_relevant_points = 0));
        assert!(bad(|c| c.sogmm.bandwidth = -1.0));
        let mut map = GlobalMap::new(GlobalMapConfig::default()).unwrap();
        let mut fp = flight(1, 20, 15).remove(0);
        fp.depth_intensity.pop();
        assert!(map.insert_frame(&fp).is_err());
        let one = Gmm4::new(
            vec![1.0],
            vec![Vector4::zeros()],
            vec![nalgebra::Matrix4::identity()],
        )
        .unwrap();
        assert!(map.merge(&one, 0.0).is_err());
        assert!(map.merge(&one, f64::NAN).is_err());
        assert!(map.is_empty());
        map.merge(&one, 10.0).unwrap();
        assert_eq!(map.len(), 1);
    }
}
