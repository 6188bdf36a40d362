//! The MAVLink vehicle actor: streams the committed plan's reference to a PX4 or
//! ArduPilot autopilot, publishes the autopilot's odometry and status, and never arms
//! or changes mode.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Duration;

use mavlink::dialects::common::{
    ATTITUDE_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavMessage,
};
use nalgebra::{Isometry3, Point3, Translation3, Vector3};
use troupe_actors::msgs::{DEPTH_FRAME, ODOMETRY, VEHICLE_HOLD, VehicleHold};
use troupe_actors::vehicle::{Vehicle, vehicle_actor};
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::plan::Plan;
use troupe_core::Time;
use troupe_runtime::{ActorError, ActorResult, ActorSpec, Context, QueuePolicy, Received};

use super::config::{MavlinkConfig, MavlinkSettings, OdometrySource};
use super::link::{INBOUND_CAPACITY, Inbound, MavlinkLink, Outbound};
use super::setpoint::{Target, position_target};
use super::status::{AUTOPILOT_STATUS, AutopilotStatus, GaveUp, flight_mode, in_control, is_armed};
use crate::ConfigError;
use crate::frames::{ned_frd_from_euler, ned_frd_to_enu_flu, ned_to_enu};
use crate::safety::{
    GuardConfig, GuardInput, HoldReason, RESUME_TOLERANCE_M, SetpointGuard, WatchdogChange,
};

/// Period of this program's own heartbeat.
const OWN_HEARTBEAT_PERIOD_S: f64 = 1.0;
/// Period of the status topic when nothing changes.
const STATUS_PERIOD_S: f64 = 0.5;
/// Period of the hold topic when nothing changes.
const HOLD_PERIOD_S: f64 = 1.0;

/// Builds the vehicle for [`RobotParts::vehicle`](crate::RobotParts::vehicle) from a
/// `[mavlink]` section (the registry's `mavlink` vehicle driver); a bad value is an
/// error naming its key.
pub fn mavlink_vehicle(config: &MavlinkConfig) -> Result<ActorSpec, ConfigError> {
    let settings = config.validate()?;
    Ok(vehicle_actor(move || MavlinkVehicle::new(settings.clone())))
}

/// The robot's vehicle driver on a MAVLink autopilot (a [`Vehicle`], in the robot's
/// `vehicle` actor); see the [`mavlink`](crate::mavlink) module for what it does.
pub struct MavlinkVehicle {
    settings: MavlinkSettings,
    link: Option<MavlinkLink>,
    guard: Option<SetpointGuard>,
    target: Option<Target>,
    heartbeat: Option<HEARTBEAT_DATA>,
    attitude: Option<ATTITUDE_DATA>,
    local_position: Option<LOCAL_POSITION_NED_DATA>,
    /// A position arrived since the last odometry was published.
    fresh_position: bool,
    own_heartbeat_at: Option<Time>,
    status_at: Option<Time>,
    status_key: Option<(bool, String, bool, Option<HoldReason>)>,
    /// What was last published on [`VEHICLE_HOLD`], and the hold reason then.
    hold_published: Option<(VehicleHold, Option<HoldReason>)>,
    /// When the actor started (the waits count from it).
    started_at: Time,
    /// Whether the pilot has ever handed control over.
    ever_in_control: bool,
    /// Why it gave up waiting, once it did: it sends nothing more.
    gave_up: Option<GaveUp>,
    /// When the setpoints of the last second were sent.
    sent_at: VecDeque<Time>,
}

impl MavlinkVehicle {
    /// A vehicle with checked settings; the connection opens when it starts.
    #[must_use]
    pub fn new(settings: MavlinkSettings) -> Self {
        let target = settings
            .target_system_id
            .zip(settings.target_component_id)
            .map(|(system_id, component_id)| Target {
                system_id,
                component_id,
            });
        MavlinkVehicle {
            settings,
            link: None,
            guard: None,
            target,
            heartbeat: None,
            attitude: None,
            local_position: None,
            fresh_position: false,
            own_heartbeat_at: None,
            status_at: None,
            status_key: None,
            hold_published: None,
            started_at: Time::ZERO,
            ever_in_control: false,
            gave_up: None,
            sent_at: VecDeque::new(),
        }
    }

    fn guard(&mut self) -> Result<&mut SetpointGuard, ActorError> {
        self.guard
            .as_mut()
            .ok_or_else(|| ActorError::msg("MAVLink vehicle used before start"))
    }

