//! The local grid + planner pipeline flying in the cave: safe against ground truth.

use troupe_robot::RobotConfig;
use troupe_sims::scenario::Scenario;
use troupe_sims::team::Team;

fn planner_flight(selection: &str, seed: u64) -> troupe_sims::team::Summary {
    let scenario = Scenario {
        name: format!("planner_{selection}_{seed}"),
        seed,
        duration_s: 40.0,
        robots: 1,
        robot: RobotConfig {
            behaviour: "planner".into(),
            selection: selection.into(),
            ..RobotConfig::default()
        },
        ..Scenario::default()
    };
    Team::new(&scenario).expect("assemble").run(|_| {}).summary
}

#[test]
fn planned_flights_never_commit_unsafe_plans_or_collide() {
    for (selection, seed) in [("greedy", 1), ("random", 2)] {
        let s = planner_flight(selection, seed);
        let robot = &s.per_robot[0];
        assert_eq!(s.collisions, 0, "{selection}: collisions with the world");
        assert!(
            robot.truth.plans >= 35,
            "{selection}: {} plans",
            robot.truth.plans
        );
        assert_eq!(
            robot.truth.unsafe_plans, 0,
            "{selection}: plans entering the rock"
        );
        assert!(robot.truth.min_clearance_m > 0.0);
        assert!(
            robot.truth.distance_m > 1.0,
            "{selection}: the robot did not move"
        );
        assert!(s.coverage.final_fraction > 0.01);
        assert!(robot.actors.iter().all(|a| a.panics == 0 && a.errors == 0));
    }
}

#[test]
fn teleoperated_flight_moves_forward_safely() {
    use troupe_actors::planner::{ScriptedCommand, ScriptedTeleop};
    use troupe_actors::runtime::ActorSpec;

    let scenario = Scenario {
        name: "teleop_cave".into(),
        seed: 1,
        duration_s: 20.0,
        robots: 1,
        robot: RobotConfig {
            behaviour: troupe_robot::TELEOP.into(),
            ..RobotConfig::default()
        },
        ..Scenario::default()
    };
    // Full speed ahead the whole time; the teleop actor slows down and stops where
    // the space ahead is not known to be free.
    let script = vec![ScriptedCommand {
        from_s: 0.0,
        vx_mps: 1.5,
        vz_mps: 0.0,
        yaw_rate_rad_s: 0.0,
    }];
    let team = Team::new_with(&scenario, |_, robot| {
        let script = script.clone();
        robot.add(ActorSpec::new("joystick", move || {
            ScriptedTeleop::new(script.clone(), 5.0)
        }));
    })
    .expect("assemble");
    let s = team.run(|_| {}).summary;
    let robot = &s.per_robot[0];
    assert_eq!(s.collisions, 0);
    assert!(robot.truth.plans >= 15, "{} plans", robot.truth.plans);
    assert_eq!(robot.truth.unsafe_plans, 0, "plans entering the rock");
    assert!(
        robot.truth.distance_m > 1.0,
        "moved {} m",
        robot.truth.distance_m
    );
    assert!(robot.actors.iter().all(|a| a.panics == 0 && a.errors == 0));
}
