//! The base's own actors beside its link: the operator's commands from standard
//! input ([`read_commands`] → `Commander` → [`BASE_COMMAND`]) and the count of what
//! the link rejects.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use troupe_actors::collision::{BASE_COMMAND, BaseCommand};
use troupe_actors::planner::MISSION_STATUS;
use troupe_core::ErrorChain;
use troupe_runtime::{Actor, ActorResult, Context, Event, TimerId};

use super::lock;

/// The base's link: what its handler rejects (each a bad frame or message from the
/// network) is counted and logged at the 1st, 2nd, 4th, … rejection instead of once
/// per frame, so a flood of hostile bytes cannot flood the log.
pub(super) struct CountRejections {
    pub(super) inner: Box<dyn Actor>,
    pub(super) rejected: Arc<AtomicU64>,
}

impl Actor for CountRejections {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        self.inner.start(ctx)
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if let Err(e) = self.inner.handle(event, ctx) {
            let n = self.rejected.fetch_add(1, Ordering::Relaxed) + 1;
            if n.is_power_of_two() {
                tracing::warn!("base link: {n} rejected so far; latest: {}", ErrorChain(&e));
            }
        }
        Ok(())
    }

    fn stop(&mut self, ctx: &mut Context<'_>) {
        self.inner.stop(ctx);
    }
}

/// The operator's end of the link: shares [`BASE_COMMAND`] with the team and publishes
/// the operator's commands on it as they arrive from the standard-input reader
/// ([`read_commands`]), and shares the robots' [`MISSION_STATUS`] so that the link
/// delivers it to the base (the status lines show each robot's phase).
pub(super) struct Commander {
    pub(super) commands: Arc<Mutex<std::sync::mpsc::Receiver<BaseCommand>>>,
}

const POLL_COMMANDS: TimerId = TimerId(0);

impl Actor for Commander {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        BASE_COMMAND.share(ctx);
        MISSION_STATUS.share(ctx);
        ctx.set_timer(POLL_COMMANDS, Duration::from_millis(50));
        Ok(())
    }

    fn handle(&mut self, _event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let commands: Vec<BaseCommand> = lock(&self.commands).try_iter().collect();
        for command in commands {
            ctx.publish(&BASE_COMMAND.topic(), command);
        }
        Ok(())
    }
}

/// Reads operator lines from `input` until it ends, answering each on `out`
/// (`command robot1 hold: sent (id …)`, or why the line is not a command) and
/// sending the commands to `to`. Ids start at the wall clock in microseconds and grow
/// by at least one per command, so a restarted base's commands are newer.
pub fn read_commands(
    input: impl std::io::BufRead,
    mut out: impl std::io::Write,
    to: &std::sync::mpsc::Sender<BaseCommand>,
) {
    let mut last_id = 0u64;
    for line in input.lines() {
        let Ok(line) = line else { return };
        let now_us = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX));
        let id = now_us.max(last_id + 1);
        let answer = match BaseCommand::parse(&line, id) {
            Ok(None) => continue,
            Ok(Some(command)) => {
                last_id = id;
                if to.send(command).is_err() {
                    return;
                }
                format!("command {}: sent (id {id})", line.trim())
            }
            Err(e) => format!("command {}: not sent: {e}", line.trim()),
        };
        let _ = writeln!(out, "{answer}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_actors::collision::OperatorCommand;

    #[test]
    fn reads_operator_lines_into_commands_with_growing_ids() {
        let input = "robot1 hold\n\nrobot1 fly\nall resume\nrobot0 vel 0.5 0 0.1\n";
        let (to, from) = std::sync::mpsc::channel();
        let mut out = Vec::new();
        read_commands(input.as_bytes(), &mut out, &to);
        let sent: Vec<BaseCommand> = from.try_iter().collect();
        let targets: Vec<_> = sent.iter().map(|c| (c.robot, c.command)).collect();
        assert_eq!(
            targets,
            [
                (Some(1), OperatorCommand::Hold),
                (None, OperatorCommand::Resume),
                (
                    Some(0),
                    OperatorCommand::Velocity {
                        vx_mps: 0.5,
                        vz_mps: 0.0,
                        yaw_rate_rad_s: 0.1
                    }
                ),
            ]
        );
        assert!(sent.windows(2).all(|w| w[0].id < w[1].id));
        let out = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(lines.len(), 4, "{out}");
        assert!(lines[0].starts_with("command robot1 hold: sent (id "));
        assert!(
            lines[1].starts_with("command robot1 fly: not sent: `fly` is not a command"),
            "{out}"
        );
    }
}
