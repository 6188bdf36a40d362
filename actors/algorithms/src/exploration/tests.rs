//! Tests of the frontier memory, the guidance field and coordination, on synthetic
//! tunnel worlds whose grid snapshots are built cell by cell.

use nalgebra::{Isometry3, Matrix4, Point3, Vector3, Vector4};
use troupe_core::{RobotId, Time};

use super::*;
use crate::grid::{CellState, GridSnapshot, LocalGrid, LogOddsParams};
use crate::keyframe::Keyframe;
use crate::planner::primitives::FlatState;
use crate::planner::problem::PlanningProblem;
use crate::planner::round::{Candidate, RoundConfig};
use crate::planner::scenes::{forward_camera, snapshot_of};
use crate::sogmm::Gmm4;
use crate::team::PeerKeyframe;

/// A snapshot of a window of `size_m` at 0.2 m centred on `centre`, each cell set to
/// what `world` says of its centre (known free, occupied, or never seen).
fn window(
    centre: Point3<f64>,
    size_m: [f64; 3],
    world: impl Fn(&Point3<f64>) -> CellState,
) -> GridSnapshot {
    let mut grid = LocalGrid::centred(
        &centre,
        &Vector3::from(size_m),
        0.2,
        LogOddsParams::default(),
    );
    let geometry = grid.geometry();
    for i in 0..grid.values().len() {
        let p = geometry.cell_centre(grid.cell_at(i));
        match world(&p) {
            CellState::Free => grid.update(i, -10.0),
            CellState::Occupied => grid.update(i, 10.0),
            CellState::Unknown => {}
        }
    }
    snapshot_of(grid)
}

/// A box-shaped tunnel world: inside any of `tunnels` (min, max corners) is air,
/// rock within 0.5 m of air is a wall; air is known where `known` says so.
fn tunnels(
    tunnels: Vec<([f64; 3], [f64; 3])>,
    known: impl Fn(&Point3<f64>) -> bool,
) -> impl Fn(&Point3<f64>) -> CellState {
    move |p| {
        let gap = |(lo, hi): &([f64; 3], [f64; 3])| -> f64 {
            (0..3)
                .map(|i| (lo[i] - p[i]).max(p[i] - hi[i]).max(0.0))
                .fold(0.0, f64::max)
        };
        let nearest = tunnels.iter().map(gap).fold(f64::INFINITY, f64::min);
        if nearest == 0.0 {
            if known(p) {
                CellState::Free
            } else {
                CellState::Unknown
            }
        } else if nearest < 0.5 {
            // A wall is known where the air beside it is.
            if known(p) {
                CellState::Occupied
            } else {
                CellState::Unknown
            }
        } else {
            CellState::Unknown
        }
    }
}

fn keyframe_towards(
    id: u32,
    from: Point3<f64>,
    surface: Point3<f64>,
    spread_m: [f64; 3],
) -> Keyframe {
    let cov = Matrix4::from_diagonal(&Vector4::new(
        spread_m[0].powi(2),
        spread_m[1].powi(2),
        spread_m[2].powi(2),
        0.01,
    ));
    Keyframe {
        id,
        stamp: Time::ZERO,
        pose: Isometry3::translation(from.x, from.y, from.z),
        support_size: 5000,
        gmm: Gmm4::new(
            vec![1.0],
            vec![Vector4::new(surface.x, surface.y, surface.z, 0.5)],
            vec![cov],
        )
        .expect("valid mixture"),
    }
}

/// A memory cell seen and passable.
const PASSABLE_CELL: CellRecord = CellRecord {
    seen: true,
    passable: true,
    frontier: false,
    settled: false,
};

/// A memory cell seen and holding a frontier.
const FRONTIER_CELL: CellRecord = CellRecord {
    seen: true,
    passable: false,
    frontier: true,
    settled: false,
};

/// Keyframe `id` of robot 1 at x = 3 m looking at `surface` ([`keyframe_towards`]).
fn peer_at_3_m(id: u32, surface: Point3<f64>, spread_m: [f64; 3]) -> PeerKeyframe {
    PeerKeyframe {
        robot: RobotId(1),
        keyframe: keyframe_towards(id, Point3::new(3.0, 0.0, 0.0), surface, spread_m),
        made_ns: 0,
        received_at: Time::ZERO,
    }
}

/// The window (20 × 20 × 4 m, at the origin) of a tunnel along x that is seen up to
/// x = 6 m and open (unknown) beyond.
fn tunnel_seen_to_6_m() -> GridSnapshot {
    let world = tunnels(vec![([-3.0, -2.0, -1.0], [30.0, 2.0, 1.0])], |p| p.x < 6.0);
    window(Point3::origin(), [20.0, 20.0, 4.0], &world)
}

#[test]
fn memory_retires_a_frontier_a_peers_keyframe_sees() {
    let snapshot = tunnel_seen_to_6_m();
    let mut guide = Guide::new(GuidanceConfig::default());
    guide.observe_snapshot(&snapshot, 0.67, None);
    let frontiers: Vec<CellKey> = guide.memory().frontiers().collect();
    assert!(!frontiers.is_empty());
    assert!(
        frontiers.iter().all(|k| (5..=6).contains(&k[0])),
        "{frontiers:?}"
    );
    // A peer looking the other way (at the tunnel's closed start) retires nothing.
    let behind = peer_at_3_m(0, Point3::new(-2.5, 0.0, 0.0), [0.2, 1.0, 0.6]);
    assert_eq!(guide.observe_peer_keyframe(&behind).retired, 0);
    assert_eq!(guide.memory().frontiers().count(), frontiers.len());
    // A peer looking down the tunnel, at its walls beyond x = 6 m, sees them all.
    let ahead = peer_at_3_m(1, Point3::new(9.0, 0.0, 0.0), [1.0, 1.2, 0.7]);
    let update = guide.observe_peer_keyframe(&ahead);
    assert_eq!(update.retired, frontiers.len());
    assert_eq!(guide.memory().frontiers().count(), 0);
    assert_eq!(guide.retired_by_peers(), frontiers.len() as u64);
    // The cells it looked through are remembered as seen.
    assert!(guide.memory().record([8, 0, 0]).seen);
}

#[test]
fn with_quick_end_frontiers_where_a_peer_looked_keep_no_mission_going() {
    let snapshot = tunnel_seen_to_6_m();
    let ahead = peer_at_3_m(1, Point3::new(9.0, 0.0, 0.0), [1.0, 1.2, 0.7]);
    let here = Point3::new(2.0, 0.0, 0.0);
    let has_work = |config: GuidanceConfig, peer_looked: bool| {
        let mut guide = Guide::new(config);
        guide.observe_snapshot(&snapshot, 0.67, None);
        let frontiers: Vec<CellKey> = guide.memory().frontiers().collect();
        if peer_looked {
            assert_eq!(guide.observe_peer_keyframe(&ahead).retired, frontiers.len());
            // A window rebuilt over that space (from the peer's keyframes, sparser than
            // the frames that first filled it) shows the frontiers again.
            guide.observe_snapshot(&snapshot, 0.67, None);
        }
        let field = guide.field((RobotId(0), &here, 0.0), Time::ZERO);
        // They pull the robot either way.
        assert!(!frontiers.is_empty() && frontiers.iter().all(|f| field.seeds(*f)));
        assert!(field.distance_m(&here).is_finite());
        guide.has_work(&field, &here)
    };
    let quick = GuidanceConfig {
        quick_end: true,
        ..GuidanceConfig::default()
    };
    assert!(!has_work(quick, true));
    assert!(has_work(quick, false));
    assert!(has_work(GuidanceConfig::default(), true));
}

