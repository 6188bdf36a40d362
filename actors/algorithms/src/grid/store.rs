//! The GMM components a local grid is rebuilt from (thesis §3.2.3, Fig. 3.2; paper
//! IV-B): every keyframe mixture the grid has been given, with its sensor origin, in a
//! spatial index over the component means.
//!
//! Each component is sampled deterministically (its own generator, seeded by the
//! keyframe's source, the keyframe id and the component index), so the same component
//! always yields the same points. When the window moves, only the components that can
//! reach a novel box are re-traced, into those boxes only; because every cell then
//! receives exactly the updates, in exactly the order, that a rebuild from scratch
//! would give it, the moved grid equals a grid rebuilt at the new pose cell for cell.

use std::collections::HashMap;

use nalgebra::{Matrix3, Point3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::scan::{ScanScratch, UpdateRule};
use super::{CellBox, LocalGrid};
use crate::geometry::Aabb;
use crate::keyframe::Keyframe;
use crate::mixture::box_muller;
use troupe_core::RobotId;

/// Who produced a keyframe (part of each component's sampling seed).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum KeyframeSource {
    /// This robot's mapper (`msgs::KEYFRAME`).
    Own,
    /// A peer, through the link (`msgs::PEER_KEYFRAME`).
    Peer(RobotId),
}

impl KeyframeSource {
    fn key(self) -> u64 {
        match self {
            KeyframeSource::Own => 0,
            KeyframeSource::Peer(r) => 1 + u64::from(r.0),
        }
    }
}

/// One stored component: where its samples come from and how far they reach.
#[derive(Clone, Debug)]
struct Component {
    /// Index of its keyframe in [`ComponentStore::keyframes`].
    keyframe: usize,
    mean: Point3<f64>,
    /// Lower Cholesky factor of the spatial covariance.
    chol: Matrix3<f64>,
    samples: u32,
    seed: u64,
    /// Largest distance of a sample from the mean, metres.
    radius_m: f64,
}

/// One stored keyframe.
#[derive(Clone, Debug)]
struct StoredKeyframe {
    source: KeyframeSource,
    id: u32,
    origin: Point3<f64>,
    /// Its components' range in [`ComponentStore::components`].
    first: usize,
    end: usize,
    /// Largest `|mean − origin| + radius` over its components, metres.
    reach_m: f64,
}

/// What a rebuild did (for logs and benchmarks).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RebuildStats {
    /// Components whose mean the spatial index returned.
    pub candidates: usize,
    /// Components that passed the ray–box test and were re-traced.
    pub traced: usize,
    /// Rays inserted.
    pub rays: usize,
}

/// Every keyframe mixture the grid was given, sampled deterministically, with a
/// uniform hash grid over component means (thesis §3.2.3).
#[derive(Clone, Debug)]
pub struct ComponentStore {
    max_samples_per_keyframe: usize,
    max_keyframes: usize,
    index_cell_m: f64,
    keyframes: Vec<StoredKeyframe>,
    components: Vec<Component>,
    index: HashMap<[i64; 3], Vec<u32>>,
    /// Largest `|mean − origin| + radius` over all components, metres: no sample ray
    /// of any component leaves the ball of this radius around its mean.
    max_reach_m: f64,
    rule: UpdateRule,
    scratch: ScanScratch,
}

/// SplitMix64 finaliser: a well-mixed 64-bit seed from a counter.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The sampling seed of component `m` of keyframe `id` from `source`.
fn component_seed(source: KeyframeSource, id: u32, m: usize) -> u64 {
    mix(mix(mix(source.key()) ^ u64::from(id)) ^ m as u64)
}

impl Component {
    /// Its samples, always the same: `μ + L z`, `z` standard normal (Box–Muller) from a
    /// generator seeded with [`component_seed`] (§6.1.5).
    fn sample_into(&self, out: &mut Vec<Point3<f64>>) {
        out.clear();
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        for _ in 0..self.samples {
            let (z0, z1) = box_muller(&mut rng);
            let (z2, _) = box_muller(&mut rng);
            out.push(self.mean + self.chol * Vector3::new(z0, z1, z2));
        }
    }
}

impl ComponentStore {
    /// An empty store: at most `max_samples_per_keyframe` points per keyframe (at most
    /// its support size), at most `max_keyframes` keyframes (the oldest goes first), and
    /// a hash grid of `index_cell_m` buckets over the means.
    #[must_use]
    pub fn new(max_samples_per_keyframe: usize, max_keyframes: usize, index_cell_m: f64) -> Self {
        ComponentStore {
            max_samples_per_keyframe,
            max_keyframes: max_keyframes.max(1),
            index_cell_m: if index_cell_m.is_finite() && index_cell_m > 0.0 {
                index_cell_m
            } else {
                4.0
            },
            keyframes: Vec::new(),
            components: Vec::new(),
            index: HashMap::new(),
            max_reach_m: 0.0,
            rule: UpdateRule::PerRay,
            scratch: ScanScratch::default(),
        }
    }

