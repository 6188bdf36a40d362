//! Tests of [`UpdateRule::PerEndVoxel`]: the fast scan insertion equals a slow,
//! set-based statement of the rule on random scans, and the moving window still
//! equals a rebuild from scratch under it.

use std::collections::BTreeSet;

use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::tests::{auc_against_raw, grid_at, random_ends, window_and_move, window_at};
use super::*;
use crate::sogmm::synthetic::room_corner_frame;

/// The rule the slow way: the set of distinct end voxels (lattice cells), one walk
/// per voxel to its centre through the `RayWalk` iterator, then one update per cell
/// from two index sets.
fn reference(grid: &mut LocalGrid, origin: &Point3<f64>, ends: &[Point3<f64>], hit: bool) {
    let Some(g0) = grid.lattice_coords(origin) else {
        return;
    };
    let voxels: BTreeSet<[u64; 3]> = ends
        .iter()
        .filter_map(|e| grid.lattice_coords(e))
        .map(|g| {
            [
                g[0].floor() as u64,
                g[1].floor() as u64,
                g[2].floor() as u64,
            ]
        })
        .collect();
    let (mut crossed, mut ended) = (BTreeSet::new(), BTreeSet::new());
    for v in &voxels {
        let centre = Vector3::new(v[0] as f64 + 0.5, v[1] as f64 + 0.5, v[2] as f64 + 0.5);
        for step in grid.walk_lattice(&g0, &centre) {
            if let Some(i) = step.index {
                if step.is_end {
                    ended.insert(i);
                } else {
                    crossed.insert(i);
                }
            }
        }
    }
    let p = *grid.params();
    let mut values = grid.values().to_vec();
    for &i in &ended {
        let delta = if hit { p.hit } else { p.miss };
        values[i] = (values[i] + delta).clamp(p.min, p.max);
    }
    for &i in crossed.difference(&ended) {
        values[i] = (values[i] + p.miss).clamp(p.min, p.max);
    }
    grid.set_values_for_test(values);
}

/// `n` end points around `origin`, 0.2–`reach_m` away (many leave the window), plus a
/// cluster of points sharing a few voxels and one non-finite point.
fn random_scan(
    rng: &mut ChaCha8Rng,
    origin: &Point3<f64>,
    n: usize,
    reach_m: f64,
) -> Vec<Point3<f64>> {
    let mut ends = random_ends(rng, origin, n, 0.2, reach_m);
    let wall = Point3::new(1.1, 0.3, 0.1);
    ends.extend((0..200).map(|_| wall + Vector3::from_fn(|_, _| rng.random_range(-0.15..0.15))));
    ends.push(Point3::new(f64::NAN, 0.0, 0.0));
    ends.push(Point3::new(0.0, f64::INFINITY, 0.0));
    ends
}

#[test]
fn the_fast_scan_equals_the_reference_on_random_scans() {
    for seed in 0..4u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
        for case in 0..6 {
            // Origins inside the window, and (odd cases) outside it.
            let origin = if case % 2 == 0 {
                Point3::new(
                    rng.random_range(-1.5..1.5),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-0.6..0.6),
                )
            } else {
                Point3::new(
                    rng.random_range(2.5..4.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-2.0..2.0),
                )
            };
            let n = [50, 400, 3000][case % 3];
            let ends = random_scan(&mut rng, &origin, n, 6.0);
            let hit = case != 4;
            let mut scratch = EndVoxelScratch::default();
            let (mut fast, mut slow) = (grid_at(0.3), grid_at(0.3));
            // Two scans, so that the second starts from non-zero cells and reused
            // scratch; then a free-space scan on top.
            for h in [hit, hit, false] {
                let traced = scratch.insert_scan(&mut fast, &origin, &ends, h, None);
                assert!(traced > 0 && traced < ends.len(), "seed {seed} case {case}");
                reference(&mut slow, &origin, &ends, h);
            }
            assert!(fast.values() == slow.values(), "seed {seed} case {case}");
            assert!(fast.values().iter().any(|v| *v != 0.0));
            // Any order of the points gives the same cells.
            let mut shuffled = ends.clone();
            for i in (1..shuffled.len()).rev() {
                shuffled.swap(i, rng.random_range(0..=i));
            }
            let mut other = grid_at(0.3);
            for h in [hit, hit, false] {
                scratch.insert_scan(&mut other, &origin, &shuffled, h, None);
            }
            assert!(
                other.values() == fast.values(),
                "seed {seed} case {case}: order"
            );
            // Restricted to boxes: the same cells inside them, nothing outside.
            let boxes = [
                CellBox {
                    min: [3, 2, 1],
                    max: [12, 9, 6],
                },
                CellBox {
                    min: [14, 0, 0],
                    max: [20, 15, 10],
                },
            ];
            let mut boxed = grid_at(0.3);
            scratch.insert_scan(&mut boxed, &origin, &ends, hit, Some(&boxes));
            let mut once = grid_at(0.3);
            reference(&mut once, &origin, &ends, hit);
            for (i, (a, e)) in boxed.values().iter().zip(once.values()).enumerate() {
                let c = boxed.cell_at(i);
                let expected = if boxes.iter().any(|b| b.contains(c)) {
                    *e
                } else {
                    0.0
                };
                assert_eq!(*a, expected, "seed {seed} case {case} cell {c:?}");
            }
        }
    }
}

