//! Priority-based inter-robot avoidance (thesis §8.2.3, after \[24\]).
//!
//! Every robot has a priority, fixed before the run (optionally raised while it is
//! blocked, [`PriorityConfig::boost_after_s`]). A robot checks its candidate plans only
//! against peers of higher priority (ties: the lower robot id wins); those ignore it.
//! The three cost savings of §8.2.3 are kept:
//!
//! 1. only peers within [`PriorityConfig::check_radius_m`] (from their odometry, shared
//!    at 10 Hz, against plans at 1 Hz) are checked;
//! 2. both robots are vertical cylinders (radius, height) sampled along both
//!    trajectories at common times, at most [`PriorityConfig::max_samples`] per pair;
//! 3. only the candidate primitive and its stopping primitive are checked (the
//!    candidate trajectory carries both), held at its end until the peer's plan ends.
//!
//! Sampling is made continuous-time safe: between two samples `Δt` apart each robot
//! moves at most `v_max Δt / 2` from the nearer sample, so a pair whose sampled centres
//! stay `2r + (v₁ + v₂) Δt / 2` apart horizontally never overlaps (the thesis picks a
//! conservative radius for the same reason).
//!
//! A peer whose plan is older than [`PriorityConfig::stale_plan_s`] (counted from when
//! it was made, not when it arrived), or that never sent one, is an obstacle at its last
//! known position inflated by its stopping envelope: at each moment `t` of the check
//! (up to [`PriorityConfig::stale_growth_s`] ahead, when the next round decides again),
//! the distance it may have flown from then to `t` plus its braking distance
//! `v² / (2 a)` from the speed `v` it may have reached, speeding up from its speed then
//! at [`PriorityConfig::peer_accel_mps2`] to [`PriorityConfig::peer_max_speed_mps`], or
//! to the fastest its last plan flies if that is faster. The
//! envelope grows over the candidate: a peer whose plans do not arrive keeps flying the
//! ones it committed, and brakes only once ours reach it (with an envelope fixed at the
//! moment of the check, a robot over a saturated 250 kbit/s link flew into the end of
//! a lower-priority peer's committed plan and came within 0.52 m of it). A candidate
//! may still take the robot away from where such a peer was last seen, never closer,
//! even as the envelope grows over it: hovering would be no safer. Ages count on this
//! robot's clock
//! from the earlier of a message's stamp and its arrival (stamps are on the team clock,
//! `troupe_core::TeamClock`, and the link rejects those more than `max_clock_ahead_s`
//! ahead); a restarted peer's new run replaces what its earlier run said (`PeerTable`).
//!
//! Deviation from the thesis (on by default, [`PriorityConfig::clear_of_lower_priority`]):
//! a robot also keeps its candidates clear of nearby peers of *lower* priority, modelled
//! as following their committed plan and braking to a stop at any moment until they
//! must have reacted to ours ([`PriorityConfig::lower_priority_react_s`]: their
//! replanning period plus the link's delay; [`PeerModel::Yielding`]); without a fresh plan, their
//! stopping envelope. In §8.2.3 a higher-priority robot ignores them, which is safe only
//! while they can always move out of its way in time; in the safety study a robot with
//! nothing safe to do hovered and was flown into (0.22 m between centres), and two
//! robots that committed within one round met head on.

use serde::{Deserialize, Serialize};
pub use troupe_algorithms::collision::peers::must_yield;
use troupe_algorithms::collision::peers::{PeerAvoidance, PeerConflict, PeerTable, PeerTrack};
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::trajectory::Trajectory;
use troupe_core::{ConfigError, RobotId, Time};

/// Settings of the priority check (thesis §8.2.3).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PriorityConfig {
    /// Fixed priority; larger values are avoided by smaller ones.
    pub priority: u16,
    /// Dynamic rule: after this many seconds of consecutive rounds stopped by peers,
    /// the priority rises by `boost_step` per further such period (0 disables: fixed
    /// priorities, as in the thesis). Peers learn the raised value with the next plan.
    pub boost_after_s: f64,
    /// Priority added per blocked period.
    pub boost_step: u16,
    /// Radius of the cylinder model of every robot, metres (default 0.4: the 0.3 m body
    /// plus 0.1 m for tracking error).
    pub cylinder_radius_m: f64,
    /// Height of the cylinder model, metres (centred on the body; default 0.8: the
    /// 0.6 m body plus 0.1 m above and below, the same tracking margin as the radius —
    /// with the body's own height, robots passing over each other in 8-robot cave runs
    /// came within 0.57 m of each other).
    pub cylinder_height_m: f64,
    /// Peers farther than this (centre to centre) are not checked, metres.
    pub check_radius_m: f64,
    /// Largest number of sample times per pair (≥ 2).
    pub max_samples: usize,
    /// A peer plan made longer ago than this is stale, seconds (default 1.5: plans are
    /// shared once a second, and a plan older than a period and half a second of
    /// delay may have been replaced by one not yet received — at 2.5 s, two robots
    /// over a saturated 250 kbit/s link each trusted a 2 s old plan in which the other
    /// hovered, and flew within 0.14 m of each other).
    pub stale_plan_s: f64,
    /// Braking deceleration assumed for a peer's stopping envelope, m/s².
    pub stop_decel_mps2: f64,
    /// Largest acceleration assumed for a peer since it was last heard of, m/s² (default
    /// 3.0: the planner's `max_accel_mps2`). A peer seen hovering a tenth of a second ago
    /// cannot be flying at its plans' top speed yet (counted so, its envelope was 1.3 m
    /// at 1.5 m/s).
    pub peer_accel_mps2: f64,
    /// How far ahead of the check a stale peer's envelope grows, seconds (default 1.2: a
    /// planning period plus the link's delay, as `lower_priority_react_s`). By then this
    /// robot's next round decides again with newer word of the peer, or stops; grown
    /// over a whole candidate (a route robot's is its route), the envelope of a peer
    /// hovering 4 m beside a robot's line kept it from flying past.
    pub stale_growth_s: f64,
    /// Fastest a peer is assumed to fly once its plans stop arriving, m/s (default 1.5:
    /// the planner's `max_speed_mps`); a faster last plan or odometry counts as it is.
    /// A peer whose last plan hovered may have committed a flight since (counted at
    /// that plan's top speed, its envelope stayed at its last position).
    pub peer_max_speed_mps: f64,
    /// Keep clear of lower-priority peers too (module docs; the thesis ignores them).
    pub clear_of_lower_priority: bool,
    /// How long a lower-priority peer may keep to its plan before it has seen ours and
    /// can brake, seconds (its replanning period plus the link's delay).
    pub lower_priority_react_s: f64,
}

