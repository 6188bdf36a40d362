//! The planner actor: at a fixed rate, scores the motion primitive library from the
//! committed reference state against the latest grid snapshot, lets an
//! [`ActionSelection`] policy choose, and commits the choice followed by its
//! stopping primitive (thesis §4.1.3: if nothing is safe, the stopping trajectory is
//! sent).
//!
//! With a collision actor ([`PlannerActor::deferring_to_collision`]) the planner does
//! not commit itself: it publishes the round's candidates on [`PLAN_CANDIDATES`], the
//! selection's choice first and the rest by decreasing reward, with the stopping
//! trajectory, and replans from the reference of whatever is committed on [`PLAN`]
//! (the primitive it carries), as the vehicle follows it.
//!
//! With guidance on (`[robot.planner.guidance]`, the default) the planner also keeps a
//! team frontier memory ([`troupe_algorithms::exploration`]): every grid snapshot, the
//! peers' keyframes ([`PEER_KEYFRAME`]) or, in a team sharing grids, their change sets
//! ([`PEER_GRID_CHANGES`]), and their plans ([`PEER_PLAN`]) feed it, and its
//! rounds score the frontier reward over the route distance to the remembered
//! frontiers (beyond the window), avoiding those peers are heading to.
//!
//! With guidance on, the planner also keeps the robot's [`Mission`]
//! (`[robot.planner.mission]`): once no frontier is left for it (or the base commands
//! it home, [`MISSION_RETURN`]) it flies home along its memory's route, scoring only
//! the route distance ([`PlanningProblem::homing`]), and holds there by committing
//! stopping trajectories. Each change of phase or idleness is published on
//! [`MISSION_STATUS`], which the link carries to the peers (a robot with nothing left
//! of its own ends only once its peers are idle or done) and the base station.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use nalgebra::{Isometry3, Point3};
use serde::{Deserialize, Serialize};

use super::memory_share::{MEMORY_CELLS, MemoryCells};
use crate::grid::changeset::cell_centres;
use crate::link::{Peer, SharePolicy, SharedTopic};
use crate::msgs::{
    GRID_SNAPSHOT, ODOMETRY, PEER_GRID_CHANGES, PEER_KEYFRAME, PEER_PLAN, PLAN, PLAN_CANDIDATES,
    PLAN_DECISION,
};
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_algorithms::exploration::{
    GuidanceConfig, GuidanceField, Guide, Mission, MissionConfig, MissionPhase, MissionStatus,
};
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::grid::GridSnapshot;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::planner::candidates::{CandidatePlan, PlanCandidates, PlanDecision};
use troupe_algorithms::planner::committed::{Committed, replanning_root};
use troupe_algorithms::planner::primitives::FlatState;
use troupe_algorithms::planner::problem::PlanningProblem;
use troupe_algorithms::planner::round::{Candidate, RoundConfig};
use troupe_algorithms::planner::selection::ActionSelection;
use troupe_runtime::{
    Actor, ActorError, ActorResult, Context, Event, Message, QueuePolicy, RobotId, Time, TimerId,
    Topic,
};

/// Planner settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlannerConfig {
    /// Replanning rate, Hz (thesis: 1 Hz).
    pub rate_hz: f64,
    /// The round: library, limits, rewards, safety.
    pub round: RoundConfig,
    /// Spacing of the knots sent to the vehicle, seconds.
    pub knot_step_s: f64,
    /// A round plans from the committed reference this far ahead of its own time
    /// (thesis §4.1.3: replanning from a future reference point), and its plan takes
    /// over there; until then the robot keeps flying what it had committed, so a plan
    /// decided within this time joins the flight without a jump. It should exceed a
    /// round's compute time plus the collision decision (0.1 s + 0.005 s modelled in
    /// simulation), seconds, below the replanning period. When the decisions of the
    /// last rounds came later (a busy real-time robot), the planner leads by the
    /// slowest of them with 25 % headroom instead, up to 0.8 of the period.
    pub lead_s: f64,
    /// Team frontier memory, global guidance and implicit coordination.
    pub guidance: GuidanceConfig,
    /// How the mission ends: home and hold once nothing is left to explore (needs
    /// guidance).
    pub mission: MissionConfig,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        PlannerConfig {
            rate_hz: 1.0,
            round: RoundConfig::default(),
            knot_step_s: 0.1,
            lead_s: 0.11,
            guidance: GuidanceConfig::default(),
            mission: MissionConfig::default(),
        }
    }
}

