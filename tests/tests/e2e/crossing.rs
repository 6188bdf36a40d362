//! Crossing missions in an open field (thesis §8.2.3): robots on straight lines that
//! meet at the centre at the same time, the collision actor with fixed priorities, the
//! link delayed by 500 ms. Ground truth: no two bodies ever come closer than the sum
//! of the cylinder radii, and every robot reaches its goal.

use std::sync::{Arc, Mutex};

use troupe_actors::msgs::PLAN_DECISION;
use troupe_runtime::{Actor, ActorResult, ActorSpec, Context, Event, QueuePolicy, RobotSpec};
use troupe_sims::scenario::Scenario;
use troupe_sims::team::Team;
use troupe_sims::world::{OpenField, Site};

/// Counts the rounds in which a robot's collision actor committed the stop.
struct StopCounter(Arc<Mutex<Vec<u32>>>, usize);

impl Actor for StopCounter {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&PLAN_DECISION, QueuePolicy::Fifo { capacity: 64 });
        Ok(())
    }
    fn handle(&mut self, event: &Event, _ctx: &mut Context<'_>) -> ActorResult {
        if let Event::Message(m) = event
            && let Some(d) = m.get(&PLAN_DECISION)
            && d.chosen.is_none()
            && !d.stale
        {
            self.0.lock().unwrap()[self.1] += 1;
        }
        Ok(())
    }
}

fn crossing(robots: u32, collision: bool) -> (Scenario, troupe_sims::team::RunOutput, Vec<u32>) {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../sims/scenarios/crossing_4.toml"
    );
    let mut scenario = Scenario::load(std::path::Path::new(path)).unwrap();
    scenario.robots = robots;
    scenario.robot.collision.enabled = collision;
    let (output, stops) = run_counting_stops(&scenario);
    (scenario, output, stops)
}

/// Runs the scenario with a [`StopCounter`] on every robot: the run and each robot's
/// stops.
fn run_counting_stops(scenario: &Scenario) -> (troupe_sims::team::RunOutput, Vec<u32>) {
    let stops = Arc::new(Mutex::new(vec![0; scenario.robots as usize]));
    let counters = stops.clone();
    let team = Team::new_with(scenario, |i, robot: &mut RobotSpec| {
        let counters = counters.clone();
        robot.add(ActorSpec::new("stops", move || {
            StopCounter(counters.clone(), i)
        }));
    })
    .unwrap();
    let output = team.run(|_| {});
    let stops = stops.lock().unwrap().clone();
    (output, stops)
}

fn assert_safe_and_arrived(robots: u32) {
    let (scenario, output, stops) = crossing(robots, true);
    let s = &output.summary;
    let radii_m = 2.0 * scenario.robot.collision.peers.cylinder_radius_m;
    let closest_m = s.min_inter_robot_distance_m.unwrap();
    println!("{robots} robots: closest approach {closest_m:.3} m, stops per robot {stops:?}");
    assert!(
        closest_m >= radii_m,
        "{robots} robots: closest approach {closest_m} m < {radii_m} m"
    );
    assert_eq!(s.robot_contacts, 0);
    assert_eq!(s.collisions, 0);
    // Somebody yielded: the crossing is timed so that they would meet.
    assert!(
        stops.iter().sum::<u32>() > 0,
        "no robot ever stopped: {stops:?}"
    );
    let field = OpenField::generate(&scenario.world.open_field, scenario.world.seed);
    for (i, robot) in s.per_robot.iter().enumerate() {
        let goal = *field.route(i, robots as usize).last().unwrap();
        let at = robot.truth.position.unwrap();
        assert!(
            (at - goal).norm() < 0.5,
            "{} ended at {at} (goal {goal}), stopped {} rounds",
            robot.name,
            stops[i]
        );
    }
}

#[test]
fn two_crossing_robots_keep_apart_and_arrive() {
    assert_safe_and_arrived(2);
}

#[test]
fn four_crossing_robots_keep_apart_and_arrive() {
    assert_safe_and_arrived(4);
}

#[test]
fn without_the_collision_actor_the_crossing_robots_meet() {
    // The scene is a real test: with the same timing and no avoidance, bodies touch.
    let (scenario, output, _) = crossing(2, false);
    let radii_m = 2.0 * scenario.robot.collision.peers.cylinder_radius_m;
    let closest_m = output.summary.min_inter_robot_distance_m.unwrap();
    assert!(closest_m < radii_m, "{closest_m}");
}

#[test]
fn planner_robots_commit_through_the_collision_actor() {
    // The planner pipeline offers ranked candidates and follows the decisions.
    let mut scenario = Scenario {
        name: "planner_collision".into(),
        duration_s: 20.0,
        robots: 1,
        ..Scenario::default()
    };
    scenario.robot.behaviour = "planner".into();
    scenario.robot.collision.enabled = true;
    let s = run_counting_stops(&scenario).0.summary;
    let robot = &s.per_robot[0];
    assert_eq!(s.collisions, 0);
    assert_eq!(robot.truth.unsafe_plans, 0);
    let decisions = s.topics["plan/decision"].messages;
    assert!(decisions >= 15, "{decisions} decisions");
    // Every committed plan came from a decision (the planner no longer commits).
    assert_eq!(s.topics["plan/committed"].messages, decisions);
    assert!(
        robot.truth.distance_m > 1.0,
        "flew {} m",
        robot.truth.distance_m
    );
}