    /// The same store updating the grid by `rule`: with [`UpdateRule::PerScan`] or
    /// [`UpdateRule::PerEndVoxel`] the samples of one keyframe form one scan.
    #[must_use]
    pub fn with_rule(mut self, rule: UpdateRule) -> Self {
        self.rule = rule;
        self
    }

    /// Number of stored keyframes.
    #[must_use]
    pub fn keyframe_count(&self) -> usize {
        self.keyframes.len()
    }

    /// Number of stored components.
    #[must_use]
    pub fn component_count(&self) -> usize {
        self.components.len()
    }

    fn bucket(&self, p: &Point3<f64>) -> [i64; 3] {
        [0, 1, 2].map(|i| (p[i] / self.index_cell_m).floor() as i64)
    }

    /// Stores a keyframe's components (drawing `min(support, max)` samples split over
    /// the components by weight, rounded) and returns its position for
    /// [`ComponentStore::trace_keyframe`], or `None` when it has a non-finite pose or
    /// carries no usable component. A keyframe with the same source and id replaces
    /// nothing: ids are expected to be unique per source.
    pub fn insert(&mut self, source: KeyframeSource, keyframe: &Keyframe) -> Option<usize> {
        let origin = Point3::from(keyframe.pose.translation.vector);
        if !origin.coords.iter().all(|v| v.is_finite()) {
            return None;
        }
        let spatial = keyframe.gmm.marginal_spatial();
        let total = (keyframe.support_size as usize).min(self.max_samples_per_keyframe) as f64;
        let mut components = Vec::new();
        let mut points = Vec::new();
        for (m, ((w, mean), cov)) in spatial
            .weights()
            .iter()
            .zip(spatial.means())
            .zip(spatial.covariances())
            .enumerate()
        {
            let samples = (w * total).round();
            let Some(chol) = cov.cholesky() else { continue };
            if !(samples >= 1.0 && mean.iter().all(|v| v.is_finite())) {
                continue;
            }
            let mut component = Component {
                keyframe: 0,
                mean: Point3::from(*mean),
                chol: chol.l(),
                samples: samples as u32,
                seed: component_seed(source, keyframe.id, m),
                radius_m: 0.0,
            };
            component.sample_into(&mut points);
            component.radius_m = points
                .iter()
                .map(|p| (p - component.mean).norm())
                .fold(0.0, f64::max);
            components.push(component);
        }
        if components.is_empty() {
            return None;
        }
        if self.keyframes.len() >= self.max_keyframes {
            self.evict_oldest();
        }
        let k = self.keyframes.len();
        let first = self.components.len();
        for mut component in components {
            component.keyframe = k;
            self.components.push(component);
        }
        self.keyframes.push(StoredKeyframe {
            source,
            id: keyframe.id,
            origin,
            first,
            end: self.components.len(),
            reach_m: 0.0,
        });
        for c in first..self.components.len() {
            self.index_component(c);
        }
        Some(k)
    }

    fn index_component(&mut self, c: usize) {
        let component = &self.components[c];
        let keyframe = &mut self.keyframes[component.keyframe];
        let reach = (component.mean - keyframe.origin).norm() + component.radius_m;
        keyframe.reach_m = keyframe.reach_m.max(reach);
        self.max_reach_m = self.max_reach_m.max(reach);
        let bucket = self.bucket(&component.mean);
        self.index.entry(bucket).or_default().push(c as u32);
    }

    /// Drops the oldest keyframe and its components. The index is mended in place, to
    /// what indexing the remaining components afresh would give: each bucket lists its
    /// components in storage order, so the dropped ones (the first `n`) lead their
    /// buckets' lists, and the rest move down by `n`.
    fn evict_oldest(&mut self) {
        if self.keyframes.is_empty() {
            return;
        }
        let dropped = self.keyframes.remove(0);
        let n = dropped.end - dropped.first;
        for c in dropped.first..dropped.end {
            let bucket = self.bucket(&self.components[c].mean);
            if let Some(ids) = self.index.get_mut(&bucket) {
                let kept = ids.partition_point(|&id| (id as usize) < dropped.end);
                ids.drain(..kept);
                if ids.is_empty() {
                    self.index.remove(&bucket);
                }
            }
        }
        let shift = u32::try_from(n).unwrap_or(u32::MAX);
        for ids in self.index.values_mut() {
            for id in ids {
                *id -= shift;
            }
        }
        self.components.drain(dropped.first..dropped.end);
        for c in &mut self.components {
            c.keyframe -= 1;
        }
        for k in &mut self.keyframes {
            k.first -= n;
            k.end -= n;
        }
        self.max_reach_m = self.keyframes.iter().map(|k| k.reach_m).fold(0.0, f64::max);
    }

    /// Ray-traces every sample of stored keyframe `k` (as returned by
    /// [`ComponentStore::insert`]) into the whole grid: a hit at each sample, misses on
    /// the way from the keyframe's sensor origin (§8.2.2). Returns the rays inserted.
    pub fn trace_keyframe(&mut self, grid: &mut LocalGrid, k: usize) -> usize {
        let Some(keyframe) = self.keyframes.get(k) else {
            return 0;
        };
        let all: Vec<u32> = (keyframe.first as u32..keyframe.end as u32).collect();
        self.trace(grid, &all, None)
    }

