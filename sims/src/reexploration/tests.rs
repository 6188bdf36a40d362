use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use troupe_core::Time;

use super::*;
use crate::camera::CameraParams;
use crate::coverage::CoverageGrid;
use crate::world::{Aabb, BoxRoom};

/// One frame: robot, time in seconds, the cells its rays crossed (repeats allowed),
/// the robot's speed.
type Frame = (usize, f64, Vec<usize>, f64);

/// Cell edge of the synthetic grids: 0.125 m³ cells, so volumes are exact.
const CELL_M: f64 = 0.5;

fn run(frames: &[Frame], cells: usize, robots: usize) -> ReExplorationLedger {
    let mut ledger = ReExplorationLedger::new(cells, CELL_M, robots);
    for (robot, t, seen, speed) in frames {
        let mut account = ledger
            .frame(*robot, Time::from_secs_f64(*t))
            .expect("robot in team");
        for c in seen {
            account.saw(*c);
        }
        account.finish(*speed);
    }
    ledger
}

/// The definitions of the module documentation, computed the slow way from the whole
/// sequence: per robot, observed, first-observed, re-explored and exclusive cells and
/// redundant flight nanoseconds, and the cells observed by several robots.
fn reference(frames: &[Frame], robots: usize) -> (Vec<[u64; 5]>, u64) {
    let ns = |t: f64| Time::from_secs_f64(t).as_nanos();
    // Per cell, per robot: the time of its first frame that observed the cell.
    let mut first_by: BTreeMap<usize, BTreeMap<usize, u64>> = BTreeMap::new();
    for (robot, t, seen, _) in frames {
        for c in seen {
            let e = first_by
                .entry(*c)
                .or_default()
                .entry(*robot)
                .or_insert(ns(*t));
            *e = (*e).min(ns(*t));
        }
    }
    let mut out = vec![[0u64; 5]; robots];
    let mut shared = 0;
    for by in first_by.values() {
        let team_first = by.values().copied().min().expect("observed");
        for (&r, &t) in by {
            out[r][0] += 1;
            if t == team_first {
                out[r][1] += 1;
            } else {
                out[r][2] += 1;
            }
        }
        if by.len() == 1 {
            out[*by.keys().next().expect("one")][3] += 1;
        } else {
            shared += 1;
        }
    }
    for (r, counts) in out.iter_mut().enumerate() {
        let mut last: Option<u64> = None;
        for (_, t, seen, speed) in frames.iter().filter(|f| f.0 == r) {
            let new = seen
                .iter()
                .any(|c| first_by[c].values().copied().min() == Some(ns(*t)));
            if let Some(last) = last
                && !new
                && *speed >= UNPRODUCTIVE_SPEED_MPS
            {
                counts[4] += ns(*t) - last;
            }
            last = Some(ns(*t));
        }
    }
    (out, shared)
}

/// The ledger's figures as the reference's integers.
fn counts(ledger: &ReExplorationLedger, robot: usize) -> [u64; 5] {
    let f = ledger.robot(robot);
    let cells = |m3: f64| {
        let n = m3 / CELL_M.powi(3);
        assert_eq!(n, n.round(), "{m3} m³ is whole cells");
        n as u64
    };
    [
        cells(f.observed_m3),
        cells(f.first_observed_m3),
        cells(f.reexplored_m3),
        cells(f.exclusive_m3),
        Time::from_secs_f64(f.redundant_flight_s).as_nanos(),
    ]
}

/// A hand-made sequence: two robots, ten cells.
fn hand_made() -> Vec<Frame> {
    vec![
        (0, 1.0, vec![0, 1, 2, 1], 1.0), // 0, 1, 2 new (1 twice in the frame)
        (1, 1.0, vec![2, 3], 1.0),       // a tie on 2: both first observers; 3 new
        (1, 2.0, vec![0, 4], 1.0),       // 0 re-explored (robot 0 at 1 s); 4 new
        (0, 3.0, vec![4, 5, 1], 1.0),    // 4 re-explored; 5 new; 1 its own
        (0, 4.0, vec![0, 1, 5], 1.0),    // nothing new to the team: 1 s redundant
        (1, 5.0, vec![3], 1.0),          // nothing new: 3 s redundant
        (1, 6.0, vec![2], 0.05),         // nothing new, but hovering: none
    ]
}

