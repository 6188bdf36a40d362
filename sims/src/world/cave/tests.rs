use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;

const SEEDS: [u64; 6] = [0, 1, 2, 7, 42, 12345];

fn cave(seed: u64) -> CaveWorld {
    CaveWorld::generate(&CaveParams::default(), seed)
}

fn random_point(rng: &mut ChaCha8Rng, b: &Aabb) -> Point3<f64> {
    Point3::new(
        rng.random_range(b.min.x..b.max.x),
        rng.random_range(b.min.y..b.max.y),
        rng.random_range(b.min.z..b.max.z),
    )
}

#[test]
fn shape_is_a_tree_of_the_expected_size() {
    for seed in SEEDS {
        let w = cave(seed);
        let g = w.graph();
        assert_eq!(g.nodes.len(), g.edges.len() + 1, "seed {seed}");
        assert!(
            g.edges.len() >= 7,
            "seed {seed}: only {} tunnels",
            g.edges.len()
        );
        let chambers = g
            .nodes
            .iter()
            .filter(|n| n.chamber_radius_m.is_some())
            .count();
        assert!(
            (2..=4).contains(&chambers),
            "seed {seed}: {chambers} chambers"
        );
        let size = w.bounds().size();
        let extent = size.x.max(size.y);
        assert!(
            (45.0..=120.0).contains(&extent),
            "seed {seed}: extent {extent}"
        );
        assert!(w.entrance().coords.norm() < 1e-12);
        for e in &g.edges {
            assert_eq!(e.points[0], g.nodes[e.from].position);
            assert_eq!(e.points[e.points.len() - 1], g.nodes[e.to].position);
        }
    }
}

#[test]
fn indexed_field_equals_brute_force() {
    let w = cave(3);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let b = w.bounds().expanded(3.0);
    for _ in 0..20_000 {
        let p = random_point(&mut rng, &b);
        assert_eq!(w.field.base_m(&p), w.field.base_brute_m(&p), "at {p}");
    }
    // Points near walls and chamber floors too, where the pruning matters.
    for _ in 0..20_000 {
        let p = random_point(&mut rng, &w.bounds());
        if w.field.base_m(&p).abs() < 0.6 {
            assert_eq!(w.field.base_m(&p), w.field.base_brute_m(&p), "at {p}");
        }
    }
    // The fine index against the coarse one, bit for bit, on many near-wall points.
    for seed in [0, 1, 2, 3] {
        let w = cave(seed);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut near = 0;
        while near < 200_000 {
            let p = random_point(&mut rng, &w.bounds());
            let fine = w.field.base_m(&p);
            if fine.abs() < 0.5 {
                near += 1;
            }
            assert_eq!(
                fine.to_bits(),
                w.field.base_coarse_m(&p).to_bits(),
                "at {p}"
            );
        }
    }
    let [coarse, fine] = w.field.mean_items_per_busy_cell();
    assert!(coarse < 12.0, "index lists {coarse} primitives per cell");
    assert!(fine < 4.0, "fine index lists {fine} primitives per cell");
    eprintln!("primitives per busy cell: coarse {coarse:.2}, fine {fine:.2}");
}

#[test]
fn sdf_sign_inside_and_outside() {
    for seed in SEEDS {
        let w = cave(seed);
        for p in w.centreline_route(0, 1) {
            assert!(w.sdf_m(&p) > 1.0, "seed {seed}: route point {p} not free");
        }
        let b = w.bounds();
        let far = [
            b.min - Vector3::repeat(5.0),
            b.max + Vector3::repeat(5.0),
            Point3::new(b.centre().x, b.centre().y, b.max.z + 10.0),
        ];
        for p in far {
            assert!(w.sdf_m(&p) < 0.0, "seed {seed}: {p} should be rock");
        }
        // Bounds hold all free space: sample just outside them.
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        for _ in 0..2000 {
            let mut p = random_point(&mut rng, &b);
            let axis = rng.random_range(0..3);
            p[axis] = if rng.random_bool(0.5) {
                b.min[axis] - 0.01
            } else {
                b.max[axis] + 0.01
            };
            assert!(
                w.sdf_m(&p) < 0.0,
                "seed {seed}: free point {p} outside bounds"
            );
        }
    }
}

