//! One robot's guide: its frontier memory, what it knows of where its peers are
//! heading, and the rule that decides when a planning round follows the global field.

use std::collections::{BTreeMap, BTreeSet};

use nalgebra::{Isometry3, Point3};
use troupe_core::{RobotId, Time};

use super::config::GuidanceConfig;
use super::guidance::{Coordination, FieldParams, GuidanceField, PeerIntent, ViewCone};
use super::memory::{CellKey, CellRecord, FrontierMemory, MemoryUpdate};
use crate::camera::PinholeIntrinsics;
use crate::grid::GridSnapshot;
use crate::planner::round::Candidate;
use crate::team::{PeerKeyframe, PeerPlan};

/// The frontier memory of one robot, fed by its grid snapshots and its peers'
/// keyframes and plans, and the guidance field built from it each round.
#[derive(Clone, Debug)]
pub struct Guide {
    config: GuidanceConfig,
    memory: FrontierMemory,
    peers: BTreeMap<RobotId, PeerIntent>,
    retired_by_peers: u64,
    /// Seconds spent near each remembered frontier while it stayed one.
    watched_s: BTreeMap<CellKey, f64>,
    /// Frontiers watched for [`GuidanceConfig::give_up_after_s`] without being retired,
    /// and when each was given up.
    given_up: BTreeMap<CellKey, Time>,
    /// Every frontier given up at least once, looked for again or not (bounded by the
    /// memory, like `watched_s`): what is left of them does not keep a mission going.
    ever_given_up: BTreeSet<CellKey>,
    /// Pockets this robot gave up since [`Self::take_given_up`] last ran, for its peers
    /// (kept only with [`GuidanceConfig::share_given_up`]; bounded by the memory, as
    /// it holds frontiers of it).
    newly_given_up: BTreeSet<CellKey>,
    last_field: Option<Time>,
    /// The frontier this robot's route led to in the last field.
    last_target: Option<CellKey>,
    /// Progress towards the goal being tracked: its centre, the route distance to
    /// beat, metres (the route when it last got [`PROGRESS_M`] shorter, raised while
    /// the robot moves away), and when the route last got that much shorter.
    progress: Option<(Point3<f64>, f64, Time)>,
    /// Where the robot was at the last [`Self::field`].
    last_position_m: Option<Point3<f64>>,
    /// What the robot's camera sees, when it has one ([`Self::seeing_with`]).
    camera: Option<ViewCone>,
    /// The route distance from the robot to its target at the last [`Self::field`].
    last_route_m: f64,
    /// How the robot has looked around since its first round, until it has
    /// ([`LookAround`]): no frontier is given up before.
    look_around: LookAround,
}

/// Whether a robot has looked around since it started: turned through a full circle
/// or flown [`GuidanceConfig::give_up_radius_m`] from where it started. Before, a
/// frontier near it may simply lie where the camera has not yet turned (at the start
/// every frontier is near), so time near frontiers does not count towards giving them
/// up.
#[derive(Clone, Copy, Debug, Default)]
struct LookAround {
    /// Where the robot started.
    start_m: Option<Point3<f64>>,
    /// Its last heading, radians.
    last_yaw_rad: Option<f64>,
    /// The heading it turned through so far, radians.
    turned_rad: f64,
    /// It has looked around.
    done: bool,
}

