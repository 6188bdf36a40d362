//! The teleoperation actors: [`TeleopActor`] replans at a fixed rate from the
//! committed reference state, mapping the latest operator command on
//! [`TELEOP_COMMAND`] to the closest safe primitive (thesis §5.1.2) and committing it
//! with its stopping primitive (the stopping trajectory alone when nothing is safe);
//! [`ScriptedTeleop`] publishes a timed list of commands, standing in for a joystick.

use std::sync::Arc;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::msgs::{GRID_SNAPSHOT, ODOMETRY, PLAN};
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::grid::GridSnapshot;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::planner::committed::{Committed, replanning_root};
use troupe_algorithms::planner::round::RoundConfig;
use troupe_algorithms::planner::teleop::{TeleopCommand, TeleopParams, closest_safe_primitive};
use troupe_runtime::{Actor, ActorResult, Context, Event, QueuePolicy, TimerId, Topic};

/// Operator commands (a joystick driver or a script publishes here).
pub const TELEOP_COMMAND: Topic<TeleopCommand> = Topic::new("teleop/command");

/// Teleoperation settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TeleopConfig {
    /// Replanning rate, Hz.
    pub rate_hz: f64,
    /// Limits, safety margin and planning period (the library settings are unused:
    /// the teleoperation library is built from [`TeleopParams`]).
    pub round: RoundConfig,
    /// The command library and speed adaptation.
    pub params: TeleopParams,
    /// Spacing of the knots sent to the vehicle, seconds.
    pub knot_step_s: f64,
}

impl Default for TeleopConfig {
    fn default() -> Self {
        TeleopConfig {
            rate_hz: 1.0,
            round: RoundConfig::default(),
            params: TeleopParams::default(),
            knot_step_s: 0.1,
        }
    }
}

const REPLAN: TimerId = TimerId(0);

/// Maps operator commands to safe primitives at a fixed rate (thesis §5.1.2) and
/// commits them on [`PLAN`].
pub struct TeleopActor {
    config: TeleopConfig,
    snapshot: Option<Arc<GridSnapshot>>,
    odometry: Option<Arc<Odometry>>,
    command: Option<Arc<TeleopCommand>>,
    reference: Option<Committed>,
}

impl TeleopActor {
    /// A teleoperation planner with `config`.
    #[must_use]
    pub fn new(config: TeleopConfig) -> Self {
        TeleopActor {
            config,
            snapshot: None,
            odometry: None,
            command: None,
            reference: None,
        }
    }

    fn plan(&mut self, ctx: &mut Context<'_>) {
        let (Some(snapshot), Some(odometry)) = (self.snapshot.clone(), self.odometry.clone())
        else {
            return;
        };
        let now = ctx.now();
        let root = replanning_root(self.reference.as_ref(), now, &odometry.pose);
        let timeout = Duration::from_secs_f64(self.config.params.command_timeout_s.max(0.0));
        let command = self
            .command
            .as_deref()
            .filter(|c| (now - c.stamp) <= timeout);
        let round = &self.config.round;
        let reference = match closest_safe_primitive(
            round,
            &self.config.params,
            &snapshot,
            &root,
            command,
        ) {
            Some(choice) => Committed {
                start: now,
                switch_s: round.planning_period_s.min(choice.primitive.duration_s()),
                primitive: choice.primitive,
                stopping: choice.stopping,
            },
            None => {
                tracing::debug!(robot = ctx.robot_name(), time = %now, "teleop: nothing safe, stopping");
                let Some(stop) = Committed::braking(&round.limits, &root, now) else {
                    return;
                };
                stop
            }
        };
        ctx.publish(
            &PLAN,
            Plan::new(now, reference.trajectory(self.config.knot_step_s)),
        );
        self.reference = Some(reference);
    }
}

impl Actor for TeleopActor {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        ctx.subscribe(&GRID_SNAPSHOT, QueuePolicy::LATEST);
        ctx.subscribe(&TELEOP_COMMAND, QueuePolicy::LATEST);
        ctx.set_timer(
            REPLAN,
            Duration::from_secs_f64(1.0 / self.config.rate_hz.max(1e-3)),
        );
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(m) => {
                if let Some(odometry) = m.get_arc(&ODOMETRY) {
                    self.odometry = Some(odometry);
                } else if let Some(snapshot) = m.get_arc(&GRID_SNAPSHOT) {
                    self.snapshot = Some(snapshot);
                } else if let Some(command) = m.get_arc(&TELEOP_COMMAND) {
                    self.command = Some(command);
                }
                ctx.bookkeeping_only();
            }
            Event::Timer(_) => self.plan(ctx),
        }
        Ok(())
    }
}

/// One scripted command: from `from_s` seconds of run time on (until the next).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptedCommand {
    /// Start of this command, seconds of run time.
    pub from_s: f64,
    /// Forward speed, m/s.
    pub vx_mps: f64,
    /// Vertical speed, m/s.
    pub vz_mps: f64,
    /// Yaw rate, rad/s.
    pub yaw_rate_rad_s: f64,
}

/// Publishes a script of commands on [`TELEOP_COMMAND`] at a fixed rate, like a
/// joystick driver would (the command in force is the last one whose `from_s` has
/// passed; nothing is published before the first).
pub struct ScriptedTeleop {
    script: Vec<ScriptedCommand>,
    rate_hz: f64,
}

impl ScriptedTeleop {
    /// A script (sorted by `from_s` here) published at `rate_hz`.
    #[must_use]
    pub fn new(mut script: Vec<ScriptedCommand>, rate_hz: f64) -> Self {
        script.sort_by(|a, b| a.from_s.total_cmp(&b.from_s));
        ScriptedTeleop { script, rate_hz }
    }
}

impl Actor for ScriptedTeleop {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(
            REPLAN,
            Duration::from_secs_f64(1.0 / self.rate_hz.max(1e-3)),
        );
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if let Event::Timer(_) = event {
            let now = ctx.now();
            let now_s = now.as_secs_f64();
            if let Some(c) = self.script.iter().rev().find(|c| c.from_s <= now_s) {
                ctx.publish(
                    &TELEOP_COMMAND,
                    TeleopCommand {
                        stamp: now,
                        vx_mps: c.vx_mps,
                        vz_mps: c.vz_mps,
                        yaw_rate_rad_s: c.yaw_rate_rad_s,
                    },
                );
            }
        }
        Ok(())
    }
}
