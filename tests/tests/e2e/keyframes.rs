//! Keyframe GMMs flow from one robot's mapper over the shaped link to its peers.

use troupe_actors::mapper::MapperConfig;
use troupe_robot::RobotConfig;
use troupe_sims::report::write_run;
use troupe_sims::scenario::Scenario;
use troupe_sims::team::Team;
use troupe_sims::world::surface_distance_m;

#[test]
fn keyframes_are_fitted_shared_and_received() {
    let scenario = Scenario {
        name: "keyframes".into(),
        duration_s: 12.0,
        robot: RobotConfig {
            mapper: MapperConfig {
                enabled: true,
                pixel_stride: 4,
                ..MapperConfig::default()
            },
            ..RobotConfig::default()
        },
        ..Scenario::default()
    };
    let output = Team::new(&scenario).expect("assemble").run(|_| {});
    let s = &output.summary;
    for (me, peer) in [(0, 1), (1, 0)] {
        let mine = &s.per_robot[me];
        let theirs = &s.per_robot[peer];
        let sent = mine.topics.get("mapper/keyframe").map_or(0, |t| t.messages);
        let received = theirs.topics.get("peer/keyframe").map_or(0, |t| t.messages);
        assert!(sent >= 2, "robot{me} made {sent} keyframes");
        // Every keyframe published before the last moments arrives at the peer.
        assert!(
            received + 1 >= sent && received <= sent,
            "sent {sent}, peer received {received}"
        );
        let link = mine.truth.link.as_ref().expect("link status");
        assert_eq!(link.rejected_messages, 0);
        assert!(
            mine.actors.iter().all(|a| a.errors == 0 && a.panics == 0),
            "{:?}",
            mine.actors
        );
    }
    assert_eq!(s.collisions, 0);

    // The run's report holds each robot's map and the merged point cloud, with
    // points from both robots, near the rock surface (ground truth).
    for (map, published) in output.maps.iter().zip(&s.per_robot) {
        let sent = published
            .topics
            .get("mapper/keyframe")
            .map_or(0, |t| t.messages);
        assert_eq!(map.keyframes.len() as u64, sent);
    }
    let root = tempfile::tempdir().expect("tempdir");
    let dir = write_run(root.path(), "keyframes", &output).expect("write run");
    for i in 0..2 {
        assert!(dir.join(format!("maps/robot{i}.troupe")).is_file());
    }
    let ply = std::fs::read(dir.join("merged_map.ply")).expect("merged map");
    let end = ply
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("PLY header")
        + 11;
    let vertices = &ply[end..];
    assert_eq!(vertices.len() % 20, 0);
    let world = scenario.world.build().expect("world");
    let mut per_robot = [0usize; 2];
    let mut near_surface = 0usize;
    for v in vertices.chunks(20) {
        per_robot[usize::from(v[19])] += 1;
        let xyz: Vec<f64> = (0..3)
            .map(|k| {
                f64::from(f32::from_le_bytes([
                    v[4 * k],
                    v[4 * k + 1],
                    v[4 * k + 2],
                    v[4 * k + 3],
                ]))
            })
            .collect();
        let at = nalgebra::Point3::new(xyz[0], xyz[1], xyz[2]);
        if surface_distance_m(world.as_ref(), &at, 0.1).abs() < 0.1 {
            near_surface += 1;
        }
    }
    assert!(per_robot.iter().all(|&n| n > 1000), "{per_robot:?}");
    let fraction = near_surface as f64 / (vertices.len() / 20) as f64;
    assert!(
        fraction > 0.8,
        "{fraction} of the merged map within 0.1 m of the rock"
    );
}

/// Known (not unknown) cells in each robot's latest grid snapshot after a short run.
fn known_cells(scenario: &Scenario) -> (troupe_sims::team::Summary, Vec<usize>) {
    use std::sync::{Arc, Mutex};
    use troupe_actors::msgs::GRID_SNAPSHOT;
    use troupe_algorithms::grid::CellState;
    use troupe_runtime::Publication;

    let known = Arc::new(Mutex::new(vec![0usize; scenario.robots as usize]));
    let seen = known.clone();
    let mut team = Team::new(scenario).expect("assemble");
    team.add_tap(move |p: &Publication<'_>| {
        if let Some(snapshot) = p.get(&GRID_SNAPSHOT) {
            let g = &snapshot.grid;
            let n = g
                .values()
                .iter()
                .filter(|v| g.classify(**v) != CellState::Unknown)
                .count();
            seen.lock().expect("lock")[p.robot.0 as usize] = n;
        }
    });
    let summary = team.run(|_| {}).summary;
    let known = known.lock().expect("lock").clone();
    (summary, known)
}

#[test]
fn occupancy_change_sets_are_shared_and_fused_instead_of_keyframes() {
    use troupe_robot::MapSharing;
    let base = Scenario {
        name: "changes".into(),
        duration_s: 15.0,
        robot: RobotConfig {
            mapper: MapperConfig {
                enabled: false,
                ..MapperConfig::default()
            },
            map_sharing: MapSharing::Grid,
            ..RobotConfig::default()
        },
        ..Scenario::default()
    };
    let (s, shared) = known_cells(&base);
    let mut alone = base.clone();
    alone.robot.map_sharing = MapSharing::None;
    let (_, solo) = known_cells(&alone);
    for (me, peer) in [(0, 1), (1, 0)] {
        let mine = &s.per_robot[me];
        let sent = mine.topics["grid/changes"].messages;
        let received = s.per_robot[peer].topics["peer/grid_changes"].messages;
        // One set per frame (5 Hz); each arrives (the last may be in flight).
        assert!(sent >= 70, "robot{me} sent {sent} change sets");
        assert!(
            received + 1 >= sent && received <= sent,
            "{sent} → {received}"
        );
        assert_eq!(
            mine.topics.get("peer/keyframe").map_or(0, |t| t.messages),
            0
        );
        let link = mine.truth.link.as_ref().expect("link status");
        assert_eq!(link.rejected_messages, 0);
        assert!(mine.actors.iter().all(|a| a.errors == 0 && a.panics == 0));
        // The peer's observations are in this robot's grid.
        assert!(
            shared[me] > solo[me] + 1000,
            "robot{me}: {} known cells with the peer's change sets, {} alone",
            shared[me],
            solo[me]
        );
    }
}
