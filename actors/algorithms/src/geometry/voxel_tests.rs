//! The voxel traversal against brute-force sampling.

use std::collections::BTreeSet;

use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::VoxelGrid;

/// Cells hit by samples every `step` along the segment (the brute-force reference).
fn sampled_cells(
    g: &VoxelGrid,
    o: &Point3<f64>,
    d: &Vector3<f64>,
    t_end: f64,
    step: f64,
) -> BTreeSet<[usize; 3]> {
    let n = (t_end * d.norm() / step).ceil() as usize;
    (0..n)
        .filter_map(|i| g.cell_of(&(o + d * (t_end * i as f64 / n as f64))))
        .collect()
}

#[test]
fn dda_marks_exactly_the_cells_fine_sampling_visits() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let step = 1e-4;
    for case in 0..400 {
        let g = VoxelGrid {
            origin: Point3::new(
                rng.random_range(-2.0..2.0),
                rng.random_range(-2.0..2.0),
                0.0,
            ),
            cell_m: rng.random_range(0.1..0.7),
            dims: [
                rng.random_range(1..12),
                rng.random_range(1..12),
                rng.random_range(1..12),
            ],
        };
        let b = g.aabb().expanded(1.0);
        let mut pick = || {
            Point3::new(
                rng.random_range(b.min.x..b.max.x),
                rng.random_range(b.min.y..b.max.y),
                rng.random_range(b.min.z..b.max.z),
            )
        };
        let (o, e) = (pick(), pick());
        // Also axis-aligned segments, which exercise zero direction components.
        let e = if case % 10 == 0 {
            Point3::new(e.x, o.y, o.z)
        } else {
            e
        };
        let d = (e - o) * 0.5;
        let t_end = 2.0;
        let mut visited = Vec::new();
        let mut last_exit = None;
        g.traverse(&o, &d, t_end, |c, t0, t1| {
            assert!(t1 > t0);
            if let Some(prev) = last_exit {
                assert!(
                    t0 - prev >= -1e-12 && t0 - prev < 1e-9,
                    "gap in case {case}"
                );
            }
            last_exit = Some(t1);
            visited.push((c, (t1 - t0) * d.norm()));
            true
        });
        let dda: BTreeSet<[usize; 3]> = visited.iter().map(|(c, _)| *c).collect();
        assert_eq!(
            dda.len(),
            visited.len(),
            "case {case}: a cell visited twice"
        );
        let brute = sampled_cells(&g, &o, &d, t_end, step);
        for c in &brute {
            assert!(dda.contains(c), "case {case}: DDA missed {c:?}");
        }
        for (c, len) in &visited {
            assert!(
                brute.contains(c) || *len < 2.0 * step,
                "case {case}: extra {c:?} ({len})"
            );
        }
    }
}
