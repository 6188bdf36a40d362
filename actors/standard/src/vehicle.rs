//! The vehicle driver: what moves a robot. It follows the committed plan and says where
//! the robot is.
//!
//! [`Vehicle`] is the driver, beside the sensor's [`FrameSource`](crate::sensor::FrameSource);
//! [`VehicleActor`] is the robot's `vehicle` actor around one: it subscribes to the
//! committed [`PLAN`] (keep-latest) and hands each plan to [`Vehicle::follow`], runs
//! [`Vehicle::step`] every [`Vehicle::period`], and publishes the odometry the driver
//! returns on [`ODOMETRY`]. The simulated vehicle (`troupe_sims::vehicle::SimVehicle`)
//! and the MAVLink vehicle (`troupe_robot::mavlink::MavlinkVehicle`) are drivers; a
//! robot's file chooses one by name (`troupe_robot::registry`).
//!
//! ```
//! use std::sync::Arc;
//! use std::time::Duration;
//! use troupe_actors::vehicle::{Vehicle, vehicle_actor};
//! use troupe_algorithms::frame::Odometry;
//! use troupe_algorithms::plan::Plan;
//! use troupe_runtime::{ActorError, ActorResult, Context};
//!
//! /// Stays where it is and says so at 10 Hz.
//! struct Parked(nalgebra::Isometry3<f64>);
//!
//! impl Vehicle for Parked {
//!     fn period(&self) -> Duration { Duration::from_millis(100) }
//!     fn follow(&mut self, _plan: Arc<Plan>, _ctx: &mut Context<'_>) -> ActorResult { Ok(()) }
//!     fn step(&mut self, ctx: &mut Context<'_>) -> Result<Option<Odometry>, ActorError> {
//!         Ok(Some(Odometry { stamp: ctx.now(), pose: self.0, velocity_mps: nalgebra::Vector3::zeros() }))
//!     }
//! }
//!
//! let spec = vehicle_actor(|| Parked(nalgebra::Isometry3::identity()));
//! assert_eq!(spec.name(), "vehicle");
//! ```

use std::sync::Arc;
use std::time::Duration;

use troupe_algorithms::frame::Odometry;
use troupe_algorithms::plan::Plan;
use troupe_runtime::{
    Actor, ActorError, ActorResult, ActorSpec, Context, Event, QueuePolicy, Received, TimerId,
};

use crate::msgs::{ODOMETRY, PLAN};

/// What moves a robot (see the [module docs](self)). Hooks run on the vehicle actor's
/// thread; none may block for long (a connection's I/O belongs on its own thread).
pub trait Vehicle: Send + 'static {
    /// How often [`Vehicle::step`] runs (the odometry or setpoint rate).
    fn period(&self) -> Duration;

    /// The actor starts, after it subscribed to [`PLAN`] and set the step timer:
    /// subscribe to what else the driver reads, open its connection. Returns the
    /// odometry to publish at once, if the driver knows where the robot is.
    fn start(&mut self, ctx: &mut Context<'_>) -> Result<Option<Odometry>, ActorError> {
        let _ = ctx;
        Ok(None)
    }

    /// A committed plan arrived: its trajectory is the reference from now on (a
    /// stopping plan brings the robot to rest).
    fn follow(&mut self, plan: Arc<Plan>, ctx: &mut Context<'_>) -> ActorResult;

    /// One period: move the robot (or command the autopilot) and read its state.
    /// Returns the odometry to publish on [`ODOMETRY`], if there is new odometry. A
    /// driver that interleaves its odometry with its other outputs may publish it
    /// itself and return `None`.
    fn step(&mut self, ctx: &mut Context<'_>) -> Result<Option<Odometry>, ActorError>;

    /// A message on a topic other than [`PLAN`] that the driver subscribed to in
    /// [`Vehicle::start`].
    fn receive(&mut self, message: &Received, ctx: &mut Context<'_>) -> ActorResult {
        let _ = (message, ctx);
        Ok(())
    }

    /// The actor stops (end of the run, or before a restart): close connections.
    fn stop(&mut self, ctx: &mut Context<'_>) {
        let _ = ctx;
    }
}

const STEP: TimerId = TimerId(0);

/// The robot's `vehicle` actor around a [`Vehicle`] driver (module docs).
pub struct VehicleActor<V> {
    vehicle: V,
}

impl<V: Vehicle> VehicleActor<V> {
    /// The actor driving `vehicle`.
    #[must_use]
    pub fn new(vehicle: V) -> Self {
        VehicleActor { vehicle }
    }
}

impl<V: Vehicle> Actor for VehicleActor<V> {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&PLAN, QueuePolicy::LATEST);
        ctx.set_timer(STEP, self.vehicle.period());
        if let Some(odometry) = self.vehicle.start(ctx)? {
            ctx.publish(&ODOMETRY, odometry);
        }
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(m) => match m.get_arc(&PLAN) {
                Some(plan) => self.vehicle.follow(plan, ctx),
                None => self.vehicle.receive(m, ctx),
            },
            Event::Timer(_) => {
                if let Some(odometry) = self.vehicle.step(ctx)? {
                    ctx.publish(&ODOMETRY, odometry);
                }
                Ok(())
            }
        }
    }

    fn stop(&mut self, ctx: &mut Context<'_>) {
        self.vehicle.stop(ctx);
    }
}

/// The robot's `vehicle` actor, each instance (at start and on every restart) driving
/// the vehicle `factory` builds.
pub fn vehicle_actor<V: Vehicle>(mut factory: impl FnMut() -> V + Send + 'static) -> ActorSpec {
    ActorSpec::new("vehicle", move || VehicleActor::new(factory()))
}
