//! What the occupancy-grid baseline would send, counted on a team's own frames
//! (`metrics.og_change_set_resolutions_m`, thesis §8.2.6): it matches what the baseline
//! sends when it is flown, and counting it changes nothing else in the run.

use troupe_algorithms::grid::UpdateRule;
use troupe_robot::MapSharing;
use troupe_sims::camera::CameraBackend;
use troupe_sims::report::timeseries_csv;
use troupe_sims::scenario::Scenario;

use crate::run;

#[test]
fn og_meter_matches_the_flown_baseline_and_changes_no_flight() {
    // One robot sharing change sets, its grid built from its own frames alone (no
    // mapper, no peers): what it publishes on `grid/changes` is the baseline.
    let mut scenario = Scenario {
        name: "og_meter".into(),
        duration_s: 15.0,
        robots: 1,
        ..Scenario::default()
    };
    scenario.camera.backend = CameraBackend::Cpu;
    scenario.robot.map_sharing = MapSharing::Grid;
    scenario.robot.mapper.enabled = false;
    scenario.robot.grid.update_rule = UpdateRule::PerScan;
    let plain = run(&scenario);
    let resolution_m = scenario.robot.grid.resolution_m;
    scenario.metrics.og_change_set_resolutions_m = vec![resolution_m, resolution_m / 2.0];
    let counted = run(&scenario);

    // Counting is observation only: the same flight, the same summary otherwise.
    let mut summary = counted.summary.clone();
    let og = std::mem::take(&mut summary.og_change_sets);
    assert_eq!(summary, plain.summary);
    assert_eq!(
        timeseries_csv(&counted.timeseries),
        timeseries_csv(&plain.timeseries)
    );

    assert_eq!(og.len(), 2);
    let (at_grid, finer) = (&og[0].totals, &og[1].totals);
    let frames = summary.per_robot[0].truth.frames;
    assert_eq!(at_grid.frames, frames);
    let flown = summary.per_robot[0].topics["grid/changes"].bytes as f64;
    assert!(flown > 100_000.0, "the baseline sent {flown} B");
    // The flown grid forgets cells that leave its window and drops changes outside
    // it; over 15 s the two agree closely.
    let ratio = at_grid.bytes as f64 / flown;
    eprintln!("og meter: counted {} B, flown {flown} B", at_grid.bytes);
    assert!(
        (0.98..=1.02).contains(&ratio),
        "counted {} B, flown {flown} B",
        at_grid.bytes
    );
    // Halving the cell edge multiplies the cells a frame changes.
    assert!(finer.bytes > 3 * at_grid.bytes, "{og:?}");
}

#[test]
fn a_peers_change_sets_at_the_camera_rate_do_not_crowd_out_a_robots_own_frames() {
    // The Fig. 8.9 study's OG team with no rate limit: each robot's grid actor takes
    // its own depth frames and its peer's change sets, both at 10 Hz. Fusing a set is
    // not charged a frame's modelled latency; when it was, the actor fell behind,
    // dropped its own odometry and frames, and the team stopped exploring at 31 s.
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../sims/scenarios/fig_8_9.toml"
    );
    let mut scenario = Scenario::load(std::path::Path::new(path)).unwrap();
    scenario.duration_s = 15.0;
    scenario.robot.map_sharing = MapSharing::Grid;
    let output = run(&scenario);
    for robot in &output.summary.per_robot {
        let received = robot.topics["peer/grid_changes"].messages;
        assert!(received > 50, "{} fused {received} sets", robot.name);
        let grid = robot.actors.iter().find(|a| a.name == "grid").unwrap();
        assert_eq!(grid.errors, 0);
        for topic in ["sensor/frame", "odometry", "peer/grid_changes"] {
            assert_eq!(grid.dropped[topic], 0, "{}: {:?}", robot.name, grid.dropped);
        }
    }
}
