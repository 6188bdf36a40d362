//! Component store tests: the moving window rebuilt from stored GMM components equals
//! a rebuild from scratch at the new pose, cell for cell (thesis §3.2.3, Fig. 3.2).

use nalgebra::{
    Isometry3, Matrix3, Matrix4, Point3, Translation3, UnitQuaternion, Vector3, Vector4,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::grid::UpdateRule;
use crate::keyframe::Keyframe;
use crate::mixture::Gmm4;
use troupe_core::{RobotId, Time};

/// A keyframe seen from a random origin near the world origin: `n` small anisotropic
/// components 2–7 m away in random directions.
fn random_keyframe(rng: &mut ChaCha8Rng, id: u32, n: usize) -> Keyframe {
    let origin = Vector3::new(
        rng.random_range(-1.5..1.5),
        rng.random_range(-1.5..1.5),
        rng.random_range(-0.5..0.5),
    );
    let mut means = Vec::new();
    let mut covariances = Vec::new();
    for _ in 0..n {
        let dir = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-0.4..0.4),
        )
        .normalize();
        let p = origin + dir * rng.random_range(2.0..7.0);
        means.push(Vector4::new(p.x, p.y, p.z, 0.5));
        let a = Matrix3::from_fn(|_, _| rng.random_range(-0.15..0.15));
        let spatial = a * a.transpose() + Matrix3::identity() * 1e-3;
        let mut cov = Matrix4::identity() * 0.01;
        cov.fixed_view_mut::<3, 3>(0, 0).copy_from(&spatial);
        covariances.push(cov);
    }
    let weights = vec![1.0 / n as f64; n];
    Keyframe {
        id,
        stamp: Time::ZERO,
        pose: Isometry3::from_parts(Translation3::from(origin), UnitQuaternion::identity()),
        support_size: 1500,
        gmm: Gmm4::new(weights, means, covariances).unwrap(),
    }
}

const SIZE_M: [f64; 3] = [8.0, 7.0, 4.0];

fn empty_grid(at: &Point3<f64>) -> LocalGrid {
    LocalGrid::centred(at, &Vector3::from(SIZE_M), 0.2, LogOddsParams::default())
}

fn whole(grid: &LocalGrid) -> CellBox {
    CellBox {
        min: [0; 3],
        max: grid.dims(),
    }
}

#[test]
fn incremental_moves_equal_a_rebuild_from_scratch() {
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    for case in 0..4 {
        let keyframes: Vec<Keyframe> = (0..6).map(|i| random_keyframe(&mut rng, i, 40)).collect();
        let mut store = ComponentStore::new(1000, 64, 2.0);
        let poses: Vec<Point3<f64>> = (0..3)
            .map(|_| {
                Point3::new(
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-1.0..1.0),
                )
            })
            .collect();
        let mut moved = empty_grid(&poses[0]);
        let mut skipped = 0;
        for (step, chunk) in keyframes.chunks(2).enumerate() {
            if step > 0 {
                let novel = moved.shift_to(&poses[step]);
                assert!(novel.len() <= 3);
                let stats = store.rebuild(&mut moved, &novel);
                assert!(stats.traced <= stats.candidates);
                skipped += store.component_count() - stats.traced;
            }
            for (i, kf) in chunk.iter().enumerate() {
                let source = if i == 0 {
                    KeyframeSource::Own
                } else {
                    KeyframeSource::Peer(RobotId(3))
                };
                let k = store.insert(source, kf).unwrap();
                assert!(store.trace_keyframe(&mut moved, k) > 0);
            }
        }
        let last = poses[2];
        let mut rebuilt = empty_grid(&last);
        let all = whole(&rebuilt);
        let stats = store.rebuild(&mut rebuilt, &[all]);
        assert!(stats.rays > 0);
        assert_eq!(moved.geometry(), rebuilt.geometry(), "case {case}");
        assert!(
            moved.values() == rebuilt.values(),
            "case {case}: cells differ"
        );
        // The same again without the index or the ray–box test: every keyframe traced
        // whole, in order.
        let mut naive = empty_grid(&last);
        for k in 0..store.keyframe_count() {
            store.trace_keyframe(&mut naive, k);
        }
        assert!(
            naive.values() == rebuilt.values(),
            "case {case}: filter lost rays"
        );
        assert!(naive.values().iter().any(|v| *v != 0.0));
        assert!(
            skipped > 0,
            "case {case}: the ray–box test never skipped anything"
        );
    }
}

