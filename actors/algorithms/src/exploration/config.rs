//! Settings of the team frontier memory and global guidance (`[robot.planner.guidance]`).

use serde::{Deserialize, Serialize};
use troupe_core::ConfigError;

use super::guidance::Coordination;

/// Settings of the frontier memory ([`FrontierMemory`](super::FrontierMemory)), the
/// global guidance field ([`GuidanceField`](super::GuidanceField)) and implicit
/// coordination. On by default.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GuidanceConfig {
    /// Remember frontiers beyond the grid window and steer towards them.
    pub enabled: bool,
    /// Edge of a memory cell, metres.
    pub cell_m: f64,
    /// Most memory cells held (memory bound: about 64 bytes each); cells beyond it are
    /// not remembered and counted.
    pub max_cells: usize,
    /// Fine frontier cells (of the grid window) a memory cell must hold to be a
    /// remembered frontier.
    pub min_frontier_cells: usize,
    /// Remembered frontiers pull a robot only as part of a region of at least this many
    /// 26-connected frontier cells: single cells left along a flown tunnel (a niche, a
    /// pocket under the floor) are not worth the trip back (Yamauchi 1997 discards
    /// frontier regions smaller than the robot for the same reason). 1 (the default)
    /// keeps every one: in the default cave a branch first seen as one or two cells
    /// was hidden too (docs/exploration.md).
    pub min_region_cells: usize,
    /// With `min_region_cells` above 1: the route length added to the frontiers of a
    /// smaller region instead of leaving them out, metres — a leftover cell pulls a
    /// robot only when no real opening lies within this much further. `None` (the
    /// default) leaves them out.
    pub small_region_penalty_m: Option<f64>,
    /// The frontier reward of a round is measured over the memory (route distance to
    /// the remembered frontiers) whenever the memory's field reaches the robot. With a
    /// value here, a round whose best candidate's information (CSQMI, nats) reaches it
    /// keeps the window's own frontier reward instead, unless the window shows no
    /// frontier; absent (the default): always the memory's.
    pub window_reward_above_nats: Option<f64>,
    /// A window retires remembered frontiers and settles cells only within this
    /// distance of the robot, metres (its camera's range, 5 m, and a memory cell);
    /// farther cells may become frontiers but keep those they are. The window beyond
    /// the camera's reach is rebuilt from keyframe samples, whose gaps hid the opening
    /// to the rest of the cave from a robot 9.6 m away (seed 7, before this setting:
    /// the team ended its mission at 103 s with 26 % seen). `None`: the whole window
    /// judges.
    pub retire_radius_m: Option<f64>,
    /// Points sampled from each peer keyframe's GMM (§6.1.5); the rays from the peer's
    /// sensor to them retire the remembered frontiers they cross.
    pub peer_keyframe_samples: usize,
    /// How the peers' claims on remembered frontiers are decided.
    pub coordination: Coordination,
    /// A frontier within this distance of where a peer is heading (the frontier
    /// assigned to it, or the end of its committed plan — then only when closer to that
    /// end than to this robot) is the peer's claim, metres.
    pub claim_radius_m: f64,
    /// Route length added to a frontier a peer claims, metres.
    pub claim_penalty_m: f64,
    /// Commitment: route length added to every frontier farther than
    /// [`Self::claim_radius_m`] from the one this robot's route led to last round, while
    /// that one is open, metres — a robot changes its goal only for one this much
    /// nearer (0: it follows the nearest every round).
    pub switch_penalty_m: f64,
    /// The guided frontier reward measures the route distance this far ahead of a
    /// pose, so that turning to face the route pays, metres.
    pub look_ahead_m: f64,
    /// A remembered frontier that stays a frontier while this robot spends this long
    /// within [`Self::give_up_radius_m`] of it is given up by this robot (no longer
    /// pulls it), seconds: what the camera cannot see from anywhere the robot can fly —
    /// pockets under the floor, crevices behind boulders — would otherwise hold the
    /// robot for the rest of the run. Until the robot has looked around (turned a full
    /// circle or flown [`Self::give_up_radius_m`] from its start: at the start every
    /// frontier is near, most where the camera has not yet turned) time counts only
    /// for frontiers above or below what its camera sees from where it is, which
    /// turning cannot show. `None` never gives up.
    pub give_up_after_s: Option<f64>,
    /// A goal (the remembered frontier the robot's route leads to) whose route has not
    /// got 0.5 m shorter for this long is given up with the frontiers within 2 m of it,
    /// seconds (a progress timeout, as in ROS' explore_lite); `None` never. A robot
    /// whose route leads through a gap its primitives cannot pass otherwise hovers at
    /// the route's local minimum (seed 4 at 700 s with `share_memory`: 460 s in one
    /// place); 10 s by default.
    pub give_up_without_progress_s: Option<f64>,
    /// A given-up frontier is looked for again this long after it was given up,
    /// seconds; `None`: never. Time near a frontier counts on every pass, so a real
    /// opening beside a junction the robots cross again and again can be given up
    /// with the pockets; 100 s is long enough that what was given up does not pull a
    /// robot back while new space lies nearby (it flies 100 m or more meanwhile), and
    /// short enough that such an opening is found again within a 700 s mission.
    pub retry_given_up_after_s: Option<f64>,
    /// How close the robot must be for time to count towards giving a frontier up,
    /// metres (about the camera's useful range).
    pub give_up_radius_m: f64,
    /// Send the peers what changed in this robot's memory every planning round, and
    /// take theirs where this memory knows nothing (their frontiers, passable and
    /// settled cells beyond this robot's window); a peer's cells are moved into this
    /// robot's world frame when its file gives that peer's (`[[link.peer_frames]]`).
    /// On by default: a robot whose peer explores beyond its window otherwise has no
    /// frontier of its own, and a team's mission ends only when no robot knows of one
    /// (docs/exploration.md). The link studies of §8.2.7, where robots share maps only,
    /// turn it off.
    pub share_memory: bool,
    /// With [`Self::share_memory`]: also send the peers the pockets this robot gave up
    /// (frontiers watched for [`Self::give_up_after_s`] from nearby that lay above or
    /// below its camera's view), and give up those a peer sent until they are looked
    /// for again. Pockets beside a robot's start, given up there in its first seconds,
    /// otherwise pull its peer back across the cave (seed 1: each robot flew back 40 m
    /// or more, at 69 and 92 s, to a pocket beside the start the other had given up).
    pub share_given_up: bool,
    /// Judge remembered frontiers by their viewpoints: a frontier seeds the guidance
    /// field at the passable cells within [`Self::viewpoint_range_m`] from which the
    /// robot's level camera, with its real vertical field of view, sees it along a line
    /// of passable cells, and a frontier without one is no goal
    /// ([`viewpoints`](super::viewpoints)). `false` (the default): the passable cells
    /// beside a frontier seed it, whatever the camera can see — viewpoints end more
    /// missions but hid a real opening on one seed of ten at 700 s
    /// (docs/exploration.md).
    pub viewpoints: bool,
    /// Farthest a viewpoint may be from its frontier, metres (capped at the camera's
    /// range).
    pub viewpoint_range_m: f64,
    /// End missions sooner: two kinds of frontier still pull the robot but no longer
    /// keep its [`Mission`](super::Mission) going — frontiers in cells a peer's
    /// keyframe rays (or change sets) showed, which this robot's window shows again
    /// when it is rebuilt from the peer's sparser keyframe samples, and pockets within
    /// [`Self::give_up_radius_m`] of its start, above or below what its camera sees
    /// from there, once it has looked around. Off by default: at 700 s (seeds 1–10)
    /// every robot was home on 7 seeds against 3, but two seeds ended at 96.0 and
    /// 94.6 % coverage against 100 % (docs/exploration.md).
    pub quick_end: bool,
}