#[test]
fn occupied_cells_match_per_scan_and_free_cells_differ_only_at_the_edges() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let origin = Point3::new(0.05, -0.1, 0.02);
    let ends = random_scan(&mut rng, &origin, 4000, 1.9);
    let mut by_voxel = grid_at(0.0);
    EndVoxelScratch::default().insert_scan(&mut by_voxel, &origin, &ends, true, None);
    let mut by_point = grid_at(0.0);
    ScanScratch::default().insert_scan(&mut by_point, &origin, &ends, true, None);
    let occupied = |g: &LocalGrid| -> Vec<usize> {
        (0..g.values().len())
            .filter(|&i| g.classify(g.values()[i]) == CellState::Occupied)
            .collect()
    };
    assert_eq!(occupied(&by_voxel), occupied(&by_point));
    // Free space differs, but only at the edges of the swept volume: a segment to a
    // voxel centre stays within half a cell per axis of the segments to the voxel's
    // points, so each cell free under one rule only touches a cell free under the
    // other.
    let free = |g: &LocalGrid| -> BTreeSet<usize> {
        (0..g.values().len())
            .filter(|&i| g.classify(g.values()[i]) == CellState::Free)
            .collect()
    };
    let (fv, fp) = (free(&by_voxel), free(&by_point));
    assert!(fv.len() > 100);
    let next_to = |c: usize, other: &BTreeSet<usize>| {
        let c = by_voxel.cell_at(c);
        let d = by_voxel.dims();
        (0..27).any(|k| {
            let n = [k % 3, k / 3 % 3, k / 9].map(|o| o as i64 - 1);
            let m = [0, 1, 2].map(|a| c[a] as i64 + n[a]);
            (0..3).all(|a| (0..d[a] as i64).contains(&m[a]))
                && other.contains(&by_voxel.index(m.map(|v| v as usize)))
        })
    };
    let only_voxel: Vec<usize> = fv.difference(&fp).copied().collect();
    let only_point: Vec<usize> = fp.difference(&fv).copied().collect();
    assert!(!only_voxel.is_empty() || !only_point.is_empty());
    assert!(only_voxel.iter().all(|&c| next_to(c, &fp)));
    assert!(only_point.iter().all(|&c| next_to(c, &fv)));
}

#[test]
fn a_bad_origin_or_an_empty_scan_changes_nothing() {
    let mut grid = grid_at(0.0);
    let mut scratch = EndVoxelScratch::default();
    let ends = [Point3::new(1.0, 0.2, 0.1)];
    assert_eq!(
        scratch.insert_scan(
            &mut grid,
            &Point3::new(f64::NAN, 0.0, 0.0),
            &ends,
            true,
            None
        ),
        0
    );
    assert_eq!(
        scratch.insert_scan(&mut grid, &Point3::origin(), &[], true, None),
        0
    );
    assert!(grid.values().iter().all(|v| *v == 0.0));
    // The scratch is reusable after a grid of another size.
    let mut big = LocalGrid::centred(
        &Point3::origin(),
        &Vector3::new(6.0, 5.0, 3.0),
        0.2,
        LogOddsParams::default(),
    );
    assert_eq!(
        scratch.insert_scan(&mut big, &Point3::origin(), &ends, true, None),
        1
    );
    let end = big.cell_of(&ends[0]).unwrap();
    assert_eq!(big.state(end), CellState::Occupied);
    assert_eq!(
        big.state(big.cell_of(&Point3::new(0.5, 0.1, 0.05)).unwrap()),
        CellState::Free
    );
}

#[test]
fn moving_the_window_equals_a_rebuild_per_end_voxel() {
    let mut rng = ChaCha8Rng::seed_from_u64(19);
    for case in 0..10 {
        let origin = Point3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-0.4..0.4),
        );
        let scans: Vec<(Vec<Point3<f64>>, bool)> = (0..3)
            .map(|s| (random_scan(&mut rng, &origin, 500, 4.0), s != 1))
            .collect();
        let (mut moved, to) = window_and_move(&mut rng);
        let mut scratch = ScanScratch::default();
        let rule = UpdateRule::PerEndVoxel;
        for (ends, hit) in &scans {
            scratch.insert_by(rule, &mut moved, &origin, ends, *hit, None);
        }
        let novel = moved.shift_to(&to);
        for (ends, hit) in &scans {
            scratch.insert_by(rule, &mut moved, &origin, ends, *hit, Some(&novel));
        }
        let mut rebuilt = window_at(&to);
        for (ends, hit) in &scans {
            scratch.insert_by(rule, &mut rebuilt, &origin, ends, *hit, None);
        }
        assert!(moved.values() == rebuilt.values(), "case {case}");
    }
}

#[test]
fn occupancy_from_a_keyframe_gmm_agrees_with_the_raw_frame_per_end_voxel() {
    use crate::grid::insert_frame_with;
    use crate::sogmm::{SogmmConfig, fit_depth_frame};

    let frame = room_corner_frame();
    let origin = Point3::from(frame.pose.translation.vector);
    let size = Vector3::new(16.0, 16.0, 8.0);
    let rule = UpdateRule::PerEndVoxel;
    let mut scratch = ScanScratch::default();
    let mut raw = LocalGrid::centred(&origin, &size, 0.2, LogOddsParams::default());
    insert_frame_with(&mut raw, &frame, 1, rule, &mut scratch);
    let config = SogmmConfig {
        bandwidth: 0.03,
        ..SogmmConfig::default()
    };
    let fit = fit_depth_frame(&frame, &config).unwrap();
    let samples: Vec<Point3<f64>> = fit
        .gmm
        .marginal_spatial()
        .sample(frame.valid_pixels(), &mut ChaCha8Rng::seed_from_u64(1))
        .into_iter()
        .map(Point3::from)
        .collect();
    let mut from_gmm = LocalGrid::centred(&origin, &size, 0.2, LogOddsParams::default());
    scratch.insert_by(rule, &mut from_gmm, &origin, &samples, true, None);
    let auc = auc_against_raw(&raw, &from_gmm);
    assert!(auc >= 0.9, "AUC {auc}");
}