/// What one planning round did (for reports and the selection comparison).
#[derive(Clone, Debug, PartialEq)]
pub struct PlanningReport {
    /// When.
    pub stamp: Time,
    /// Safe, feasible candidates.
    pub candidates: usize,
    /// Reward of the chosen one (`None`: the stopping trajectory was sent).
    pub chosen_reward: Option<f64>,
    /// Whether the round followed the global guidance field.
    pub guided: bool,
    /// Remembered frontiers that seed the round's guidance field — the ones that pull
    /// this robot (given-up ones and ones no known route reaches left out); `None`
    /// with guidance off.
    pub frontiers: Option<usize>,
    /// The mission after this round (its phase, and the return so far).
    pub mission: MissionStatus,
}
impl Message for PlanningReport {}

/// Planning reports.
pub const PLANNING_REPORT: Topic<PlanningReport> = Topic::new("planner/report");

/// The team frontier memory's remembered frontiers at a planning round (guidance on),
/// for recordings and monitors: nothing in a robot subscribes.
#[derive(Clone, Debug, PartialEq)]
pub struct RememberedFrontiers {
    /// When (the round's time).
    pub stamp: Time,
    /// Edge of a memory cell, metres.
    pub cell_m: f64,
    /// Centres of the remembered frontier cells, world frame, metres.
    pub centres_m: Vec<nalgebra::Point3<f64>>,
    /// The route the round's guidance field leads along from the robot: centres of the
    /// memory cells it crosses, ending at the frontier it leads to
    /// ([`GuidanceField::route_from`]); empty when the field does not reach the robot.
    pub route_m: Vec<nalgebra::Point3<f64>>,
}
impl Message for RememberedFrontiers {
    fn payload_bytes(&self) -> usize {
        std::mem::size_of::<Self>() + 24 * (self.centres_m.len() + self.route_m.len())
    }
}

/// A robot's mission ([`MissionStatus`]) at each change of phase: shared with the
/// peers and the base station, store-and-forward at plan priority (three messages a
/// mission).
pub const MISSION_STATUS: SharedTopic<MissionStatus> = SharedTopic::new(
    "mission/status",
    1,
    SharePolicy::store_and_forward_in_plan_class(),
);

/// The base station's command home (`robot<N> return`), as the operator actor
/// passes it on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReturnCommand;
impl Message for ReturnCommand {}

/// Where the operator actor passes on the base's command home.
pub const MISSION_RETURN: Topic<ReturnCommand> = Topic::new("mission/return");

/// Remembered frontiers, one message per planning round.
pub const REMEMBERED_FRONTIERS: Topic<RememberedFrontiers> = Topic::new("planner/frontiers");

const REPLAN: TimerId = TimerId(0);
/// One-shot delay before the first round (see [`round_phase_s`]).
const PHASE: TimerId = TimerId(1);

/// Delay of robot `robot`'s planning rounds within the replanning period: the
/// fractional part of `robot · φ` (golden ratio) times the period, so that teammates do
/// not commit at the same instant. A robot that commits while a peer commits cannot
/// know the peer's new plan (§8.2.3 checks against received plans); with staggered
/// rounds each plan is checked against the peer's latest one whenever the link
/// delivers within the offset (0.38 of the period between robots 0 and 1).
#[must_use]
pub fn round_phase_s(robot: u32, period_s: f64) -> f64 {
    let golden = 0.5 * (5f64.sqrt() - 1.0);
    (f64::from(robot) * golden).fract() * period_s
}