impl Default for GuidanceConfig {
    fn default() -> Self {
        GuidanceConfig {
            enabled: true,
            cell_m: 1.0,
            max_cells: 262_144,
            min_frontier_cells: 4,
            min_region_cells: 1,
            small_region_penalty_m: None,
            window_reward_above_nats: None,
            retire_radius_m: Some(6.0),
            peer_keyframe_samples: 1000,
            coordination: Coordination::default(),
            claim_radius_m: 6.0,
            claim_penalty_m: 30.0,
            switch_penalty_m: 0.0,
            look_ahead_m: 1.0,
            give_up_after_s: Some(4.0),
            give_up_without_progress_s: Some(10.0),
            give_up_radius_m: 3.0,
            retry_given_up_after_s: Some(100.0),
            share_memory: true,
            share_given_up: false,
            viewpoints: false,
            viewpoint_range_m: 4.0,
            quick_end: false,
        }
    }
}

impl GuidanceConfig {
    /// Checks the numbers; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.cell_m.is_finite() && (0.2..=10.0).contains(&self.cell_m)) {
            return Err(ConfigError::new(
                "cell_m",
                "must be between 0.2 and 10",
                self.cell_m,
            ));
        }
        if !(1..=16_777_216).contains(&self.max_cells) {
            return Err(ConfigError::new(
                "max_cells",
                "must be between 1 and 16777216",
                self.max_cells,
            ));
        }
        if self.min_frontier_cells == 0 {
            return Err(ConfigError::new("min_frontier_cells", "must be ≥ 1", 0));
        }
        if self.min_region_cells == 0 {
            return Err(ConfigError::new("min_region_cells", "must be ≥ 1", 0));
        }
        if self.peer_keyframe_samples > 100_000 {
            return Err(ConfigError::new(
                "peer_keyframe_samples",
                "must be at most 100000",
                self.peer_keyframe_samples,
            ));
        }
        if let Some(m) = self.small_region_penalty_m {
            ConfigError::non_negative("small_region_penalty_m", m)?;
        }
        if let Some(nats) = self.window_reward_above_nats {
            ConfigError::non_negative("window_reward_above_nats", nats)?;
        }
        ConfigError::non_negative("claim_radius_m", self.claim_radius_m)?;
        ConfigError::non_negative("claim_penalty_m", self.claim_penalty_m)?;
        ConfigError::non_negative("switch_penalty_m", self.switch_penalty_m)?;
        if let Some(s) = self.give_up_after_s {
            ConfigError::positive("give_up_after_s", s)?;
        }
        if let Some(s) = self.retry_given_up_after_s {
            ConfigError::positive("retry_given_up_after_s", s)?;
        }
        if let Some(s) = self.give_up_without_progress_s {
            ConfigError::positive("give_up_without_progress_s", s)?;
        }
        ConfigError::non_negative("give_up_radius_m", self.give_up_radius_m)?;
        if let Some(r) = self.retire_radius_m {
            ConfigError::positive("retire_radius_m", r)?;
        }
        let range_m = self.viewpoint_range_m;
        if !(range_m.is_finite() && (0.5..=64.0).contains(&range_m)) {
            return Err(ConfigError::new(
                "viewpoint_range_m",
                "must be between 0.5 and 64",
                range_m,
            ));
        }
        ConfigError::non_negative("look_ahead_m", self.look_ahead_m)
    }
}