    /// Whether a message comes from the autopilot we talk to (or could: the first
    /// autopilot heartbeat picks it when the ids are not configured).
    fn is_from_autopilot(&self, inbound: &Inbound) -> bool {
        let system_ok = self
            .settings
            .target_system_id
            .is_none_or(|id| u32::from(id) == inbound.system_id);
        let known_ok = self.target.is_none_or(|t| {
            u32::from(t.system_id) == inbound.system_id && t.component_id == inbound.component_id
        });
        system_ok && known_ok
    }

    fn receive(&mut self, inbound: Inbound, now: Time) -> ActorResult {
        if !self.is_from_autopilot(&inbound) {
            return Ok(());
        }
        match inbound.message {
            MavMessage::HEARTBEAT(hb) => {
                // Ground stations and companion computers also send heartbeats.
                if hb.autopilot == MavAutopilot::MAV_AUTOPILOT_INVALID {
                    return Ok(());
                }
                if self.target.is_none() {
                    let Ok(system_id) = u8::try_from(inbound.system_id) else {
                        return Ok(());
                    };
                    let target = Target {
                        system_id,
                        component_id: self
                            .settings
                            .target_component_id
                            .unwrap_or(inbound.component_id),
                    };
                    tracing::info!(
                        system = target.system_id,
                        component = target.component_id,
                        "autopilot found: {}",
                        flight_mode(&hb)
                    );
                    self.target = Some(target);
                }
                if self
                    .target
                    .is_some_and(|t| t.component_id == inbound.component_id)
                {
                    let control = in_control(&hb);
                    let was = self.heartbeat.as_ref().map(in_control);
                    if was != Some(control) {
                        log_control(control, &hb, self.ever_in_control, &self.settings);
                    }
                    self.ever_in_control |= control;
                    self.heartbeat = Some(hb);
                    let guard = self.guard()?;
                    guard.control(control);
                    let change = guard.heartbeat(now);
                    log_change(GuardInput::Heartbeat, change);
                }
            }
            MavMessage::LOCAL_POSITION_NED(p) if self.target.is_some() => {
                self.local_position = Some(p);
                self.fresh_position = true;
            }
            MavMessage::ATTITUDE(a) if self.target.is_some() => self.attitude = Some(a),
            _ => {}
        }
        Ok(())
    }

    /// The autopilot's latest estimate as troupe odometry (ENU / FLU).
    fn autopilot_odometry(&self, now: Time) -> Option<Odometry> {
        let (p, a) = (self.local_position.as_ref()?, self.attitude.as_ref()?);
        let values = [p.x, p.y, p.z, p.vx, p.vy, p.vz, a.roll, a.pitch, a.yaw];
        if !values.iter().all(|v| v.is_finite()) {
            return None;
        }
        let position = ned_to_enu(&Vector3::new(
            f64::from(p.x),
            f64::from(p.y),
            f64::from(p.z),
        ));
        let velocity = ned_to_enu(&Vector3::new(
            f64::from(p.vx),
            f64::from(p.vy),
            f64::from(p.vz),
        ));
        let rotation = ned_frd_to_enu_flu(&ned_frd_from_euler(
            f64::from(a.roll),
            f64::from(a.pitch),
            f64::from(a.yaw),
        ));
        Some(Odometry {
            stamp: now,
            pose: Isometry3::from_parts(Translation3::from(position), rotation),
            velocity_mps: velocity,
        })
    }

    fn odometry_arrived(&mut self, odometry: &Odometry, now: Time) -> ActorResult {
        let position = Point3::from(odometry.pose.translation.vector);
        let forward = odometry.pose.rotation * Vector3::x();
        let yaw = forward.y.atan2(forward.x);
        let change = self.guard()?.odometry(now, position, yaw);
        log_change(GuardInput::Odometry, change);
        Ok(())
    }