/// Replans at a fixed rate: scores the primitive library from the committed reference
/// state against the latest grid snapshot, lets the [`ActionSelection`] policy choose,
/// and commits the choice followed by its stopping primitive (the stopping trajectory
/// alone when nothing is safe, thesis §4.1.3).
pub struct PlannerActor<S> {
    config: PlannerConfig,
    camera: PinholeIntrinsics,
    selection: S,
    snapshot: Option<Arc<GridSnapshot>>,
    odometry: Option<Arc<Odometry>>,
    committed: Option<Committed>,
    deferred: bool,
    round: u64,
    guide: Option<Guide>,
    mission: Mission,
    /// The mission's route home is unknown (warned once per return).
    no_route_home: bool,
    /// The phase, idleness and home last published on [`MISSION_STATUS`].
    published_status: Option<(MissionPhase, bool, Option<[f64; 3]>)>,
    /// The peers' missions as they last reported them.
    peer_missions: BTreeMap<RobotId, MissionStatus>,
    /// Each peer's own home (the first its missions reported), in this robot's frame.
    peer_homes: BTreeMap<RobotId, Point3<f64>>,
    /// Where the link publishes the peers' memory cells.
    peer_memory: Topic<Peer<MemoryCells>>,
    /// Where the link publishes the peers' missions.
    peer_mission: Topic<Peer<MissionStatus>>,
    /// Each peer's world frame in ours, for peers without a frame in common with us.
    peer_frames: BTreeMap<RobotId, Isometry3<f64>>,
    /// The latest rounds sent to the collision actor and their times.
    sent_rounds: VecDeque<(u64, Time)>,
    /// Seconds from the latest rounds to their decisions ([`PlanDecision`]).
    decision_delays_s: VecDeque<f64>,
}

/// Rounds whose decision delays [`PlannerActor`] keeps to size its lead.
const LEAD_WINDOW: usize = 8;
/// Headroom of the lead over the slowest recent decision.
const LEAD_HEADROOM: f64 = 1.25;

impl<S: ActionSelection> PlannerActor<S> {
    /// Time between planning rounds (`1 / rate_hz`).
    fn replan_period(&self) -> Duration {
        Duration::from_secs_f64(1.0 / self.config.rate_hz.max(1e-3))
    }

    /// A planner scoring views of `camera`, choosing with `selection`.
    #[must_use]
    pub fn new(config: PlannerConfig, camera: PinholeIntrinsics, selection: S) -> Self {
        PlannerActor {
            config,
            camera,
            selection,
            snapshot: None,
            odometry: None,
            committed: None,
            deferred: false,
            round: 0,
            guide: config
                .guidance
                .enabled
                .then(|| Guide::new(config.guidance).seeing_with(&camera)),
            mission: Mission::new(config.mission),
            no_route_home: false,
            published_status: None,
            peer_missions: BTreeMap::new(),
            peer_homes: BTreeMap::new(),
            peer_memory: MEMORY_CELLS.peer_topic(),
            peer_mission: MISSION_STATUS.peer_topic(),
            peer_frames: BTreeMap::new(),
            sent_rounds: VecDeque::new(),
            decision_delays_s: VecDeque::new(),
        }
    }

    /// How far ahead of a round its plans take over (thesis §4.1.3: replanning from a
    /// future reference point): [`PlannerConfig::lead_s`], or, when the collision
    /// actor's decisions of the last rounds came later than that (a real-time robot
    /// on a busy computer), the slowest of them with 25 % headroom — at most 0.8 of
    /// the period. A round decided after its plans should have taken over is refused
    /// as stale, and its robot flies on to its stop.
    fn lead_s(&self) -> f64 {
        let configured = self.config.lead_s;
        let slowest = self.decision_delays_s.iter().copied().fold(0.0, f64::max);
        if slowest <= configured {
            return configured;
        }
        let cap = 0.8 * self.replan_period().as_secs_f64();
        (slowest * LEAD_HEADROOM).min(cap).max(configured)
    }

    /// A decision arrived: how long after its round.
    fn decided(&mut self, decision: &PlanDecision, now: Time, ctx: &Context<'_>) {
        let Some(&(_, at)) = self.sent_rounds.iter().find(|(r, _)| *r == decision.round) else {
            return;
        };
        let before = self.lead_s();
        if self.decision_delays_s.len() == LEAD_WINDOW {
            self.decision_delays_s.pop_front();
        }
        self.decision_delays_s
            .push_back(now.saturating_since(at).as_secs_f64());
        let after = self.lead_s();
        if (after - before).abs() > 0.02 {
            tracing::info!(
                robot = ctx.robot_name(),
                lead_s = after,
                "planning rounds are decided up to {:.3} s after they begin: plans take over \
                 {after:.3} s ahead",
                self.decision_delays_s.iter().copied().fold(0.0, f64::max)
            );
        }
    }