#[test]
fn a_peers_memory_cells_give_its_frontiers_and_the_way_there_and_are_not_echoed() {
    // The peer has seen the tunnel up to x = 6 m; this robot has seen nothing yet.
    let snapshot = tunnel_seen_to_6_m();
    let sharing = GuidanceConfig::default();
    assert!(sharing.share_memory, "on by default");
    // Without sharing no change is kept.
    let mut alone = Guide::new(GuidanceConfig {
        share_memory: false,
        ..sharing
    });
    alone.observe_snapshot(&snapshot, 0.67, None);
    assert!(alone.take_memory_changes().is_empty());
    let mut peer = Guide::new(sharing);
    peer.observe_snapshot(&snapshot, 0.67, None);
    let changes = peer.take_memory_changes();
    assert_eq!(changes.len(), peer.memory().cell_count());
    assert!(peer.take_memory_changes().is_empty(), "each change once");
    // The same view again changes no record, so there is nothing to send.
    peer.observe_snapshot(&snapshot, 0.67, None);
    assert!(peer.take_memory_changes().is_empty());
    let mut own = Guide::new(sharing);
    let here = Point3::new(-1.5, 0.0, 0.0);
    assert!(
        !own.field((RobotId(0), &here, 0.0), Time::ZERO)
            .distance_m(&here)
            .is_finite()
    );
    let _ = own.take_memory_changes();
    let update = own.observe_peer_memory(changes.iter().copied(), None);
    // Every cell: the one this robot already held (its own, marked by the field) is
    // one the peer settled, so it is settled here too.
    assert_eq!(update.cells, changes.len());
    let frontiers: Vec<CellKey> = own.memory().frontiers().collect();
    assert_eq!(frontiers, peer.memory().frontiers().collect::<Vec<_>>());
    // The peer's passable cells lead this robot to them.
    let field = own.field((RobotId(0), &here, 0.0), second(1.0));
    let route_m = field.distance_m(&here);
    assert!(route_m.is_finite() && route_m > 5.0, "{route_m}");
    // What came from the peer is not sent back: only this robot's own marks (its body).
    let echoed = own.take_memory_changes();
    assert!(echoed.len() <= 1, "{echoed:?}");
    // A cell the memory holds keeps its record whatever a later message says.
    let key = frontiers[0];
    let mut other = Guide::new(GuidanceConfig::default());
    let settled = CellRecord {
        seen: true,
        passable: true,
        frontier: false,
        settled: true,
    };
    other.observe_peer_memory([(key, settled)], None);
    let frontier = CellRecord {
        frontier: true,
        settled: false,
        ..settled
    };
    assert_eq!(other.observe_peer_memory([(key, frontier)], None).cells, 0);
    assert_eq!(other.memory().record(key), settled);
    // A frontier here — its own, or one taken from the peer earlier — that the peer
    // has since explored (settled) is retired: the peer's later word is not ignored.
    let update = own.observe_peer_memory([(key, settled)], None);
    assert_eq!((update.cells, update.retired), (1, 1));
    assert_eq!(own.memory().record(key), settled);
    assert!(
        own.take_memory_changes().is_empty(),
        "a peer's record is not echoed"
    );
}

#[test]
fn a_peers_memory_cells_in_its_own_world_frame_land_where_they_are_in_ours() {
    // The peer's world frame is ours turned by 90° about z and moved 10 m along x
    // (Eq. 8.1): its cell [3, 0, 0] (centre (3.5, 0.5, 0.5)) is at (9.5, 3.5, 0.5) here.
    let frame = Isometry3::new(
        Vector3::new(10.0, 0.0, 0.0),
        Vector3::z() * std::f64::consts::FRAC_PI_2,
    );
    let frontier = FRONTIER_CELL;
    let mut guide = Guide::new(GuidanceConfig::default());
    let update = guide.observe_peer_memory([([3, 0, 0], frontier)], Some(&frame));
    assert_eq!(update.cells, 1);
    assert_eq!(guide.memory().frontiers().collect::<Vec<_>>(), [[9, 3, 0]]);
    // A cell the frame moves beyond the memory's key range is left out, not wrapped.
    let far = Isometry3::translation(1e12, 0.0, 0.0);
    assert_eq!(
        guide
            .observe_peer_memory([([0, 0, 0], frontier)], Some(&far))
            .cells,
        0
    );
}

#[test]
fn explored_space_stays_explored_and_passable_when_a_rebuilt_window_shows_gaps_in_it() {
    let tunnel = || vec![([-3.0, -2.0, -1.0], [30.0, 2.0, 1.0])];
    // First look: the tunnel known up to x = 8 m.
    let first = window(
        Point3::origin(),
        [20.0, 20.0, 4.0],
        tunnels(tunnel(), |p| p.x < 8.0),
    );
    // The same window rebuilt from keyframe samples: a third of the cells between
    // x = 1 m and 5 m were crossed by no sample ray.
    let gappy = |p: &Point3<f64>| {
        let hole = ((p.x * 5.0).floor() + (p.y * 5.0).floor() + (p.z * 5.0).floor()) as i64;
        p.x < 8.0 && !((1.0..5.0).contains(&p.x) && hole.rem_euclid(3) == 0)
    };
    let rebuilt = window(
        Point3::origin(),
        [20.0, 20.0, 4.0],
        tunnels(tunnel(), gappy),
    );
    let in_gaps = |k: &CellKey| (1..5).contains(&k[0]);
    let ahead = |k: &CellKey| (7..=8).contains(&k[0]);

    // Seen only sparsely, the gaps are frontiers, and their unknown cells leave no
    // robot centre the clearance it needs there (so the checks below can fail) ...
    let mut fresh = Guide::new(GuidanceConfig::default());
    fresh.observe_snapshot(&rebuilt, 0.67, None);
    assert!(fresh.memory().frontiers().any(|k| in_gaps(&k)));
    assert!(!fresh.memory().passable().any(|k| in_gaps(&k)));
    // ... but not where the memory already saw everything; the open end stays one.
    let mut guide = Guide::new(GuidanceConfig::default());
    guide.observe_snapshot(&first, 0.67, None);
    assert!(!guide.memory().frontiers().any(|k| in_gaps(&k)));
    let passable: Vec<CellKey> = guide.memory().passable().filter(in_gaps).collect();
    assert!(!passable.is_empty());
    guide.observe_snapshot(&rebuilt, 0.67, None);
    let frontiers: Vec<CellKey> = guide.memory().frontiers().collect();
    assert!(!frontiers.iter().any(in_gaps), "{frontiers:?}");
    assert!(frontiers.iter().any(ahead), "{frontiers:?}");
    assert!(guide.memory().record([2, 0, 0]).settled);
    // The route through the flown tunnel stays open: a window rebuilt with gaps
    // does not take passable cells back (on seed 14 such windows cut the way to the
    // team's last frontier, and its mission ended at 97 s with 25.6 % seen).
    assert!(passable.iter().all(|k| guide.memory().record(*k).passable));
}

