//! Re-exploration, measured on ground truth: the thesis' mechanism for why map sharing
//! pays over a weak link (§8.2.7, Fig. 8.9) — a robot re-flies space its peer already
//! saw because the peer's map did not arrive — as numbers per robot and per run.
//!
//! [`ReExplorationLedger`] keeps, per ground-truth coverage cell
//! ([`crate::coverage::CoverageGrid`]), the sim time of its first observation by any
//! robot and which robots observed it, fed with the cells each depth frame's rays cross
//! ([`CoverageGrid::observe_visiting`](crate::coverage::CoverageGrid::observe_visiting)).
//! A robot *observes* a free cell when one of its frames' rays crosses it (the rays and
//! cells of ground-truth coverage). With `T(c)` the time of the first frame of any robot
//! that observed cell `c`, and `t_r(c)` the time of robot `r`'s first frame that did:
//!
//! - `c` is *first observed* by `r` when `t_r(c) = T(c)`. Ties: robots whose frames share
//!   that time are all first observers (none of them re-explored it), whatever order the
//!   executor handled the frames in;
//! - `r`'s **re-explored volume** is the volume of the cells with `t_r(c) > T(c)`: those it
//!   observed strictly after some other robot had observed them;
//! - `r`'s **exclusive volume** is the volume of the cells no other robot ever observed;
//! - a frame of `r` at time `t` *observes something new to the team* when it observes a
//!   cell no robot had observed before `t` (a cell first observed at `t` counts);
//! - `r`'s **redundant flight time** is the time between consecutive frames of `r` (the
//!   camera's frame period: the finest interval ground-truth coverage is sampled at)
//!   where the later frame observed nothing new to the team while `r`'s latest odometry
//!   speed was at least [`UNPRODUCTIVE_SPEED_MPS`] — flying where it saw nothing its team
//!   had not seen. Unlike [`crate::monitor::UnproductiveTime`] there is no window and no
//!   volume threshold: one new cell makes the frame productive.
//!
//! Per robot, observed = first observed + re-explored. Over a team, the exclusive volumes
//! plus the volume observed by several robots make the explored volume. Counts are
//! integers (cells, nanoseconds), converted to m³ and seconds once when read, so results
//! depend only on the frames, never on summation order. Frames must come in time order
//! (the sim-time executor's order); a frame earlier than one already counted is taken at
//! its own time but revises nothing counted before.

use serde::{Deserialize, Serialize};
use troupe_core::Time;

use crate::monitor::UNPRODUCTIVE_SPEED_MPS;

/// No robot observed the cell (in [`ReExplorationLedger`]'s `sole`).
const UNSEEN: u32 = u32::MAX;
/// Several robots observed the cell.
const SHARED: u32 = u32::MAX - 1;

/// One robot's re-exploration figures (`summary.json` per robot, `timeseries.csv`);
/// definitions in the [module documentation](self).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReExploration {
    /// Volume the robot's frames observed, m³.
    pub observed_m3: f64,
    /// Volume the robot observed no later than any other robot (ties count for each
    /// robot in the tie), m³.
    pub first_observed_m3: f64,
    /// Volume the robot observed strictly after another robot had observed it, m³.
    pub reexplored_m3: f64,
    /// Volume only this robot observed, m³.
    pub exclusive_m3: f64,
    /// Time spent moving between frames that observed nothing new to the team, seconds.
    pub redundant_flight_s: f64,
}

/// The team's re-exploration figures (`summary.json`'s `reexploration`, study rows);
/// definitions in the [module documentation](self).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TeamReExploration {
    /// The robots' re-explored volumes summed (a cell re-explored by two robots counts
    /// twice), m³.
    pub reexplored_m3: f64,
    /// The robots' exclusive volumes summed, m³.
    pub exclusive_m3: f64,
    /// Volume observed by more than one robot, m³.
    pub shared_m3: f64,
    /// The robots' redundant flight times summed, seconds.
    pub redundant_flight_s: f64,
}

/// Integer counters of one robot.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Counts {
    observed_cells: u64,
    first_cells: u64,
    reexplored_cells: u64,
    exclusive_cells: u64,
    redundant_flight_ns: u64,
    /// Time of the robot's latest frame.
    last_frame: Option<Time>,
}

/// Who observed which ground-truth cell when; see the [module documentation](self).
#[derive(Clone, Debug, PartialEq)]
pub struct ReExplorationLedger {
    cell_m3: f64,
    /// Per cell, the time of its first observation (`Time::MAX`: none).
    first: Vec<Time>,
    /// Per cell, the one robot that observed it, [`SHARED`] or [`UNSEEN`].
    sole: Vec<u32>,
    /// Per robot, a bit per cell: observed.
    seen: Vec<Vec<u64>>,
    robots: Vec<Counts>,
    /// Cells observed by more than one robot.
    shared_cells: u64,
}

