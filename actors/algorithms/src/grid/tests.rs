//! Grid tests: the distance transform against brute force, rays, the moving window
//! against a rebuild from scratch, frontiers and entropy.

use crate::sogmm::synthetic::room_corner_frame;
use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::distance::{distance_to, unsafe_distance};
use super::frontier::{entropy_bits, frontier_mask};
use super::*;

fn brute_force(sources: &[bool], dims: [usize; 3], cell_m: f64) -> Vec<f64> {
    let cells: Vec<[usize; 3]> = (0..dims[2])
        .flat_map(|z| (0..dims[1]).flat_map(move |y| (0..dims[0]).map(move |x| [x, y, z])))
        .collect();
    cells
        .iter()
        .map(|c| {
            cells
                .iter()
                .zip(sources)
                .filter(|(_, s)| **s)
                .map(|(o, _)| {
                    let d2: f64 = (0..3).map(|i| (c[i] as f64 - o[i] as f64).powi(2)).sum();
                    d2.sqrt() * cell_m
                })
                .fold(f64::INFINITY, f64::min)
        })
        .collect()
}

#[test]
fn distance_transform_equals_brute_force_on_random_grids() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for case in 0..60 {
        let dims = [
            rng.random_range(1..9),
            rng.random_range(1..9),
            rng.random_range(1..7),
        ];
        // Sparse sources (a frontier field), and dense ones around a few free cells
        // (an unsafe-distance field: only the box around the free cells is transformed).
        let density = if case % 2 == 0 {
            rng.random_range(0.0..0.3)
        } else {
            rng.random_range(0.9..1.0)
        };
        let n = dims.iter().product();
        let sources: Vec<bool> = (0..n).map(|_| rng.random_bool(density)).collect();
        let fast = distance_to(&sources, dims, 0.2);
        let slow = brute_force(&sources, dims, 0.2);
        for (i, (a, b)) in fast.iter_m().zip(&slow).enumerate() {
            assert!(
                a.to_bits() == b.to_bits(),
                "case {case} {dims:?} cell {i}: {a} vs {b}"
            );
        }
    }
}

/// A 4 m × 3 m × 2 m grid at 0.2 m centred on `(x, 0, 0)`.
pub(super) fn grid_at(x: f64) -> LocalGrid {
    LocalGrid::centred(
        &Point3::new(x, 0.0, 0.0),
        &Vector3::new(4.0, 3.0, 2.0),
        0.2,
        LogOddsParams::default(),
    )
}

#[test]
fn a_ray_frees_its_path_and_occupies_its_end() {
    let mut grid = grid_at(0.0);
    let origin = Point3::new(-1.5, 0.1, 0.1);
    let end = Point3::new(1.1, 0.1, 0.1);
    grid.insert_ray(&origin, &end, true, None);
    let end_cell = grid.cell_of(&end).unwrap();
    assert_eq!(grid.state(end_cell), CellState::Occupied);
    for x in [-1.4, -0.5, 0.0, 0.9] {
        let c = grid.cell_of(&Point3::new(x, 0.1, 0.1)).unwrap();
        assert_eq!(grid.state(c), CellState::Free, "x = {x}");
    }
    let beyond = grid.cell_of(&Point3::new(1.5, 0.1, 0.1)).unwrap();
    assert_eq!(grid.state(beyond), CellState::Unknown);
    // Clamping: many hits saturate at max.
    for _ in 0..50 {
        grid.insert_ray(&origin, &end, true, None);
    }
    assert_eq!(grid.value(end_cell), grid.params().max);
    // Non-finite rays are ignored.
    let before = grid.clone();
    grid.insert_ray(&Point3::new(f64::NAN, 0.0, 0.0), &end, true, None);
    assert_eq!(grid, before);
}

/// A vector with x and y in [-1, 1) and z in [-0.5, 0.5), drawn in that order: a
/// random origin near the test grids' centre, or a random ray direction once
/// normalised.
fn random_offset(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    Vector3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-0.5..0.5),
    )
}