#[test]
fn a_window_retires_remembered_frontiers_only_near_the_robot() {
    let tunnel = || vec![([-3.0, -2.0, -1.0], [30.0, 2.0, 1.0])];
    let window_m = [20.0, 20.0, 4.0];
    let first = window(Point3::origin(), window_m, tunnels(tunnel(), |p| p.x < 8.0));
    // The same window rebuilt from samples that missed everything beyond x = 5 m.
    let thin = window(Point3::origin(), window_m, tunnels(tunnel(), |p| p.x < 5.0));
    let opening = |k: &CellKey| (7..=8).contains(&k[0]);
    // The opening is 9.5 m from a robot at x = -2 m, beyond the 6 m within which a
    // window retires frontiers; 3.5 m from one at x = 4 m.
    assert_eq!(GuidanceConfig::default().retire_radius_m, Some(6.0));
    for (robot_x, kept) in [(-2.0, true), (4.0, false)] {
        let robot = Point3::new(robot_x, 0.0, 0.0);
        let mut guide = Guide::new(GuidanceConfig::default());
        guide.observe_snapshot(&first, 0.67, Some(&robot));
        assert!(guide.memory().frontiers().any(|k| opening(&k)));
        guide.observe_snapshot(&thin, 0.67, Some(&robot));
        let frontiers: Vec<CellKey> = guide.memory().frontiers().collect();
        assert_eq!(
            frontiers.iter().any(opening),
            kept,
            "{robot_x}: {frontiers:?}"
        );
    }
}

#[test]
fn memory_retires_a_frontier_a_peers_change_set_sees() {
    // The peer shares occupancy-grid change sets: the centres of the 0.2 m cells its
    // rays updated.
    let snapshot = tunnel_seen_to_6_m();
    let mut guide = Guide::new(GuidanceConfig::default());
    guide.observe_snapshot(&snapshot, 0.67, None);
    let frontiers = guide.memory().frontiers().count();
    assert!(frontiers > 0);
    let cells = |x: std::ops::Range<i32>| {
        let mut centres = Vec::new();
        for i in x {
            for j in -9..10 {
                for k in -4..5 {
                    centres.push(Point3::new(
                        0.2 * f64::from(i) + 0.1,
                        0.2 * f64::from(j) + 0.1,
                        0.2 * f64::from(k) + 0.1,
                    ));
                }
            }
        }
        centres
    };
    // Cells behind the frontiers (x < 4 m) retire nothing.
    assert_eq!(guide.observe_peer_cells(cells(0..20)).retired, 0);
    assert_eq!(guide.memory().frontiers().count(), frontiers);
    // Cells observed down the tunnel (x from 4 to 10 m) retire every frontier.
    let update = guide.observe_peer_cells(cells(20..50));
    assert_eq!(update.retired, frontiers);
    assert_eq!(guide.memory().frontiers().count(), 0);
    assert_eq!(guide.retired_by_peers(), frontiers as u64);
    assert!(guide.memory().record([8, 0, 0]).seen);
    // Hostile centres are skipped.
    assert_eq!(
        guide
            .observe_peer_cells([Point3::new(f64::NAN, 0.0, 0.0)])
            .cells,
        0
    );
}

#[test]
fn a_full_memory_keeps_its_bound_and_counts_what_it_drops() {
    let snapshot = tunnel_seen_to_6_m();
    let mut memory = FrontierMemory::new(1.0, 50);
    let update = memory.observe_window(&snapshot, 0.67, 4, None);
    assert_eq!(memory.cell_count(), 50);
    assert!(update.dropped > 0);
    assert_eq!(memory.dropped_cells(), update.dropped as u64);
    // Hostile input changes nothing and does not panic.
    assert_eq!(
        memory.mark_body(&Point3::new(f64::NAN, 0.0, 0.0)),
        MemoryUpdate::default()
    );
    let mut bad = keyframe_towards(0, Point3::origin(), Point3::new(3.0, 0.0, 0.0), [1.0; 3]);
    bad.pose = Isometry3::translation(f64::INFINITY, 0.0, 0.0);
    assert_eq!(
        memory.observe_keyframe(&bad, 100, 1),
        MemoryUpdate::default()
    );
}

/// Flies a robot with greedy single-step selection (paper Alg. 1) from `start` through
/// `world`, one planning period per round, each round seeing a fresh window of the
/// known world; returns the positions and how many rounds were guided.
fn fly(
    guide: &mut Option<Guide>,
    world: &impl Fn(&Point3<f64>) -> CellState,
    start: FlatState,
    rounds: usize,
) -> (Vec<Point3<f64>>, usize) {
    let config = RoundConfig::default();
    let camera = forward_camera();
    let mut state = start;
    let mut path = vec![Point3::from(state.position_m())];
    let mut guided = 0;
    for round in 0..rounds {
        let now = Time::from_nanos(1_000_000_000 * round as u64);
        let here = Point3::from(state.position_m());
        let snapshot = window(here, [20.0, 20.0, 4.0], world);
        let margin_m = config.margin_m(snapshot.resolution_m());
        let field = guide.as_mut().map(|g| {
            g.observe_snapshot(&snapshot, margin_m, None);
            g.field((RobotId(0), &here, 0.0), now)
        });
        let mut problem = PlanningProblem::new(&config, &snapshot, &camera);
        let mut candidates = problem.children(&state);
        if let (Some(g), Some(f)) = (guide.as_ref(), field.as_ref())
            && g.should_guide(f, &here, &candidates, snapshot.frontier_distance(&here))
        {
            problem = problem.guided(f);
            candidates = problem.rescored(&state, candidates);
            guided += 1;
        }
        let Some(best) = greedy(&candidates) else {
            break;
        };
        // Safe as the planner checks it: the whole period keeps the margin.
        let switch_s = config.planning_period_s.min(best.primitive.duration_s());
        for i in 0..=10 {
            let p = Point3::from(
                best.primitive
                    .state_at(switch_s * f64::from(i) / 10.0)
                    .position_m(),
            );
            assert!(snapshot.clearance_m(&p) >= margin_m - 1e-9, "unsafe at {p}");
        }
        state = best.primitive.state_at(switch_s);
        path.push(Point3::from(state.position_m()));
    }
    (path, guided)
}

/// The greedy choice: the highest reward, the first action on a tie.
fn greedy(candidates: &[Candidate]) -> Option<&Candidate> {
    candidates.iter().max_by(|a, b| {
        a.reward
            .total_cmp(&b.reward)
            .then(b.action_index.cmp(&a.action_index))
    })
}

/// A 45 m tunnel along x, closed at x = 40 m, seen from x = 0 on: its frontier lies at
/// x ≈ 0, 36 m from the dead end.
fn dead_end_tunnel() -> impl Fn(&Point3<f64>) -> CellState {
    tunnels(vec![([-5.0, -2.0, -1.0], [40.0, 2.0, 1.0])], |p| p.x >= 0.0)
}

/// Sim time `s` seconds after the start.
fn second(s: f64) -> Time {
    Time::from_nanos((s * 1e9) as u64)
}