    /// The world frames of peers that share none with this robot (`[[link.peer_frames]]`,
    /// Eq. 8.1): their memory cells are moved into ours
    /// ([`Guide::observe_peer_memory`]). The link moves their keyframes and plans itself.
    #[must_use]
    pub fn with_peer_frames(
        mut self,
        frames: impl IntoIterator<Item = (RobotId, Isometry3<f64>)>,
    ) -> Self {
        self.peer_frames.extend(frames);
        self
    }

    /// Publishes ranked candidates for a collision actor instead of committing, and
    /// replans from what it commits on [`PLAN`] (module docs).
    #[must_use]
    pub fn deferring_to_collision(mut self) -> Self {
        self.deferred = true;
        self
    }

    /// Sends the round's candidates to the collision actor, best first: the
    /// selection's choice, then the rest by decreasing reward.
    fn defer(
        &mut self,
        (now, start): (Time, Time),
        root: &FlatState,
        candidates: &[Candidate],
        choice: Option<usize>,
        ctx: &mut Context<'_>,
    ) {
        let Some(stop) = Committed::braking(&self.config.round.limits, root, start) else {
            return;
        };
        let mut order: Vec<usize> = (0..candidates.len())
            .filter(|&i| Some(i) != choice)
            .collect();
        order.sort_by(|&a, &b| candidates[b].reward.total_cmp(&candidates[a].reward));
        if let Some(c) = choice.filter(|&c| c < candidates.len()) {
            order.insert(0, c);
        }
        let period_s = self.config.round.planning_period_s;
        let ranked: Vec<Committed> = order
            .iter()
            .map(|&i| {
                let c = &candidates[i];
                Committed {
                    start,
                    primitive: c.primitive.clone(),
                    switch_s: period_s.min(c.primitive.duration_s()),
                    stopping: c.stopping.clone(),
                }
            })
            .collect();
        self.round += 1;
        if self.sent_rounds.len() == LEAD_WINDOW {
            self.sent_rounds.pop_front();
        }
        self.sent_rounds.push_back((self.round, now));
        let step = self.config.knot_step_s;
        ctx.publish(
            &PLAN_CANDIDATES,
            PlanCandidates {
                round: self.round,
                stamp: now,
                candidates: ranked
                    .iter()
                    .zip(&order)
                    .map(|(c, &i)| CandidatePlan {
                        trajectory: c.trajectory(step),
                        reference: Some(c.clone()),
                        switch_at: start + Duration::from_secs_f64(c.switch_s),
                        reward: candidates[i].reward,
                    })
                    .collect(),
                stop: stop.trajectory(step),
                stop_reference: Some(stop),
            },
        );
    }

    /// Logs the frontiers the guide gave up this round, publishes the memory's changes
    /// to peers (with `share_memory`) and the remembered frontiers with the route to
    /// the current target.
    fn publish_memory(
        &mut self,
        ctx: &mut Context<'_>,
        now: Time,
        here: &nalgebra::Point3<f64>,
        field: Option<&GuidanceField>,
    ) {
        if let Some(guide) = &self.guide
            && tracing::enabled!(tracing::Level::DEBUG)
        {
            let memory = guide.memory();
            for (key, _) in guide.given_up().iter().filter(|(_, at)| **at == now) {
                tracing::debug!(robot = ctx.robot_name(), time = %now, frontier = ?memory.centre(*key).coords.as_slice(), position = ?here.coords.as_slice(), "gave up a remembered frontier");
            }
        }
        if self.config.guidance.share_memory
            && let Some(guide) = self.guide.as_mut()
        {
            let changes = guide.take_memory_changes();
            let given_up = guide.take_given_up();
            if !(changes.is_empty() && given_up.is_empty()) {
                let cell_m = guide.memory().cell_m();
                ctx.publish(
                    &MEMORY_CELLS.topic(),
                    MemoryCells::new(cell_m, &changes, &given_up),
                );
            }
        }
        if let Some(guide) = &self.guide {
            let memory = guide.memory();
            ctx.publish(
                &REMEMBERED_FRONTIERS,
                RememberedFrontiers {
                    stamp: now,
                    cell_m: memory.cell_m(),
                    centres_m: memory.frontiers().map(|k| memory.centre(k)).collect(),
                    route_m: field.map_or_else(Vec::new, |f| f.route_from(here)),
                },
            );
        }
    }

