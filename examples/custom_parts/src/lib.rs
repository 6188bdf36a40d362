//! A sensor driver and an actor of one's own, added to troupe's robots from outside
//! troupe's crates and chosen by name in a scenario file (`scenario.toml` beside this
//! crate; `docs/custom-parts.md`).
//!
//! - [`BurstyCamera`] (`sensor = { kind = "bursty_camera", … }`): the simulator's
//!   camera whose frames go missing in bursts (a two-state Markov chain, the
//!   Gilbert–Elliott model of a flaky USB link), where the simulator's own camera
//!   loses none.
//! - [`Battery`] (`[[robot.actors]] kind = "battery"`): drains a battery with the
//!   flight (hover power plus a term in speed, from odometry) and publishes what is
//!   left on `battery/level` once a second; says so in the log when it runs low.
//! - [`registry`]: the simulator's parts and these two, for
//!   [`troupe_sims::cli::main_with`] (the `custom-parts` binary) or
//!   [`troupe_sims::team::Team::with_parts`].

use std::sync::Arc;
use std::time::Duration;

use serde::Deserialize;
use troupe_actors::msgs::ODOMETRY;
use troupe_actors::sensor::FrameSource;
use troupe_algorithms::frame::{DepthFrame, Odometry};
use troupe_core::{ConfigError, Time};
use troupe_robot::registry::{PartContext, Registry, SensorDriver};
use troupe_runtime::{
    Actor, ActorError, ActorResult, ActorSpec, Context, Event, Message, QueuePolicy, TimerId, Topic,
};
use troupe_sims::parts::SimEnvironment;
use troupe_sims::sim_sensor::SimCameraSource;
use troupe_sims::world::World;

/// The sensor driver's name in a scenario file.
pub const BURSTY_CAMERA: &str = "bursty_camera";
/// The actor's name in a scenario file (and the actor's own name).
pub const BATTERY: &str = "battery";

/// The simulator's parts ([`troupe_sims::parts::registry`]) and this crate's two.
#[must_use]
pub fn registry() -> Registry {
    let mut registry = troupe_sims::parts::registry();
    registry.add_sensor(BURSTY_CAMERA, bursty_camera);
    registry.add_actor(BATTERY, battery);
    registry
}

/// `[robot.sensor]` settings of [`BurstyCamera`].
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BurstySettings {
    /// Fraction of frames lost in the long run, in [0, 1).
    pub dropout: f64,
    /// Mean length of a burst of lost frames, frames (≥ 1).
    pub burst_frames: f64,
}

impl Default for BurstySettings {
    fn default() -> Self {
        BurstySettings {
            dropout: 0.2,
            burst_frames: 3.0,
        }
    }
}

/// Which frames a [`BurstyCamera`] loses: after a delivered frame the next is lost
/// with probability `p`, after a lost one the next is delivered with probability
/// `1 / burst_frames`; `p` is chosen so that the long-run loss is `dropout`.
/// Deterministic: a splitmix64 generator from `seed`.
#[derive(Clone, Debug)]
pub struct BurstChain {
    /// Probability of losing the next frame after a delivered one.
    enter_burst: f64,
    /// Probability of delivering the next frame after a lost one.
    leave_burst: f64,
    in_burst: bool,
    state: u64,
}

impl BurstChain {
    /// The chain of `settings` (valid ones: [`bursty_camera`] checks them).
    #[must_use]
    pub fn new(settings: BurstySettings, seed: u64) -> Self {
        let leave_burst = 1.0 / settings.burst_frames;
        BurstChain {
            enter_burst: settings.dropout * leave_burst / (1.0 - settings.dropout),
            leave_burst,
            in_burst: false,
            state: seed,
        }
    }

    /// Whether the next frame is lost.
    pub fn next_lost(&mut self) -> bool {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        let u = (z ^ (z >> 31)) as f64 / (u64::MAX as f64 + 1.0);
        self.in_burst = if self.in_burst {
            u >= self.leave_burst
        } else {
            u < self.enter_burst
        };
        self.in_burst
    }
}

/// The simulator's camera ([`SimCameraSource`]) losing frames in bursts
/// ([`BurstChain`]), where the simulator's own camera loses none.
pub struct BurstyCamera {
    camera: SimCameraSource,
    chain: BurstChain,
}

impl BurstyCamera {
    /// `camera`, losing the frames `chain` says.
    #[must_use]
    pub fn new(camera: SimCameraSource, chain: BurstChain) -> Self {
        BurstyCamera { camera, chain }
    }
}

impl FrameSource for BurstyCamera {
    fn capture(
        &mut self,
        now: Time,
        odometry: Option<&Odometry>,
    ) -> Result<Option<DepthFrame>, ActorError> {
        let frame = self.camera.capture(now, odometry)?;
        if frame.is_none() || !self.chain.next_lost() {
            return Ok(frame);
        }
        Ok(None)
    }
}