    fn tick(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        let now = ctx.now();
        let Some(link) = &self.link else {
            return Err(ActorError::msg("MAVLink vehicle ticked before start"));
        };
        let received: Vec<Inbound> = (0..INBOUND_CAPACITY)
            .map_while(|_| link.try_recv())
            .collect();
        for inbound in received {
            self.receive(inbound, now)?;
        }
        if std::mem::take(&mut self.fresh_position)
            && self.settings.odometry_source == OdometrySource::Autopilot
            && let Some(odometry) = self.autopilot_odometry(now)
        {
            self.odometry_arrived(&odometry, now)?;
            ctx.publish(&ODOMETRY, odometry);
        }
        let mut changes = Vec::new();
        let setpoint = self.guard()?.tick(now, &mut changes);
        for (input, change) in changes {
            // An autopilot never heard is not lost: `check_waits` gives up on it.
            if input != GuardInput::Heartbeat || self.heartbeat.is_some() {
                log_change(input, Some(change));
            }
        }
        self.check_waits(now);
        self.publish_hold(ctx)?;
        while self
            .sent_at
            .front()
            .is_some_and(|at| now.saturating_since(*at) > Duration::from_secs(1))
        {
            self.sent_at.pop_front();
        }
        if self.gave_up.is_some() {
            return self.publish_status(ctx);
        }
        if let Some(link) = &self.link {
            if let (Some(setpoint), Some(target)) = (setpoint, self.target) {
                let time_boot_ms = (now.as_nanos() / 1_000_000) as u32;
                link.try_send(Outbound::Setpoint(position_target(
                    &setpoint,
                    target,
                    time_boot_ms,
                )));
                self.sent_at.push_back(now);
            }
            if self
                .own_heartbeat_at
                .is_none_or(|at| now.saturating_since(at).as_secs_f64() >= OWN_HEARTBEAT_PERIOD_S)
            {
                link.try_send(Outbound::Heartbeat);
                self.own_heartbeat_at = Some(now);
            }
        }
        self.publish_status(ctx)
    }

    /// Gives up when the autopilot stays silent, or the pilot never hands control over,
    /// for longer than the settings allow (0: for ever).
    fn check_waits(&mut self, now: Time) {
        if self.gave_up.is_some() {
            return;
        }
        let waited_s = now.saturating_since(self.started_at).as_secs_f64();
        let over = |wait_s: f64| wait_s > 0.0 && waited_s >= wait_s;
        let s = &self.settings;
        self.gave_up = match &self.heartbeat {
            None if over(s.autopilot_wait_s) => Some(GaveUp::NoAutopilot {
                connection: s.connection.clone(),
                wait_s: s.autopilot_wait_s,
            }),
            Some(hb) if !self.ever_in_control && over(s.control_wait_s) => {
                Some(GaveUp::NoControl {
                    wait_s: s.control_wait_s,
                    armed: is_armed(hb),
                    mode: flight_mode(hb),
                })
            }
            _ => None,
        };
    }

    /// Says where the vehicle stands instead of following the plan when that changes —
    /// at once when it begins, ends or changes reason, at most every 0.2 s while it
    /// follows a pilot — and again every second (so that a restarted collision actor
    /// learns it).
    fn publish_hold(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        let now = ctx.now();
        let guard = self.guard()?;
        let (at, reason) = (guard.hold_point(), guard.hold_reason());
        let due = self.hold_published.is_none_or(|(last, last_reason)| {
            let since_s = now.saturating_since(last.stamp).as_secs_f64();
            let moved = match (last.at, at) {
                (Some((a, _)), Some((b, _))) => (a - b).norm() > RESUME_TOLERANCE_M,
                (None, None) => false,
                _ => return true,
            };
            last_reason != reason || (moved && since_s >= 0.2) || since_s >= HOLD_PERIOD_S
        });
        if due {
            let hold = VehicleHold { stamp: now, at };
            self.hold_published = Some((hold, reason));
            ctx.publish(&VEHICLE_HOLD, hold);
        }
        Ok(())
    }

    fn publish_status(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        let now = ctx.now();
        let (armed, mode) = self
            .heartbeat
            .as_ref()
            .map_or((false, String::new()), |hb| (is_armed(hb), flight_mode(hb)));
        let guard = self.guard()?;
        let (lost, hold) = (guard.heartbeat_missing(), guard.hold_reason());
        let (heartbeat_age_s, counters) = (guard.heartbeat_age_s(now), guard.counters());
        let key = (armed, mode.clone(), lost, hold);
        let due = self
            .status_at
            .is_none_or(|at| now.saturating_since(at).as_secs_f64() >= STATUS_PERIOD_S);
        if !due && self.status_key.as_ref() == Some(&key) {
            return Ok(());
        }
        self.status_key = Some(key);
        self.status_at = Some(now);
        let link = self
            .link
            .as_ref()
            .map(MavlinkLink::stats)
            .unwrap_or_default();
        ctx.publish(
            &AUTOPILOT_STATUS,
            AutopilotStatus {
                stamp: now,
                autopilot: self.target.map(|t| (t.system_id, t.component_id)),
                armed,
                mode,
                heartbeat_age_s,
                heartbeat_lost: lost,
                in_control: self.heartbeat.as_ref().is_some_and(in_control),
                hold,
                setpoint_rate_hz: self.sent_at.len() as f64,
                gave_up: self.gave_up.clone(),
                guard: counters,
                link,
            },
        );
        Ok(())
    }
}

