//! The default team under the sim-time executor: determinism, coverage, safety,
//! supervision.

use troupe_sims::report::{timeseries_csv, write_run};
use troupe_sims::scenario::{Fault, Scenario};
use troupe_sims::team::{RunOutput, Team};

fn run(scenario: &Scenario) -> RunOutput {
    Team::new(scenario).expect("assemble").run(|_| {})
}

fn files(output: &RunOutput) -> (Vec<u8>, Vec<u8>) {
    let dir = tempfile::tempdir().unwrap();
    let run = write_run(dir.path(), "r", output).unwrap();
    (
        std::fs::read(run.join("summary.json")).unwrap(),
        std::fs::read(run.join("timeseries.csv")).unwrap(),
    )
}

#[test]
fn default_run_is_deterministic_explores_and_never_collides() {
    let scenario = Scenario::default();
    let first = run(&scenario);
    let second = run(&scenario);
    let (summary_a, series_a) = files(&first);
    let (summary_b, series_b) = files(&second);
    assert!(
        summary_a == summary_b,
        "summary.json differs between identical runs"
    );
    assert!(
        series_a == series_b,
        "timeseries.csv differs between identical runs"
    );

    let s = &first.summary;
    assert_eq!(s.robots, 2);
    assert_eq!(s.collisions, 0, "collisions with the world");
    assert_eq!(s.robot_contacts, 0, "robot bodies overlapped");
    // Coverage rises: never decreases, and grows over the run.
    let over_time = &s.coverage.over_time;
    assert_eq!(over_time.len(), 120);
    assert!(over_time.windows(2).all(|w| w[1][1] >= w[0][1]));
    assert!(
        over_time[0][1] < 0.05 && s.coverage.final_fraction > 0.15,
        "{over_time:?}"
    );
    assert!(over_time[119][1] > over_time[30][1] + 0.1, "{over_time:?}");
    for robot in &s.per_robot {
        // The standard robot: every actor ran, none failed.
        let names: Vec<&str> = robot.actors.iter().map(|a| a.name.as_str()).collect();
        for actor in [
            "vehicle",
            "sensor",
            "mapper",
            "grid",
            "planner",
            "collision",
            "link",
        ] {
            assert!(names.contains(&actor), "{} lacks {actor}", robot.name);
        }
        assert!(robot.actors.iter().all(|a| a.panics == 0 && a.errors == 0));
        assert!(
            robot.truth.distance_m > 20.0,
            "{} flew {} m",
            robot.name,
            robot.truth.distance_m
        );
        assert!(robot.truth.min_clearance_m > 0.0);
        assert_eq!(robot.truth.unsafe_plans, 0, "{}", robot.name);
        assert_eq!(robot.truth.frames, 599);
        // Each robot's keyframes reached the other.
        assert!(robot.topics["mapper/keyframe"].messages >= 5);
        assert!(robot.topics["peer/keyframe"].messages >= 5);
    }
    // Maps of both robots are in the report.
    assert!(s.maps.iter().all(|m| m.keyframes >= 5 && m.components > 0));
    // Odometry crossed the link both ways, and every topic is counted.
    assert!(s.topics["peer/odometry"].messages > 2000);
    assert_eq!(
        s.topics["link/tx"].messages,
        s.topics["link/rx"].messages + 2
    );
    assert!(s.topics["sensor/frame"].bytes > 100_000_000);
    // The run says how fast it went.
    assert!(first.timing.sim_seconds_per_wall_second > 0.0);
    assert_eq!(
        timeseries_csv(&first.timeseries).lines().count(),
        1 + 2 * 120
    );
}

#[test]
fn a_different_seed_gives_a_different_run() {
    let short = Scenario {
        duration_s: 20.0,
        ..Scenario::default()
    };
    let a = files(&run(&short));
    let b = files(&run(&Scenario {
        seed: 2,
        ..short.clone()
    }));
    assert!(a.0 != b.0, "summary.json should depend on the seed");
    assert!(a.1 != b.1, "timeseries.csv should depend on the seed");
    let again = files(&run(&short));
    assert!(a == again, "same seed, different files");
}

#[test]
fn injected_panics_are_restarted_counted_and_the_run_completes() {
    let scenario = Scenario {
        duration_s: 40.0,
        faults: vec![
            Fault::ActorPanic {
                robot: 0,
                actor: "planner".into(),
                at_s: 10.0,
            },
            Fault::ActorPanic {
                robot: 1,
                actor: "sensor".into(),
                at_s: 5.0,
            },
            Fault::ActorPanic {
                robot: 1,
                actor: "vehicle".into(),
                at_s: 20.0,
            },
        ],
        ..Scenario::default()
    };
    let output = run(&scenario);
    let s = &output.summary;
    let actor = |robot: usize, name: &str| {
        s.per_robot[robot]
            .actors
            .iter()
            .find(|a| a.name == name)
            .unwrap_or_else(|| panic!("no actor {name}"))
            .clone()
    };
    for (robot, name) in [(0, "planner"), (1, "sensor"), (1, "vehicle")] {
        let a = actor(robot, name);
        assert_eq!(
            (a.panics, a.restarts, a.stopped),
            (1, 1, false),
            "{name} of robot {robot}"
        );
    }
    assert_eq!(actor(0, "sensor").panics, 0);
    assert_eq!(s.coverage.over_time.len(), 40);
    assert_eq!(s.collisions, 0);
    // The restarted planner went on committing plans (1 Hz) instead of stopping.
    assert!(
        s.per_robot[0].truth.plans >= 35,
        "{}",
        s.per_robot[0].truth.plans
    );
    // The restarted sensor kept producing frames.
    assert!(
        s.per_robot[1].truth.frames >= 195,
        "{}",
        s.per_robot[1].truth.frames
    );
}

#[test]
fn crash_partition_and_loss_burst_strike_are_reported_and_the_team_keeps_exploring() {
    let scenario = Scenario {
        duration_s: 60.0,
        faults: vec![
            Fault::RobotCrash {
                robot: 1,
                at_s: 15.0,
                down_s: 10.0,
            },
            Fault::LinkPartition {
                robots: [0, 1],
                at_s: 30.0,
                until_s: 40.0,
            },
            Fault::LossBurst {
                robots: Vec::new(),
                at_s: 45.0,
                until_s: 55.0,
                loss_probability: 0.5,
            },
        ],
        ..Scenario::default()
    };
    let output = run(&scenario);
    let s = &output.summary;
    assert_eq!(s.faults.len(), 3);
    assert!(s.faults.iter().all(|f| f.effect.struck), "{:?}", s.faults);
    assert!(s.faults[0].effect.dropped_events > 0);
    assert!(s.faults[2].effect.dropped_packets > 0);
    assert!(s.network.partitioned > 0);
    assert_eq!(s.collisions, 0);
    // Robot 1 lost ten seconds of frames (5 Hz) and nothing else: it rebooted, its
    // sensor came back.
    let frames = s.per_robot[1].truth.frames;
    assert!((230..=260).contains(&frames), "{frames} frames");
    // Its planner came back with it and committed plans again (1 Hz, 10 s down).
    let plans = s.per_robot[1].truth.plans;
    assert!(plans >= 40, "robot 1 committed {plans} plans");
    for robot in &s.per_robot {
        assert!(robot.actors.iter().all(|a| !a.stopped), "{}", robot.name);
    }
}