#[test]
fn sdf_respects_lipschitz_bound() {
    for seed in [0, 5] {
        let w = cave(seed);
        let l = w.lipschitz();
        assert!(l > 1.0 && l < 1.5, "lipschitz {l}");
        let mut rng = ChaCha8Rng::seed_from_u64(seed + 100);
        let b = w.bounds();
        for i in 0..50_000 {
            let p = random_point(&mut rng, &b);
            let scale = if i % 2 == 0 { 0.05 } else { 3.0 };
            let d = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ) * scale;
            let q = p + d;
            let lhs = (w.sdf_m(&p) - w.sdf_m(&q)).abs();
            assert!(
                lhs <= l * d.norm() + 1e-12,
                "seed {seed}: {lhs} > {l} * {}",
                d.norm()
            );
            // A safe step from a free point never lands in rock.
            let s = w.safe_step_m(&p);
            if w.sdf_m(&p) > 0.0 && d.norm() <= s {
                assert!(
                    w.sdf_m(&q) >= -1e-12,
                    "step {s} from {p} reached rock at {q}"
                );
            }
        }
    }
}

#[test]
fn same_seed_same_cave_other_seed_other_cave() {
    let (a, b, c) = (cave(9), cave(9), cave(10));
    assert_eq!(a.graph(), b.graph());
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let bounds = a.bounds();
    let mut differ = 0;
    for _ in 0..5000 {
        let p = random_point(&mut rng, &bounds);
        assert_eq!(a.sdf_m(&p).to_bits(), b.sdf_m(&p).to_bits());
        assert_eq!(a.albedo(&p).to_bits(), b.albedo(&p).to_bits());
        if a.sdf_m(&p) != c.sdf_m(&p) {
            differ += 1;
        }
    }
    assert!(
        differ > 2500,
        "seeds 9 and 10 differ at only {differ} points"
    );
    assert_ne!(a.graph(), c.graph());
}

#[test]
fn albedo_in_unit_interval_with_structure() {
    let w = cave(4);
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let b = w.bounds();
    let (mut lo, mut hi) = (1.0f64, 0.0f64);
    for _ in 0..10_000 {
        let a = w.albedo(&random_point(&mut rng, &b));
        assert!((0.0..=1.0).contains(&a));
        lo = lo.min(a);
        hi = hi.max(a);
    }
    assert!(hi - lo > 0.5, "albedo range {lo}..{hi} too flat");
}

/// Largest gap between dense samples on a route segment, in metres.
const SAMPLE_STEP_M: f64 = 0.05;