    /// The round at debug level (with the route along `field`: the exploring field, or
    /// the way home while returning) and every candidate at trace level.
    fn log_round(
        &self,
        ctx: &mut Context<'_>,
        root: &FlatState,
        candidates: &[Candidate],
        choice: Option<usize>,
        guided: bool,
        field: Option<&GuidanceField>,
    ) {
        let now = ctx.now();
        let here = nalgebra::Point3::from(root.position_m());
        tracing::debug!(
            robot = ctx.robot_name(),
            time = %now,
            candidates = candidates.len(),
            clearance_m = self.snapshot.as_ref().map(|s| s.clearance_m(&here)),
            reward = choice.map(|i| candidates[i].reward),
            guided,
            frontiers = field.map(|f| f.frontier_count()),
            unexplored = field.zip(self.guide.as_ref()).map(|(f, g)| g.unexplored_count(f)),
            idle = self.mission.status().idle,
            route_m = field.map(|f| f.distance_m(&here)),
            target = ?field.and_then(|f| f.target_of(&here)).zip(self.guide.as_ref()).map(|(k, g)| g.memory().centre(k).coords.as_slice().to_vec()),
            position = ?root.position_m().as_slice(), yaw = root.yaw_rad(), action = ?choice.map(|i| candidates[i].primitive.action()), "planning round"
        );
        for c in candidates {
            tracing::trace!(
                robot = ctx.robot_name(),
                time = %now,
                action = ?c.primitive.action(),
                information = c.information,
                frontier_gain_m = c.frontier_gain_m,
                reward = c.reward,
                "candidate"
            );
        }
    }

    /// The mission's round: whether a frontier is left for the robot (with guidance
    /// off, always — only the base's command ends its exploring) and whether its
    /// peers are idle or done, the phase they give, and the status on
    /// [`MISSION_STATUS`] at the first round and at every change of phase or idleness.
    fn advance_mission(
        &mut self,
        ctx: &mut Context<'_>,
        now: Time,
        root: &FlatState,
        field: Option<&GuidanceField>,
    ) -> MissionPhase {
        let here = &Point3::from(root.position_m());
        // While returning, where the robot comes to rest if it holds from this round:
        // the end of the braking a robot at home commits (only a return reads it).
        let rest = match self.mission.phase() {
            MissionPhase::Returning => self
                .config
                .round
                .limits
                .braking(root)
                .map_or(*here, |stop| Point3::from(stop.end_state().position_m())),
            _ => *here,
        };
        let work = match (&self.guide, field) {
            (Some(guide), Some(field)) => guide.has_work(field, here),
            _ => true,
        };
        let peers_done = self
            .peer_missions
            .values()
            .all(|m| m.idle || m.phase != MissionPhase::Exploring);
        let phase = self.mission.update(now, here, &rest, work, peers_done);
        if phase == MissionPhase::Returning && self.config.mission.share_homes {
            self.choose_home(ctx, here);
        }
        let status = self.mission.status();
        let published = (phase, status.idle, status.home_m);
        if self.published_status != Some(published) {
            let changed_phase = self.published_status.map(|(p, ..)| p) != Some(phase);
            self.published_status = Some(published);
            if changed_phase && phase != MissionPhase::Exploring {
                tracing::info!(
                    robot = ctx.robot_name(),
                    time = %now,
                    phase = phase.as_str(),
                    end = ?status.end,
                    home = ?status.home_m,
                    return_distance_m = status.return_distance_m,
                    home_gap_m = status.home_gap_m,
                    "mission: {}",
                    match phase {
                        MissionPhase::Returning => "exploring ended, flying home",
                        _ => "home, holding",
                    }
                );
            }
            ctx.publish(&MISSION_STATUS.topic(), status);
        }
        phase
    }