#[test]
fn guidance_leaves_a_dead_end_window_and_reaches_a_remembered_frontier() {
    // A 45 m tunnel along x, closed at x = 40 m; everything from x = 0 on has been
    // seen, what lies before x = 0 has not (the frontier, 36 m from the dead end).
    let world = dead_end_tunnel();
    let mut guide = Some(Guide::new(GuidanceConfig::default()));
    // Remembered from when the robot passed the tunnel's start.
    if let Some(g) = guide.as_mut() {
        for x in [4.0, 14.0, 24.0, 34.0] {
            let here = Point3::new(x, 0.0, 0.0);
            g.observe_snapshot(&window(here, [20.0, 20.0, 4.0], &world), 0.67, None);
            g.field((RobotId(0), &here, 0.0), Time::ZERO);
        }
        assert!(g.memory().frontiers().all(|k| k[0] == -1 || k[0] == 0));
        assert!(g.memory().frontiers().count() > 0);
    }
    // Now it hovers at the dead end, facing the end wall: the window holds no frontier
    // and nothing informative.
    let start = FlatState::at_rest(Vector3::new(37.0, 0.0, 0.0), 0.0);
    let (path, guided) = fly(&mut guide, &world, start, 60);
    let reached = path.iter().position(|p| p.x < 3.0);
    assert!(
        reached.is_some(),
        "never reached the frontier: {:?}",
        path.last()
    );
    assert!(guided > 5, "{guided} guided rounds");
    // Without the memory the window offers nothing, and the robot stays at the end.
    let (unguided, _) = fly(&mut None, &world, start, 20);
    assert!(unguided.iter().all(|p| p.x > 25.0), "{:?}", unguided.last());
}

#[test]
fn the_route_to_a_remembered_frontier_follows_passable_cells_and_is_as_long_as_the_field_says() {
    let world = dead_end_tunnel();
    let mut guide = Guide::new(GuidanceConfig::default());
    for x in [4.0, 14.0, 24.0, 34.0] {
        let here = Point3::new(x, 0.0, 0.0);
        guide.observe_snapshot(&window(here, [20.0, 20.0, 4.0], &world), 0.67, None);
    }
    let robot = Point3::new(37.2, 0.3, 0.1);
    let field = guide.field((RobotId(0), &robot, 0.0), Time::ZERO);
    let route = field.route_from(&robot);
    let memory = guide.memory();
    let target = field
        .target_of(&robot)
        .expect("the field reaches the robot");
    assert_eq!(
        route.last(),
        Some(&memory.centre(target)),
        "ends at the frontier"
    );
    assert!((route[0] - robot).norm() < 1.8, "starts next to the robot");
    let cell_m = memory.cell_m();
    for step in route.windows(2) {
        let d = (step[1] - step[0]).norm();
        assert!(d > 0.0 && d <= 3f64.sqrt() * cell_m + 1e-9, "{step:?}");
    }
    // The cells on the way are passable; no penalty applies to a lone robot, so the
    // way there is exactly the field's distance.
    let record = |c: &Point3<f64>| memory.record(memory.key_of(c).unwrap());
    assert!(route[..route.len() - 1].iter().all(|c| record(c).passable));
    let length_m: f64 =
        (route[0] - robot).norm() + route.windows(2).map(|w| (w[1] - w[0]).norm()).sum::<f64>();
    assert!(
        (length_m - field.distance_m(&robot)).abs() < 1e-9,
        "{length_m} m along the route, {} m in the field",
        field.distance_m(&robot)
    );
    assert!(length_m > 35.0, "the frontier lies at the tunnel's start");
    // Off the field: no route.
    assert!(field.route_from(&Point3::new(0.0, 50.0, 0.0)).is_empty());
}

#[test]
fn coordination_sends_two_robots_at_a_fork_into_different_branches() {
    // A stem along x from x = 0 to the fork at x = 10, two branches along ±y; the left
    // one was seen up to y = 6.5 m, the right one up to y = −7.5 m: its frontier is the
    // farther one for both robots.
    let world = tunnels(
        vec![
            ([0.0, -1.8, -1.0], [11.0, 1.8, 1.0]),
            ([7.5, -14.0, -1.0], [11.0, 14.0, 1.0]),
        ],
        |p| p.y < 6.5 && p.y > -7.5,
    );
    let mut guides = [
        Guide::new(GuidanceConfig::default()),
        Guide::new(GuidanceConfig::default()),
    ];
    for g in &mut guides {
        g.observe_snapshot(
            &window(Point3::new(8.0, 0.0, 0.0), [24.0, 24.0, 4.0], &world),
            0.67,
            None,
        );
    }
    let left = |k: CellKey| k[1] >= 5;
    let right = |k: CellKey| k[1] <= -7;
    assert!(guides[0].memory().frontiers().any(left));
    assert!(guides[0].memory().frontiers().any(right));
    // Robot 0 leads, robot 1 follows; alone, both would take the left branch.
    let (lead, follow) = (Point3::new(8.5, 0.5, 0.0), Point3::new(4.0, 0.0, 0.0));
    let target = |g: &mut Guide, id: u32, at: &Point3<f64>| {
        g.field((RobotId(id), at, 0.0), Time::ZERO)
            .target_of(at)
            .expect("a route")
    };
    let lead_target = target(&mut guides[0], 0, &lead);
    assert!(left(lead_target), "{lead_target:?}");
    assert!(left(target(&mut guides[1], 1, &follow)));
    // Robot 0 commits towards the left branch; robot 1 hears its plan and takes the
    // right one, while robot 0, hearing robot 1 head right, keeps left.
    let plan = |robot: u32, from: Point3<f64>, to: Point3<f64>| crate::team::PeerPlan {
        robot: RobotId(robot),
        priority: 0,
        plan: crate::plan::Plan::new(
            Time::ZERO,
            crate::trajectory::Trajectory::new(vec![
                crate::trajectory::Knot {
                    time: Time::ZERO,
                    position_m: from,
                    yaw_rad: 0.0,
                },
                crate::trajectory::Knot {
                    time: Time::from_nanos(2_000_000_000),
                    position_m: to,
                    yaw_rad: 0.0,
                },
            ])
            .expect("a trajectory"),
        ),
        run_start_ns: 0,
        received_at: Time::ZERO,
    };
    guides[1].observe_peer_plan(&plan(0, lead, Point3::new(9.0, 3.0, 0.0)));
    let follow_target = target(&mut guides[1], 1, &follow);
    assert!(right(follow_target), "{follow_target:?}");
    guides[0].observe_peer_plan(&plan(1, follow, Point3::new(7.0, 0.0, 0.0)));
    assert!(left(target(&mut guides[0], 0, &lead)));
    // Deterministic: the same inputs give the same field.
    let again = target(&mut guides[1], 1, &follow);
    assert_eq!(again, follow_target);

    // Side by side at the fork, both heading the same way: the assignment splits them,
    // each robot computing the same split from its own memory.
    let beside = Point3::new(8.5, -0.5, 0.0);
    let towards = Point3::new(9.0, 0.0, 0.0);
    let split = |coordination: Coordination| {
        let config = GuidanceConfig {
            coordination,
            ..GuidanceConfig::default()
        };
        let mut pair = [Guide::new(config), Guide::new(config)];
        for g in &mut pair {
            g.observe_snapshot(
                &window(Point3::new(8.0, 0.0, 0.0), [24.0, 24.0, 4.0], &world),
                0.67,
                None,
            );
        }
        pair[0].observe_peer_plan(&plan(1, beside, towards));
        pair[1].observe_peer_plan(&plan(0, lead, towards));
        [
            target(&mut pair[0], 0, &lead),
            target(&mut pair[1], 1, &beside),
        ]
    };
    let [a, b] = split(Coordination::Assignment);
    assert!(
        left(a) != left(b) && (left(a) || right(a)) && (left(b) || right(b)),
        "{a:?} {b:?}"
    );
    // With maps only (the thesis' link study) the leader's plan is not heard: the
    // follower takes the branch it would take alone, the one the leader took.
    let mut maps_only = Guide::new(GuidanceConfig {
        coordination: Coordination::MapsOnly,
        ..GuidanceConfig::default()
    });
    maps_only.observe_snapshot(
        &window(Point3::new(8.0, 0.0, 0.0), [24.0, 24.0, 4.0], &world),
        0.67,
        None,
    );
    maps_only.observe_peer_plan(&plan(0, lead, Point3::new(9.0, 3.0, 0.0)));
    assert!(left(target(&mut maps_only, 1, &follow)));
}

