//! A user-written actor joins a simulated team.
//!
//! `Odometer` subscribes to the robot's `odometry` topic, integrates the distance
//! flown, and publishes it on its own topic `odometer/distance` once a second. It is
//! added to every robot of the default cave scenario with one `robot.add(...)` line.
//!
//! Run: `cargo run --release -p troupe-tests --example custom_actor`

use std::sync::{Arc, Mutex};
use std::time::Duration;

use troupe_actors::msgs::ODOMETRY;
use troupe_algorithms::frame::Odometry;
use troupe_runtime::{
    Actor, ActorResult, ActorSpec, Context, Event, Message, QueuePolicy, TimerId, Topic,
};
use troupe_sims::scenario::Scenario;
use troupe_sims::team::Team;

/// What the odometer publishes.
#[derive(Debug, Clone, Copy)]
struct Distance {
    metres: f64,
}
impl Message for Distance {}

/// The odometer's own topic.
const DISTANCE: Topic<Distance> = Topic::new("odometer/distance");
const REPORT: TimerId = TimerId(0);

#[derive(Default)]
struct Odometer {
    last: Option<Arc<Odometry>>,
    metres: f64,
    /// Shared with `main` only so that the example can print the result.
    shared: Arc<Mutex<f64>>,
}

impl Actor for Odometer {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::fifo(64));
        ctx.set_timer(REPORT, Duration::from_secs(1));
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(m) => {
                if let Some(odometry) = m.get_arc(&ODOMETRY) {
                    if let Some(last) = &self.last {
                        self.metres += (odometry.pose.translation.vector
                            - last.pose.translation.vector)
                            .norm();
                    }
                    self.last = Some(odometry);
                }
            }
            Event::Timer(_) => {
                let distance = Distance {
                    metres: self.metres,
                };
                tracing::debug!(
                    robot = ctx.robot_name(),
                    metres = distance.metres,
                    "odometer"
                );
                ctx.publish(&DISTANCE, distance);
                if let Ok(mut shared) = self.shared.lock() {
                    *shared = self.metres;
                }
            }
        }
        Ok(())
    }
}

fn main() -> anyhow::Result<()> {
    let scenario = Scenario {
        name: "custom_actor".into(),
        duration_s: 20.0,
        ..Scenario::default()
    };
    let flown: Vec<Arc<Mutex<f64>>> = (0..scenario.robots).map(|_| Arc::default()).collect();
    let handles = flown.clone();
    let team = Team::new_with(&scenario, move |index, robot| {
        let shared = handles[index].clone();
        // The one line that adds a user-written actor to a robot:
        robot.add(ActorSpec::new("odometer", move || Odometer {
            shared: shared.clone(),
            ..Odometer::default()
        }));
    })?;
    let output = team.run(|_| {});
    for (robot, metres) in output.summary.per_robot.iter().zip(&flown) {
        let topic = &robot.topics[DISTANCE.name()];
        println!(
            "{}: odometer published {} messages; flew {:.1} m (ground truth {:.1} m)",
            robot.name,
            topic.messages,
            *metres.lock().map_err(|_| anyhow::anyhow!("poisoned"))?,
            robot.truth.distance_m
        );
    }
    Ok(())
}
