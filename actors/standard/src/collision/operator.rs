//! Operator commands from the base station (issue 17): hold, resume, or a velocity
//! command for teleoperation (thesis §5.1.2), addressed to one robot or to all.
//!
//! The base publishes a [`BaseCommand`] on the shared topic [`BASE_COMMAND`]
//! (store-and-forward in the odometry class: the highest priority, retransmitted until
//! acknowledged). On each robot the [`OperatorActor`] takes the commands addressed to
//! it, newest first ([`BaseCommand::id`] only grows, so a retransmitted or reordered
//! older command changes nothing), and
//!
//! - `hold`: publishes [`OperatorHold`] `held = true` (the collision actor then commits
//!   the round's stopping trajectory whatever the candidates) and a zero teleop command;
//! - `resume`: publishes `held = false`: planning goes on;
//! - `velocity`: publishes the command on the teleop topic ([`TELEOP_COMMAND`]), which a
//!   `behaviour = "teleop"` robot maps to its closest safe primitive;
//! - `return`: ends the robot's exploring ([`MISSION_RETURN`]: its planner flies it home
//!   along its memory's route and holds there) and releases a hold.
//!
//! It republishes the hold state every second, so a restarted collision actor learns it
//! again. Only the base may send commands: the link accepts frames of its own team
//! only, the session's TLS certificates and user/password (`[zenoh] tls`, `auth`)
//! decide who joins, and a command whose sender is not the base's id (`[robot.link]
//! base_id`, default the team size) is rejected and counted
//! ([`Rejection::NotFromBase`](crate::link::Rejection::NotFromBase)).

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::link::{Peer, ShareClass, ShareFrom, SharePolicy, ShareTo, SharedTopic};
use crate::planner::{MISSION_RETURN, ReturnCommand, TELEOP_COMMAND};
use troupe_algorithms::planner::teleop::TeleopCommand;
use troupe_comms::shaping::QueuePolicy as ShaperPolicy;
use troupe_runtime::{
    Actor, ActorResult, Context, Event, Message, QueuePolicy, RobotId, Time, TimerId, Topic,
};

/// What the operator asks of a robot.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum OperatorCommand {
    /// Stop and hold position until `Resume`.
    Hold,
    /// Go on planning.
    Resume,
    /// End exploring: fly home and hold there (a held robot is released).
    Return,
    /// A teleoperation command in the body frame (thesis §5.1.2: a = (v_x, v_z, ω)).
    Velocity {
        /// Forward speed, m/s.
        vx_mps: f64,
        /// Vertical speed, m/s.
        vz_mps: f64,
        /// Yaw rate, rad/s.
        yaw_rate_rad_s: f64,
    },
}

/// Why a line is not an operator command.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CommandParseError {
    /// The target is neither `robot<N>` nor `all`.
    #[error("`{0}` is not a robot: write robot<N> (e.g. robot1) or all")]
    Target(String),
    /// The verb is unknown or its arguments are wrong.
    #[error(
        "`{0}` is not a command: write hold, resume, return or velocity VX_MPS VZ_MPS \
         YAW_RATE_RAD_S (finite numbers)"
    )]
    Command(String),
}

/// A command from the base: to whom, which, and its id.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaseCommand {
    /// The robot it is for; `None`: every robot.
    pub robot: Option<u32>,
    /// Grows with every command the base sends (it starts from the wall clock in
    /// microseconds, so a restarted base keeps growing): a robot applies a command
    /// only when its id is above the last one applied.
    pub id: u64,
    /// The command.
    pub command: OperatorCommand,
}
impl Message for BaseCommand {}

impl BaseCommand {
    /// Parses an operator's line, `robot1 hold`, `all hold`, `robot0 resume`, `all return`,
    /// `robot2 velocity 0.5 0 0.1` (`vel` for short); `Ok(None)` for a blank line.
    pub fn parse(line: &str, id: u64) -> Result<Option<Self>, CommandParseError> {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some((&target, rest)) = words.split_first() else {
            return Ok(None);
        };
        let robot = match target {
            "all" => None,
            t => Some(
                t.strip_prefix("robot")
                    .and_then(|n| n.parse::<u32>().ok())
                    .ok_or_else(|| CommandParseError::Target(t.to_owned()))?,
            ),
        };
        let bad = || CommandParseError::Command(rest.join(" "));
        let command = match rest {
            ["hold" | "stop"] => OperatorCommand::Hold,
            ["resume"] => OperatorCommand::Resume,
            ["return" | "home"] => OperatorCommand::Return,
            ["velocity" | "vel", vx, vz, w] => {
                let number = |s: &str| s.parse::<f64>().ok().filter(|v| v.is_finite());
                OperatorCommand::Velocity {
                    vx_mps: number(vx).ok_or_else(bad)?,
                    vz_mps: number(vz).ok_or_else(bad)?,
                    yaw_rate_rad_s: number(w).ok_or_else(bad)?,
                }
            }
            _ => return Err(bad()),
        };
        Ok(Some(BaseCommand { robot, id, command }))
    }