impl LookAround {
    /// Folds the robot's position and heading in; whether it has now looked around.
    fn update(&mut self, robot_m: &Point3<f64>, yaw_rad: f64, radius_m: f64) -> bool {
        if self.done {
            return true;
        }
        let start_m = *self.start_m.get_or_insert(*robot_m);
        if let Some(last) = self.last_yaw_rad.replace(yaw_rad) {
            let step = (yaw_rad - last + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            if step.is_finite() {
                self.turned_rad += step.abs();
            }
        }
        self.done =
            self.turned_rad >= std::f64::consts::TAU || (robot_m - start_m).norm() >= radius_m;
        self.done
    }
}

/// How much shorter the route to a goal must get to count as progress, metres.
pub const PROGRESS_M: f64 = 0.5;

/// Goals this close to the tracked one are the same opening, metres.
pub const GOAL_RADIUS_M: f64 = 2.0;

/// The sampling seed of a peer keyframe: the same keyframe always gives the same rays.
fn keyframe_seed(robot: RobotId, id: u32) -> u64 {
    (u64::from(robot.0) << 32 | u64::from(id)).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ 0xf00d
}

impl Guide {
    /// An empty guide.
    #[must_use]
    pub fn new(config: GuidanceConfig) -> Self {
        let mut memory = FrontierMemory::new(config.cell_m, config.max_cells);
        if config.share_memory {
            memory = memory.tracking_changes();
        }
        if config.quick_end {
            memory = memory.tracking_peer_sight();
        }
        Guide {
            config,
            memory,
            peers: BTreeMap::new(),
            retired_by_peers: 0,
            watched_s: BTreeMap::new(),
            given_up: BTreeMap::new(),
            ever_given_up: BTreeSet::new(),
            newly_given_up: BTreeSet::new(),
            last_field: None,
            last_target: None,
            progress: None,
            last_position_m: None,
            camera: None,
            last_route_m: f64::INFINITY,
            look_around: LookAround::default(),
        }
    }

    /// The same guide judging frontiers by what `camera` (level, on the robot) can see
    /// of them within [`GuidanceConfig::viewpoint_range_m`]: a frontier seeds the field
    /// at its viewpoints ([`viewpoints`](super::viewpoints)), and one without any is no
    /// goal. Without a camera, or with [`GuidanceConfig::viewpoints`] off, the passable
    /// cells beside a frontier seed it.
    #[must_use]
    pub fn seeing_with(mut self, camera: &PinholeIntrinsics) -> Self {
        self.camera = Some(ViewCone::of_camera(camera, self.config.viewpoint_range_m));
        self
    }

    /// The camera's cone when frontiers are judged by their viewpoints
    /// ([`GuidanceConfig::viewpoints`]).
    fn view(&self) -> Option<ViewCone> {
        self.camera.filter(|_| self.config.viewpoints)
    }

    /// The memory.
    #[must_use]
    pub fn memory(&self) -> &FrontierMemory {
        &self.memory
    }

    /// Remembered frontiers retired by peers' keyframes so far.
    #[must_use]
    pub fn retired_by_peers(&self) -> u64 {
        self.retired_by_peers
    }

    /// Folds the robot's own grid snapshot in; `margin_m` is the clearance a robot
    /// centre needs (the planner's [`margin_m`](crate::planner::round::RoundConfig::margin_m)),
    /// `position` the robot's, within [`GuidanceConfig::retire_radius_m`] of which the
    /// window retires frontiers (`None`: anywhere in it).
    pub fn observe_snapshot(
        &mut self,
        snapshot: &GridSnapshot,
        margin_m: f64,
        position: Option<&Point3<f64>>,
    ) -> MemoryUpdate {
        let retire_within = self
            .config
            .retire_radius_m
            .zip(position)
            .map(|(r, p)| (*p, r));
        self.memory.observe_window(
            snapshot,
            margin_m,
            self.config.min_frontier_cells,
            retire_within,
        )
    }

    /// Folds a peer's keyframe in: its rays retire the frontiers they cross.
    pub fn observe_peer_keyframe(&mut self, peer: &PeerKeyframe) -> MemoryUpdate {
        let update = self.memory.observe_keyframe(
            &peer.keyframe,
            self.config.peer_keyframe_samples,
            keyframe_seed(peer.robot, peer.keyframe.id),
        );
        self.retired_by_peers += update.retired as u64;
        update
    }