/// The factory of `bursty_camera`: checks the settings, renders the scenario's world
/// with its `[camera]`.
pub fn bursty_camera(ctx: &PartContext<'_>) -> Result<SensorDriver, ConfigError> {
    let settings: BurstySettings = ctx.settings()?;
    if !(settings.dropout.is_finite() && (0.0..1.0).contains(&settings.dropout)) {
        return Err(ConfigError::new(
            format!("{}.dropout", ctx.key),
            "must be in [0, 1)",
            settings.dropout,
        ));
    }
    if !(settings.burst_frames.is_finite() && settings.burst_frames >= 1.0) {
        return Err(ConfigError::new(
            format!("{}.burst_frames", ctx.key),
            "must be ≥ 1 frame",
            settings.burst_frames,
        ));
    }
    let env = SimEnvironment::of(ctx)?;
    let world: Arc<dyn World> = env.world.clone();
    let (camera, seed) = (env.scenario.camera.clone(), env.noise_seed);
    Ok(SensorDriver {
        frames: Box::new(move || {
            let camera = SimCameraSource::new(world.clone(), camera.clone(), seed);
            Box::new(BurstyCamera::new(
                camera,
                BurstChain::new(settings, seed ^ 0xb0b5),
            ))
        }),
        camera: env.scenario.camera.intrinsics(),
    })
}

/// What [`Battery`] publishes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BatteryLevel {
    /// Energy left, Wh.
    pub remaining_wh: f64,
    /// Energy left as a fraction of the capacity.
    pub fraction: f64,
}

impl Message for BatteryLevel {}

/// The battery's topic.
pub const BATTERY_LEVEL: Topic<BatteryLevel> = Topic::new("battery/level");

/// `[[robot.actors]]` settings of [`Battery`].
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BatterySettings {
    /// Energy when full, Wh.
    pub capacity_wh: f64,
    /// Power while airborne, W.
    pub hover_w: f64,
    /// Extra power per m/s of speed, W.
    pub per_mps_w: f64,
    /// Below this fraction the battery says so in the log (once).
    pub low_fraction: f64,
}

impl Default for BatterySettings {
    fn default() -> Self {
        BatterySettings {
            capacity_wh: 50.0,
            hover_w: 150.0,
            per_mps_w: 20.0,
            low_fraction: 0.2,
        }
    }
}

const REPORT: TimerId = TimerId(0);

/// Drains a battery with the flight (module docs).
pub struct Battery {
    settings: BatterySettings,
    remaining_wh: f64,
    /// The latest odometry's time and speed.
    latest: Option<(Time, f64)>,
    warned: bool,
}

impl Battery {
    /// A full battery.
    #[must_use]
    pub fn new(settings: BatterySettings) -> Self {
        Battery {
            settings,
            remaining_wh: settings.capacity_wh,
            latest: None,
            warned: false,
        }
    }
}

impl Actor for Battery {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        ctx.set_timer(REPORT, Duration::from_secs(1));
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(m) => {
                if let Some(odometry) = m.get(&ODOMETRY) {
                    let now = ctx.now();
                    if let Some((then, speed_mps)) = self.latest {
                        let hours = (now.as_secs_f64() - then.as_secs_f64()) / 3600.0;
                        let watts = self.settings.hover_w + self.settings.per_mps_w * speed_mps;
                        self.remaining_wh = (self.remaining_wh - watts * hours).max(0.0);
                    }
                    self.latest = Some((now, odometry.velocity_mps.norm()));
                }
            }
            Event::Timer(_) => {
                let fraction = self.remaining_wh / self.settings.capacity_wh;
                if fraction < self.settings.low_fraction && !self.warned {
                    self.warned = true;
                    tracing::warn!(
                        robot = ctx.robot_name(),
                        remaining_wh = self.remaining_wh,
                        "battery low"
                    );
                }
                ctx.publish(
                    &BATTERY_LEVEL,
                    BatteryLevel {
                        remaining_wh: self.remaining_wh,
                        fraction,
                    },
                );
            }
        }
        Ok(())
    }
}

/// The factory of `battery`: checks the settings.
pub fn battery(ctx: &PartContext<'_>) -> Result<ActorSpec, ConfigError> {
    let settings: BatterySettings = ctx.settings()?;
    for (key, value) in [
        ("capacity_wh", settings.capacity_wh),
        ("hover_w", settings.hover_w),
    ] {
        ConfigError::positive(key, value).map_err(|e| e.within(&ctx.key))?;
    }
    for (key, value) in [
        ("per_mps_w", settings.per_mps_w),
        ("low_fraction", settings.low_fraction),
    ] {
        ConfigError::non_negative(key, value).map_err(|e| e.within(&ctx.key))?;
    }
    Ok(ActorSpec::new(BATTERY, move || Battery::new(settings)).with_options(ctx.options(0.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_burst_chain_loses_the_configured_fraction_in_bursts() {
        let settings = BurstySettings {
            dropout: 0.3,
            burst_frames: 3.0,
        };
        let mut chain = BurstChain::new(settings, 7);
        let (mut lost, mut bursts, mut previous) = (0_u32, 0_u32, false);
        let n = 200_000;
        for _ in 0..n {
            let now = chain.next_lost();
            lost += u32::from(now);
            bursts += u32::from(now && !previous);
            previous = now;
        }
        let fraction = f64::from(lost) / f64::from(n);
        let mean_burst = f64::from(lost) / f64::from(bursts);
        assert!((fraction - 0.3).abs() < 0.01, "{fraction}");
        assert!((mean_burst - 3.0).abs() < 0.1, "{mean_burst}");
    }
}