impl Default for PriorityConfig {
    fn default() -> Self {
        PriorityConfig {
            priority: 0,
            boost_after_s: 0.0,
            boost_step: 1,
            cylinder_radius_m: 0.4,
            cylinder_height_m: 0.8,
            check_radius_m: 12.0,
            max_samples: 60,
            stale_plan_s: 1.5,
            stop_decel_mps2: 1.0,
            peer_accel_mps2: 3.0,
            peer_max_speed_mps: 1.5,
            stale_growth_s: 1.2,
            clear_of_lower_priority: true,
            lower_priority_react_s: 1.2,
        }
    }
}

impl PriorityConfig {
    /// Checks every number; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (key, value) in [
            ("cylinder_radius_m", self.cylinder_radius_m),
            ("cylinder_height_m", self.cylinder_height_m),
            ("check_radius_m", self.check_radius_m),
            ("stale_plan_s", self.stale_plan_s),
            ("stop_decel_mps2", self.stop_decel_mps2),
            ("peer_accel_mps2", self.peer_accel_mps2),
            ("peer_max_speed_mps", self.peer_max_speed_mps),
            ("stale_growth_s", self.stale_growth_s),
            ("lower_priority_react_s", self.lower_priority_react_s),
        ] {
            ConfigError::positive(key, value)?;
        }
        ConfigError::non_negative("boost_after_s", self.boost_after_s)?;
        if self.max_samples < 2 {
            return Err(ConfigError::new(
                "max_samples",
                "must be ≥ 2",
                self.max_samples,
            ));
        }
        Ok(())
    }
}

/// The dynamic rule: `base` raised by `step` per full `after_s` of being blocked
/// (`blocked_s`), saturating; `after_s = 0` keeps it fixed.
#[must_use]
pub fn effective_priority(base: u16, after_s: f64, step: u16, blocked_s: f64) -> u16 {
    if after_s <= 0.0 || blocked_s < after_s {
        return base;
    }
    let periods = (blocked_s / after_s).floor().min(f64::from(u16::MAX)) as u16;
    base.saturating_add(periods.saturating_mul(step))
}

/// Where a peer is taken to be, for the check.
#[derive(Clone, Debug, PartialEq)]
pub enum PeerModel<'a> {
    /// Following its (fresh) plan in time.
    Plan(&'a Trajectory),
    /// Centred on its last known position, inflated by a stopping envelope that grows
    /// with time (stale or missing plan; [`StoppingEnvelope::radius_m_at`]).
    Envelope(StoppingEnvelope),
    /// A lower-priority peer: following its plan until it brakes along its velocity at
    /// `decel_mps2` to a stop, and holds there; it may brake at any moment up to
    /// `react_at` ([`PeerModel::possible_positions`]).
    Yielding {
        /// Its fresh plan.
        plan: &'a Trajectory,
        /// When it has seen our plan and may brake.
        react_at: Time,
        /// Braking deceleration, m/s².
        decel_mps2: f64,
    },
}

/// Where a peer known only by its last position may be (module docs): anywhere within
/// [`StoppingEnvelope::radius_m_at`] of `position_m`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StoppingEnvelope {
    /// Last known position, metres.
    pub position_m: nalgebra::Point3<f64>,
    /// When it was there.
    pub known_at: Time,
    /// Its speed then, m/s.
    pub speed_mps: f64,
    /// The fastest it may fly (the most of [`PriorityConfig::peer_max_speed_mps`], its
    /// last plan's top speed and `speed_mps`), m/s.
    pub top_speed_mps: f64,
    /// Largest acceleration assumed, m/s² ([`PriorityConfig::peer_accel_mps2`]).
    pub accel_mps2: f64,
    /// Braking deceleration assumed, m/s² ([`PriorityConfig::stop_decel_mps2`]).
    pub decel_mps2: f64,
}

impl StoppingEnvelope {
    /// The envelope's radius at `t`: the distance the peer may have flown from
    /// `known_at` to `t`, speeding up to its top speed, plus its braking distance from
    /// the speed it may have reached, metres.
    #[must_use]
    pub fn radius_m_at(&self, t: Time) -> f64 {
        let age_s = t.saturating_since(self.known_at).as_secs_f64();
        let (flown_m, speed_mps) =
            reach(self.speed_mps, self.top_speed_mps, self.accel_mps2, age_s);
        flown_m + speed_mps * speed_mps / (2.0 * self.decel_mps2)
    }
}

/// Where a robot following `plan` until `from` and braking from there along its
/// velocity at `decel_mps2` to a stop (then holding) is at `t ≥ from`.
fn braking_from(
    plan: &Trajectory,
    from: Time,
    t: Time,
    decel_mps2: f64,
) -> Option<nalgebra::Point3<f64>> {
    let s = plan.state_at(from)?;
    let speed = s.velocity_mps.norm();
    let tau = t
        .saturating_since(from)
        .as_secs_f64()
        .min(speed / decel_mps2);
    let travelled = speed * tau - 0.5 * decel_mps2 * tau * tau;
    Some(
        s.velocity_mps
            .try_normalize(1e-12)
            .map_or(s.position_m, |dir| s.position_m + dir * travelled.max(0.0)),
    )
}

/// Step between the moments a yielding peer is assumed able to start braking, seconds.
const REACTION_STEP_S: f64 = 0.1;