/// `n` end points of rays from `origin` in [`random_offset`] directions, each
/// `near_m`–`far_m` long (direction, then length, drawn per point).
pub(super) fn random_ends(
    rng: &mut ChaCha8Rng,
    origin: &Point3<f64>,
    n: usize,
    near_m: f64,
    far_m: f64,
) -> Vec<Point3<f64>> {
    (0..n)
        .map(|_| {
            let d = random_offset(rng);
            origin + d.normalize() * rng.random_range(near_m..far_m)
        })
        .collect()
}

fn random_rays(rng: &mut ChaCha8Rng, n: usize) -> Vec<(Point3<f64>, Point3<f64>, bool)> {
    (0..n)
        .map(|_| {
            let origin = Point3::from(random_offset(rng));
            let dir = random_offset(rng);
            let end = origin + dir.normalize() * rng.random_range(0.5..3.0);
            (origin, end, rng.random_bool(0.8))
        })
        .collect()
}

/// A 3 × 2.6 × 1.8 m window of 0.2 m cells centred at `centre`.
pub(super) fn window_at(centre: &Point3<f64>) -> LocalGrid {
    let size = Vector3::new(3.0, 2.6, 1.8);
    LocalGrid::centred(centre, &size, 0.2, LogOddsParams::default())
}

/// A [`window_at`] a random point within 0.5 m of the origin (at z = 0), and a
/// random point to move it to: within 2 m across and 1 m up or down.
pub(super) fn window_and_move(rng: &mut ChaCha8Rng) -> (LocalGrid, Point3<f64>) {
    let from = Point3::new(
        rng.random_range(-0.5..0.5),
        rng.random_range(-0.5..0.5),
        0.0,
    );
    let to = from
        + Vector3::new(
            rng.random_range(-2.0..2.0),
            rng.random_range(-2.0..2.0),
            rng.random_range(-1.0..1.0),
        );
    (window_at(&from), to)
}

#[test]
fn moving_the_window_equals_rebuilding_at_the_new_pose() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for case in 0..20 {
        let rays = random_rays(&mut rng, 300);
        let (mut moved, to) = window_and_move(&mut rng);
        for (o, e, hit) in &rays {
            moved.insert_ray(o, e, *hit, None);
        }
        let novel = moved.shift_to(&to);
        assert!(novel.len() <= 3);
        for (o, e, hit) in &rays {
            for b in &novel {
                moved.insert_ray(o, e, *hit, Some(b));
            }
        }
        let mut rebuilt = window_at(&to);
        for (o, e, hit) in &rays {
            rebuilt.insert_ray(o, e, *hit, None);
        }
        assert_eq!(moved.geometry(), rebuilt.geometry(), "case {case}");
        assert!(
            moved.values() == rebuilt.values(),
            "case {case}: cells differ"
        );
    }
}

#[test]
fn novel_boxes_are_disjoint_and_cover_exactly_the_new_cells() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for _ in 0..50 {
        let mut grid = grid_at(0.0);
        // Mark every cell as seen so that kept cells are recognisable.
        let dims = grid.dims();
        let all = CellBox {
            min: [0; 3],
            max: dims,
        };
        assert_eq!(all.cell_count(), grid.values().len());
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let p = grid.geometry().cell_centre([x, y, z]);
                    grid.insert_ray(&p, &p, true, None);
                }
            }
        }
        let to = Point3::new(
            rng.random_range(-5.0..5.0),
            rng.random_range(-4.0..4.0),
            rng.random_range(-3.0..3.0),
        );
        let novel = grid.shift_to(&to);
        let mut count = 0;
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let c = [x, y, z];
                    let inside = novel.iter().filter(|b| b.contains(c)).count();
                    assert!(inside <= 1, "boxes overlap at {c:?}");
                    let unknown = grid.value(c) == 0.0;
                    assert_eq!(inside == 1, unknown, "cell {c:?}");
                    count += inside;
                }
            }
        }
        assert_eq!(count, novel.iter().map(CellBox::cell_count).sum::<usize>());
    }
}