    /// While returning with [`MissionConfig::share_homes`]: ranks the team's homes
    /// once, by their routes over the frontier memory from where the return begins
    /// ([`Mission::rank_homes`]), then each round flies to the deepest one no peer
    /// holds at ([`Mission::choose_home`]).
    fn choose_home(&mut self, ctx: &Context<'_>, here: &Point3<f64>) {
        let Some(guide) = &self.guide else {
            return;
        };
        if self.mission.wants_home_ranking() {
            let look_ahead_m = self.config.guidance.look_ahead_m;
            let homes: Vec<(Point3<f64>, f64)> = self
                .mission
                .own_home_m()
                .into_iter()
                .chain(self.peer_homes.values().copied())
                .map(|home| {
                    let route_m = GuidanceField::towards(guide.memory(), &home, look_ahead_m)
                        .distance_m(here);
                    (home, route_m)
                })
                .collect();
            self.mission.rank_homes(&homes);
        }
        let occupied: Vec<Point3<f64>> = self
            .peer_missions
            .iter()
            .filter(|(_, m)| m.phase == MissionPhase::Home)
            .filter_map(|(peer, m)| m.home_m.map(|h| self.peer_point(*peer, h)))
            .collect();
        if self.mission.choose_home(&occupied) {
            tracing::info!(
                robot = ctx.robot_name(),
                time = %ctx.now(),
                home = ?self.mission.home_m().map(|p| [p.x, p.y, p.z]),
                "mission: flying to the deepest home no peer holds at"
            );
        }
    }

    /// A point a peer reported in its world frame, in this robot's.
    fn peer_point(&self, peer: RobotId, p: [f64; 3]) -> Point3<f64> {
        let p = Point3::from(p);
        self.peer_frames.get(&peer).map_or(p, |frame| frame * p)
    }

    /// While returning: the route distance home over the frontier memory
    /// ([`GuidanceField::towards`], or along the robot's trail once the return has
    /// stalled, [`GuidanceField::retracing`]); `None` when it does not reach the robot
    /// (no guidance, or no known route: the robot holds where it is, warned once, and
    /// tries again each round). The mission learns the route's length
    /// ([`Mission::returning`]), so that a return that gets no nearer retraces, then
    /// ends.
    fn home_field(
        &mut self,
        ctx: &Context<'_>,
        phase: MissionPhase,
        here: &nalgebra::Point3<f64>,
    ) -> Option<GuidanceField> {
        if phase != MissionPhase::Returning {
            return None;
        }
        let retracing = self.mission.retracing();
        let look_ahead_m = self.config.guidance.look_ahead_m;
        let field = self
            .guide
            .as_ref()
            .zip(self.mission.home_m())
            .map(|(guide, home)| {
                if retracing {
                    GuidanceField::retracing(guide.memory(), &home, look_ahead_m)
                } else {
                    GuidanceField::towards(guide.memory(), &home, look_ahead_m)
                }
            })
            .filter(|f| f.distance_m(here).is_finite());
        let route_m = field.as_ref().map_or(f64::INFINITY, |f| f.distance_m(here));
        self.mission.returning(ctx.now(), route_m, here);
        if self.mission.retracing() && !retracing {
            tracing::info!(
                robot = ctx.robot_name(),
                time = %ctx.now(),
                route_m,
                "mission: the route home got no nearer; retracing the robot's own trail"
            );
        }
        if field.is_none() && !std::mem::replace(&mut self.no_route_home, true) {
            tracing::warn!(
                robot = ctx.robot_name(),
                home = ?self.mission.home_m().map(|p| [p.x, p.y, p.z]),
                "mission: no known route home; holding here"
            );
        }
        self.no_route_home &= field.is_none();
        field
    }