    /// Whether it is addressed to `robot`.
    #[must_use]
    pub fn is_for(&self, robot: RobotId) -> bool {
        self.robot.is_none_or(|r| r == robot.0)
    }
}

/// The shared topic of base commands: store-and-forward at the highest priority, to
/// every peer (each robot keeps the ones addressed to it), accepted from the base
/// station's id only (a command from any other id is rejected and counted as
/// `not_from_base` in the link's rejections).
pub const BASE_COMMAND: SharedTopic<BaseCommand> = SharedTopic::new(
    "base/command",
    1,
    SharePolicy {
        class: ShareClass::Odometry,
        policy: ShaperPolicy::StoreAndForward,
        to: ShareTo::Peers,
        from: ShareFrom::Base,
    },
);

/// Whether the operator holds this robot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OperatorHold {
    /// `true` from a `hold` until a `resume`.
    pub held: bool,
}
impl Message for OperatorHold {}

/// The operator's hold state (the collision actor reads it).
pub const OPERATOR_HOLD: Topic<OperatorHold> = Topic::new("operator/hold");

const REPUBLISH: TimerId = TimerId(0);

/// Applies the base's commands addressed to this robot: `hold` and `resume` on
/// [`OPERATOR_HOLD`] (republished every second while held), `velocity` on
/// [`TELEOP_COMMAND`]; only commands with an id above the last one applied.
#[derive(Debug, Default)]
pub struct OperatorActor {
    last_id: Option<u64>,
    held: bool,
}

impl OperatorActor {
    /// An operator actor, not holding.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    fn apply(&mut self, peer: &Peer<BaseCommand>, ctx: &mut Context<'_>) {
        let c = &peer.message;
        if !c.is_for(ctx.robot()) || self.last_id.is_some_and(|last| c.id <= last) {
            return;
        }
        self.last_id = Some(c.id);
        tracing::info!(robot = ctx.robot_name(), from = peer.robot.0, id = c.id, command = ?c.command, "operator command");
        let stop = |now: Time| TeleopCommand {
            stamp: now,
            vx_mps: 0.0,
            vz_mps: 0.0,
            yaw_rate_rad_s: 0.0,
        };
        let now = ctx.now();
        match c.command {
            OperatorCommand::Hold => {
                self.held = true;
                ctx.publish(&TELEOP_COMMAND, stop(now));
            }
            OperatorCommand::Resume => self.held = false,
            OperatorCommand::Return => {
                self.held = false;
                ctx.publish(&MISSION_RETURN, ReturnCommand);
            }
            OperatorCommand::Velocity {
                vx_mps,
                vz_mps,
                yaw_rate_rad_s,
            } => ctx.publish(
                &TELEOP_COMMAND,
                TeleopCommand {
                    vx_mps,
                    vz_mps,
                    yaw_rate_rad_s,
                    ..stop(now)
                },
            ),
        }
        ctx.publish(&OPERATOR_HOLD, OperatorHold { held: self.held });
    }
}

impl Actor for OperatorActor {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        BASE_COMMAND.share(ctx);
        ctx.subscribe(&BASE_COMMAND.peer_topic(), QueuePolicy::fifo(64));
        ctx.set_timer(REPUBLISH, Duration::from_secs(1));
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(m) => {
                if let Some(peer) = m.get(&BASE_COMMAND.peer_topic()) {
                    self.apply(peer, ctx);
                }
            }
            Event::Timer(REPUBLISH) if self.held => {
                ctx.publish(&OPERATOR_HOLD, OperatorHold { held: true });
            }
            _ => {}
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    use super::*;
    use troupe_runtime::{ActorSpec, Publication, RobotSpec, SimExecutor};

    /// Delivers the commands as robot 0's link would, one every 0.5 s.
    struct Deliver(Vec<BaseCommand>);

