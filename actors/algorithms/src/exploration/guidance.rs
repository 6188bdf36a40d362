//! Global guidance: the route distance from anywhere in known passable space to the
//! nearest remembered frontier (paper Alg. 1, V-B: the frontier-distance reward
//! V = d(ξ₀) − d(ξτ), here over the team's frontier memory instead of the window),
//! with frontiers that peers are heading to made longer (implicit coordination).

use std::cmp::Ordering;
use std::collections::{BTreeSet, BinaryHeap, HashMap};
use std::hash::BuildHasherDefault;

use nalgebra::Point3;

use super::memory::{CellKey, FrontierMemory};

/// Where a peer is and where it is heading (the end of its committed plan).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeerIntent {
    /// The peer's latest position.
    pub position_m: Point3<f64>,
    /// Where its committed plan ends.
    pub goal_m: Point3<f64>,
}

/// How frontiers are weighed when the field is built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldParams {
    /// A frontier within this distance of a peer's goal, and closer to that goal than to
    /// this robot, is the peer's claim, metres.
    pub claim_radius_m: f64,
    /// Route length added to a claimed frontier, metres.
    pub claim_penalty_m: f64,
    /// How far ahead of a pose [`GuidanceField::pose_distance_m`] measures, metres.
    pub look_ahead_m: f64,
}

/// A deterministic hasher: lookups only (the field is never iterated to decide).
type Fixed = BuildHasherDefault<std::collections::hash_map::DefaultHasher>;

/// Route distance (metres) from passable memory cells to the nearest remembered
/// frontier, plus the claim penalty of that frontier: multi-source Dijkstra over the
/// 26-connected passable cells. A frontier cell is seldom passable itself (it borders
/// unknown, unsafe space): it seeds the passable cells of its 26-neighbourhood.
///
/// Time: `O(c log c)` for `c` passable cells; memory: one entry per reached cell.
#[derive(Clone, Debug)]
pub struct GuidanceField {
    cell_m: f64,
    key_scale: f64,
    look_ahead_m: f64,
    distance_m: HashMap<CellKey, (f64, CellKey), Fixed>,
    frontiers: usize,
}

/// A heap entry ordered by cost, then key (deterministic ties), smallest first.
#[derive(Clone, Copy, PartialEq)]
struct Entry {
    cost_m: f64,
    key: CellKey,
    target: CellKey,
}

impl Eq for Entry {}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .cost_m
            .total_cmp(&self.cost_m)
            .then_with(|| other.key.cmp(&self.key))
    }
}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

fn neighbours(key: CellKey) -> impl Iterator<Item = (CellKey, f64)> {
    (-1i32..=1).flat_map(move |dz| {
        (-1i32..=1).flat_map(move |dy| {
            (-1i32..=1).filter_map(move |dx| {
                if dx == 0 && dy == 0 && dz == 0 {
                    return None;
                }
                let step = f64::from(dx * dx + dy * dy + dz * dz).sqrt();
                Some(([key[0] + dx, key[1] + dy, key[2] + dz], step))
            })
        })
    })
}