#[test]
fn samples_are_fixed_per_keyframe_and_component() {
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let kf = random_keyframe(&mut rng, 7, 20);
    let at = Point3::from(kf.pose.translation.vector);
    let grid_of = |kf: &Keyframe, source| {
        let mut store = ComponentStore::new(800, 8, 2.0);
        let k = store.insert(source, kf).unwrap();
        let mut grid = empty_grid(&at);
        let rays = store.trace_keyframe(&mut grid, k);
        (grid, rays)
    };
    let (a, rays) = grid_of(&kf, KeyframeSource::Own);
    // 20 components of weight 1/20 share 800 samples.
    assert_eq!(rays, 800);
    let (b, _) = grid_of(&kf, KeyframeSource::Own);
    assert!(a.values() == b.values());
    let (c, _) = grid_of(&kf, KeyframeSource::Peer(RobotId(1)));
    assert!(
        a.values() != c.values(),
        "another source draws other samples"
    );
    let mut other = kf.clone();
    other.id = 8;
    let (d, _) = grid_of(&other, KeyframeSource::Own);
    assert!(a.values() != d.values(), "another id draws other samples");
}

#[test]
fn the_oldest_keyframe_is_evicted_and_the_index_follows() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let keyframes: Vec<Keyframe> = (0..3).map(|i| random_keyframe(&mut rng, i, 10)).collect();
    let mut store = ComponentStore::new(300, 2, 2.0);
    for kf in &keyframes {
        store.insert(KeyframeSource::Own, kf).unwrap();
    }
    assert_eq!(store.keyframe_count(), 2);
    assert_eq!(store.component_count(), 20);
    assert_eq!(store.keyframe_key(0), Some((KeyframeSource::Own, 1)));
    let at = Point3::origin();
    let mut rebuilt = empty_grid(&at);
    let all = whole(&rebuilt);
    store.rebuild(&mut rebuilt, &[all]);
    let mut expected = empty_grid(&at);
    let mut only_newer = ComponentStore::new(300, 2, 2.0);
    for kf in &keyframes[1..] {
        let k = only_newer.insert(KeyframeSource::Own, kf).unwrap();
        only_newer.trace_keyframe(&mut expected, k);
    }
    assert!(rebuilt.values() == expected.values());
    assert_eq!(store.index_state(), only_newer.index_state());
    // Evicting again and again mends the index to what the newest keyframes alone
    // index: buckets, their order and the largest reach.
    let more: Vec<Keyframe> = (3..9)
        .map(|i| random_keyframe(&mut rng, i, 7 + i as usize))
        .collect();
    for kf in &more {
        store.insert(KeyframeSource::Own, kf).unwrap();
    }
    let mut newest = ComponentStore::new(300, 2, 2.0);
    for kf in &more[4..] {
        newest.insert(KeyframeSource::Own, kf).unwrap();
    }
    assert_eq!(store.component_count(), newest.component_count());
    assert_eq!(store.index_state(), newest.index_state());
    // A keyframe with a non-finite pose is refused.
    let mut bad = keyframes[0].clone();
    bad.pose.translation.vector.x = f64::NAN;
    assert_eq!(store.insert(KeyframeSource::Own, &bad), None);
}

#[test]
fn incremental_moves_equal_a_rebuild_from_scratch_per_scan() {
    for rule in [UpdateRule::PerScan, UpdateRule::PerEndVoxel] {
        incremental_moves_equal_a_rebuild_from_scratch_by(rule);
    }
}

fn incremental_moves_equal_a_rebuild_from_scratch_by(rule: UpdateRule) {
    let mut rng = ChaCha8Rng::seed_from_u64(22);
    let keyframes: Vec<Keyframe> = (0..4).map(|i| random_keyframe(&mut rng, i, 60)).collect();
    let mut store = ComponentStore::new(3000, 64, 2.0).with_rule(rule);
    let (from, to) = (Point3::new(-1.0, 0.5, 0.0), Point3::new(1.7, -1.1, 0.6));
    let mut moved = empty_grid(&from);
    for kf in &keyframes[..2] {
        let k = store.insert(KeyframeSource::Own, kf).unwrap();
        store.trace_keyframe(&mut moved, k);
    }
    let novel = moved.shift_to(&to);
    store.rebuild(&mut moved, &novel);
    for kf in &keyframes[2..] {
        let k = store.insert(KeyframeSource::Own, kf).unwrap();
        store.trace_keyframe(&mut moved, k);
    }
    let mut rebuilt = empty_grid(&to);
    let all = whole(&rebuilt);
    store.rebuild(&mut rebuilt, &[all]);
    assert!(moved.values() == rebuilt.values(), "{rule:?}");
    // Per scan differs from per ray (cells crossed by several rays of a keyframe).
    let mut per_ray = ComponentStore::new(3000, 64, 2.0);
    let mut other = empty_grid(&to);
    for kf in &keyframes {
        let k = per_ray.insert(KeyframeSource::Own, kf).unwrap();
        per_ray.trace_keyframe(&mut other, k);
    }
    assert!(other.values() != rebuilt.values());
}