    /// Folds the cells a peer observed in, by their centres in our world frame (its
    /// occupancy-grid change sets, when the team shares grids instead of keyframes):
    /// they retire the frontiers they lie in ([`FrontierMemory::observe_cells`]).
    pub fn observe_peer_cells(
        &mut self,
        centres: impl IntoIterator<Item = Point3<f64>>,
    ) -> MemoryUpdate {
        let update = self.memory.observe_cells(centres);
        self.retired_by_peers += update.retired as u64;
        update
    }

    /// What this robot's own observations changed in its memory since the last call
    /// ([`FrontierMemory::take_changes`]), for its peers.
    pub fn take_memory_changes(&mut self) -> Vec<(CellKey, CellRecord)> {
        self.memory.take_changes()
    }

    /// The pockets this robot gave up since the last call, with their records, in key
    /// order, for its peers: frontiers watched for [`GuidanceConfig::give_up_after_s`]
    /// from nearby that lay above or below its camera's view from where it was, which
    /// no turn could show and a peer's level camera could not see from there either.
    /// Empty unless [`GuidanceConfig::share_given_up`] (and `share_memory`). Frontiers
    /// level with the robot are kept to itself (an opening beside a junction crossed
    /// again and again is given up that way too), and so are those given up for want
    /// of progress (that a route stalled says something of the robot's way there, not
    /// of the place).
    pub fn take_given_up(&mut self) -> Vec<(CellKey, CellRecord)> {
        std::mem::take(&mut self.newly_given_up)
            .into_iter()
            .map(|k| (k, self.memory.record(k)))
            .collect()
    }

    /// Gives up, as of `now`, the remembered frontiers among `cells` that a peer gave up
    /// ([`Self::take_given_up`], moved by `frame` as in [`Self::observe_peer_memory`]):
    /// a pocket the peer's camera could not see into from nearby no longer pulls this
    /// robot either, until it is looked for again
    /// ([`GuidanceConfig::retry_given_up_after_s`]); like this robot's own give-ups,
    /// it keeps no mission going after that ([`Self::has_work`]). Cells this memory does
    /// not hold as frontiers are left out. Returns how many were given up here.
    pub fn observe_peer_given_up(
        &mut self,
        cells: impl IntoIterator<Item = CellKey>,
        frame: Option<&Isometry3<f64>>,
        now: Time,
    ) -> usize {
        let memory = &self.memory;
        let frontiers: Vec<CellKey> = cells
            .into_iter()
            .filter_map(|key| match frame {
                Some(frame) => memory.moved_key(key, frame),
                None => Some(key),
            })
            .filter(|key| memory.record(*key).frontier && !self.given_up.contains_key(key))
            .collect();
        for &f in &frontiers {
            self.give_up(f, now);
        }
        frontiers.len()
    }

    /// Folds in the memory cells a peer sent ([`FrontierMemory::merge_peer_cells`]).
    /// `frame` is the peer's world frame in ours when the team has none in common
    /// (`[[link.peer_frames]]`, Eq. 8.1): each cell's centre is moved by it and the
    /// record lands in our cell holding that point (cells beyond the memory's key
    /// range are left out).
    pub fn observe_peer_memory(
        &mut self,
        cells: impl IntoIterator<Item = (CellKey, CellRecord)>,
        frame: Option<&Isometry3<f64>>,
    ) -> MemoryUpdate {
        let Some(frame) = frame else {
            return self.memory.merge_peer_cells(cells);
        };
        let memory = &self.memory;
        let moved: Vec<(CellKey, CellRecord)> = cells
            .into_iter()
            .filter_map(|(key, record)| memory.moved_key(key, frame).map(|k| (k, record)))
            .collect();
        self.memory.merge_peer_cells(moved)
    }