    fn plan(&mut self, ctx: &mut Context<'_>) {
        let (Some(snapshot), Some(odometry)) = (self.snapshot.clone(), self.odometry.clone())
        else {
            return;
        };
        let now = ctx.now();
        let start = now + Duration::from_secs_f64(self.lead_s());
        let root = replanning_root(self.committed.as_ref(), start, &odometry.pose);
        let here = nalgebra::Point3::from(root.position_m());
        let own = ctx.robot();
        let field = self
            .guide
            .as_mut()
            .map(|g| g.field((own, &here, root.yaw_rad()), now));
        let phase = self.advance_mission(ctx, now, &root, field.as_ref());
        let home_field = self.home_field(ctx, phase, &here);
        self.publish_memory(ctx, now, &here, home_field.as_ref().or(field.as_ref()));
        let round = &self.config.round;
        // Under simulated time a search stops on work done, never on the wall clock.
        let mut problem =
            PlanningProblem::new(round, &snapshot, &self.camera).under(ctx.time_source());
        let candidates = match (phase, &home_field) {
            (MissionPhase::Exploring, _) => {
                let mut candidates = problem.children(&root);
                if let (Some(guide), Some(field)) = (&self.guide, &field)
                    && guide.should_guide(
                        field,
                        &here,
                        &candidates,
                        snapshot.frontier_distance(&here),
                    )
                {
                    problem = problem.guided(field);
                    candidates = problem.rescored(&root, candidates);
                }
                candidates
            }
            (MissionPhase::Returning, Some(home)) => {
                problem = problem.homing(home);
                problem.children(&root)
            }
            // Home, or no known route there: hold (the stopping trajectory).
            _ => Vec::new(),
        };
        let guided = problem.is_guided();
        // A return stuck at a local minimum of its route home takes the way out;
        // otherwise the round's selection chooses.
        let escape = (phase == MissionPhase::Returning)
            .then(|| problem.route_escape(&candidates))
            .flatten();
        if let Some(i) = escape {
            tracing::debug!(
                robot = ctx.robot_name(),
                time = %now,
                action = ?candidates[i].primitive.action(),
                "no primitive gets nearer along the route; escaping"
            );
        }
        let choice = escape.or_else(|| {
            self.selection
                .select_in(&problem, &root, &candidates, ctx.rng())
        });
        let steering = home_field.as_ref().or(field.as_ref());
        self.log_round(ctx, &root, &candidates, choice, guided, steering);
        let report = PlanningReport {
            stamp: now,
            candidates: candidates.len(),
            chosen_reward: choice.and_then(|i| candidates.get(i)).map(|c| c.reward),
            guided,
            frontiers: field.as_ref().map(GuidanceField::frontier_count),
            mission: self.mission.status(),
        };
        if self.deferred {
            ctx.publish(&PLANNING_REPORT, report);
            self.defer((now, start), &root, &candidates, choice, ctx);
            return;
        }
        let committed = match choice.and_then(|i| candidates.get(i)) {
            Some(c) => Committed {
                start,
                primitive: c.primitive.clone(),
                switch_s: round.planning_period_s.min(c.primitive.duration_s()),
                stopping: c.stopping.clone(),
            },
            None => {
                tracing::debug!(robot = ctx.robot_name(), time = %now, candidates = candidates.len(), "no safe action: stopping");
                let Some(stop) = Committed::braking(&self.config.round.limits, &root, start) else {
                    return;
                };
                stop
            }
        };
        ctx.publish(&PLANNING_REPORT, report);
        let stopping = choice.and_then(|i| candidates.get(i)).is_none();
        // The flight that leads to the new plan: the previous one, which took over
        // before now (`lead_s` is below the period).
        let step_s = self.config.knot_step_s;
        let planned = committed.trajectory(step_s);
        let trajectory = match &self.committed {
            Some(last) => last.trajectory(step_s).continued_by(now, &planned),
            None => planned,
        };
        ctx.publish(
            &PLAN,
            Plan {
                stamp: now,
                trajectory,
                reference: Some(Box::new(committed.clone())),
                stopping,
            },
        );
        self.committed = Some(committed);
    }
}

