//! What each robot receives of its peers' broadcasts (issue 22): per-robot network
//! load that need not grow with the team.
//!
//! A robot's broadcast odometry, plans and keyframes are published under a key
//! naming a coarse square cell of the sender's own position (`cell_m` on a side,
//! in x and y of the team's shared frame; [`cell_segment`]). A robot with scope
//! [`Scope::Neighbourhood`] subscribes only to the cells near its own cell, and
//! re-subscribes when it enters another cell; with [`Scope::Base`] it subscribes
//! to none. Everything else stays team-wide whatever the scope: bulk messages,
//! frames addressed to one robot (acknowledgements, store-and-forward, catch-up),
//! and frames whose sender does not know its position yet (a base station that
//! never moves, a robot before its first odometry). Odometry is scoped too: at
//! 10 Hz from every peer it would otherwise be most of what a robot receives in a
//! large team, and grow with it. The selection happens in the network's routing
//! (zenoh key expressions and subscriptions; the simulated network's
//! [`SubscriptionConfig::receives`]), never by dropping what arrived.
//!
//! The cell set is chosen so that every sender within `radius_m` of the receiver
//! is in it: the cells whose square comes within `radius_m` of the receiver's
//! own cell's square. So a robot hears everyone within `radius_m`, and some
//! robots up to `radius_m` plus two cell diagonals away.
//!
//! Cells are computed in each robot's own odometry frame: the neighbourhood
//! scope needs robots that share a frame (a simulated team, or robots started
//! from a common origin); with `[[link.peer_frames]]` use [`Scope::All`].

use serde::{Deserialize, Serialize};

use crate::wire::Class;
use troupe_core::ConfigError;

/// Which peers' broadcast odometry, plans and keyframes a robot receives.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scope {
    /// Every peer's (the traffic grows with the team).
    #[default]
    All,
    /// Peers within `radius_m` of this robot's own odometry (and some beyond,
    /// see the [module docs](self)).
    Neighbourhood,
    /// None: only what is team-wide (bulk, addressed frames, and the base
    /// station's frames).
    Base,
}

/// A robot's subscription settings (`[robot.link.subscribe]`).
///
/// ```
/// use troupe_comms::scope::{Scope, SubscriptionConfig};
/// let config: SubscriptionConfig = toml::from_str(r#"
///     scope = "neighbourhood"
///     radius_m = 12.0
///     cell_m = 10.0
/// "#).unwrap();
/// config.validate().unwrap();
/// assert_eq!(config.scope, Scope::Neighbourhood);
/// // Every cell whose square comes within 12 m of the own cell's square: 5 × 5
/// // but the corners.
/// assert_eq!(config.cells_near((0, 0)).len(), 21);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SubscriptionConfig {
    /// What the robot receives.
    pub scope: Scope,
    /// Neighbourhood radius around the robot's own position, metres.
    pub radius_m: f64,
    /// Edge of the square cells odometry, plans and keyframes are published
    /// under, metres.
    /// Every robot of a team must use the same value (senders pick the cell).
    pub cell_m: f64,
}

impl Default for SubscriptionConfig {
    fn default() -> Self {
        SubscriptionConfig {
            scope: Scope::All,
            radius_m: 20.0,
            cell_m: 10.0,
        }
    }
}

/// Most cells one robot may subscribe to (one zenoh subscriber each).
pub const MAX_CELLS: usize = 1024;

/// A cell index: `(floor(x / cell_m), floor(y / cell_m))`.
pub type Cell = (i32, i32);