/// A guide whose memory holds the tunnel of the dead-end test seen from `near`
/// (x = 2 m; seen from x = 0 on, the frontier at x ≈ 0), and its `give_up_after_s`
/// (the rule alone: no progress timeout).
fn beside_dead_end() -> (Guide, Point3<f64>, f64) {
    let config = GuidanceConfig {
        give_up_without_progress_s: None,
        ..GuidanceConfig::default()
    };
    let limit_s = config.give_up_after_s.expect("on by default");
    let mut guide = Guide::new(config);
    let near = Point3::new(2.0, 0.0, 0.0);
    guide.observe_snapshot(
        &window(near, [20.0, 20.0, 4.0], dead_end_tunnel()),
        0.67,
        None,
    );
    (guide, near, limit_s)
}

#[test]
fn a_frontier_watched_from_nearby_without_being_seen_into_is_given_up() {
    let world = dead_end_tunnel();
    let (mut guide, near, limit_s) = beside_dead_end();
    let frontiers = guide.memory().frontiers().count();
    assert!(frontiers > 0);
    // Far away, time does not count.
    let far = Point3::new(10.0, 0.0, 0.0);
    for s in 0..30 {
        assert!(
            guide
                .field((RobotId(0), &far, 0.0), second(f64::from(s)))
                .distance_m(&far)
                .is_finite()
        );
    }
    assert!(guide.given_up().is_empty());
    // Hovering nearby (the camera never sees into it: nothing retires it), the pull
    // lasts `give_up_after_s`, then the frontiers within reach stop pulling.
    let mut when = None;
    for s in 30..60 {
        let field = guide.field((RobotId(0), &near, 0.0), second(f64::from(s)));
        if when.is_none() && field.frontier_count() < frontiers {
            when = Some(f64::from(s) - 30.0);
        }
    }
    let when = when.expect("never given up");
    // (The first near round counts the second since the last far one.)
    assert!(
        (limit_s - 1.0..=limit_s + 1.0).contains(&when),
        "given up after {when} s"
    );
    assert!(!guide.given_up().is_empty());
    // A look that no longer shows them as frontiers, then one that shows them again
    // (a frontier's flicker at a surface's edge): they stay given up.
    let given_up = guide.given_up().clone();
    let seen_all = tunnels(vec![([-5.0, -2.0, -1.0], [40.0, 2.0, 1.0])], |_| true);
    guide.observe_snapshot(&window(near, [20.0, 20.0, 4.0], &seen_all), 0.67, None);
    guide.field((RobotId(0), &near, 0.0), second(61.0));
    guide.observe_snapshot(&window(near, [20.0, 20.0, 4.0], &world), 0.67, None);
    let field = guide.field((RobotId(0), &near, 0.0), second(62.0));
    assert_eq!(guide.given_up(), &given_up);
    assert!(field.frontier_count() < frontiers);
}

#[test]
fn a_pocket_a_peer_gave_up_no_longer_pulls_this_robot() {
    // A corridor of passable cells along x at z = 0, with two frontiers near its start
    // cell: one straight below it (outside the level camera's ±29.6° from there) and
    // one level with it 2 m ahead (in view once the camera turns there).
    let (below, ahead) = ([0, 0, -1], [2, 1, 0]);
    let cells: Vec<(CellKey, CellRecord)> = (-3..=8)
        .map(|x| ([x, 0, 0], PASSABLE_CELL))
        .chain([(below, FRONTIER_CELL), (ahead, FRONTIER_CELL)])
        .collect();
    let config = GuidanceConfig {
        give_up_without_progress_s: None,
        share_given_up: true,
        ..GuidanceConfig::default()
    };
    let limit_s = config.give_up_after_s.expect("on by default");
    let camera = crate::planner::scenes::forward_camera();
    let guide = || {
        let mut guide = Guide::new(config).seeing_with(&camera);
        guide.observe_peer_memory(cells.clone(), None);
        guide
    };
    // The peer looks around at the start and hovers there: it gives both up.
    let (mut peer, mut own) = (guide(), guide());
    let start = Point3::new(0.5, 0.5, 0.5);
    look_around(&mut peer, &start);
    for s in 0..=(2 * limit_s as u32) {
        peer.field((RobotId(1), &start, 0.0), second(f64::from(s)));
    }
    assert_eq!(
        peer.given_up().keys().copied().collect::<Vec<_>>(),
        vec![below, ahead]
    );
    // Only the pocket goes to the peers: the other was in view from there had the
    // camera turned to it (an opening beside a junction crossed again and again is
    // given up that way too), and each, once.
    assert_eq!(peer.take_given_up(), vec![(below, FRONTIER_CELL)]);
    assert!(peer.take_given_up().is_empty());
    // This robot, far along the corridor, no longer goes for the pocket; cells its
    // memory holds no frontier in are left out.
    let far = Point3::new(7.5, 0.5, 0.5);
    assert!(own.field((RobotId(0), &far, 0.0), second(0.0)).seeds(below));
    assert_eq!(
        own.observe_peer_given_up([below, [5, 0, 0], [50, 50, 50]], None, second(10.0)),
        1
    );
    let field = own.field((RobotId(0), &far, 0.0), second(11.0));
    assert!(!field.seeds(below) && field.seeds(ahead));
    // It pulls again once looked for again, counted from when this robot heard.
    let retry_s = config.retry_given_up_after_s.expect("on by default");
    let field = own.field((RobotId(0), &far, 0.0), second(10.0 + retry_s));
    assert!(field.seeds(below));
    // Off (the default), nothing is kept to send.
    let mut alone = Guide::new(GuidanceConfig {
        share_given_up: false,
        ..config
    })
    .seeing_with(&camera);
    alone.observe_peer_memory(cells, None);
    look_around(&mut alone, &start);
    for s in 0..=(2 * limit_s as u32) {
        alone.field((RobotId(0), &start, 0.0), second(f64::from(s)));
    }
    assert!(!alone.given_up().is_empty() && alone.take_given_up().is_empty());
}

/// The robot at `at` turns through a full circle in no time: it has looked around.
fn look_around(guide: &mut Guide, at: &Point3<f64>) {
    for yaw_rad in [0.0, 3.0, 6.0, 9.0] {
        guide.field((RobotId(0), at, yaw_rad), Time::ZERO);
    }
}