#[test]
fn route_and_its_segments_keep_clearance() {
    for seed in SEEDS {
        let w = cave(seed);
        for robot_count in [1, 3] {
            for robot in 0..robot_count {
                let route = w.centreline_route(robot, robot_count);
                assert_eq!(route[0], w.start_position(robot, robot_count));
                for pair in route.windows(2) {
                    let (a, b) = (pair[0], pair[1]);
                    let n = ((b - a).norm() / SAMPLE_STEP_M).ceil().max(1.0) as usize;
                    for i in 0..=n {
                        let p = a + (b - a) * (i as f64 / n as f64);
                        let s = w.sdf_m(&p);
                        assert!(
                            s >= ROUTE_CLEARANCE_M,
                            "seed {seed} robot {robot}: {s} at {p}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn route_visits_every_node_and_branches_differ() {
    for seed in SEEDS {
        let w = cave(seed);
        let g = w.graph();
        let routes: Vec<_> = (0..3).map(|r| w.centreline_route(r, 3)).collect();
        for (r, route) in routes.iter().enumerate() {
            for (i, n) in g.nodes.iter().enumerate() {
                assert!(
                    route.iter().any(|p| (p - n.position).norm() < 1e-9),
                    "seed {seed}: robot {r} misses node {i}"
                );
            }
            // Each tunnel is walked out and back once: about twice the total length.
            let len = polyline_length(route);
            let total = 2.0 * g.total_length_m();
            let seg = CaveParams::default().segment_length_m;
            assert!(len <= total + 1e-6 && len > total - seg, "{len} vs {total}");
        }
        let junction = g.nodes.iter().any(|n| n.child_edges.len() > 1);
        if junction {
            assert_ne!(
                routes[0], routes[1],
                "seed {seed}: robots 0 and 1 take the same order"
            );
        }
    }
}

#[test]
fn start_positions_are_spaced_and_clear() {
    for seed in SEEDS {
        let w = cave(seed);
        let n = 8;
        let starts: Vec<_> = (0..n).map(|i| w.start_position(i, n)).collect();
        for (i, p) in starts.iter().enumerate() {
            assert!(w.sdf_m(p) >= ROUTE_CLEARANCE_M, "seed {seed}: robot {i}");
            assert!(
                (p - w.entrance()).norm() < 20.0,
                "seed {seed}: robot {i} far in"
            );
            for q in &starts[..i] {
                assert!((p - q).norm() >= 1.5, "seed {seed}: robots too close");
            }
        }
    }
}

#[test]
fn a_team_larger_than_the_entrance_tunnel_holds_starts_spaced_in_the_other_tunnels() {
    for seed in [1, 2] {
        let w = cave(seed);
        let n = 64;
        let starts: Vec<_> = (0..n).map(|i| w.start_position(i, n)).collect();
        // The first robots are where they always were.
        assert_eq!(
            starts[..8],
            (0..8).map(|i| w.start_position(i, 8)).collect::<Vec<_>>()[..]
        );
        for (i, p) in starts.iter().enumerate() {
            assert!(w.sdf_m(p) >= ROUTE_CLEARANCE_M, "seed {seed}: robot {i}");
            for (k, q) in starts[..i].iter().enumerate() {
                assert!(
                    (p - q).norm() >= START_SPACING_M - 1e-9,
                    "seed {seed}: robots {k} and {i} {} m apart",
                    (p - q).norm()
                );
            }
        }
    }
}

#[test]
fn tetrahedral_normal_matches_central_differences() {
    let w = cave(1);
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let b = w.bounds();
    let central = |p: &Point3<f64>| {
        let h = crate::world::NORMAL_STEP_M;
        let d = |e: Vector3<f64>| w.sdf_m(&(p + e * h)) - w.sdf_m(&(p - e * h));
        Vector3::new(d(Vector3::x()), d(Vector3::y()), d(Vector3::z())).normalize()
    };
    let mut checked = 0;
    while checked < 2000 {
        let p = random_point(&mut rng, &b);
        if w.sdf_m(&p).abs() > 0.05 {
            continue;
        }
        checked += 1;
        let (a, c) = (w.normal(&p), central(&p));
        assert!((a - c).norm() < 0.02, "{a} vs {c} at {p}");
    }
}

#[test]
fn minimal_parameters_still_give_a_usable_cave() {
    let params = CaveParams {
        tunnel_count: 1,
        chamber_count: 0,
        max_grade: 0.0,
        wiggle_deg: 0.0,
        ..CaveParams::default()
    };
    assert_eq!(params.validate(), Ok(()));
    let w = CaveWorld::generate(&params, 1);
    assert_eq!(w.graph().edges.len(), 1);
    let route = w.centreline_route(2, 3);
    assert_eq!(route[0], w.start_position(2, 3));
    assert!(route.iter().all(|p| w.sdf_m(p) >= ROUTE_CLEARANCE_M));
    // Robots beyond what the cave holds share the chain's last point rather than panicking.
    let last = w.start_position(1000, 1001);
    assert!(w.sdf_m(&last) >= ROUTE_CLEARANCE_M);
}