    impl Actor for Deliver {
        fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
            ctx.set_timer(TimerId(0), Duration::from_millis(500));
            Ok(())
        }
        fn handle(&mut self, _event: &Event, ctx: &mut Context<'_>) -> ActorResult {
            if !self.0.is_empty() {
                let message = self.0.remove(0);
                let now = ctx.now();
                ctx.publish(
                    &BASE_COMMAND.peer_topic(),
                    Peer {
                        robot: RobotId(2),
                        sent_at: now,
                        received_at: now,
                        message,
                    },
                );
            }
            Ok(())
        }
    }

    #[test]
    fn applies_the_newest_commands_addressed_to_it() {
        let c = |robot, id, command| BaseCommand { robot, id, command };
        let velocity = OperatorCommand::Velocity {
            vx_mps: 0.5,
            vz_mps: 0.0,
            yaw_rate_rad_s: 0.1,
        };
        let commands = vec![
            c(Some(1), 10, OperatorCommand::Hold),   // another robot's
            c(Some(0), 11, OperatorCommand::Hold),   // held
            c(None, 9, OperatorCommand::Resume),     // older: ignored
            c(Some(0), 12, velocity),                // teleop, still held
            c(None, 13, OperatorCommand::Resume),    // resumed
            c(Some(0), 14, OperatorCommand::Return), // home
        ];
        let robot = RobotSpec::new("r0")
            .with(ActorSpec::new("deliver", move || Deliver(commands.clone())))
            .with(ActorSpec::new("operator", OperatorActor::new));
        let log: Arc<Mutex<Vec<(f64, String)>>> = Arc::default();
        let tap = log.clone();
        let mut exec = SimExecutor::new(vec![robot], 1);
        exec.add_tap(move |p: &Publication<'_>| {
            let t = p.time.as_secs_f64();
            if let Some(h) = p.get(&OPERATOR_HOLD) {
                tap.lock().unwrap().push((t, format!("held={}", h.held)));
            } else if let Some(c) = p.get(&TELEOP_COMMAND) {
                tap.lock()
                    .unwrap()
                    .push((t, format!("teleop vx={}", c.vx_mps)));
            } else if p.get(&MISSION_RETURN).is_some() {
                tap.lock().unwrap().push((t, "return".into()));
            }
        });
        exec.run_until(Time::from_secs_f64(4.2));
        let _ = exec.finish();
        let log = log.lock().unwrap();
        let at = |e: &str| -> Vec<f64> {
            log.iter()
                .filter(|(_, x)| x == e)
                .map(|(t, _)| *t)
                .collect()
        };
        // Robot 0's hold and the teleop stop at 1.0 s, robot 1's at 0.5 s ignored.
        assert_eq!(at("teleop vx=0"), [1.0], "{log:?}");
        assert_eq!(at("teleop vx=0.5"), [2.0], "{log:?}");
        // Held from 1.0 s (republished each second, the older resume ignored) until
        // the resume at 2.5 s; nothing after.
        let held = at("held=true");
        assert_eq!(held.first(), Some(&1.0), "{log:?}");
        assert!(
            held.contains(&2.0) && held.iter().all(|&t| t < 2.5),
            "{log:?}"
        );
        assert_eq!(at("held=false"), [2.5, 3.0], "{log:?}");
        // The command home at 3.0 s goes to the planner.
        assert_eq!(at("return"), [3.0], "{log:?}");
        assert!(log.iter().all(|(t, _)| *t <= 3.0), "{log:?}");
    }

    #[test]
    fn parses_operator_lines() {
        let c = BaseCommand::parse("robot1 hold", 7).unwrap().unwrap();
        assert_eq!(
            c,
            BaseCommand {
                robot: Some(1),
                id: 7,
                command: OperatorCommand::Hold
            }
        );
        assert!(c.is_for(RobotId(1)) && !c.is_for(RobotId(0)));
        let c = BaseCommand::parse("  all   resume ", 8).unwrap().unwrap();
        assert_eq!((c.robot, c.command), (None, OperatorCommand::Resume));
        assert!(c.is_for(RobotId(0)) && c.is_for(RobotId(5)));
        let c = BaseCommand::parse("robot0 vel 0.5 -0.1 0.2", 9)
            .unwrap()
            .unwrap();
        assert_eq!(
            c.command,
            OperatorCommand::Velocity {
                vx_mps: 0.5,
                vz_mps: -0.1,
                yaw_rate_rad_s: 0.2
            }
        );
        let c = BaseCommand::parse("all return", 10).unwrap().unwrap();
        assert_eq!((c.robot, c.command), (None, OperatorCommand::Return));
        assert_eq!(BaseCommand::parse("   ", 1), Ok(None));
        for (line, error) in [
            ("robotX hold", "`robotX` is not a robot"),
            ("drone1 hold", "`drone1` is not a robot"),
            ("robot1 jump", "`jump` is not a command"),
            ("robot1", "`` is not a command"),
            ("robot1 hold now", "`hold now` is not a command"),
            (
                "robot1 velocity 1 NaN 0",
                "`velocity 1 NaN 0` is not a command",
            ),
            ("robot1 velocity 1 0", "`velocity 1 0` is not a command"),
        ] {
            let e = BaseCommand::parse(line, 1).unwrap_err();
            assert!(e.to_string().starts_with(error), "{line}: {e}");
        }
    }
}