    /// Records where a peer is and where it is heading (its plan's first and last
    /// knots); its position is passable. Ignored under [`Coordination::MapsOnly`],
    /// where a robot knows of its peers only through their maps.
    pub fn observe_peer_plan(&mut self, peer: &PeerPlan) {
        if self.config.coordination == Coordination::MapsOnly {
            return;
        }
        let knots = peer.plan.trajectory.knots();
        let (Some(first), Some(last)) = (knots.first(), knots.last()) else {
            return;
        };
        let finite = |p: &Point3<f64>| p.coords.iter().all(|v| v.is_finite());
        if !(finite(&first.position_m) && finite(&last.position_m)) {
            return;
        }
        self.memory.mark_body(&first.position_m);
        self.peers.insert(
            peer.robot,
            PeerIntent {
                position_m: first.position_m,
                goal_m: last.position_m,
            },
        );
    }

    /// Remembered frontiers this robot has given up (watched for
    /// [`GuidanceConfig::give_up_after_s`] from nearby without seeing into them), with
    /// when each was given up.
    #[must_use]
    pub fn given_up(&self) -> &BTreeMap<CellKey, Time> {
        &self.given_up
    }

    /// Marks the robot's own cell passable and the way from its last position on its
    /// trail ([`FrontierMemory::mark_trail`]), counts the time since the last call
    /// towards the frontiers near `robot_m` (giving up those watched too long; before
    /// the robot has looked around — turned a full circle or flown
    /// [`GuidanceConfig::give_up_radius_m`] from its start — only those its camera
    /// cannot see from there) and builds the field for
    /// robot `own` there, heading `yaw_rad`, at `now`, with the peers' claims.
    pub fn field(
        &mut self,
        (own, robot_m, yaw_rad): (RobotId, &Point3<f64>, f64),
        now: Time,
    ) -> GuidanceField {
        self.memory.mark_body(robot_m);
        let from = self.last_position_m.replace(*robot_m).unwrap_or(*robot_m);
        self.memory.mark_trail(&from, robot_m);
        let looking_at = self.looking_at();
        let looked_around = self
            .look_around
            .update(robot_m, yaw_rad, self.config.give_up_radius_m);
        self.watch(robot_m, looking_at, looked_around, now);
        let field = GuidanceField::build(
            &self.memory,
            (own, robot_m),
            &self.peers,
            &self.given_up,
            self.last_target,
            &FieldParams {
                coordination: self.config.coordination,
                min_region_cells: self.config.min_region_cells,
                small_region_penalty_m: self.config.small_region_penalty_m,
                claim_radius_m: self.config.claim_radius_m,
                claim_penalty_m: self.config.claim_penalty_m,
                switch_penalty_m: self.config.switch_penalty_m,
                look_ahead_m: self.config.look_ahead_m,
                view: self.view(),
            },
        );
        let (route_m, target) = field.distance_at(robot_m);
        if let Some(limit_s) = self.config.give_up_without_progress_s {
            self.check_progress(target, route_m, now, limit_s);
        }
        self.last_target = target;
        self.last_route_m = route_m;
        field
    }

    /// Where the robot looks from the end of its route: the frontier its route led to
    /// last round, when that route was no longer than a viewpoint may be from it (the
    /// robot is at one of its viewpoints, or on the line of sight from it). `None`
    /// without viewpoints.
    fn looking_at(&self) -> Option<Point3<f64>> {
        let view = self.view()?;
        let target = self.last_target?;
        (self.last_route_m <= view.range_m).then(|| self.memory.centre(target))
    }