#[test]
fn unsafe_distance_frontiers_and_entropy() {
    let mut grid = grid_at(0.0);
    let cells = grid.values().len() as f64;
    assert!(
        (entropy_bits(&grid) - cells).abs() < 1e-6,
        "all unknown: one bit per cell"
    );
    assert!(frontier_mask(&grid).iter().all(|f| !f));
    assert!(unsafe_distance(&grid).iter_m().all(|d| d == 0.0));
    for y in [-0.3, -0.1, 0.1, 0.3] {
        grid.insert_ray(
            &Point3::new(-1.9, y, 0.1),
            &Point3::new(1.0, y, 0.1),
            true,
            None,
        );
    }
    // Each cell was updated once: a miss leaves p = 0.4, a hit p = 0.7.
    let h = |p: f64| -(p * p.log2() + (1.0 - p) * (1.0 - p).log2());
    let count = |s: CellState| {
        grid.values()
            .iter()
            .filter(|v| grid.classify(**v) == s)
            .count() as f64
    };
    let (free, occupied) = (count(CellState::Free), count(CellState::Occupied));
    assert_eq!(occupied, 4.0);
    assert!(free >= 4.0 * 14.0);
    let expected = cells - free * (1.0 - h(0.4)) - occupied * (1.0 - h(0.7));
    assert!(
        (entropy_bits(&grid) - expected).abs() < 1e-3,
        "{} vs {expected}",
        entropy_bits(&grid)
    );
    let free = grid.cell_of(&Point3::new(0.0, -0.1, 0.1)).unwrap();
    assert_eq!(grid.state(free), CellState::Free);
    let edge = grid.cell_of(&Point3::new(0.0, -0.3, 0.1)).unwrap();
    let frontiers = frontier_mask(&grid);
    assert!(
        frontiers[grid.index(edge)],
        "a free cell with unknown space beside it is a frontier"
    );
    let distance = unsafe_distance(&grid);
    assert!((distance.metres(grid.index(free)) - 0.2).abs() < 1e-12);
}

/// A gap in a wall's occupied layer (unknown behind it) is no frontier; the edge of
/// what was seen in open space is.
#[test]
fn frontiers_are_openings_not_gaps_in_a_wall() {
    let mut grid = LocalGrid::centred(
        &Point3::origin(),
        &Vector3::new(4.0, 4.0, 2.0),
        0.2,
        LogOddsParams::default(),
    );
    let origin = Point3::new(-1.9, 0.1, 0.1);
    // A fan of rays: most end on a wall at x = 1 (hits), one short ray stops in open
    // space at x = -1 (a no-return pixel, free up to there).
    for k in -6..=6 {
        let y = 0.1 + 0.2 * f64::from(k);
        grid.insert_ray(&origin, &Point3::new(1.0, y, 0.1), k != 0, None);
    }
    grid.insert_ray(&origin, &Point3::new(-1.0, -1.5, 0.1), false, None);
    let mask = frontier_mask(&grid);
    // The gap in the wall (the ray at y = 0.1 gave no hit): its last free cell has
    // unknown space behind it, but touches the wall's occupied cells.
    let gap = (0..12)
        .map(|i| 0.5 + 0.1 * f64::from(i))
        .map(|x| grid.cell_of(&Point3::new(x, 0.1, 0.1)).unwrap())
        .take_while(|c| grid.state(*c) == CellState::Free)
        .last()
        .unwrap();
    let behind = [gap[0] + 1, gap[1], gap[2]];
    assert_eq!(grid.state(behind), CellState::Unknown);
    assert!(!mask[grid.index(gap)], "a gap in the wall");
    // The end of the short ray in open space borders unknown space away from walls.
    let open_end = grid.cell_of(&Point3::new(-1.05, -1.45, 0.1)).unwrap();
    assert!(mask[grid.index(open_end)], "the open end is a frontier");
    // Free cells with unknown space only above and below (the fan is one layer
    // thick): floor and ceiling, not openings.
    let inside_fan = grid.cell_of(&Point3::new(0.0, 0.5, 0.1)).unwrap();
    assert_eq!(grid.state(inside_fan), CellState::Free);
    assert_eq!(
        grid.state([inside_fan[0], inside_fan[1], inside_fan[2] + 1]),
        CellState::Unknown
    );
    assert!(
        !mask[grid.index(inside_fan)],
        "unknown only above and below"
    );
}