/// Says once per change whether the pilot handed control over.
fn log_control(control: bool, hb: &HEARTBEAT_DATA, before: bool, s: &MavlinkSettings) {
    let (armed, mode) = (
        if is_armed(hb) { "armed" } else { "disarmed" },
        flight_mode(hb),
    );
    if control {
        tracing::info!("the pilot handed control over ({armed}, {mode}): following plans");
    } else if before {
        tracing::warn!(
            "the pilot took control back ({armed}, {mode}): holding where the vehicle is until \
             it is armed and in OFFBOARD or GUIDED again"
        );
    } else {
        tracing::info!(
            "waiting for the pilot to arm and switch to OFFBOARD (PX4) or GUIDED (ArduPilot) \
             ({armed}, {mode} now; up to {} s, [mavlink] control_wait_s): holding, planning \
             nothing",
            s.control_wait_s
        );
    }
}

fn log_change(input: GuardInput, change: Option<WatchdogChange>) {
    let what = match input {
        GuardInput::Sensor => "depth frames",
        GuardInput::Odometry => "odometry",
        GuardInput::Heartbeat => "autopilot heartbeat",
    };
    match change {
        Some(WatchdogChange::Lost) if input == GuardInput::Heartbeat => {
            tracing::warn!("{what} lost: setpoints stop until it returns");
        }
        Some(WatchdogChange::Lost) => tracing::warn!("{what} lost: holding position"),
        Some(WatchdogChange::Restored) => tracing::info!("{what} back"),
        None => {}
    }
}

/// The MAVLink vehicle as a [`Vehicle`] driver. Its [`Vehicle::step`] is the setpoint
/// tick, which publishes the autopilot's odometry itself (between reading the
/// autopilot and publishing the hold and status topics, as it always did) and returns
/// none for the vehicle actor to publish.
impl Vehicle for MavlinkVehicle {
    fn period(&self) -> Duration {
        Duration::from_secs_f64(1.0 / self.settings.setpoint_rate_hz)
    }

    fn start(&mut self, ctx: &mut Context<'_>) -> Result<Option<Odometry>, ActorError> {
        // The vehicle actor has subscribed to the plan and set the tick's timer: the
        // ticks come first, so that without a link they still give up after
        // `autopilot_wait_s`.
        let s = &self.settings;
        ctx.subscribe(&DEPTH_FRAME, QueuePolicy::LATEST);
        if s.odometry_source == OdometrySource::External {
            ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        }
        self.started_at = ctx.now();
        self.guard = Some(SetpointGuard::new(
            GuardConfig {
                sensor_timeout_s: s.sensor_timeout_s,
                odometry_timeout_s: s.odometry_timeout_s,
                heartbeat_timeout_s: s.heartbeat_timeout_s,
                geofence: s.geofence,
            },
            ctx.now(),
        ));
        let link = MavlinkLink::open(&s.connection, s.source_system_id, s.source_component_id)
            .map_err(|e| ActorError::with_source("cannot start the MAVLink link", e))?;
        self.link = Some(link);
        if s.autopilot_wait_s > 0.0 {
            tracing::info!(
                "waiting for the autopilot's heartbeat on `{}` (up to {} s, [mavlink] \
                 autopilot_wait_s)",
                s.connection,
                s.autopilot_wait_s
            );
        }
        Ok(None)
    }

    fn follow(&mut self, plan: Arc<Plan>, _ctx: &mut Context<'_>) -> ActorResult {
        if let Err(violation) = self.guard()?.plan(plan) {
            tracing::warn!(
                "committed plan leaves the geofence ({violation}); \
                 the vehicle will hold inside it"
            );
        }
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context<'_>) -> Result<Option<Odometry>, ActorError> {
        self.tick(ctx).map(|()| None)
    }

    fn receive(&mut self, message: &Received, ctx: &mut Context<'_>) -> ActorResult {
        let now = ctx.now();
        if message.get(&DEPTH_FRAME).is_some() {
            let change = self.guard()?.depth_frame(now);
            log_change(GuardInput::Sensor, change);
        } else if let Some(odometry) = message.get(&ODOMETRY) {
            self.odometry_arrived(odometry, now)?;
        }
        Ok(())
    }

    fn stop(&mut self, _ctx: &mut Context<'_>) {
        // Dropping the link stops its threads and closes the connection.
        self.link = None;
    }
}