impl GuidanceField {
    /// The field over `memory` for a robot at `robot_m`, with the `peers`' claims;
    /// the frontiers in `given_up` do not seed it.
    #[must_use]
    pub fn build(
        memory: &FrontierMemory,
        robot_m: &Point3<f64>,
        peers: &[PeerIntent],
        given_up: &BTreeSet<CellKey>,
        params: &FieldParams,
    ) -> Self {
        let cell_m = memory.cell_m();
        let mut heap = BinaryHeap::new();
        let mut frontiers = 0;
        for f in memory.frontiers().filter(|f| !given_up.contains(f)) {
            let centre = memory.centre(f);
            let mine_m = (centre - robot_m).norm();
            let claimed = peers.iter().any(|peer| {
                let theirs_m = (centre - peer.goal_m).norm();
                theirs_m <= params.claim_radius_m && theirs_m < mine_m
            });
            let penalty_m = if claimed { params.claim_penalty_m } else { 0.0 };
            let mut seeded = false;
            for (n, step) in std::iter::once((f, 0.0)).chain(neighbours(f)) {
                if memory.record(n).passable {
                    seeded = true;
                    heap.push(Entry {
                        cost_m: step * cell_m + penalty_m,
                        key: n,
                        target: f,
                    });
                }
            }
            frontiers += usize::from(seeded);
        }
        let mut distance_m: HashMap<CellKey, (f64, CellKey), Fixed> = HashMap::default();
        while let Some(Entry {
            cost_m,
            key,
            target,
        }) = heap.pop()
        {
            if distance_m.contains_key(&key) {
                continue;
            }
            distance_m.insert(key, (cost_m, target));
            for (n, step) in neighbours(key) {
                if !distance_m.contains_key(&n) && memory.record(n).passable {
                    heap.push(Entry {
                        cost_m: cost_m + step * cell_m,
                        key: n,
                        target,
                    });
                }
            }
        }
        GuidanceField {
            cell_m,
            key_scale: 1.0 / cell_m,
            look_ahead_m: params.look_ahead_m,
            distance_m,
            frontiers,
        }
    }

    /// Remembered frontiers that seed the field (next to a passable cell).
    #[must_use]
    pub fn frontier_count(&self) -> usize {
        self.frontiers
    }

    fn key_of(&self, p: &Point3<f64>) -> Option<CellKey> {
        let k = p.coords.map(|v| (v * self.key_scale).floor());
        k.iter()
            .all(|v| v.is_finite() && v.abs() < 1e9)
            .then(|| [k.x as i32, k.y as i32, k.z as i32])
    }

    fn centre(&self, key: CellKey) -> Point3<f64> {
        Point3::new(
            (f64::from(key[0]) + 0.5) * self.cell_m,
            (f64::from(key[1]) + 0.5) * self.cell_m,
            (f64::from(key[2]) + 0.5) * self.cell_m,
        )
    }

    /// The route distance from `p` to the best frontier, metres, and that frontier's
    /// cell: the least of `d(n) + |p − centre(n)|` over the reached cells `n` of the
    /// cell holding `p` and its 26 neighbours (∞ and `None` when none was reached).
    #[must_use]
    pub fn distance_at(&self, p: &Point3<f64>) -> (f64, Option<CellKey>) {
        let Some(key) = self.key_of(p) else {
            return (f64::INFINITY, None);
        };
        std::iter::once((key, 0.0))
            .chain(neighbours(key))
            .filter_map(|(n, _)| {
                self.distance_m
                    .get(&n)
                    .map(|(d, target)| (d + (p - self.centre(n)).norm(), *target))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0).then_with(|| a.1.cmp(&b.1)))
            .map_or((f64::INFINITY, None), |(d, t)| (d, Some(t)))
    }

    /// The route distance from `p` to the best frontier, metres (∞ off the field).
    #[must_use]
    pub fn distance_m(&self, p: &Point3<f64>) -> f64 {
        self.distance_at(p).0
    }

    /// The route distance measured from the point `look_ahead_m` ahead of a pose at
    /// `p` heading `yaw_rad` (level), or from `p` itself when that point is off the
    /// field: a robot that turns to face its route gains, so a robot at a dead end
    /// turns round instead of hovering.
    #[must_use]
    pub fn pose_distance_m(&self, p: &Point3<f64>, yaw_rad: f64) -> f64 {
        let ahead =
            p + nalgebra::Vector3::new(yaw_rad.cos(), yaw_rad.sin(), 0.0) * self.look_ahead_m;
        let d = self.distance_m(&ahead);
        if d.is_finite() { d } else { self.distance_m(p) }
    }

    /// The frontier the route from `p` leads to, if any.
    #[must_use]
    pub fn target_of(&self, p: &Point3<f64>) -> Option<CellKey> {
        self.distance_at(p).1
    }
}