    /// The rule of goals that cannot be reached (explore_lite's progress timeout): a
    /// goal whose route has not got [`PROGRESS_M`] shorter for `limit_s` — a pocket
    /// under the floor the robot hovers beside, out of the camera's view — is given up
    /// with the frontiers within [`GOAL_RADIUS_M`] of it. The route's end moves between
    /// neighbouring cells of one opening from round to round: a goal within
    /// [`GOAL_RADIUS_M`] of the tracked one is the same goal; a farther one starts afresh.
    /// The route to beat rises with the route while the robot moves away, so that a
    /// robot coming back towards a goal it once was nearer to makes progress.
    fn check_progress(&mut self, target: Option<CellKey>, route_m: f64, now: Time, limit_s: f64) {
        let Some(goal) = target.filter(|_| route_m.is_finite()) else {
            self.progress = None;
            return;
        };
        let goal_m = self.memory.centre(goal);
        let (tracked_m, best_m, since) = match self.progress {
            Some((tracked_m, best_m, since)) if (tracked_m - goal_m).norm() <= GOAL_RADIUS_M => {
                (tracked_m, best_m.max(route_m), since)
            }
            _ => (goal_m, route_m, now),
        };
        if route_m <= best_m - PROGRESS_M {
            self.progress = Some((tracked_m, route_m, now));
        } else if now.saturating_since(since).as_secs_f64() >= limit_s {
            let memory = &self.memory;
            let near: Vec<CellKey> = memory
                .frontiers()
                .filter(|f| {
                    (memory.centre(*f) - tracked_m).norm() <= GOAL_RADIUS_M
                        || (memory.centre(*f) - goal_m).norm() <= GOAL_RADIUS_M
                })
                .collect();
            for f in near.into_iter().chain(std::iter::once(goal)) {
                self.give_up(f, now);
            }
            self.progress = None;
        } else {
            self.progress = Some((tracked_m, best_m, since));
        }
    }

    fn give_up(&mut self, frontier: CellKey, now: Time) {
        self.given_up.entry(frontier).or_insert(now);
        self.ever_given_up.insert(frontier);
    }

    /// Whether a frontier is left for the robot at `robot_m` to explore in `field`
    /// (built by [`Self::field`] this round): one that seeds the field and that this
    /// robot never gave up, while the field reaches the robot. Frontiers it gave up
    /// and looks for again still pull it while it explores, but do not keep its
    /// [`Mission`](super::Mission) going: the camera could not see into them before.
    #[must_use]
    pub fn has_work(&self, field: &GuidanceField, robot_m: &Point3<f64>) -> bool {
        field.distance_m(robot_m).is_finite()
            && self
                .memory
                .frontiers()
                .any(|f| self.keeps_mission_going(f, field))
    }

    /// How many remembered frontiers seed `field` that this robot never gave up (and,
    /// with [`GuidanceConfig::quick_end`], that lie neither in space a peer's keyframes
    /// showed nor in a pocket beside its start): the ones that keep its mission going
    /// ([`Self::has_work`]).
    #[must_use]
    pub fn unexplored_count(&self, field: &GuidanceField) -> usize {
        self.memory
            .frontiers()
            .filter(|f| self.keeps_mission_going(*f, field))
            .count()
    }

    /// Whether the frontier `f` keeps the mission going ([`Self::unexplored_count`]).
    fn keeps_mission_going(&self, f: CellKey, field: &GuidanceField) -> bool {
        !self.ever_given_up.contains(&f)
            && !(self.config.quick_end
                && (self.memory.seen_by_peers(f) || self.hidden_from_start(f)))
            && field.seeds(f)
    }

    /// Whether the frontier `f` lies within [`GuidanceConfig::give_up_radius_m`] of
    /// where the robot started, under or above it beyond what its camera sees
    /// ([`Self::seeing_with`]), once the robot has looked around: turning there could
    /// not show it. Such a pocket still pulls the robot, but does not keep its mission
    /// going ([`GuidanceConfig::quick_end`]; no time near it counted before the look
    /// around, so it is seldom given up, and on seeds 1 and 3 at 700 s these pockets
    /// alone kept the missions going).
    fn hidden_from_start(&self, f: CellKey) -> bool {
        let (Some(camera), Some(start_m), true) =
            (self.camera, self.look_around.start_m, self.look_around.done)
        else {
            return false;
        };
        let centre_m = self.memory.centre(f);
        (centre_m - start_m).norm() <= self.config.give_up_radius_m
            && !camera.reaches(&start_m, &centre_m)
    }