impl ReExplorationLedger {
    /// A ledger for `robots` robots over `cell_count` cells of edge `cell_m` metres.
    #[must_use]
    pub fn new(cell_count: usize, cell_m: f64, robots: usize) -> Self {
        ReExplorationLedger {
            cell_m3: cell_m.powi(3),
            first: vec![Time::MAX; cell_count],
            sole: vec![UNSEEN; cell_count],
            seen: vec![vec![0; cell_count.div_ceil(64)]; robots],
            robots: vec![Counts::default(); robots],
            shared_cells: 0,
        }
    }

    /// Starts accounting one frame of `robot` at `time`: report its cells with
    /// [`FrameAccount::saw`], then close it with [`FrameAccount::finish`]. `None` for a
    /// robot index outside the team.
    pub fn frame(&mut self, robot: usize, time: Time) -> Option<FrameAccount<'_>> {
        (robot < self.robots.len()).then_some(FrameAccount {
            ledger: self,
            robot,
            time,
            saw_new: false,
        })
    }

    /// Robot `robot`'s figures so far (zeros for an index outside the team).
    #[must_use]
    pub fn robot(&self, robot: usize) -> ReExploration {
        let Some(c) = self.robots.get(robot) else {
            return ReExploration::default();
        };
        ReExploration {
            observed_m3: c.observed_cells as f64 * self.cell_m3,
            first_observed_m3: c.first_cells as f64 * self.cell_m3,
            reexplored_m3: c.reexplored_cells as f64 * self.cell_m3,
            exclusive_m3: c.exclusive_cells as f64 * self.cell_m3,
            redundant_flight_s: Time::from_nanos(c.redundant_flight_ns).as_secs_f64(),
        }
    }

    /// The team's figures so far.
    #[must_use]
    pub fn team(&self) -> TeamReExploration {
        let sum = |f: fn(&Counts) -> u64| self.robots.iter().map(f).sum::<u64>();
        TeamReExploration {
            reexplored_m3: sum(|c| c.reexplored_cells) as f64 * self.cell_m3,
            exclusive_m3: sum(|c| c.exclusive_cells) as f64 * self.cell_m3,
            shared_m3: self.shared_cells as f64 * self.cell_m3,
            redundant_flight_s: Time::from_nanos(sum(|c| c.redundant_flight_ns)).as_secs_f64(),
        }
    }
}

/// One frame being accounted ([`ReExplorationLedger::frame`]).
#[derive(Debug)]
pub struct FrameAccount<'a> {
    ledger: &'a mut ReExplorationLedger,
    robot: usize,
    time: Time,
    saw_new: bool,
}

impl FrameAccount<'_> {
    /// The frame observed cell `cell` (a linear index; repeats are counted once, and an
    /// index outside the grid is ignored).
    pub fn saw(&mut self, cell: usize) {
        let l = &mut *self.ledger;
        let (word, bit) = (cell / 64, 1u64 << (cell % 64));
        let Some(seen) = l.seen[self.robot].get_mut(word) else {
            return;
        };
        if *seen & bit != 0 || cell >= l.first.len() {
            return;
        }
        *seen |= bit;
        let counts = &mut l.robots[self.robot];
        counts.observed_cells += 1;
        let first = &mut l.first[cell];
        if *first < self.time {
            counts.reexplored_cells += 1;
        } else {
            // Unseen, seen at this very time (a tie), or by a frame stamped later.
            *first = self.time;
            counts.first_cells += 1;
            self.saw_new = true;
        }
        let sole = &mut l.sole[cell];
        match *sole {
            UNSEEN => {
                *sole = self.robot as u32;
                counts.exclusive_cells += 1;
            }
            SHARED => {}
            other => {
                *sole = SHARED;
                l.shared_cells += 1;
                if let Some(c) = l.robots.get_mut(other as usize) {
                    c.exclusive_cells -= 1;
                }
            }
        }
    }

    /// Closes the frame, the robot's latest odometry speed being `speed_mps`: the time
    /// since its previous frame is redundant flight when this frame observed nothing new
    /// to the team and the speed is at least [`UNPRODUCTIVE_SPEED_MPS`] (a first frame,
    /// or one earlier than the previous, adds none). Returns whether the frame observed
    /// something new to the team.
    pub fn finish(self, speed_mps: f64) -> bool {
        let counts = &mut self.ledger.robots[self.robot];
        let step_ns = counts.last_frame.map_or(0, |last| {
            self.time.as_nanos().saturating_sub(last.as_nanos())
        });
        if !self.saw_new && speed_mps >= UNPRODUCTIVE_SPEED_MPS {
            counts.redundant_flight_ns += step_ns;
        }
        counts.last_frame = Some(counts.last_frame.map_or(self.time, |l| l.max(self.time)));
        self.saw_new
    }
}

#[cfg(test)]
mod tests;