/// Area under the ROC curve of `scores` for binary `labels` (Mann–Whitney, ties half).
fn roc_auc(labels: &[bool], scores: &[f64]) -> f64 {
    let mut pairs: Vec<(f64, bool)> = scores.iter().copied().zip(labels.iter().copied()).collect();
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let positives = labels.iter().filter(|l| **l).count() as f64;
    let negatives = labels.len() as f64 - positives;
    let (mut rank_sum, mut i) = (0.0, 0);
    while i < pairs.len() {
        let mut j = i;
        while j < pairs.len() && pairs[j].0 == pairs[i].0 {
            j += 1;
        }
        let average_rank = (i + j + 1) as f64 / 2.0;
        rank_sum += pairs[i..j].iter().filter(|p| p.1).count() as f64 * average_rank;
        i = j;
    }
    (rank_sum - positives * (positives + 1.0) / 2.0) / (positives * negatives)
}

/// Area under the ROC curve of `from_gmm`'s occupancy probability against the cells
/// `raw` observed (paper Fig. 6: occupancy from ray-tracing the sensor data is the
/// ground truth); requires more than 50 occupied cells in `raw`.
pub(super) fn auc_against_raw(raw: &LocalGrid, from_gmm: &LocalGrid) -> f64 {
    let (mut labels, mut scores) = (Vec::new(), Vec::new());
    for (i, v) in raw.values().iter().enumerate() {
        match raw.classify(*v) {
            CellState::Occupied => labels.push(true),
            CellState::Free => labels.push(false),
            CellState::Unknown => continue,
        }
        scores.push(1.0 / (1.0 + (-f64::from(from_gmm.values()[i])).exp()));
    }
    assert!(labels.iter().filter(|l| **l).count() > 50);
    roc_auc(&labels, &scores)
}

#[test]
fn occupancy_from_a_keyframe_gmm_agrees_with_the_raw_frame() {
    use crate::grid::{insert_frame, insert_keyframe};
    use crate::keyframe::Keyframe;
    use crate::sogmm::{SogmmConfig, fit_depth_frame};
    use troupe_core::Time;

    let frame = room_corner_frame();
    let pose = frame.pose;
    let origin = Point3::from(pose.translation.vector);
    let size = Vector3::new(16.0, 16.0, 8.0);
    let mut raw = LocalGrid::centred(&origin, &size, 0.2, LogOddsParams::default());
    insert_frame(&mut raw, &frame, 1);
    let fit = fit_depth_frame(
        &frame,
        &SogmmConfig {
            bandwidth: 0.03,
            ..SogmmConfig::default()
        },
    )
    .unwrap();
    let keyframe = Keyframe {
        id: 0,
        stamp: Time::ZERO,
        pose,
        support_size: frame.valid_pixels() as u32,
        gmm: fit.gmm,
    };
    let mut from_gmm = LocalGrid::centred(&origin, &size, 0.2, LogOddsParams::default());
    insert_keyframe(
        &mut from_gmm,
        &keyframe,
        usize::MAX,
        &mut ChaCha8Rng::seed_from_u64(1),
    );
    let auc = auc_against_raw(&raw, &from_gmm);
    // Paper Fig. 6: AUC ≈ 0.9 at 0.2 m for GMM-reconstructed occupancy.
    assert!(auc >= 0.9, "AUC {auc}");
}