impl PeerModel<'_> {
    /// Where the peer is taken to be at `t` (`None` for an empty plan); a yielding peer
    /// at its latest, braking only from `react_at`.
    #[must_use]
    pub fn position_at(&self, t: Time) -> Option<nalgebra::Point3<f64>> {
        match self {
            PeerModel::Plan(plan) => plan.state_at(t).map(|s| s.position_m),
            PeerModel::Envelope(envelope) => Some(envelope.position_m),
            PeerModel::Yielding {
                plan,
                react_at,
                decel_mps2,
            } => {
                if t <= *react_at {
                    return plan.state_at(t).map(|s| s.position_m);
                }
                braking_from(plan, *react_at, t, *decel_mps2)
            }
        }
    }

    /// Everywhere the peer may be at `t` when the check is made at `now`: a yielding
    /// peer may see our plan and brake at any moment from `now` to `react_at` (its next
    /// planning round comes whenever it comes), so it may be at the braking stop from
    /// any point of its plan in between — a peer that stopped early stays in the way
    /// it was about to leave (in an 8-robot cave run, a robot flew into a lower-priority
    /// peer that was expected to move on and stopped instead). Sampled every
    /// 0.1 s; the other models give their one position.
    #[must_use]
    pub fn possible_positions(&self, now: Time, t: Time) -> Vec<nalgebra::Point3<f64>> {
        let PeerModel::Yielding {
            plan,
            react_at,
            decel_mps2,
        } = self
        else {
            return self.position_at(t).into_iter().collect();
        };
        let last = t.min(*react_at);
        let span_s = last.saturating_since(now).as_secs_f64();
        let steps = (span_s / REACTION_STEP_S).ceil() as usize;
        (0..=steps)
            .filter_map(|k| {
                let from = if k == steps {
                    last
                } else {
                    now + std::time::Duration::from_secs_f64(REACTION_STEP_S * k as f64)
                };
                braking_from(plan, from, t, *decel_mps2)
            })
            .collect()
    }
}

/// How the check models a peer at `now` (plan if fresh, else stopping envelope from the
/// newest of its odometry and its plan); `None` when nothing is known of its position.
#[must_use]
pub fn peer_model<'a>(
    config: &PriorityConfig,
    now: Time,
    track: &'a PeerTrack,
) -> Option<PeerModel<'a>> {
    // Ages count from the earlier of the stamp and the arrival: a plan that arrives
    // late describes the peer as it was when it was made (a link that held it 3 s
    // made a crossing peer look as if it hovered at the end of a finished plan:
    // robots 0.7 m apart over a saturated 250 kbit/s link), and a sender's clock a
    // little ahead of ours (the link rejects more than `max_clock_ahead_s`) must not
    // make an old position look fresh.
    let known_at = |stamp: Time, received_at: Time| stamp.min(received_at);
    if let Some(plan) = &track.plan
        && now
            .saturating_since(known_at(plan.plan.stamp, plan.received_at))
            .as_secs_f64()
            <= config.stale_plan_s
    {
        return Some(PeerModel::Plan(&plan.plan.trajectory));
    }
    let from_odometry = track.odometry.as_ref().map(|o| {
        (
            known_at(o.odometry.stamp, o.received_at),
            nalgebra::Point3::from(o.odometry.pose.translation.vector),
            o.odometry.velocity_mps.norm(),
        )
    });
    let from_plan = track.plan.as_ref().and_then(|p| {
        let at = known_at(p.plan.stamp, p.received_at);
        let state = p.plan.trajectory.state_at(at)?;
        Some((at, state.position_m, state.velocity_mps.norm()))
    });
    let (stamp, position_m, speed) = match (from_odometry, from_plan) {
        (Some(a), Some(b)) => {
            if a.0 >= b.0 {
                a
            } else {
                b
            }
        }
        (Some(a), None) | (None, Some(a)) => a,
        (None, None) => return None,
    };
    // Since then it may have sped up to the team's speed bound, or as fast as its last
    // plan said it would fly if that is faster.
    let top_speed = track
        .plan
        .as_ref()
        .map_or(speed, |p| speed.max(max_speed(&p.plan.trajectory)))
        .max(config.peer_max_speed_mps);
    Some(PeerModel::Envelope(StoppingEnvelope {
        position_m,
        known_at: stamp,
        speed_mps: speed,
        top_speed_mps: top_speed,
        accel_mps2: config.peer_accel_mps2,
        decel_mps2: config.stop_decel_mps2,
    }))
}

/// How far a body flying at `speed_mps` may get in `age_s` when it accelerates at
/// most `accel_mps2` up to `top_speed_mps` (at least its speed), and how fast it may
/// fly then: `(distance_m, speed_mps)`.
fn reach(speed_mps: f64, top_speed_mps: f64, accel_mps2: f64, age_s: f64) -> (f64, f64) {
    let top_speed_mps = top_speed_mps.max(speed_mps);
    let speeding_up_s = ((top_speed_mps - speed_mps) / accel_mps2).min(age_s);
    let distance_m = speed_mps * speeding_up_s
        + 0.5 * accel_mps2 * speeding_up_s * speeding_up_s
        + top_speed_mps * (age_s - speeding_up_s);
    (distance_m, speed_mps + accel_mps2 * speeding_up_s)
}

fn max_speed(trajectory: &Trajectory) -> f64 {
    trajectory
        .knots()
        .windows(2)
        .map(|w| {
            let dt = (w[1].time - w[0].time).as_secs_f64();
            if dt > 0.0 {
                (w[1].position_m - w[0].position_m).norm() / dt
            } else {
                0.0
            }
        })
        .fold(0.0, f64::max)
}