    /// Ray-traces the samples of `components` (sorted, in storage order) into `grid`,
    /// only into `boxes` if given; with [`UpdateRule::PerScan`] each keyframe's share
    /// is one scan. Returns the rays inserted.
    fn trace(
        &mut self,
        grid: &mut LocalGrid,
        components: &[u32],
        boxes: Option<&[CellBox]>,
    ) -> usize {
        let mut points = Vec::new();
        let mut scan = Vec::new();
        let mut rays = 0;
        let mut at = 0;
        while at < components.len() {
            let k = self.components[components[at] as usize].keyframe;
            let origin = self.keyframes[k].origin;
            scan.clear();
            while at < components.len() && self.components[components[at] as usize].keyframe == k {
                let component = &self.components[components[at] as usize];
                component.sample_into(&mut points);
                match self.rule {
                    UpdateRule::PerScan | UpdateRule::PerEndVoxel => {
                        scan.extend_from_slice(&points);
                    }
                    UpdateRule::PerRay => {
                        for p in &points {
                            match boxes {
                                None => grid.insert_ray(&origin, p, true, None),
                                Some(b) => grid.insert_ray_boxes(&origin, p, true, b),
                            }
                        }
                    }
                }
                rays += points.len();
                at += 1;
            }
            if self.rule != UpdateRule::PerRay {
                self.scratch
                    .insert_by(self.rule, grid, &origin, &scan, true, boxes);
            }
        }
        rays
    }

    /// Rebuilds the cells of `boxes` (the novel boxes of [`LocalGrid::shift_to`], or
    /// the whole grid) from the stored components that can affect them (thesis
    /// §3.2.3): candidates from the index over means (within the largest component
    /// reach of a box, about twice the sensor range for the paper's 20 m window and
    /// 10 m range), then a ray–box test of the segment from the sensor origin to the
    /// mean against each box grown by the component's sample radius and two cells.
    /// The test is conservative: every sample ray of a skipped component misses every
    /// box. Components are traced in storage order, so cells see their updates in the
    /// same order as in a rebuild from scratch.
    pub fn rebuild(&mut self, grid: &mut LocalGrid, boxes: &[CellBox]) -> RebuildStats {
        let mut stats = RebuildStats::default();
        let geometry = grid.geometry();
        let cell_m = geometry.cell_m;
        let world: Vec<Aabb> = boxes
            .iter()
            .filter(|b| b.cell_count() > 0)
            .map(|b| Aabb {
                min: geometry.origin + Vector3::from(b.min.map(|v| v as f64)) * cell_m,
                max: geometry.origin + Vector3::from(b.max.map(|v| v as f64)) * cell_m,
            })
            .collect();
        if world.is_empty() || self.components.is_empty() {
            return stats;
        }
        let mut candidates = self.candidates(&world, cell_m);
        candidates.sort_unstable();
        candidates.dedup();
        stats.candidates = candidates.len();
        candidates.retain(|&c| {
            let component = &self.components[c as usize];
            let origin = self.keyframes[component.keyframe].origin;
            let dir = component.mean - origin;
            let margin = component.radius_m + 2.0 * cell_m;
            world.iter().any(|b| {
                b.expanded(margin)
                    .clip_ray(&origin, &dir, 0.0, 1.0)
                    .is_some()
            })
        });
        stats.traced = candidates.len();
        stats.rays = self.trace(grid, &candidates, Some(boxes));
        stats
    }

    /// Components whose mean lies within the largest reach (plus two cells of
    /// `cell_m` for the walk's rounding) of one of `boxes`, with repeats, from the hash
    /// grid — or from a scan of all buckets when the query
    /// would visit more buckets than there are.
    fn candidates(&self, boxes: &[Aabb], cell_m: f64) -> Vec<u32> {
        let reach = self.max_reach_m + 2.0 * cell_m;
        let mut out = Vec::new();
        for b in boxes {
            let grown = b.expanded(reach);
            let lo = self.bucket(&grown.min);
            let hi = self.bucket(&grown.max);
            let visits: f64 = (0..3).map(|i| (hi[i] - lo[i] + 1) as f64).product();
            if visits > self.index.len() as f64 {
                for (key, ids) in &self.index {
                    if (0..3).all(|i| lo[i] <= key[i] && key[i] <= hi[i]) {
                        out.extend_from_slice(ids);
                    }
                }
                continue;
            }
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        if let Some(ids) = self.index.get(&[x, y, z]) {
                            out.extend_from_slice(ids);
                        }
                    }
                }
            }
        }
        out
    }

    /// The spatial index (bucket → components in storage order) and the largest reach,
    /// for tests that compare a mended index with a fresh one.
    #[cfg(test)]
    pub(super) fn index_state(&self) -> (&HashMap<[i64; 3], Vec<u32>>, f64) {
        (&self.index, self.max_reach_m)
    }

    /// The source and id of stored keyframe `k`.
    #[must_use]
    pub fn keyframe_key(&self, k: usize) -> Option<(KeyframeSource, u32)> {
        self.keyframes.get(k).map(|s| (s.source, s.id))
    }
}