impl SubscriptionConfig {
    /// Checks the radius and the cell edge, and that the neighbourhood spans at
    /// most [`MAX_CELLS`] cells.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.radius_m.is_finite() && self.radius_m >= 0.0) {
            return Err(ConfigError::new(
                "radius_m",
                "must be a finite number ≥ 0",
                self.radius_m,
            ));
        }
        if !(self.cell_m.is_finite() && self.cell_m >= 0.5) {
            return Err(ConfigError::new(
                "cell_m",
                "must be a finite number ≥ 0.5",
                self.cell_m,
            ));
        }
        let reach = self.reach_cells() as usize;
        if (2 * reach + 1).pow(2) > MAX_CELLS {
            return Err(ConfigError::new(
                "radius_m",
                "spans more than 1024 cells of cell_m: use larger cells",
                self.radius_m,
            ));
        }
        Ok(())
    }

    /// Cells beyond the own one a neighbourhood reaches along an axis.
    fn reach_cells(&self) -> i32 {
        (self.radius_m / self.cell_m).ceil().min(1e6) as i32
    }

    /// The cell of a position; `None` for a position that is not finite or too
    /// far out for a cell index.
    #[must_use]
    pub fn cell_of(&self, position_m: [f64; 3]) -> Option<Cell> {
        let index = |v: f64| {
            let i = (v / self.cell_m).floor();
            (i.is_finite() && i.abs() < f64::from(i32::MAX / 2)).then_some(i as i32)
        };
        Some((index(position_m[0])?, index(position_m[1])?))
    }

    /// The cells a robot in cell `own` subscribes to under
    /// [`Scope::Neighbourhood`]: those whose square comes within `radius_m` of
    /// `own`'s square, in a fixed order.
    #[must_use]
    pub fn cells_near(&self, own: Cell) -> Vec<Cell> {
        let reach = self.reach_cells();
        let gap = |d: i32| f64::from((d.abs() - 1).max(0)) * self.cell_m;
        let mut cells = Vec::new();
        for dx in -reach..=reach {
            for dy in -reach..=reach {
                if gap(dx).hypot(gap(dy)) <= self.radius_m {
                    cells.push((own.0.saturating_add(dx), own.1.saturating_add(dy)));
                }
            }
        }
        cells
    }

    /// The cells a robot at `position_m` subscribes to under this scope (none
    /// for [`Scope::All`], which subscribes to everything, and for a position
    /// that has no cell).
    #[must_use]
    pub fn subscribed_cells(&self, position_m: Option<[f64; 3]>) -> Vec<Cell> {
        match (self.scope, position_m.and_then(|p| self.cell_of(p))) {
            (Scope::Neighbourhood, Some(own)) => self.cells_near(own),
            _ => Vec::new(),
        }
    }

    /// The cell a frame is published under: broadcast odometry, plans and
    /// keyframes of a sender that knows its position, when the scope is not
    /// [`Scope::All`] (a team shares one scope: the scenario's); `None`: the
    /// team-wide key.
    #[must_use]
    pub fn publish_cell(
        &self,
        class: Class,
        addressed: bool,
        sender_m: Option<[f64; 3]>,
    ) -> Option<Cell> {
        if self.scope == Scope::All || addressed || class == Class::Bulk {
            return None;
        }
        sender_m.and_then(|p| self.cell_of(p))
    }

    /// Whether a robot at `receiver_m` with these settings gets a frame of
    /// `class` sent from `sender_m` by a robot with the same settings: the
    /// same decision zenoh's routing makes for the keys of
    /// [`publish_cell`](Self::publish_cell) and the subscriptions of
    /// [`subscribed_cells`](Self::subscribed_cells). The simulated network calls it.
    #[must_use]
    pub fn receives(
        &self,
        class: Class,
        addressed: bool,
        sender_m: Option<[f64; 3]>,
        receiver_m: Option<[f64; 3]>,
    ) -> bool {
        if self.scope == Scope::All {
            return true;
        }
        match self.publish_cell(class, addressed, sender_m) {
            None => true,
            Some(cell) => self.subscribed_cells(receiver_m).contains(&cell),
        }
    }
}

/// The key-expression segment of a cell: `c<x>_<y>`, e.g. `c-3_12`.
#[must_use]
pub fn cell_segment(cell: Cell) -> String {
    format!("c{}_{}", cell.0, cell.1)
}