#[test]
fn a_hand_made_sequence_gives_the_hand_counted_figures() {
    let ledger = run(&hand_made(), 10, 2);
    let v = CELL_M.powi(3);
    assert_eq!(
        ledger.robot(0),
        ReExploration {
            observed_m3: 5.0 * v,       // 0 1 2 4 5
            first_observed_m3: 4.0 * v, // 0 1 2 5
            reexplored_m3: v,           // 4
            exclusive_m3: 2.0 * v,      // 1 5
            redundant_flight_s: 1.0,
        }
    );
    assert_eq!(
        ledger.robot(1),
        ReExploration {
            observed_m3: 4.0 * v,       // 0 2 3 4
            first_observed_m3: 3.0 * v, // 2 3 4
            reexplored_m3: v,           // 0
            exclusive_m3: v,            // 3
            redundant_flight_s: 3.0,
        }
    );
    assert_eq!(
        ledger.team(),
        TeamReExploration {
            reexplored_m3: 2.0 * v,
            exclusive_m3: 3.0 * v,
            shared_m3: 3.0 * v, // 0 2 4
            redundant_flight_s: 4.0,
        }
    );
    assert_eq!(
        reference(&hand_made(), 2),
        ((0..2).map(|r| counts(&ledger, r)).collect(), 3)
    );
}

#[test]
fn frames_of_the_same_time_count_the_same_in_either_order() {
    let mut swapped = hand_made();
    swapped.swap(0, 1);
    let (a, b) = (run(&swapped, 10, 2), run(&hand_made(), 10, 2));
    for r in 0..2 {
        assert_eq!(a.robot(r), b.robot(r), "robot {r}");
    }
    assert_eq!(a.team(), b.team());
}

#[test]
fn the_ledger_matches_the_slow_reference_on_random_sequences() {
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    for case in 0..200 {
        let robots = rng.random_range(1..=4);
        let cells = rng.random_range(1..=80);
        let mut t = 0.0;
        let mut frames: Vec<Frame> = Vec::new();
        for _ in 0..rng.random_range(0..40) {
            // Frames in time order; about half share their time with the previous one
            // (another robot's frame at the same instant, as cameras tick together).
            if rng.random_bool(0.5) || frames.is_empty() {
                t += 0.25;
            }
            let robot = rng.random_range(0..robots);
            if frames.last().is_some_and(|f| f.1 == t && f.0 == robot) {
                continue; // one frame per robot per instant
            }
            let seen = (0..rng.random_range(0..12))
                .map(|_| rng.random_range(0..cells))
                .collect();
            let speed = if rng.random_bool(0.8) { 1.0 } else { 0.0 };
            frames.push((robot, t, seen, speed));
        }
        let ledger = run(&frames, cells, robots);
        let (expected, shared) = reference(&frames, robots);
        for (r, e) in expected.iter().enumerate() {
            assert_eq!(&counts(&ledger, r), e, "case {case}, robot {r}: {frames:?}");
            assert_eq!(e[0], e[1] + e[2], "observed = first + re-explored");
        }
        assert_eq!(
            ledger.team().shared_m3,
            shared as f64 * CELL_M.powi(3),
            "case {case}"
        );
    }
}

#[test]
fn a_robot_outside_the_team_and_a_cell_outside_the_grid_count_nothing() {
    let mut ledger = ReExplorationLedger::new(10, CELL_M, 1);
    assert!(ledger.frame(1, Time::ZERO).is_none());
    let mut account = ledger.frame(0, Time::ZERO).expect("robot 0");
    account.saw(10);
    account.saw(1000);
    assert!(!account.finish(1.0), "nothing new");
    assert_eq!(ledger.robot(0), ReExploration::default());
    assert_eq!(ledger.robot(7), ReExploration::default());
}

/// A straight corridor along x, 3 m × 3 m, from x = −1 m to x = 21 m.
fn corridor() -> BoxRoom {
    BoxRoom::new(Aabb::new(
        Point3::new(-1.0, -1.5, -1.5),
        Point3::new(21.0, 1.5, 1.5),
    ))
}