#[test]
fn nothing_is_given_up_before_the_robot_has_looked_around() {
    let (mut guide, near, limit_s) = beside_dead_end();
    // Started beside the frontier, facing one way (the camera has not turned to it):
    // however long it hovers, nothing is given up.
    for s in 0..30 {
        guide.field((RobotId(0), &near, 0.0), second(f64::from(s)));
    }
    assert!(guide.given_up().is_empty());
    // Turning on the spot at 1 rad/s (headings wrap at ±π): the clock starts once the
    // turn is complete, at about 2π s.
    let mut when = None;
    for s in 30..60 {
        let yaw_rad = (f64::from(s - 30) + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        guide.field((RobotId(0), &near, yaw_rad), second(f64::from(s)));
        if when.is_none() && !guide.given_up().is_empty() {
            when = Some(f64::from(s - 30));
        }
    }
    let when = when.expect("never given up");
    let turned_s = std::f64::consts::TAU.ceil();
    assert!(
        (turned_s + limit_s - 1.0..=turned_s + limit_s + 1.0).contains(&when),
        "given up {when} s into the turn"
    );
}

#[test]
fn with_quick_end_a_pocket_under_the_start_keeps_no_mission_going_once_the_robot_has_looked_around()
{
    // A corridor of passable cells along x at z = 0 and, under the start cell, a
    // frontier (a pocket in the floor) straight below the camera's ±29.6° view.
    let cells: Vec<(CellKey, CellRecord)> = (-3..=8)
        .map(|x| ([x, 0, 0], PASSABLE_CELL))
        .chain(std::iter::once(([0, 0, -1], FRONTIER_CELL)))
        .collect();
    let start = Point3::new(0.5, 0.5, 0.5);
    let guide_from = |started: Point3<f64>, quick_end: bool| {
        let config = GuidanceConfig {
            quick_end,
            ..GuidanceConfig::default()
        };
        let mut guide = Guide::new(config).seeing_with(&crate::planner::scenes::forward_camera());
        guide.observe_peer_memory(cells.clone(), None);
        guide.field((RobotId(0), &started, 0.0), Time::ZERO);
        guide
    };
    let has_work = |started: Point3<f64>, quick_end: bool, looked_around: bool| {
        let mut guide = guide_from(started, quick_end);
        if looked_around {
            look_around(&mut guide, &started);
        }
        let field = guide.field((RobotId(0), &start, 0.0), Time::ZERO);
        assert!(guide.given_up().is_empty());
        // It pulls the robot either way.
        assert!(field.seeds([0, 0, -1]));
        guide.has_work(&field, &start)
    };
    // Once the robot has looked around at its start, the pocket keeps no mission going;
    // before, it does.
    assert!(!has_work(start, true, true));
    assert!(has_work(start, true, false));
    // A robot that started 6 m away and comes by has it as work.
    assert!(has_work(Point3::new(6.5, 0.5, 0.5), true, true));
    // Without `quick_end`, it is work.
    assert!(has_work(start, false, true));
}

#[test]
fn a_given_up_frontier_is_looked_for_again_after_the_retry_time() {
    let retry_s = GuidanceConfig::default()
        .retry_given_up_after_s
        .expect("on by default");
    let (mut guide, near, _) = beside_dead_end();
    let far = Point3::new(10.0, 0.0, 0.0);
    let frontiers = guide.memory().frontiers().count();
    look_around(&mut guide, &near);
    // Hovering beside it: given up (the rule of the test above) at about 4 s; until
    // then it is work for the robot's mission.
    for s in 0..10 {
        let field = guide.field((RobotId(0), &near, 0.0), second(f64::from(s)));
        assert_eq!(guide.has_work(&field, &near), s < 4, "at {s} s");
    }
    assert!(!guide.given_up().is_empty());
    let given_up_by_s = 10.0;
    // Away from it, it stays given up until the retry time has passed, then pulls again.
    let mut back = None;
    for s in 10..150 {
        let field = guide.field((RobotId(0), &far, 0.0), second(f64::from(s)));
        if back.is_none() && field.frontier_count() == frontiers {
            back = Some(f64::from(s));
        }
        // Looked for again or not, what was given up does not keep the mission going.
        assert!(!guide.has_work(&field, &far), "at {s} s");
    }
    let back = back.expect("never looked for again");
    assert!(
        (retry_s..=retry_s + given_up_by_s).contains(&back),
        "looked for again at {back} s"
    );
    assert!(guide.given_up().is_empty());
    // Still not seen into: hovering beside it gives it up again.
    for s in 150..160 {
        guide.field((RobotId(0), &near, 0.0), second(f64::from(s)));
    }
    assert!(!guide.given_up().is_empty());
}

#[test]
fn with_a_switch_penalty_a_robot_keeps_its_goal_until_another_is_that_much_nearer() {
    // A tunnel seen for |x| ≤ 5: frontiers at both ends.
    let world = tunnels(vec![([-15.0, -2.0, -1.0], [15.0, 2.0, 1.0])], |p| {
        p.x.abs() <= 5.0
    });
    let snapshot = window(Point3::origin(), [20.0, 20.0, 4.0], &world);
    let goal_x = |config: GuidanceConfig, path: &[f64]| -> Vec<f64> {
        let mut guide = Guide::new(config);
        guide.observe_snapshot(&snapshot, 0.67, None);
        path.iter()
            .enumerate()
            .map(|(s, x)| {
                let here = Point3::new(*x, 0.0, 0.0);
                let field = guide.field((RobotId(0), &here, 0.0), Time::from_nanos(s as u64));
                let target = field.target_of(&here).expect("a goal");
                guide.memory().centre(target).x
            })
            .collect()
    };
    // Drifting from x = 0.5 to x = −0.5, then −2.5.
    let path = [0.5, -0.5, -2.5];
    let config = GuidanceConfig {
        give_up_after_s: None,
        ..GuidanceConfig::default()
    };
    let nearest = goal_x(config, &path);
    assert!(nearest[0] > 0.0 && nearest[1] < 0.0, "{nearest:?}");
    let committed = goal_x(
        GuidanceConfig {
            switch_penalty_m: 3.0,
            ..config
        },
        &path,
    );
    // Kept while the other end is only 1 m nearer; given up once it is 5 m nearer.
    assert!(committed[0] > 0.0 && committed[1] > 0.0, "{committed:?}");
    assert!(committed[2] < 0.0, "{committed:?}");
}

#[test]
fn a_goal_the_robot_gets_no_nearer_to_is_given_up_after_the_progress_timeout() {
    // The dead-end tunnel seen from x = 0 on: the frontier at x ≈ 0.
    let world = dead_end_tunnel();
    let config = GuidanceConfig {
        give_up_after_s: None,
        give_up_without_progress_s: Some(6.0),
        ..GuidanceConfig::default()
    };
    let fresh = || {
        let mut guide = Guide::new(config);
        guide.observe_snapshot(
            &window(Point3::new(5.0, 0.0, 0.0), [20.0, 20.0, 4.0], &world),
            0.67,
            None,
        );
        guide
    };
    // Flying towards it at 1 m/s: progress all along, nothing given up.
    let mut guide = fresh();
    for s in 0..8 {
        let here = Point3::new(12.0 - f64::from(s), 0.0, 0.0);
        guide.field((RobotId(0), &here, 0.0), second(f64::from(s)));
    }
    assert!(guide.given_up().is_empty());
    // Held 10 m away (a wall, a peer, a pocket out of view): given up after 6 s.
    let mut guide = fresh();
    let here = Point3::new(10.0, 0.0, 0.0);
    let mut when = None;
    for s in 0..12 {
        guide.field((RobotId(0), &here, 0.0), second(f64::from(s)));
        if when.is_none() && !guide.given_up().is_empty() {
            when = Some(s);
        }
    }
    assert_eq!(when, Some(6));
    // Near it once (x = 3), then 5 s flying away (views elsewhere pay), then back at
    // 1 m/s: the route shortens again from where the robot turned back, so that is
    // progress, though the robot is not yet as near as it once was.
    let mut guide = fresh();
    let path = (0..=5).map(|s| 3.0 + 2.0 * f64::from(s)); // x = 3 … 13
    let path = path.chain((1..=8).map(|s| 13.0 - f64::from(s))); // back to x = 5
    for (s, x) in path.enumerate() {
        let here = Point3::new(x, 0.0, 0.0);
        guide.field((RobotId(0), &here, 0.0), second(s as f64));
    }
    assert!(guide.given_up().is_empty(), "{:?}", guide.given_up());
}

#[test]
fn before_the_look_around_only_frontiers_the_camera_cannot_see_from_here_are_given_up() {
    // A corridor of passable cells along x at z = 0 with two frontiers beside the
    // start cell: one straight below it (outside the camera's ±29.6°, whichever way
    // the robot turns) and one level with it 2 m ahead (in view once it turns there).
    let cells: Vec<(CellKey, CellRecord)> = (-3..=8)
        .map(|x| ([x, 0, 0], PASSABLE_CELL))
        .chain([([0, 0, -1], FRONTIER_CELL), ([2, 1, 0], FRONTIER_CELL)])
        .collect();
    let config = GuidanceConfig {
        give_up_without_progress_s: None,
        ..GuidanceConfig::default()
    };
    let limit_s = config.give_up_after_s.expect("on by default");
    let mut guide = Guide::new(config).seeing_with(&crate::planner::scenes::forward_camera());
    guide.observe_peer_memory(cells, None);
    // Hovering at the start facing one way (it has not looked around).
    let start = Point3::new(0.5, 0.5, 0.5);
    for s in 0..=(2 * limit_s as u32) {
        guide.field((RobotId(0), &start, 0.0), second(f64::from(s)));
    }
    let given_up: Vec<CellKey> = guide.given_up().keys().copied().collect();
    assert_eq!(given_up, vec![[0, 0, -1]]);
    // Without a camera the guide cannot tell them apart: nothing is given up.
    let mut blind = Guide::new(config);
    blind.observe_peer_memory(
        vec![([0, 0, 0], PASSABLE_CELL), ([0, 0, -1], FRONTIER_CELL)],
        None,
    );
    for s in 0..=(2 * limit_s as u32) {
        blind.field((RobotId(0), &start, 0.0), second(f64::from(s)));
    }
    assert!(blind.given_up().is_empty());
}

#[test]
fn a_robot_flies_home_along_the_field_towards_its_start_and_stops_there() {
    // The dead-end tunnel, flown from x = 2 to the blind end: the robot flies back to
    // where it began along the route distance alone (views are not scored).
    let world = dead_end_tunnel();
    let mut guide = Guide::new(GuidanceConfig::default());
    let home = Point3::new(2.0, 0.3, 0.1);
    for x in [2.0, 12.0, 22.0, 32.0, 37.0] {
        let here = Point3::new(x, 0.0, 0.0);
        guide.observe_snapshot(&window(here, [20.0, 20.0, 4.0], &world), 0.67, None);
        guide.field((RobotId(0), &here, 0.0), Time::ZERO);
    }
    let field = GuidanceField::towards(guide.memory(), &home, 1.0);
    assert_eq!(field.distance_m(&home), 0.0, "least at home itself");
    let config = RoundConfig::default();
    let camera = forward_camera();
    let mut state = FlatState::at_rest(Vector3::new(37.0, 0.0, 0.0), 0.0);
    let mut closest_m = f64::INFINITY;
    for _ in 0..60 {
        let here = Point3::from(state.position_m());
        let snapshot = window(here, [20.0, 20.0, 4.0], &world);
        let problem = PlanningProblem::new(&config, &snapshot, &camera).homing(&field);
        let candidates = problem.children(&state);
        assert!(candidates.iter().all(|c| c.information == 0.0));
        let Some(best) = greedy(&candidates) else {
            break;
        };
        state = best
            .primitive
            .state_at(config.planning_period_s.min(best.primitive.duration_s()));
        closest_m = closest_m.min((Point3::from(state.position_m()) - home).norm());
    }
    assert!(closest_m < 1.0, "came within {closest_m} m of home");
    // A home in no known passable cell gives an empty field.
    let nowhere = GuidanceField::towards(guide.memory(), &Point3::new(0.0, 50.0, 0.0), 1.0);
    assert_eq!(nowhere.frontier_count(), 0);
    assert!(!nowhere.distance_m(&Point3::new(20.0, 0.0, 0.0)).is_finite());
}

/// A route home straight along +x to `home_x`, blind to height as the memory's route
/// is within its 1 m cells.
#[derive(Debug)]
struct AlongX {
    home_x: f64,
}

impl crate::planner::problem::FrontierField for AlongX {
    fn pose_distance_m(&self, p: &Point3<f64>, _yaw_rad: f64) -> f64 {
        (self.home_x - p.x).max(0.0)
    }
}

#[test]
fn a_return_stuck_above_a_low_passage_descends_into_it_and_flies_on() {
    // A tall room (x < 0) whose only way on is a low passage along x (z from -3 to
    // -1 m), home 15 m along it; the robot hovers in the room above the passage's
    // roof. No single primitive gets nearer home: forward ones meet the wall above
    // the passage, and descending (0.3 m/s) gets no nearer by the field.
    let world = tunnels(
        vec![
            ([-6.0, -3.0, -3.0], [0.0, 3.0, 3.0]),
            ([-6.0, -1.5, -3.0], [20.0, 1.5, -1.0]),
        ],
        |_| true,
    );
    let home = AlongX { home_x: 15.0 };
    let config = RoundConfig::default();
    let camera = forward_camera();
    let fly = |escape: bool| {
        let mut state = FlatState::at_rest(Vector3::new(-1.0, 0.0, -0.3), 0.0);
        let mut escapes = 0;
        for _ in 0..40 {
            let here = Point3::from(state.position_m());
            let snapshot = window(here, [16.0, 16.0, 8.0], &world);
            let problem = PlanningProblem::new(&config, &snapshot, &camera).homing(&home);
            let candidates = problem.children(&state);
            let out = escape.then(|| problem.route_escape(&candidates)).flatten();
            escapes += usize::from(out.is_some());
            let Some(best) = out.map(|i| &candidates[i]).or_else(|| greedy(&candidates)) else {
                break;
            };
            state = best
                .primitive
                .state_at(config.planning_period_s.min(best.primitive.duration_s()));
            assert!(world(&Point3::from(state.position_m())) == CellState::Free);
        }
        (state.position_m().x, escapes)
    };
    let (stuck_x, _) = fly(false);
    assert!(
        stuck_x < 0.0,
        "without the escape: stuck in the room at x = {stuck_x}"
    );
    let (x, escapes) = fly(true);
    assert!(escapes > 0);
    assert!(x > 14.0, "with the escape: {x} m along the passage");
}

#[test]
fn the_way_a_robot_came_is_a_way_home_whatever_later_windows_say() {
    // Two ends of a flight, passable where the body was, nothing known between them
    // (later windows found no clearance there): no route home without the trail.
    let mut memory = FrontierMemory::new(1.0, 1000);
    let (home, there) = (Point3::new(0.5, 0.5, 0.5), Point3::new(10.2, 3.5, 0.5));
    memory.mark_body(&home);
    memory.mark_body(&there);
    assert!(
        !GuidanceField::towards(&memory, &home, 1.0)
            .distance_m(&there)
            .is_finite()
    );
    // The trail joins the rounds' positions without gaps, even 1.5 cells apart.
    let mut last = home;
    for k in 1..=8 {
        let p = home + (there - home) * (f64::from(k) / 8.0);
        memory.mark_trail(&last, &p);
        last = p;
    }
    let field = GuidanceField::towards(&memory, &home, 1.0);
    let route_m = field.distance_m(&there);
    let straight_m = (there - home).norm();
    assert!(
        route_m >= straight_m - 1e-9 && route_m < 1.3 * straight_m,
        "{route_m} m along the trail, {straight_m} m straight"
    );
    // The trail is this robot's alone: the frontier field does not use it.
    assert!(memory.on_trail(memory.key_of(&Point3::new(5.0, 2.0, 0.5)).unwrap()));
    assert!(
        !memory
            .record(memory.key_of(&Point3::new(5.0, 2.0, 0.5)).unwrap())
            .passable
    );
}

#[test]
fn a_retraced_return_keeps_to_the_robots_trail_and_may_leave_it_only_beside_home() {
    // The robot flew out east along y = 0 and back west along y = 6; cells seen
    // passable join the two legs at x = 10 (a gap it never flew), and its home is a
    // peer's, 1.6 m from where its trail began.
    let mut memory = FrontierMemory::new(1.0, 10_000);
    let corners = [
        Point3::new(0.5, 0.5, 0.5),
        Point3::new(20.5, 0.5, 0.5),
        Point3::new(20.5, 6.5, 0.5),
        Point3::new(10.5, 6.5, 0.5),
    ];
    for leg in corners.windows(2) {
        memory.mark_trail(&leg[0], &leg[1]);
    }
    let gap = (1..=5).map(|y| ([10, y, 0], PASSABLE_CELL));
    let beside_home = [([-1, 0, 0], PASSABLE_CELL), ([-2, 0, 0], PASSABLE_CELL)];
    memory.merge_peer_cells(gap.chain(beside_home));
    let (home, here) = (Point3::new(-1.1, 0.5, 0.5), corners[3]);
    // The shortest route takes the gap; the retraced one flies back round the loop.
    let shortest_m = GuidanceField::towards(&memory, &home, 1.0).distance_m(&here);
    let retraced = GuidanceField::retracing(&memory, &home, 1.0);
    let retraced_m = retraced.distance_m(&here);
    assert!((16.0..18.5).contains(&shortest_m), "{shortest_m}");
    assert!((34.0..40.0).contains(&retraced_m), "{retraced_m}");
    // Off the trail, far from home, no route at all.
    assert!(
        !retraced
            .distance_m(&Point3::new(10.5, 3.5, 0.5))
            .is_finite()
    );
    // A home more than two cells off the trail cannot be reached along it.
    let far_home = Point3::new(0.5, 0.5, 4.5);
    memory.merge_peer_cells((1..=4).map(|z| ([0, 0, z], PASSABLE_CELL)));
    assert!(
        GuidanceField::towards(&memory, &far_home, 1.0)
            .distance_m(&here)
            .is_finite()
    );
    assert!(
        !GuidanceField::retracing(&memory, &far_home, 1.0)
            .distance_m(&here)
            .is_finite()
    );
}

#[test]
fn a_frontier_is_a_goal_only_where_the_level_camera_can_see_it_from_a_passable_place() {
    // The default camera (±29.6° vertically), viewpoints within 4 m.
    let view = ViewCone::of_camera(&forward_camera(), 4.0);
    assert!((view.up_rad.to_degrees() - 29.6).abs() < 1.0, "{view:?}");
    let (passable, frontier) = (PASSABLE_CELL, FRONTIER_CELL);
    let wall = CellRecord {
        seen: true,
        ..CellRecord::default()
    };
    let mut memory = FrontierMemory::new(1.0, 10_000);
    // A level tunnel along x (y = 0, z = 0) from x = 0 to 10, a vertical shaft above
    // x = 20 joined to nothing else, and four frontiers: at the tunnel's open end, in a
    // pocket 2 m under its floor, behind its side wall, and at the shaft's foot.
    let tunnel = (0..=10).map(|x| ([x, 0, 0], passable));
    let shaft = (0..=6).map(|z| ([20, 0, z], passable));
    let walls = (0..=10).map(|x| ([x, 1, 0], wall));
    let (end, pocket, behind, foot) = ([11, 0, 0], [5, 0, -2], [5, 3, 0], [20, 0, -1]);
    let frontiers = [end, pocket, behind, foot].map(|f| (f, frontier));
    memory.merge_peer_cells(tunnel.chain(shaft).chain(walls).chain(frontiers));
    let seen_from = |f| viewpoints(&memory, f, Some(&view));
    // The open end is seen down the tunnel, from up to 4 m back, each viewpoint at
    // its straight distance.
    let ahead = seen_from(end);
    assert_eq!(
        ahead.iter().map(|(v, _)| *v).collect::<Vec<_>>(),
        (7..=10).map(|x| [x, 0, 0]).collect::<Vec<_>>()
    );
    for (v, d) in &ahead {
        assert!((d - f64::from(11 - v[0])).abs() < 1e-9);
    }
    // A pocket 2 m below the floor is seen only from over 3.5 m away, out of range;
    // the frontier behind the wall only through unknown space; the shaft's foot only
    // straight down.
    assert!(seen_from(pocket).is_empty());
    assert!(seen_from(behind).is_empty());
    assert!(seen_from(foot).is_empty());
    // Without a camera, the passable cells beside a frontier attend to it: the shaft's
    // foot is a goal then, seeded from the cell above it.
    assert_eq!(viewpoints(&memory, foot, None), vec![([20, 0, 0], 1.0)]);
    assert_eq!(viewpoints(&memory, pocket, None), vec![]);

    // In the field: only the open end seeds it, so a robot in the shaft has no route.
    let params = |view| FieldParams {
        coordination: Coordination::MapsOnly,
        min_region_cells: 1,
        small_region_penalty_m: None,
        claim_radius_m: 6.0,
        claim_penalty_m: 30.0,
        switch_penalty_m: 0.0,
        look_ahead_m: 1.0,
        view,
    };
    let field = |view| {
        GuidanceField::build(
            &memory,
            (RobotId(0), &Point3::new(0.5, 0.5, 0.5)),
            &std::collections::BTreeMap::new(),
            &std::collections::BTreeMap::new(),
            None,
            &params(view),
        )
    };
    let judged = field(Some(view));
    assert!(judged.seeds(end) && !judged.seeds(foot) && !judged.seeds(pocket));
    assert_eq!(judged.frontier_count(), 1);
    assert!((judged.distance_m(&Point3::new(0.5, 0.5, 0.5)) - 11.0).abs() < 1e-9);
    assert!(!judged.distance_m(&Point3::new(20.5, 0.5, 3.5)).is_finite());
    let beside = field(None);
    assert!(beside.seeds(end) && beside.seeds(foot));
    assert!(beside.distance_m(&Point3::new(20.5, 0.5, 3.5)).is_finite());
}