impl<S: ActionSelection> Actor for PlannerActor<S> {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        ctx.subscribe(&GRID_SNAPSHOT, QueuePolicy::LATEST);
        if self.deferred {
            ctx.subscribe(&PLAN, QueuePolicy::LATEST);
            ctx.subscribe(&PLAN_DECISION, QueuePolicy::fifo(LEAD_WINDOW));
        }
        if self.guide.is_some() && self.config.guidance.share_memory {
            MEMORY_CELLS.share(ctx);
            ctx.subscribe(&self.peer_memory, QueuePolicy::fifo(32));
        }
        MISSION_STATUS.share(ctx);
        ctx.subscribe(&self.peer_mission, QueuePolicy::fifo(16));
        ctx.subscribe(&MISSION_RETURN, QueuePolicy::LATEST);
        if self.guide.is_some() {
            ctx.subscribe(&PEER_KEYFRAME, QueuePolicy::fifo(32));
            ctx.subscribe(&PEER_PLAN, QueuePolicy::fifo(16));
            ctx.subscribe(&PEER_GRID_CHANGES, QueuePolicy::fifo(64));
        }
        let period_s = self.replan_period().as_secs_f64();
        let phase_s = round_phase_s(ctx.robot().0, period_s);
        if phase_s > 0.0 {
            ctx.set_timer(PHASE, Duration::from_secs_f64(phase_s));
        } else {
            ctx.set_timer(REPLAN, self.replan_period());
        }
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(m) => {
                let mut rejected = None;
                if let Some(odometry) = m.get_arc(&ODOMETRY) {
                    self.odometry = Some(odometry);
                } else if let Some(snapshot) = m.get_arc(&GRID_SNAPSHOT) {
                    if let Some(guide) = self.guide.as_mut() {
                        let margin_m = self.config.round.margin_m(snapshot.resolution_m());
                        let position = self
                            .odometry
                            .as_ref()
                            .map(|o| nalgebra::Point3::from(o.pose.translation.vector));
                        guide.observe_snapshot(&snapshot, margin_m, position.as_ref());
                    }
                    self.snapshot = Some(snapshot);
                } else if let Some(peer) = m.get(&PEER_KEYFRAME) {
                    if let Some(guide) = self.guide.as_mut() {
                        guide.observe_peer_keyframe(peer);
                    }
                } else if let Some(peer) = m.get(&PEER_PLAN) {
                    if let Some(guide) = self.guide.as_mut() {
                        guide.observe_peer_plan(peer);
                    }
                } else if let Some(peer) = m.get(&PEER_GRID_CHANGES) {
                    // The voxel size is team configuration (thesis §8.2.5): ours.
                    if let (Some(guide), Some(snapshot)) = (self.guide.as_mut(), &self.snapshot)
                        && peer.set.validate().is_ok()
                    {
                        guide.observe_peer_cells(cell_centres(
                            &peer.set,
                            snapshot.resolution_m(),
                            peer.frame.as_ref(),
                        ));
                    }
                } else if let Some(peer) = m.get(&self.peer_memory) {
                    if let Some(guide) = self.guide.as_mut() {
                        // A rejected message is the handler's error: counted in the
                        // actor's `errors` (summary.json) and logged, nothing merged.
                        rejected = peer
                            .message
                            .decode(guide.memory().cell_m())
                            .map(|decoded| {
                                let frame = self.peer_frames.get(&peer.robot);
                                guide.observe_peer_memory(decoded.cells, frame);
                                guide.observe_peer_given_up(decoded.given_up, frame, ctx.now());
                            })
                            .map_err(|e| {
                                ActorError::with_source(
                                    format!("rejected memory cells from {}", peer.robot),
                                    e,
                                )
                            })
                            .err();
                    }
                } else if let Some(plan) = m.get(&PLAN)
                    && let Some(reference) = &plan.reference
                {
                    self.committed = Some(Committed::clone(reference));
                } else if let Some(decision) = m.get(&PLAN_DECISION) {
                    self.decided(decision, ctx.now(), ctx);
                } else if m.get(&MISSION_RETURN).is_some() {
                    self.mission.command_return(ctx.now());
                } else if let Some(peer) = m.get(&self.peer_mission) {
                    if let Some(home) = peer
                        .message
                        .home_m
                        .filter(|h| h.iter().all(|v| v.is_finite()))
                    {
                        let home = self.peer_point(peer.robot, home);
                        self.peer_homes.entry(peer.robot).or_insert(home);
                    }
                    self.peer_missions.insert(peer.robot, peer.message);
                }
                // Stored for the next round (the frontier memory's update included):
                // the modelled planning latency is charged to rounds only.
                ctx.bookkeeping_only();
                if let Some(e) = rejected {
                    return Err(e);
                }
            }
            Event::Timer(PHASE) => {
                ctx.bookkeeping_only();
                ctx.cancel_timer(PHASE);
                ctx.set_timer(REPLAN, self.replan_period());
            }
            Event::Timer(_) => self.plan(ctx),
        }
        Ok(())
    }
}