/// Frames every 0.5 s, flying at 1 m/s: robot 0 from x = 0 along +x, robot 1 from
/// x = 20 along −x (the camera's 5 m range ahead of each), each stopping — hovering
/// where it is, still taking frames — once it has flown `stop_after_m`.
fn fly_towards_each_other(stop_after_m: f64) -> (CoverageGrid, ReExplorationLedger) {
    let world = corridor();
    let camera = CameraParams::default();
    let mut coverage = CoverageGrid::new(&world, 0.5);
    let mut ledger = ReExplorationLedger::new(coverage.grid().cell_count(), 0.5, 2);
    for k in 0..=40u32 {
        let t = f64::from(k) * 0.5;
        let flown = t.min(stop_after_m);
        let speed = if t < stop_after_m { 1.0 } else { 0.0 };
        for (robot, x, yaw) in [(0, flown, 0.0), (1, 20.0 - flown, std::f64::consts::PI)] {
            let pose = Isometry3::from_parts(
                Translation3::new(x, 0.0, 0.0),
                UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
            );
            let frame = camera.render(&world, Time::from_secs_f64(t), &pose, u64::from(k));
            let mut account = ledger
                .frame(robot, Time::from_secs_f64(t))
                .expect("robot in team");
            coverage.observe_visiting(&frame, 4, |c| account.saw(c));
            account.finish(speed);
        }
    }
    (coverage, ledger)
}

/// The hand-built case of issue 41: two robots, one corridor, entering from its two
/// ends. With each other's maps delivered, each turns back where its view meets what
/// the other has seen (after 5 m: the camera's range short of the middle); with the
/// peer's map withheld, each flies the whole corridor, re-flying the half its peer
/// saw. Re-explored volume is (almost) nothing in the first case, and in the second
/// each robot's is the far half it saw after its peer had.
#[test]
fn a_peer_map_withheld_makes_each_robot_re_explore_the_other_half_of_a_corridor() {
    let (delivered_cov, delivered) = fly_towards_each_other(5.0);
    let (withheld_cov, withheld) = fly_towards_each_other(20.0);
    let v = 0.5f64.powi(3);
    for (coverage, ledger) in [(&delivered_cov, &delivered), (&withheld_cov, &withheld)] {
        // Every explored cell was observed by one robot alone or by both.
        let team = ledger.team();
        let cells = (team.exclusive_m3 + team.shared_m3) / v;
        assert_eq!(cells.round() as usize, coverage.explored_cells());
        for r in 0..2 {
            let f = ledger.robot(r);
            assert!(
                (f.observed_m3 - f.first_observed_m3 - f.reexplored_m3).abs() < 1e-9,
                "{f:?}"
            );
        }
    }
    let explored_m3 = withheld_cov.explored_volume_m3();
    assert!(
        explored_m3 > 0.8 * withheld_cov.free_volume_m3(),
        "the two flights see most of the corridor: {explored_m3} m³"
    );
    for r in 0..2 {
        let (d, w) = (delivered.robot(r), withheld.robot(r));
        // Delivered: the two views meet at the middle at the same instant.
        assert!(
            d.reexplored_m3 < 0.02 * explored_m3,
            "robot {r} re-explored {} m³ of {explored_m3} m³ with maps delivered",
            d.reexplored_m3
        );
        assert_eq!(
            d.redundant_flight_s, 0.0,
            "robot {r} saw something new until it stopped"
        );
        // Withheld: the far half, seen by the peer first.
        assert!(
            w.reexplored_m3 > 0.4 * explored_m3,
            "robot {r} re-explored {} m³ of {explored_m3} m³ with maps withheld",
            w.reexplored_m3
        );
        // Alone it saw only its own end behind the peer's start; with the map its half.
        assert!(w.exclusive_m3 < 0.5 * d.exclusive_m3, "{w:?} vs {d:?}");
        // Once it has passed the cells beside the middle (about 8.5 m flown), every
        // frame looks into space the peer saw first: the rest of its 20 s is redundant.
        assert!(
            (8.0..=15.0).contains(&w.redundant_flight_s),
            "robot {r}: {} s redundant",
            w.redundant_flight_s
        );
    }
}