    /// Adds the time since the last call (at most 2 s, so a pause does not count) to
    /// every remembered frontier within [`GuidanceConfig::give_up_radius_m`] of
    /// `robot_m` or of the frontier it is `looking_at` from a viewpoint (the robot
    /// attends to it from up to [`GuidanceConfig::viewpoint_range_m`] away) — before
    /// the robot has looked around (`looked_around` false), only to those above or below
    /// its camera's view from `robot_m`, which turning cannot show; a frontier
    /// watched for [`GuidanceConfig::give_up_after_s`] in all is given up. The count
    /// survives a frontier's flicker (the window's frontier mask drops and restores
    /// cells at a surface's edge as rays accumulate); cells the memory forgets are
    /// forgotten here too, so both stay bounded by the memory.
    fn watch(
        &mut self,
        robot_m: &Point3<f64>,
        looking_at: Option<Point3<f64>>,
        looked_around: bool,
        now: Time,
    ) {
        let dt_s = self.last_field.map_or(0.0, |last| {
            now.saturating_since(last).as_secs_f64().min(2.0)
        });
        self.last_field = Some(now);
        let Some(limit_s) = self.config.give_up_after_s else {
            return;
        };
        let memory = &self.memory;
        let known = |k: &CellKey| memory.record(*k) != CellRecord::default();
        self.watched_s.retain(|k, _| known(k));
        self.ever_given_up.retain(known);
        // Given up long enough ago: looked for again (the time near a frontier counts
        // on every pass, so a real opening beside a junction crossed again and again
        // may have been given up with the pockets).
        let retry_s = self.config.retry_given_up_after_s.unwrap_or(f64::INFINITY);
        let watched_s = &mut self.watched_s;
        self.given_up.retain(|k, at| {
            let keep = known(k) && now.saturating_since(*at).as_secs_f64() < retry_s;
            if !keep {
                watched_s.remove(k);
            }
            keep
        });
        let camera = self.camera;
        let mut watched_out = Vec::new();
        for f in memory.frontiers() {
            let near =
                |p: &Point3<f64>| (memory.centre(f) - p).norm() <= self.config.give_up_radius_m;
            if !(near(robot_m) || looking_at.as_ref().is_some_and(near))
                || self.given_up.contains_key(&f)
            {
                continue;
            }
            // Before the look around, only what turning here cannot show counts: cells
            // above or below the camera's view from where the robot is.
            let hidden = || camera.is_some_and(|c| !c.reaches(robot_m, &memory.centre(f)));
            if !looked_around && !hidden() {
                continue;
            }
            let watched_s = self.watched_s.entry(f).or_insert(0.0);
            *watched_s += dt_s;
            if *watched_s >= limit_s {
                watched_out.push((f, hidden()));
            }
        }
        for (f, hidden) in watched_out {
            self.give_up(f, now);
            if hidden && self.config.share_memory && self.config.share_given_up {
                self.newly_given_up.insert(f);
            }
        }
    }

    /// Whether a round from `root_m` should score the frontier reward over `field`:
    /// whenever the field reaches the robot, unless
    /// [`GuidanceConfig::window_reward_above_nats`] is set, some candidate's information
    /// reaches it and the window shows a frontier (`local_frontier_m` finite).
    #[must_use]
    pub fn should_guide(
        &self,
        field: &GuidanceField,
        root_m: &Point3<f64>,
        candidates: &[Candidate],
        local_frontier_m: f64,
    ) -> bool {
        if !field.distance_m(root_m).is_finite() {
            return false;
        }
        let best = candidates.iter().map(|c| c.information).fold(0.0, f64::max);
        self.config
            .window_reward_above_nats
            .is_none_or(|nats| best < nats || !local_frontier_m.is_finite())
    }
}