/// The per-scan update the slow way: sets of crossed and end cells from the ray
/// iterator, then one update per cell.
fn scan_reference(grid: &mut LocalGrid, origin: &Point3<f64>, ends: &[Point3<f64>], hit: bool) {
    use std::collections::BTreeSet;
    let (mut crossed, mut ended) = (BTreeSet::new(), BTreeSet::new());
    for end in ends {
        let Some(walk) = grid.walk(origin, end) else {
            continue;
        };
        for step in walk {
            if let Some(i) = step.index {
                if step.is_end && hit {
                    ended.insert(i);
                } else {
                    crossed.insert(i);
                }
            }
        }
    }
    let p = *grid.params();
    let mut values = grid.values().to_vec();
    for i in &ended {
        values[*i] = (values[*i] + p.hit).clamp(p.min, p.max);
    }
    for i in crossed.difference(&ended) {
        values[*i] = (values[*i] + p.miss).clamp(p.min, p.max);
    }
    let mut expected = grid.clone();
    expected.set_values_for_test(values);
    *grid = expected;
}

#[test]
fn a_scan_updates_each_cell_once_in_any_order_and_thread_count() {
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    for case in 0..6 {
        let origin = Point3::from(random_offset(&mut rng));
        let n = if case % 2 == 0 { 300 } else { 5000 };
        let hit = case != 3;
        let mut ends = random_ends(&mut rng, &origin, n, 0.3, 4.0);
        ends.push(Point3::new(f64::NAN, 0.0, 0.0));
        let mut scratch = ScanScratch::default();
        let mut fast = grid_at(0.3);
        // Two scans, so that the second starts from non-zero cells and reused marks.
        for _ in 0..2 {
            scratch.insert_scan(&mut fast, &origin, &ends, hit, None);
        }
        let mut slow = grid_at(0.3);
        for _ in 0..2 {
            scan_reference(&mut slow, &origin, &ends, hit);
        }
        assert!(fast.values() == slow.values(), "case {case}");
        let mut reversed = ends.clone();
        reversed.reverse();
        let one_thread = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let mut serial = grid_at(0.3);
        one_thread.install(|| {
            let mut scratch = ScanScratch::default();
            for _ in 0..2 {
                scratch.insert_scan(&mut serial, &origin, &reversed, hit, None);
            }
        });
        assert!(
            serial.values() == fast.values(),
            "case {case}: order or threads matter"
        );
        // Restricted to a box: the same cells inside it, nothing outside.
        let b = CellBox {
            min: [3, 2, 1],
            max: [12, 9, 6],
        };
        let mut boxed = grid_at(0.3);
        scratch.insert_scan(&mut boxed, &origin, &ends, hit, Some(&[b]));
        let mut once = grid_at(0.3);
        scan_reference(&mut once, &origin, &ends, hit);
        for (i, (a, e)) in boxed.values().iter().zip(once.values()).enumerate() {
            let d = boxed.dims();
            let c = [i % d[0], (i / d[0]) % d[1], i / (d[0] * d[1])];
            assert_eq!(
                *a,
                if b.contains(c) { *e } else { 0.0 },
                "case {case} cell {c:?}"
            );
        }
    }
}

#[test]
fn the_tight_walk_visits_the_iterators_cells() {
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let grid = grid_at(0.0);
    // Axis-aligned and diagonal rays through cell corners as well as random ones.
    let mut rays = vec![
        (Point3::new(-1.0, -1.0, -0.6), Point3::new(1.0, 1.0, 0.6)),
        (Point3::new(-1.0, 0.0, 0.0), Point3::new(1.4, 0.0, 0.0)),
        (Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.0)),
    ];
    for _ in 0..3000 {
        let o = Point3::new(
            rng.random_range(-2.5..2.5),
            rng.random_range(-2.0..2.0),
            rng.random_range(-1.5..1.5),
        );
        let e = o + Vector3::new(
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
            rng.random_range(-2.0..2.0),
        );
        rays.push((o, e));
    }
    for (o, e) in rays {
        let walk = grid.walk(&o, &e).unwrap();
        let slow: Vec<(usize, [usize; 3], bool)> = walk
            .clone()
            .filter_map(|s| s.index.map(|i| (i, s.cell, s.is_end)))
            .collect();
        let mut fast = Vec::new();
        walk.for_each_inside(|i, c, end| fast.push((i, c, end)));
        assert_eq!(fast, slow, "{o} → {e}");
    }
}