/// Checks `candidate` (from `now`) against one peer model with cylinders of `config`,
/// at most `max_samples` common sample times up to the later of the two trajectories'
/// ends (module docs); returns the first overlap as `(seconds after now, horizontal
/// centre distance)`.
#[must_use]
pub fn first_overlap(
    config: &PriorityConfig,
    now: Time,
    candidate: &Trajectory,
    peer: &PeerModel<'_>,
) -> Option<(f64, f64)> {
    let own_end = candidate.end_time();
    let end = match peer {
        PeerModel::Plan(plan) => own_end.max(plan.end_time()),
        PeerModel::Envelope(_) => own_end,
        PeerModel::Yielding { react_at, .. } => own_end.max(*react_at),
    };
    let horizon_s = end.saturating_since(now).as_secs_f64();
    let n = config.max_samples.max(2);
    let dt_s = horizon_s / (n - 1) as f64;
    let (peer_speed, envelope) = match peer {
        PeerModel::Plan(plan) | PeerModel::Yielding { plan, .. } => (max_speed(plan), None),
        PeerModel::Envelope(envelope) => (0.0, Some(envelope)),
    };
    let sampling_slack_m = 0.5 * dt_s * (max_speed(candidate) + peer_speed);
    let half_step = std::time::Duration::from_secs_f64(0.5 * dt_s);
    let stale_growth = std::time::Duration::from_secs_f64(config.stale_growth_s);
    // Already too close at the start (both committed at once, or a peer appeared): the
    // least horizontal and vertical distances then; a candidate that never gets closer
    // in either lets the pair separate, one that closes in (sideways, or climbing or
    // sinking towards a peer above or below) is refused. A stopping envelope grows over
    // the candidate, so its distances at the start are always kept: a candidate that
    // gets no closer to where the peer was last seen is not refused (module docs).
    let mut too_close_at_start: Option<(f64, f64)> = None;
    for i in 0..n {
        let t_s = dt_s * i as f64;
        let t = now + std::time::Duration::from_secs_f64(t_s);
        let own = candidate.state_at(t)?;
        // The envelope as it is half a step later covers the flight between samples;
        // it grows for `stale_growth_s` at most.
        let grown_until = (t + half_step).min(now + stale_growth);
        let min_horizontal = 2.0 * config.cylinder_radius_m
            + envelope.map_or(0.0, |e| e.radius_m_at(grown_until))
            + sampling_slack_m;
        // The least horizontal and vertical distances to the peer's overlapping
        // positions, and whether one is closer than at the start.
        let mut least: Option<(f64, f64)> = None;
        let mut closer = false;
        for other in peer.possible_positions(now, t) {
            let d = own.position_m - other;
            let (h, v) = (d.xy().norm(), d.z.abs());
            if h >= min_horizontal || v >= config.cylinder_height_m {
                continue;
            }
            least = Some(least.map_or((h, v), |(lh, lv)| (lh.min(h), lv.min(v))));
            closer |= too_close_at_start.is_none_or(|(h0, v0)| h < h0 || v < v0 - 1e-9);
        }
        if i == 0 {
            too_close_at_start = match envelope {
                Some(e) => {
                    let d = own.position_m - e.position_m;
                    Some((d.xy().norm(), d.z.abs()))
                }
                None => least,
            };
            if horizon_s == 0.0 {
                break;
            }
            continue;
        }
        if let Some((least_h, _)) = least
            && closer
        {
            return Some((t_s, least_h));
        }
    }
    None
}

/// The §8.2.3 check of `candidate` against every peer this robot must yield to
/// ([`must_yield`]) that is within the check radius of `own`'s position, and against
/// the stopping envelopes of the other peers within it
/// ([`PriorityConfig::clear_of_lower_priority`]).
#[must_use]
pub fn check_candidate(
    config: &PriorityConfig,
    now: Time,
    me: RobotId,
    mine: u16,
    own: &Odometry,
    candidate: &Trajectory,
    peers: &PeerTable,
) -> Option<PeerConflict> {
    let here = nalgebra::Point3::from(own.pose.translation.vector);
    for (id, track) in peers.iter() {
        if id == me {
            continue;
        }
        let model = if must_yield(me, mine, id, track.priority()) {
            peer_model(config, now, track)
        } else if config.clear_of_lower_priority {
            match peer_model(config, now, track) {
                Some(PeerModel::Plan(plan)) => Some(PeerModel::Yielding {
                    plan,
                    react_at: now
                        + std::time::Duration::from_secs_f64(config.lower_priority_react_s),
                    decel_mps2: config.stop_decel_mps2,
                }),
                other => other,
            }
        } else {
            None
        };
        let Some(model) = model else {
            continue;
        };
        let there = model.position_at(now);
        let near = there.is_some_and(|p| (p - here).norm() <= config.check_radius_m);
        if !near {
            continue;
        }
        if let Some((at_s, separation_m)) = first_overlap(config, now, candidate, &model) {
            return Some(PeerConflict {
                peer: id,
                envelope: matches!(model, PeerModel::Envelope(_)),
                at_s,
                separation_m,
            });
        }
    }
    None
}

/// [`PeerAvoidance`] by priorities (the module's rules), with the optional dynamic rule.
#[derive(Clone, Debug, PartialEq)]
pub struct PriorityAvoidance {
    config: PriorityConfig,
    blocked_since: Option<Time>,
}

impl PriorityAvoidance {
    /// A checker with these settings.
    #[must_use]
    pub fn new(config: PriorityConfig) -> Self {
        PriorityAvoidance {
            config,
            blocked_since: None,
        }
    }
}

impl PeerAvoidance for PriorityAvoidance {
    fn priority(&self, now: Time) -> u16 {
        let blocked_s = self
            .blocked_since
            .map_or(0.0, |t| now.saturating_since(t).as_secs_f64());
        effective_priority(
            self.config.priority,
            self.config.boost_after_s,
            self.config.boost_step,
            blocked_s,
        )
    }

    fn conflict(
        &mut self,
        now: Time,
        me: RobotId,
        own: &Odometry,
        candidate: &Trajectory,
        peers: &PeerTable,
    ) -> Option<PeerConflict> {
        let mine = self.priority(now);
        check_candidate(&self.config, now, me, mine, own, candidate, peers)
    }