/// Parses [`cell_segment`]'s output.
#[must_use]
pub fn parse_cell_segment(segment: &str) -> Option<Cell> {
    let (x, y) = segment.strip_prefix('c')?.split_once('_')?;
    Some((x.parse().ok()?, y.parse().ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn neighbourhood(radius_m: f64, cell_m: f64) -> SubscriptionConfig {
        SubscriptionConfig {
            scope: Scope::Neighbourhood,
            radius_m,
            cell_m,
        }
    }

    #[test]
    fn cells_cover_every_sender_within_the_radius() {
        let config = neighbourhood(12.0, 5.0);
        let receivers = [[0.1, 0.2, 0.0], [4.9, -7.3, 2.0], [-13.0, 22.5, 0.0]];
        for r in receivers {
            for k in 0..400 {
                let angle = f64::from(k) * 0.157;
                let distance = f64::from(k % 20) * 0.6;
                let s = [
                    r[0] + distance * angle.cos(),
                    r[1] + distance * angle.sin(),
                    0.0,
                ];
                assert!(
                    config.receives(Class::Keyframe, false, Some(s), Some(r)),
                    "{s:?} from {r:?}"
                );
            }
        }
        // Far away: not subscribed.
        let far = [60.0, 0.0, 0.0];
        assert!(!config.receives(Class::Keyframe, false, Some(far), Some([0.0; 3])));
        assert!(!config.receives(Class::Plan, false, Some(far), Some([0.0; 3])));
    }

    #[test]
    fn team_wide_frames_reach_every_scope() {
        let far = Some([500.0, 0.0, 0.0]);
        let here = Some([0.0; 3]);
        for scope in [Scope::Neighbourhood, Scope::Base] {
            let config = SubscriptionConfig {
                scope,
                ..SubscriptionConfig::default()
            };
            assert!(!config.receives(Class::Odometry, false, far, here));
            assert!(config.receives(Class::Bulk, false, far, here));
            assert!(config.receives(Class::Keyframe, true, far, here));
            assert!(config.receives(Class::Odometry, true, far, here));
            assert!(config.receives(Class::Keyframe, false, None, here));
            let own_cell = config.receives(Class::Keyframe, false, here, here);
            assert_eq!(own_cell, scope == Scope::Neighbourhood);
        }
        let all = SubscriptionConfig::default();
        assert!(all.receives(Class::Keyframe, false, far, here));
        assert!(all.subscribed_cells(here).is_empty());
    }

    #[test]
    fn a_receiver_without_a_position_gets_no_cell() {
        let config = neighbourhood(20.0, 10.0);
        assert!(!config.receives(Class::Keyframe, false, Some([0.0; 3]), None));
        assert!(config.cell_of([f64::NAN, 0.0, 0.0]).is_none());
        assert!(config.cell_of([1e300, 0.0, 0.0]).is_none());
        assert_eq!(config.cell_of([-0.1, 19.9, 0.0]), Some((-1, 1)));
    }

    #[test]
    fn cell_segments_round_trip_and_reject_garbage() {
        for cell in [(0, 0), (-3, 12), (i32::MAX / 2 - 1, -7)] {
            assert_eq!(parse_cell_segment(&cell_segment(cell)), Some(cell));
        }
        for bad in ["", "c", "c1", "c1_", "x1_2", "c1_2_3", "c_1", "c1_2x"] {
            assert_eq!(parse_cell_segment(bad), None, "{bad}");
        }
    }

    #[test]
    fn validation_names_the_key() {
        let bad = |radius_m: f64, cell_m: f64| neighbourhood(radius_m, cell_m).validate();
        assert_eq!(bad(f64::NAN, 10.0).unwrap_err().key, "radius_m");
        assert_eq!(bad(-1.0, 10.0).unwrap_err().key, "radius_m");
        assert_eq!(bad(10.0, 0.0).unwrap_err().key, "cell_m");
        assert_eq!(bad(10.0, f64::INFINITY).unwrap_err().key, "cell_m");
        assert_eq!(bad(1000.0, 1.0).unwrap_err().key, "radius_m");
        bad(0.0, 10.0).unwrap();
        assert_eq!(neighbourhood(0.0, 10.0).cells_near((2, 2)), vec![(2, 2)]);
    }
}