#[test]
fn scan_marks_survive_their_counter_wrapping() {
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    let origin = Point3::new(0.1, -0.2, 0.05);
    let (mut fast, mut slow) = (grid_at(0.0), grid_at(0.0));
    let mut scratch = ScanScratch::default();
    // More scans than the byte-sized scan counter holds before it wraps.
    for scan in 0..300 {
        let ends: Vec<Point3<f64>> = (0..20)
            .map(|_| {
                origin
                    + Vector3::new(
                        rng.random_range(-2.0..2.0),
                        rng.random_range(-1.5..1.5),
                        rng.random_range(-1.0..1.0),
                    )
            })
            .collect();
        let hit = scan % 3 != 0;
        scratch.insert_scan(&mut fast, &origin, &ends, hit, None);
        scan_reference(&mut slow, &origin, &ends, hit);
        assert!(fast.values() == slow.values(), "scan {scan}");
    }
}

#[test]
fn a_dropout_in_a_wall_clears_nothing_behind_it() {
    use crate::frame::DepthFrame;
    use crate::grid::{free_range_m, insert_frame};
    use crate::sogmm::synthetic::intrinsics;
    use troupe_core::Time;

    // A wall 2 m ahead fills the view but for one dropout pixel, and the top rows see
    // nothing within range (open sky).
    let k = intrinsics(40, 30);
    let mut depth_m = vec![2.0f32; 40 * 30];
    for d in &mut depth_m[..40 * 4] {
        *d = 0.0;
    }
    depth_m[15 * 40 + 20] = 0.0;
    let frame = DepthFrame {
        stamp: Time::ZERO,
        pose: nalgebra::Isometry3::identity(),
        intrinsics: k,
        depth_m,
        intensity: vec![0.5; 40 * 30],
    };
    // The dropout is free only up to its neighbours' wall, two cells short.
    assert_eq!(free_range_m(&frame, (15, 20), 1, 0.4), Some(2.0 - 0.4));
    assert_eq!(free_range_m(&frame, (1, 20), 1, 0.4), Some(k.max_depth_m));
    assert_eq!(free_range_m(&frame, (3, 20), 1, 0.4), Some(2.0 - 0.4)); // next to the wall
    assert_eq!(free_range_m(&frame, (10, 20), 1, 0.4), None); // a return
    let mut grid = LocalGrid::centred(
        &Point3::origin(),
        &Vector3::new(12.0, 12.0, 8.0),
        0.2,
        LogOddsParams::default(),
    );
    insert_frame(&mut grid, &frame, 1);
    // Behind the wall along the dropout's ray: unknown, not free.
    let behind = grid.cell_of(&Point3::new(3.0, 0.0, 0.0)).unwrap();
    assert_eq!(grid.state(behind), CellState::Unknown);
    let wall = grid.cell_of(&Point3::new(2.0, 0.0, 0.0)).unwrap();
    assert_eq!(grid.state(wall), CellState::Occupied);

    // Read every second pixel, the free range looks at the pixels read: a camera that
    // renders only those (the others no return) gives the same ranges.
    let mut sparse = frame.clone();
    for (i, d) in sparse.depth_m.iter_mut().enumerate() {
        if (i % 40) % 2 == 1 || (i / 40) % 2 == 1 {
            *d = 0.0;
        }
    }
    let mut dropped = frame.clone();
    dropped.depth_m[16 * 40 + 20] = 0.0;
    sparse.depth_m[16 * 40 + 20] = 0.0;
    for row in (0..30).step_by(2) {
        for col in (0..40).step_by(2) {
            assert_eq!(
                free_range_m(&dropped, (row, col), 2, 0.4),
                free_range_m(&sparse, (row, col), 2, 0.4),
                "({row}, {col})"
            );
        }
    }
    assert_eq!(free_range_m(&sparse, (16, 20), 2, 0.4), Some(2.0 - 0.4));
    assert_eq!(free_range_m(&sparse, (0, 20), 2, 0.4), Some(k.max_depth_m));
}