    fn record_round(&mut self, now: Time, blocked_by_peers: bool) {
        if blocked_by_peers {
            self.blocked_since.get_or_insert(now);
        } else {
            self.blocked_since = None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Point3, Vector3};
    use troupe_algorithms::plan::Plan;
    use troupe_algorithms::team::{PeerOdometry, PeerPlan};
    use troupe_algorithms::trajectory::Knot;

    fn t(s: f64) -> Time {
        Time::from_secs_f64(s)
    }

    /// Straight line from `a` to `b` starting at `t0`, at `speed` m/s, knots every 0.1 s.
    fn line(t0: f64, a: [f64; 3], b: [f64; 3], speed: f64) -> Trajectory {
        let (a, b) = (Point3::from(a), Point3::from(b));
        let dur = (b - a).norm() / speed;
        let n = (dur / 0.1).ceil().max(1.0) as usize;
        Trajectory::new(
            (0..=n)
                .map(|i| Knot {
                    time: t(t0 + dur * i as f64 / n as f64),
                    position_m: a + (b - a) * (i as f64 / n as f64),
                    yaw_rad: 0.0,
                })
                .collect(),
        )
        .unwrap()
    }

    fn odom(at: f64, p: [f64; 3], v: [f64; 3]) -> Odometry {
        Odometry {
            stamp: t(at),
            pose: Isometry3::translation(p[0], p[1], p[2]),
            velocity_mps: Vector3::from(v),
        }
    }

    fn table_with(
        peer: u32,
        priority: u16,
        plan: Option<(Trajectory, f64)>,
        od: Option<Odometry>,
    ) -> PeerTable {
        let mut table = PeerTable::default();
        if let Some((trajectory, received)) = plan {
            table.update_plan(&PeerPlan {
                robot: RobotId(peer),
                priority,
                plan: Plan::new(t(received), trajectory),
                run_start_ns: 0,
                received_at: t(received),
            });
        }
        if let Some(odometry) = od {
            let received_at = odometry.stamp;
            table.update_odometry(&PeerOdometry {
                robot: RobotId(peer),
                odometry,
                run_start_ns: 0,
                received_at,
            });
        }
        table
    }

    /// Slow reference: smallest horizontal distance over a 1 ms grid.
    fn dense_min_distance(a: &Trajectory, b: &Trajectory, t0: f64, t1: f64) -> f64 {
        let mut best = f64::INFINITY;
        let n = ((t1 - t0) / 0.001).ceil() as usize;
        for i in 0..=n {
            let tt = t(t0 + (t1 - t0) * i as f64 / n as f64);
            let (p, q) = (
                a.state_at(tt).unwrap().position_m,
                b.state_at(tt).unwrap().position_m,
            );
            best = best.min((p - q).xy().norm());
        }
        best
    }

    #[test]
    fn priorities_and_ties() {
        assert!(must_yield(RobotId(1), 1, RobotId(0), Some(2)));
        assert!(!must_yield(RobotId(1), 3, RobotId(0), Some(2)));
        assert!(must_yield(RobotId(1), 2, RobotId(0), Some(2)));
        assert!(!must_yield(RobotId(0), 2, RobotId(1), Some(2)));
        assert!(must_yield(RobotId(0), 9, RobotId(1), None));
        assert_eq!(effective_priority(3, 0.0, 1, 100.0), 3);
        assert_eq!(effective_priority(3, 5.0, 2, 4.9), 3);
        assert_eq!(effective_priority(3, 5.0, 2, 10.0), 7);
        assert_eq!(effective_priority(u16::MAX - 1, 1.0, 5, 10.0), u16::MAX);
    }

    #[test]
    fn crossing_lines_conflict_and_passing_in_time_does_not() {
        let config = PriorityConfig::default();
        // Peer (higher) crosses the origin along x at t = 5 s; we cross along y.
        let peer = line(0.0, [-5.0, 0.0, 1.0], [5.0, 0.0, 1.0], 1.0);
        let peers = table_with(0, 5, Some((peer.clone(), 0.0)), None);
        let own = odom(0.0, [0.0, -5.0, 1.0], [0.0, 1.0, 0.0]);
        let mine = line(0.0, [0.0, -5.0, 1.0], [0.0, 5.0, 1.0], 1.0);
        let c = check_candidate(&config, t(0.0), RobotId(1), 1, &own, &mine, &peers).unwrap();
        assert_eq!(c.peer, RobotId(0));
        assert!(!c.envelope);
        assert!((c.at_s - 5.0).abs() < 1.5, "{c:?}");
        // Ours is faster: passes the origin at t = 2.5 s, 2.5 m ahead of the peer.
        let fast = line(0.0, [0.0, -5.0, 1.0], [0.0, 5.0, 1.0], 2.0);
        assert_eq!(
            check_candidate(&config, t(0.0), RobotId(1), 1, &own, &fast, &peers),
            None
        );
        // With the higher priority we do not check at all.
        assert_eq!(
            check_candidate(&config, t(0.0), RobotId(1), 9, &own, &mine, &peers),
            None
        );
        // Different altitude: cylinders do not overlap.
        let high = line(0.0, [0.0, -5.0, 2.0], [0.0, 5.0, 2.0], 1.0);
        assert_eq!(
            check_candidate(&config, t(0.0), RobotId(1), 1, &own, &high, &peers),
            None
        );
        // Out of the check radius: not checked.
        let far = PriorityConfig {
            check_radius_m: 3.0,
            ..config
        };
        assert_eq!(
            check_candidate(&far, t(0.0), RobotId(1), 1, &own, &mine, &peers),
            None
        );
    }

    #[test]
    fn holding_at_the_end_in_the_peers_path_conflicts() {
        let config = PriorityConfig::default();
        let peer = line(0.0, [-8.0, 0.0, 1.0], [8.0, 0.0, 1.0], 1.0);
        let peers = table_with(0, 5, Some((peer, 0.0)), None);
        // We stop on the peer's path at t = 2 s; it arrives there at t = 8 s.
        let mine = line(0.0, [0.0, -2.0, 1.0], [0.0, 0.0, 1.0], 1.0);
        let own = odom(0.0, [0.0, -2.0, 1.0], [0.0, 1.0, 0.0]);
        let c = check_candidate(&config, t(0.0), RobotId(1), 1, &own, &mine, &peers).unwrap();
        assert!(c.at_s > 6.0, "{c:?}");
    }

    #[test]
    fn a_lower_priority_peer_is_expected_to_keep_its_plan_until_it_can_react() {
        let config = PriorityConfig::default();
        // Peer 1 (priority 0) flies +x at 1 m/s from (-4, 0); robot 0 (priority 5)
        // would cross its path at x = -2.5 in 1.5 s: the peer brakes from 1.2 s on
        // (reaching -2.8 + 0.5 m), so the crossing conflicts.
        let peer = line(10.0, [-4.0, 0.0, 1.0], [4.0, 0.0, 1.0], 1.0);
        let peers = table_with(1, 0, Some((peer, 10.0)), None);
        let own = odom(10.0, [-2.5, -3.0, 1.0], [0.0, 1.0, 0.0]);
        let crossing = line(10.0, [-2.5, -3.0, 1.0], [-2.5, 3.0, 1.0], 2.0);
        let c = check_candidate(&config, t(10.0), RobotId(0), 5, &own, &crossing, &peers);
        assert!(c.is_some_and(|c| !c.envelope && c.peer == RobotId(1)));
        // Crossing far ahead of where it can stop is fine: it will have seen us.
        let own = odom(10.0, [3.0, -3.0, 1.0], [0.0, 1.0, 0.0]);
        let ahead = line(10.0, [3.0, -3.0, 1.0], [3.0, 3.0, 1.0], 2.0);
        assert!(check_candidate(&config, t(10.0), RobotId(0), 5, &own, &ahead, &peers).is_none());
        let model = PeerModel::Yielding {
            plan: &line(10.0, [-4.0, 0.0, 1.0], [4.0, 0.0, 1.0], 1.0),
            react_at: t(11.2),
            decel_mps2: 1.0,
        };
        let stop = model.position_at(t(20.0)).unwrap();
        assert!((stop.x - (-4.0 + 1.2 + 0.5)).abs() < 1e-9, "{stop}");
    }

    #[test]
    fn a_pair_already_too_close_may_not_close_in_vertically_either() {
        let config = PriorityConfig::default();
        // Peer 0 (higher priority) hovers 0.5 m to the side and 0.6 m above robot 1:
        // their cylinders (0.8 m tall) already overlap. Climbing towards it keeps the
        // horizontal distance and closes the vertical one (an 8-robot cave run ended
        // with the bodies 0.56 m apart that way); sinking away is fine.
        let hover = line(0.0, [0.5, 0.0, 1.6], [0.5, 0.0, 1.6], 1.0);
        let peers = table_with(0, 5, Some((hover, 9.8)), None);
        let own = odom(10.0, [0.0, 0.0, 1.0], [0.0; 3]);
        let climb = line(10.0, [0.0, 0.0, 1.0], [0.0, 0.0, 1.3], 0.3);
        let c = check_candidate(&config, t(10.0), RobotId(1), 0, &own, &climb, &peers);
        assert!(c.is_some_and(|c| c.peer == RobotId(0)));
        let sink = line(10.0, [0.0, 0.0, 1.0], [0.0, 0.0, 0.7], 0.3);
        assert!(check_candidate(&config, t(10.0), RobotId(1), 0, &own, &sink, &peers).is_none());
    }

    #[test]
    fn a_lower_priority_peer_may_stop_before_it_leaves_the_way() {
        let config = PriorityConfig::default();
        // Peer 1 (priority 0) at the origin, its plan taking it +y at 1.5 m/s; robot 0
        // (priority 5) would arrive where the peer is now 1.5 s later. Were the peer
        // sure to keep to its plan until it can react (1.2 s), the spot would be free;
        // but its next round may stop it at once, where it is.
        let leaving = line(10.0, [0.0, 0.0, 1.0], [0.0, 3.0, 1.0], 1.5);
        let peers = table_with(1, 0, Some((leaving, 10.0)), None);
        let own = odom(10.0, [-2.0, 0.0, 1.0], [1.5, 0.0, 0.0]);
        let into_the_spot = line(10.0, [-2.0, 0.0, 1.0], [0.0, 0.0, 1.0], 1.5);
        let c = check_candidate(
            &config,
            t(10.0),
            RobotId(0),
            5,
            &own,
            &into_the_spot,
            &peers,
        );
        assert!(
            c.as_ref()
                .is_some_and(|c| c.peer == RobotId(1) && !c.envelope),
            "{c:?}"
        );
        // Where it may be: from where it is now to where it would stop after 1.2 s.
        let plan = line(10.0, [0.0, 0.0, 1.0], [0.0, 3.0, 1.0], 1.5);
        let model = PeerModel::Yielding {
            plan: &plan,
            react_at: t(11.2),
            decel_mps2: 1.0,
        };
        let ys: Vec<f64> = model
            .possible_positions(t(10.0), t(20.0))
            .iter()
            .map(|p| p.y)
            .collect();
        let (lo, hi) = ys
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), y| (a.min(*y), b.max(*y)));
        // From where it is now (the plan's first knot has no velocity yet) to 1.8 m
        // along its plan (1.2 s at 1.5 m/s) plus 1.125 m of braking (1.5² / 2).
        assert!(lo.abs() < 1e-6 && (hi - 2.925).abs() < 1e-6, "{ys:?}");
        let latest = model.position_at(t(20.0)).map(|p| p.y);
        assert!(latest.is_some_and(|y| (y - 2.925).abs() < 1e-6));
        // Passing well behind where it is now is still fine.
        let own = odom(10.0, [-2.0, -3.0, 1.0], [1.5, 0.0, 0.0]);
        let behind = line(10.0, [-2.0, -3.0, 1.0], [2.0, -3.0, 1.0], 1.5);
        assert!(check_candidate(&config, t(10.0), RobotId(0), 5, &own, &behind, &peers).is_none());
    }

    #[test]
    fn a_pair_already_too_close_may_separate_but_not_close_in() {
        let config = PriorityConfig::default();
        // Peer 0 (higher priority) hovers at the origin; robot 1 is 0.5 m from it.
        let hover = line(0.0, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], 1.0);
        let peers = table_with(0, 5, Some((hover, 9.8)), None);
        let own = odom(10.0, [0.5, 0.0, 1.0], [0.0; 3]);
        let away = line(10.0, [0.5, 0.0, 1.0], [3.0, 0.0, 1.0], 0.5);
        assert!(check_candidate(&config, t(10.0), RobotId(1), 0, &own, &away, &peers).is_none());
        let closer = line(10.0, [0.5, 0.0, 1.0], [0.3, 0.0, 1.0], 0.5);
        assert!(check_candidate(&config, t(10.0), RobotId(1), 0, &own, &closer, &peers).is_some());
        let past = line(10.0, [0.5, 0.0, 1.0], [-3.0, 0.0, 1.0], 0.5);
        assert!(check_candidate(&config, t(10.0), RobotId(1), 0, &own, &past, &peers).is_some());
    }

    #[test]
    fn a_hovering_lower_priority_peer_is_kept_clear_of() {
        // Peer 1 (priority 0) hovers at the origin with a fresh plan; robot 0 (priority
        // 5) would fly through it.
        let hover = line(0.0, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], 1.0);
        let peers = table_with(
            1,
            0,
            Some((hover, 9.8)),
            Some(odom(10.0, [0.0, 0.0, 1.0], [0.0; 3])),
        );
        let own = odom(10.0, [-3.0, 0.0, 1.0], [1.0, 0.0, 0.0]);
        let through = line(10.0, [-3.0, 0.0, 1.0], [3.0, 0.0, 1.0], 1.0);
        let c = check_candidate(
            &PriorityConfig::default(),
            t(10.0),
            RobotId(0),
            5,
            &own,
            &through,
            &peers,
        );
        assert!(c.is_some_and(|c| c.peer == RobotId(1)));
        // Going elsewhere is fine.
        let away = line(10.0, [-3.0, 0.0, 1.0], [-3.0, 3.0, 1.0], 1.0);
        let config = PriorityConfig::default();
        assert!(check_candidate(&config, t(10.0), RobotId(0), 5, &own, &away, &peers).is_none());
        // The thesis rule ignores lower-priority robots.
        let thesis = PriorityConfig {
            clear_of_lower_priority: false,
            ..config
        };
        assert!(check_candidate(&thesis, t(10.0), RobotId(0), 5, &own, &through, &peers).is_none());
    }

    /// The stopping envelope of a peer modelled by it at `now`.
    fn envelope_of(config: &PriorityConfig, now: f64, peers: &PeerTable) -> StoppingEnvelope {
        let track = peers.iter().next().expect("one peer").1;
        match peer_model(config, t(now), track) {
            Some(PeerModel::Envelope(envelope)) => envelope,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_plan_that_arrives_late_is_as_old_as_when_it_was_made() {
        let config = PriorityConfig::default();
        // The peer (priority 5) planned at 0 s to fly from (-5, 0) to (-3, 0) and hover
        // there; the link held that plan and its odometry for 3 s.
        let made = line(0.0, [-5.0, 0.0, 1.0], [-3.0, 0.0, 1.0], 1.0);
        let late = |stamp_s: f64| {
            let mut peers = PeerTable::default();
            peers.update_plan(&PeerPlan {
                robot: RobotId(0),
                priority: 5,
                plan: Plan::new(t(stamp_s), made.clone()),
                run_start_ns: 0,
                received_at: t(3.0),
            });
            peers
        };
        // Our candidate passes 1.5 m beyond where that plan ends.
        let own = odom(3.1, [-1.5, -3.0, 1.0], [0.0; 3]);
        let across = line(3.1, [-1.5, -3.0, 1.0], [-1.5, 3.0, 1.0], 1.0);
        let check = |peers: &PeerTable| {
            check_candidate(&config, t(3.1), RobotId(1), 1, &own, &across, peers)
        };
        // Made when it arrived, the plan is fresh and the peer hovers 1.5 m away.
        assert_eq!(check(&late(3.0)), None);
        // Made 3.1 s ago, it is stale: the peer may have flown on with plans not yet
        // received, from rest at (-5, 0) up to 1.5 m/s at 3 m/s², for 3.1 s, plus
        // braking, and the candidate enters that envelope.
        let peers = late(0.0);
        let envelope = envelope_of(&config, 3.1, &peers);
        assert_eq!(envelope.position_m, Point3::new(-5.0, 0.0, 1.0));
        // 0.375 m speeding up, 1.5 m/s for 3.1 s - 0.5 s, 1.5² / (2 · 1) braking.
        let radius_m = envelope.radius_m_at(t(3.1));
        assert!(
            (radius_m - (0.375 + 1.5 * 2.6 + 1.125)).abs() < 1e-9,
            "{radius_m}"
        );
        assert!(check(&peers).is_some_and(|c| c.envelope));
    }

    #[test]
    fn a_peer_seen_hovering_a_moment_ago_has_not_sped_up_yet() {
        let config = PriorityConfig::default();
        // The peer (priority 5) flew its last plan at 1.5 m/s and has hovered at (1, 0)
        // since; its odometry says so, 0.1 s ago or 2 s ago.
        let flown = line(0.0, [-2.0, 0.0, 1.0], [1.0, 0.0, 1.0], 1.5);
        let hovering_since = |at: f64| {
            table_with(
                0,
                5,
                Some((flown.clone(), 0.0)),
                Some(odom(at, [1.0, 0.0, 1.0], [0.0; 3])),
            )
        };
        // 0.1 s at 3 m/s² from rest: 1.5 cm flown, 0.3 m/s, 4.5 cm of braking. Counted
        // at its plan's 1.5 m/s, its envelope (1.3 m) reached us where we stand.
        let fresh = hovering_since(9.9);
        let radius_m = envelope_of(&config, 10.0, &fresh).radius_m_at(t(10.0));
        assert!((radius_m - 0.06).abs() < 1e-9, "{radius_m}");
        // We start 1.6 m away. Flying on away from it is never refused.
        let own = odom(10.0, [2.6, 0.0, 1.0], [0.0; 3]);
        let away = line(10.0, [2.6, 0.0, 1.0], [4.6, 0.0, 1.0], 1.0);
        let check = |peers: &PeerTable, candidate: &Trajectory| {
            check_candidate(&config, t(10.0), RobotId(1), 1, &own, candidate, peers)
        };
        assert_eq!(check(&fresh, &away), None);
        assert_eq!(check(&hovering_since(8.0), &away), None);
        // Passing it 1.53 m away at the closest, 0.46 s from now, is refused either way:
        // heard of 2 s ago it may be flying at 1.5 m/s, 2.6 m from there; hovering a
        // moment ago, it may have set off since (1.6 m of envelope by then).
        let past = line(10.0, [2.6, 0.0, 1.0], [2.0, 2.0, 1.0], 1.0);
        assert!(check(&hovering_since(8.0), &past).is_some_and(|c| c.envelope));
        assert!(check(&fresh, &past).is_some_and(|c| c.envelope));
    }

    #[test]
    fn stale_or_missing_plan_is_an_envelope_that_grows_from_the_last_position() {
        let config = PriorityConfig::default();
        let peer = line(0.0, [-5.0, 0.0, 1.0], [5.0, 0.0, 1.0], 1.0);
        // Plan received at 0 s, now 10 s: stale; odometry at 9.5 s says (2, 0) moving 1 m/s.
        let peers = table_with(
            0,
            5,
            Some((peer, 0.0)),
            Some(odom(9.5, [2.0, 0.0, 1.0], [1.0, 0.0, 0.0])),
        );
        let envelope = envelope_of(&config, 10.0, &peers);
        assert_eq!(envelope.position_m, Point3::new(2.0, 0.0, 1.0));
        // From 1 m/s up to 1.5 m/s at 3 m/s² (1/6 s, 0.208 m), then 1.5 m/s, plus
        // 1.5² / (2 · 1) of braking: at 10 s (0.5 s on) and 2 s later.
        let speeding_m = 1.0 / 6.0 + 1.5 / 36.0;
        for (at_s, age_s) in [(10.0, 0.5), (12.0, 2.5)] {
            let radius_m = envelope.radius_m_at(t(at_s));
            let expected = speeding_m + 1.5 * (age_s - 1.0 / 6.0) + 1.125;
            assert!((radius_m - expected).abs() < 1e-9, "{radius_m} at {at_s}");
        }
        let own = odom(10.0, [2.0, -4.0, 1.0], [0.0, 1.0, 0.0]);
        let check = |candidate: &Trajectory, peers: &PeerTable| {
            check_candidate(&config, t(10.0), RobotId(1), 1, &own, candidate, peers)
        };
        // Stopping 3 m short of the peer, 2 s from now: clear of its envelope as it is
        // now (2 r + 1.83 m), not of where it may have flown on to by the next round
        // (2 r + 3.6 m, grown for `stale_growth_s`).
        // With the envelope held at its size now, such a candidate flew a robot into
        // the end of a peer's committed plan.
        let short = line(10.0, [2.0, -4.0, 1.0], [2.0, -2.0, 1.0], 1.0);
        assert!(check(&short, &peers).is_some_and(|c| c.envelope));
        // Backing off slower than the envelope grows: it reaches the robot, which
        // nevertheless gets no closer to where the peer was; hovering is no safer.
        let back = line(10.0, [2.0, -4.0, 1.0], [2.0, -5.0, 1.0], 0.5);
        assert_eq!(check(&back, &peers), None);
        // Sideways along the envelope's edge, closing in a little: refused.
        let along = line(10.0, [2.0, -4.0, 1.0], [0.0, -3.6, 1.0], 1.0);
        assert!(check(&along, &peers).is_some_and(|c| c.envelope));
        // Odometry only (no plan ever): unknown priority, avoided as an envelope that
        // grows at up to `peer_max_speed_mps` even while the peer hovers.
        let only = table_with(0, 0, None, Some(odom(10.0, [2.0, 0.0, 1.0], [0.0; 3])));
        let c = |candidate: &Trajectory| {
            check_candidate(&config, t(10.0), RobotId(1), 60_000, &own, candidate, &only)
        };
        assert!(c(&short).is_some_and(|c| c.envelope));
        assert_eq!(c(&back), None);
        // Far enough: 2 s of flight end 7 m from it, beyond 2 r + 0.375 + 1.5 · 0.7 + 1.125
        // (grown for `stale_growth_s`, 1.2 s).
        let far_own = odom(10.0, [2.0, -9.0, 1.0], [0.0; 3]);
        let far = line(10.0, [2.0, -9.0, 1.0], [2.0, -7.0, 1.0], 1.0);
        assert_eq!(
            check_candidate(&config, t(10.0), RobotId(1), 60_000, &far_own, &far, &only),
            None
        );
    }

    #[test]
    fn accepted_pairs_keep_their_distance_in_continuous_time() {
        // Property: whenever the capped, sampled check accepts, the dense minimum
        // horizontal distance is at least the sum of the cylinder radii.
        let config = PriorityConfig {
            max_samples: 20,
            ..PriorityConfig::default()
        };
        let mut accepted = 0;
        for k in 0..60 {
            let offset = -6.0 + 0.2 * k as f64;
            let peer = line(0.0, [-6.0, 0.0, 1.0], [6.0, 0.0, 1.0], 1.0);
            let peers = table_with(0, 5, Some((peer.clone(), 0.0)), None);
            let mine = line(0.0, [offset, -4.0, 1.0], [offset, 4.0, 1.0], 1.0);
            let own = odom(0.0, [offset, -4.0, 1.0], [0.0, 1.0, 0.0]);
            if check_candidate(&config, t(0.0), RobotId(1), 1, &own, &mine, &peers).is_none() {
                accepted += 1;
                let d = dense_min_distance(&mine, &peer, 0.0, 12.0);
                assert!(d >= 2.0 * config.cylinder_radius_m, "offset {offset}: {d}");
            }
        }
        assert!(accepted > 0 && accepted < 60, "{accepted}");
    }

    #[test]
    fn dynamic_rule_raises_priority_while_blocked() {
        let mut p = PriorityAvoidance::new(PriorityConfig {
            priority: 2,
            boost_after_s: 4.0,
            boost_step: 3,
            ..PriorityConfig::default()
        });
        assert_eq!(p.priority(t(0.0)), 2);
        p.record_round(t(1.0), true);
        p.record_round(t(2.0), true);
        assert_eq!(p.priority(t(4.0)), 2);
        assert_eq!(p.priority(t(5.0)), 5);
        p.record_round(t(6.0), false);
        assert_eq!(p.priority(t(6.0)), 2);
        assert!(
            PriorityConfig {
                max_samples: 1,
                ..PriorityConfig::default()
            }
            .validate()
            .is_err()
        );
        assert!(PriorityConfig::default().validate().is_ok());
    }
}
