//! Global guidance: the route distance from anywhere in known passable space to the
//! nearest remembered frontier (paper Alg. 1, V-B: the frontier-distance reward
//! V = d(ξ₀) − d(ξτ), here over the team's frontier memory instead of the window),
//! with the frontiers claimed by peers made longer ([`Coordination`]).

use std::cmp::Ordering;
use std::collections::{BTreeMap, BTreeSet, BinaryHeap, HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

use nalgebra::Point3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use troupe_core::{RobotId, Time};

use super::memory::{CellKey, FrontierMemory};
use crate::camera::PinholeIntrinsics;
use crate::planner::problem::FrontierField;

/// Where a peer is and where it is heading (the end of its committed plan).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeerIntent {
    /// The peer's latest position.
    pub position_m: Point3<f64>,
    /// Where its committed plan ends.
    pub goal_m: Point3<f64>,
}

/// How a robot decides which remembered frontiers its peers have claimed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Coordination {
    /// A frontier within the claim radius of where a peer's committed plan ends, and
    /// closer to that end than to this robot, is the peer's.
    PlanEnd,
    /// Every robot this robot knows of (itself and its peers, at their latest positions)
    /// is given a frontier greedily, cheapest route first (ties by robot id, so every
    /// robot computes the same assignment from the same memory); the frontiers within
    /// the claim radius of a peer's are the peer's. Greedy assignment of targets by
    /// travel cost with the utility of targets near an assigned one reduced is the
    /// coordination of Burgard et al. (IEEE T-RO 2005); the thesis' teams coordinate
    /// only implicitly (§8.2), which leaves robots side by side at a fork entering the
    /// same branch.
    #[default]
    Assignment,
    /// No claims: a robot learns where its peers have been only from the maps it
    /// receives (their keyframes or grid changes retire the frontiers they saw), never
    /// from their plans or positions. This is the thesis' coordination in its link
    /// study, which kept "the planning and coordination methodology the same" for both
    /// map representations (§8.2.7, Fig. 8.9): the only way a peer's work reaches a
    /// robot is through its map, so what the link drops a robot may fly again.
    MapsOnly,
}

/// How frontiers are weighed when the field is built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldParams {
    /// How the peers' claims are decided.
    pub coordination: Coordination,
    /// Smallest region of 26-connected frontier cells that seeds the field as it is.
    pub min_region_cells: usize,
    /// Route length added to the frontiers of a smaller region, metres; `None` leaves
    /// them out.
    pub small_region_penalty_m: Option<f64>,
    /// A frontier within this distance of the frontier assigned to a peer (or, for
    /// [`Coordination::PlanEnd`], of its plan's end and closer to it than to this robot)
    /// is the peer's claim, metres.
    pub claim_radius_m: f64,
    /// Route length added to a claimed frontier, metres.
    pub claim_penalty_m: f64,
    /// Route length added, for this robot only, to the frontiers farther than the claim
    /// radius from the frontier its route led to last round, metres (0: none).
    pub switch_penalty_m: f64,
    /// How far ahead of a pose [`GuidanceField::pose_distance_m`] measures, metres.
    pub look_ahead_m: f64,
    /// What the camera sees: a frontier then seeds the field at its viewpoints
    /// ([`viewpoints`]); `None`: at the passable cells beside it.
    pub view: Option<ViewCone>,
}

/// What a level camera that yaws with its robot sees from a point: everything within
/// `range_m` between `down_rad` below and `up_rad` above the horizontal (the
/// horizontal field of view does not limit it, since the robot can turn). Used to judge
/// remembered frontiers by their viewpoints, as FUEL (Zhou et al., RA-L 2021) samples
/// viewpoints around each frontier cluster: a frontier that no passable place sees is no
/// goal (issue 43).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewCone {
    /// Steepest view upwards, radians above the horizontal.
    pub up_rad: f64,
    /// Steepest view downwards, radians below the horizontal.
    pub down_rad: f64,
    /// Farthest a viewpoint may be from what it sees, metres.
    pub range_m: f64,
}

impl ViewCone {
    /// The cone of a level pinhole camera (rows above its principal point look up),
    /// reaching `range_m` or the camera's largest depth, whichever is less.
    #[must_use]
    pub fn of_camera(camera: &PinholeIntrinsics, range_m: f64) -> Self {
        let fy = camera.fy.max(f64::MIN_POSITIVE);
        ViewCone {
            up_rad: (camera.cy.max(0.0) / fy).atan(),
            down_rad: ((f64::from(camera.height) - camera.cy).max(0.0) / fy).atan(),
            range_m: range_m.min(camera.max_depth_m),
        }
    }

    /// Whether a camera at `eye_m` can look at `target_m`: within range and between the
    /// steepest views (straight up or down only with a field of view past ±90°).
    #[must_use]
    pub fn reaches(&self, eye_m: &Point3<f64>, target_m: &Point3<f64>) -> bool {
        let d = target_m - eye_m;
        let elevation_rad = d.z.atan2(d.x.hypot(d.y));
        d.norm() <= self.range_m && elevation_rad <= self.up_rad && elevation_rad >= -self.down_rad
    }
}

/// Whether the straight line from the centre of cell `eye` to the centre of the frontier
/// `f` crosses only passable cells or the robot's trail, apart from `eye` itself and
/// `f`'s 26 neighbours (a frontier borders unknown space): sampled every half cell.
fn line_of_sight(memory: &FrontierMemory, eye: CellKey, f: CellKey) -> bool {
    let (eye_m, target_m) = (memory.centre(eye), memory.centre(f));
    let steps = (2.0 * (target_m - eye_m).norm() / memory.cell_m()).ceil() as usize;
    let near_f = |k: CellKey| (0..3).all(|i| (k[i] - f[i]).abs() <= 1);
    (1..steps).all(|s| {
        let p = eye_m + (target_m - eye_m) * (s as f64 / steps as f64);
        memory.key_of(&p).is_some_and(|k| {
            k == eye || near_f(k) || memory.record(k).passable || memory.on_trail(k)
        })
    })
}

/// The places from which a robot attends to the frontier `f`, with the straight distance
/// from each to `f`'s centre, metres, in key order.
///
/// With a `view`: its viewpoints — every passable cell whose centre the cone lets look at
/// `f`'s centre along a line of sight through passable cells or the robot's trail (the
/// frontier's own 26 neighbours excepted: a frontier borders unknown space). A pocket
/// under the floor seen only from straight above, or a cell behind a wall, has none.
/// Without: the passable cells among `f` and its 26 neighbours.
///
/// Time: `(2⌈range / cell⌉ + 1)³` cells looked at, each with a line of at most
/// `2 range / cell` steps.
#[must_use]
pub fn viewpoints(
    memory: &FrontierMemory,
    f: CellKey,
    view: Option<&ViewCone>,
) -> Vec<(CellKey, f64)> {
    let cell_m = memory.cell_m();
    let Some(view) = view else {
        return std::iter::once((f, 0.0))
            .chain(neighbours(f))
            .filter(|(n, _)| memory.record(*n).passable)
            .map(|(n, step)| (n, step * cell_m))
            .collect();
    };
    let target_m = memory.centre(f);
    let reach = (view.range_m / cell_m).ceil().clamp(1.0, 64.0) as i32;
    let mut found = Vec::new();
    for dx in -reach..=reach {
        for dy in -reach..=reach {
            for dz in -reach..=reach {
                let v = [f[0] + dx, f[1] + dy, f[2] + dz];
                let eye_m = memory.centre(v);
                if v == f || !view.reaches(&eye_m, &target_m) || !memory.record(v).passable {
                    continue;
                }
                if line_of_sight(memory, v, f) {
                    found.push((v, (target_m - eye_m).norm()));
                }
            }
        }
    }
    found
}

/// A deterministic hasher for cell keys: lookups only (the field is never iterated to
/// decide), so the hash function changes the speed, never a route.
type Fixed = BuildHasherDefault<CellHasher>;

/// A multiply–rotate hash over 64-bit words (the scheme of rustc's `FxHasher`): a few
/// instructions for a cell key, where SipHash took a fifth of a Dijkstra's time.
#[derive(Default)]
struct CellHasher(u64);

impl CellHasher {
    fn add(&mut self, word: u64) {
        self.0 = (self.0.rotate_left(5) ^ word).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
}

impl Hasher for CellHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.add(u64::from_le_bytes(word));
        }
    }

    fn write_usize(&mut self, n: usize) {
        self.add(n as u64);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

/// Route distance (metres) from passable memory cells to the nearest remembered
/// frontier, plus the claim penalty of that frontier: multi-source Dijkstra over the
/// 26-connected passable cells. A frontier cell is seldom passable itself (it borders
/// unknown, unsafe space): it seeds the field at its [`viewpoints`].
///
/// Time: `O(c log c)` for `c` passable cells; memory: one entry per reached cell.
#[derive(Clone, Debug)]
pub struct GuidanceField {
    cell_m: f64,
    key_scale: f64,
    look_ahead_m: f64,
    distance_m: HashMap<CellKey, (f64, CellKey), Fixed>,
    /// The frontiers that seed the field (those with a viewpoint or a passable
    /// neighbour).
    seeded: BTreeSet<CellKey>,
    /// The goal of a field [`Self::towards`] a point, and its cell.
    goal: Option<(Point3<f64>, CellKey)>,
}

/// The cells of `frontiers` with the route length each one's region adds, in key
/// order: nothing for a region of at least `min_cells` 26-connected frontier cells,
/// `small_penalty_m` for a smaller one, whose cells are left out when that is `None`.
fn weigh_regions(
    frontiers: BTreeSet<CellKey>,
    min_cells: usize,
    small_penalty_m: Option<f64>,
) -> Vec<(CellKey, f64)> {
    if min_cells <= 1 {
        return frontiers.into_iter().map(|f| (f, 0.0)).collect();
    }
    let mut weighed = BTreeMap::new();
    let mut visited = BTreeSet::new();
    for &start in &frontiers {
        if !visited.insert(start) {
            continue;
        }
        let mut region = vec![start];
        let mut next = 0;
        while let Some(&key) = region.get(next) {
            next += 1;
            for (n, _) in neighbours(key) {
                if frontiers.contains(&n) && visited.insert(n) {
                    region.push(n);
                }
            }
        }
        let extra_m = if region.len() >= min_cells {
            Some(0.0)
        } else {
            small_penalty_m
        };
        if let Some(extra_m) = extra_m {
            weighed.extend(region.into_iter().map(|f| (f, extra_m)));
        }
    }
    weighed.into_iter().collect()
}

/// Route distance (metres) from `from` to every cell that `passable` admits and that it
/// reaches, from the cell holding `from` (or its passable neighbours when that cell is
/// not passable).
fn routes_from(
    memory: &FrontierMemory,
    from: &Point3<f64>,
    passable: &dyn Fn(CellKey) -> bool,
) -> Reached {
    let Some(start) = memory.key_of(from) else {
        return Reached::default();
    };
    spread(memory, route_seeds(memory, from, start, passable), passable)
}

/// The seeds of a Dijkstra from the point `from` in cell `start`: that cell and its
/// passable neighbours, at their straight distance.
fn route_seeds(
    memory: &FrontierMemory,
    from: &Point3<f64>,
    start: CellKey,
    passable: &dyn Fn(CellKey) -> bool,
) -> BinaryHeap<Entry> {
    std::iter::once(start)
        .chain(neighbours(start).map(|(n, _)| n))
        .filter(|n| passable(*n))
        .map(|n| Entry {
            cost_m: (memory.centre(n) - from).norm(),
            key: n,
            target: start,
        })
        .collect()
}

/// The passable cells of `memory`, gathered once for the Dijkstras of a field (a hash
/// lookup instead of a walk down the memory's tree for each of a cell's 26 neighbours).
fn passable_in(memory: &FrontierMemory) -> HashSet<CellKey, Fixed> {
    memory.passable().collect()
}

/// How near the goal's cell a retraced route may leave the robot's trail, in cells along
/// each axis ([`GuidanceField::retracing`]).
const RETRACE_GOAL_CELLS: i32 = 2;

/// Each reached cell's least route cost, metres, and the target of the seed it came from.
type Reached = HashMap<CellKey, (f64, CellKey), Fixed>;

/// Dijkstra over the 26-connected cells of `memory` that `passable` admits, from the
/// `seeds`.
///
/// Time: `O(c log c)` for `c` passable cells; memory: one entry per reached cell.
fn spread(
    memory: &FrontierMemory,
    seeds: BinaryHeap<Entry>,
    passable: &dyn Fn(CellKey) -> bool,
) -> Reached {
    let mut dijkstra = Dijkstra {
        heap: seeds,
        reached: Reached::default(),
    };
    while dijkstra.next_cost_m().is_some() {
        dijkstra.settle(memory, passable);
    }
    dijkstra.reached
}

/// A Dijkstra of [`spread`], a settled cell at a time (the assignment advances the
/// robots' together).
struct Dijkstra {
    heap: BinaryHeap<Entry>,
    reached: Reached,
}

impl Dijkstra {
    /// A lower bound on the cost of the next settled cell; `None` when none is left.
    fn next_cost_m(&self) -> Option<f64> {
        self.heap.peek().map(|e| e.cost_m)
    }

    /// Settles the next cell: its key and route cost, or `None` when the entry taken was
    /// of a cell settled before (or none was left).
    fn settle(
        &mut self,
        memory: &FrontierMemory,
        passable: &dyn Fn(CellKey) -> bool,
    ) -> Option<(CellKey, f64)> {
        let Entry {
            cost_m,
            key,
            target,
        } = self.heap.pop()?;
        if self.reached.contains_key(&key) {
            return None;
        }
        self.reached.insert(key, (cost_m, target));
        let cell_m = memory.cell_m();
        for (n, step) in neighbours(key) {
            if !self.reached.contains_key(&n) && passable(n) {
                self.heap.push(Entry {
                    cost_m: cost_m + step * cell_m,
                    key: n,
                    target,
                });
            }
        }
        Some((key, cost_m))
    }
}

/// The frontiers of `open` that the greedy assignment ([`Coordination::Assignment`])
/// gives to a peer of `own`: each robot's route cost to each frontier over the cells of
/// `memory` that `passable` admits (through one of its `approaches`, as the field seeds
/// it; plus the frontier's region weight and, for `own`, its cost of switching);
/// repeatedly the cheapest (robot, frontier) pair whose robot has no frontier yet and
/// whose frontier is unclaimed is assigned (ties by robot, then frontier), and the
/// unclaimed frontiers within `claim_radius_m` of it become that robot's.
///
/// The robots' Dijkstras advance together, the least settled cost first, and a pair is
/// assigned once no robot still without a frontier can settle a cell below its cost
/// (no pair is cheaper than the route to its approach, the costs added being ≥ 0); a
/// robot's Dijkstra stops when it is given a frontier, and all stop once every robot
/// has one or every frontier is claimed. The result is that of ranking every pair of
/// full Dijkstras, which a test checks, at the cost of the routes up to each robot's
/// frontier.
///
/// Time: at most one Dijkstra per robot, `O(r · c log c)` for `r` robots and `c`
/// passable cells.
fn claimed_by_assignment(
    (memory, passable): (&FrontierMemory, &dyn Fn(CellKey) -> bool),
    open: &[(CellKey, f64)],
    approaches: &[Vec<(CellKey, f64)>],
    (own, own_m): (RobotId, &Point3<f64>),
    own_extra_m: &dyn Fn(&CellKey) -> f64,
    peers: &BTreeMap<RobotId, PeerIntent>,
    claim_radius_m: f64,
) -> BTreeSet<CellKey> {
    let robots: Vec<(RobotId, Point3<f64>)> = std::iter::once((own, *own_m))
        .chain(
            peers
                .iter()
                .filter(|(id, _)| **id != own)
                .map(|(id, peer)| (*id, peer.position_m)),
        )
        .collect();
    // The frontiers each cell is an approach of, with the view's cost.
    let mut approached: HashMap<CellKey, Vec<(usize, f64)>, Fixed> = HashMap::default();
    for (i, views) in approaches.iter().enumerate() {
        for &(n, view_m) in views {
            approached.entry(n).or_default().push((i, view_m));
        }
    }
    // `None` once the robot has a frontier.
    let mut searches: Vec<Option<Dijkstra>> = robots
        .iter()
        .map(|(_, position_m)| {
            Some(Dijkstra {
                heap: memory
                    .key_of(position_m)
                    .map(|start| route_seeds(memory, position_m, start, passable))
                    .unwrap_or_default(),
                reached: Reached::default(),
            })
        })
        .collect();
    // The robots still without a frontier, by the least cost each may settle next.
    let mut next: BinaryHeap<Cheapest<usize>> = searches
        .iter()
        .enumerate()
        .filter_map(|(r, search)| {
            let cost_m = search.as_ref()?.next_cost_m()?;
            Some(Cheapest { cost_m, item: r })
        })
        .collect();
    // (robot, frontier) pairs by cost, then robot id, then frontier, with the robot's
    // index.
    let mut pairs: BinaryHeap<Cheapest<(RobotId, CellKey, usize)>> = BinaryHeap::new();
    let mut owner: BTreeMap<CellKey, RobotId> = BTreeMap::new();
    let mut unassigned = robots.len();
    while unassigned > 0 && owner.len() < open.len() {
        if let Some(pair) = pairs.peek()
            && next.peek().is_none_or(|e| pair.cost_m < e.cost_m)
        {
            let (_, f, robot) = pairs.pop().expect("peeked").item;
            if searches[robot].is_none() || owner.contains_key(&f) {
                continue;
            }
            searches[robot] = None;
            unassigned -= 1;
            let id = robots[robot].0;
            let centre = memory.centre(f);
            for &(g, _) in open {
                if (memory.centre(g) - centre).norm() <= claim_radius_m {
                    owner.entry(g).or_insert(id);
                }
            }
            continue;
        }
        let Some(Cheapest { item: r, .. }) = next.pop() else {
            break;
        };
        let Some(search) = searches[r].as_mut() else {
            continue;
        };
        let settled = search.settle(memory, passable);
        if let Some(cost_m) = search.next_cost_m() {
            next.push(Cheapest { cost_m, item: r });
        }
        let Some((n, route_m)) = settled else {
            continue;
        };
        let id = robots[r].0;
        for &(i, view_m) in approached.get(&n).into_iter().flatten() {
            let (f, extra_m) = open[i];
            let mine_m = if id == own { own_extra_m(&f) } else { 0.0 };
            let cost_m = extra_m + mine_m + (route_m + view_m);
            if cost_m.is_finite() {
                pairs.push(Cheapest {
                    cost_m,
                    item: (id, f, r),
                });
            }
        }
    }
    owner
        .into_iter()
        .filter_map(|(f, id)| (id != own).then_some(f))
        .collect()
}

/// A min-heap entry: `item` ordered by `cost_m`, then by `item`, smallest first.
#[derive(Clone, Copy, Debug)]
struct Cheapest<T> {
    cost_m: f64,
    item: T,
}

impl<T: Ord> Ord for Cheapest<T> {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .cost_m
            .total_cmp(&self.cost_m)
            .then_with(|| other.item.cmp(&self.item))
    }
}

impl<T: Ord> PartialOrd for Cheapest<T> {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl<T: Ord> PartialEq for Cheapest<T> {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl<T: Ord> Eq for Cheapest<T> {}

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
    /// The field over `memory` for robot `own` at `robot_m`, with the `peers`' claims;
    /// the frontiers in `given_up` do not seed it; those far from `last_target` (the
    /// frontier this robot's route led to last round, while it is still open) cost
    /// [`FieldParams::switch_penalty_m`] more.
    #[must_use]
    pub fn build(
        memory: &FrontierMemory,
        (own, robot_m): (RobotId, &Point3<f64>),
        peers: &BTreeMap<RobotId, PeerIntent>,
        given_up: &BTreeMap<CellKey, Time>,
        last_target: Option<CellKey>,
        params: &FieldParams,
    ) -> Self {
        let cell_m = memory.cell_m();
        let open = weigh_regions(
            memory
                .frontiers()
                .filter(|f| !given_up.contains_key(f))
                .collect(),
            params.min_region_cells,
            params.small_region_penalty_m,
        );
        // Each frontier's viewpoints are independent: on the rayon pool, in key order.
        let approaches: Vec<Vec<(CellKey, f64)>> = open
            .par_iter()
            .map(|(f, _)| viewpoints(memory, *f, params.view.as_ref()))
            .collect();
        // This robot's own cost of leaving the frontier it was heading to.
        let switching: BTreeSet<CellKey> = match last_target.filter(|t| {
            params.switch_penalty_m > 0.0 && open.binary_search_by_key(t, |(f, _)| *f).is_ok()
        }) {
            Some(last) => {
                let kept = memory.centre(last);
                open.iter()
                    .map(|(f, _)| *f)
                    .filter(|f| (memory.centre(*f) - kept).norm() > params.claim_radius_m)
                    .collect()
            }
            None => BTreeSet::new(),
        };
        let own_extra_m = |f: &CellKey| {
            if switching.contains(f) {
                params.switch_penalty_m
            } else {
                0.0
            }
        };
        let passable_cells = passable_in(memory);
        let passable = |key: CellKey| passable_cells.contains(&key);
        let claimed = match params.coordination {
            Coordination::PlanEnd => open
                .iter()
                .map(|(f, _)| *f)
                .filter(|&f| {
                    let centre = memory.centre(f);
                    let mine_m = (centre - robot_m).norm();
                    peers.values().any(|peer| {
                        let theirs_m = (centre - peer.goal_m).norm();
                        theirs_m <= params.claim_radius_m && theirs_m < mine_m
                    })
                })
                .collect(),
            Coordination::Assignment => claimed_by_assignment(
                (memory, &passable),
                &open,
                &approaches,
                (own, robot_m),
                &own_extra_m,
                peers,
                params.claim_radius_m,
            ),
            Coordination::MapsOnly => BTreeSet::new(),
        };
        let mut heap = BinaryHeap::new();
        let mut seeded = BTreeSet::new();
        for (&(f, extra_m), views) in open.iter().zip(&approaches) {
            let penalty_m = extra_m
                + own_extra_m(&f)
                + if claimed.contains(&f) {
                    params.claim_penalty_m
                } else {
                    0.0
                };
            for &(n, view_m) in views {
                heap.push(Entry {
                    cost_m: view_m + penalty_m,
                    key: n,
                    target: f,
                });
            }
            if !views.is_empty() {
                seeded.insert(f);
            }
        }
        let distance_m = spread(memory, heap, &passable);
        GuidanceField {
            cell_m,
            key_scale: 1.0 / cell_m,
            look_ahead_m: params.look_ahead_m,
            distance_m,
            seeded,
            goal: None,
        }
    }

    /// The route distance to the point `goal_m` over `memory`'s passable cells and the
    /// robot's trail ([`FrontierMemory::mark_trail`]: the way it came is always a way
    /// back), in place of a frontier's (a robot flying home,
    /// [`Mission`](super::Mission)): Dijkstra from the goal's cell (or its passable
    /// neighbours), and the straight
    /// distance within the goal's cell and its neighbours, so that the field's least
    /// value is at the goal itself. Measured `look_ahead_m` ahead of a pose, so that a
    /// robot facing away from its way home turns round, except within a look-ahead
    /// and a cell of the goal (there a look-ahead would hold a robot facing its goal
    /// one look-ahead short of it, or turning both ways for ever beside it). Empty
    /// (∞ everywhere) when the goal lies in no known
    /// passable cell.
    #[must_use]
    pub fn towards(memory: &FrontierMemory, goal_m: &Point3<f64>, look_ahead_m: f64) -> Self {
        let passable_cells = passable_in(memory);
        let passable = |key| memory.on_trail(key) || passable_cells.contains(&key);
        Self::towards_over(memory, goal_m, look_ahead_m, &passable)
    }

    /// [`Self::towards`] over the robot's own trail alone, and the passable cells within
    /// two cells along each axis of the goal's (a peer's home beside the robot's start,
    /// where its trail began): the way the robot came, which it flew and so can fly
    /// back. For a return that stalled on the shortest route
    /// ([`Mission::retracing`](super::Mission::retracing)): that route may lead through
    /// cells seen passable that no primitive can enter with its margins, so that every
    /// candidate gets farther from home.
    #[must_use]
    pub fn retracing(memory: &FrontierMemory, goal_m: &Point3<f64>, look_ahead_m: f64) -> Self {
        // Only the few cells beside the goal are looked up, so no set of every passable
        // cell is gathered.
        let goal = memory.key_of(goal_m);
        let near_goal = |key: CellKey| {
            goal.is_some_and(|g| (0..3).all(|k| (key[k] - g[k]).abs() <= RETRACE_GOAL_CELLS))
        };
        let passable =
            |key| memory.on_trail(key) || (near_goal(key) && memory.record(key).passable);
        Self::towards_over(memory, goal_m, look_ahead_m, &passable)
    }

    fn towards_over(
        memory: &FrontierMemory,
        goal_m: &Point3<f64>,
        look_ahead_m: f64,
        passable: &dyn Fn(CellKey) -> bool,
    ) -> Self {
        let cell_m = memory.cell_m();
        let distance_m = routes_from(memory, goal_m, passable);
        let goal = memory
            .key_of(goal_m)
            .filter(|_| !distance_m.is_empty())
            .map(|key| (*goal_m, key));
        GuidanceField {
            cell_m,
            key_scale: 1.0 / cell_m,
            look_ahead_m,
            seeded: goal.iter().map(|(_, key)| *key).collect(),
            goal,
            distance_m,
        }
    }

    /// Remembered frontiers that seed the field ([`viewpoints`]).
    #[must_use]
    pub fn frontier_count(&self) -> usize {
        self.seeded.len()
    }

    /// Whether the frontier `f` seeds the field (it is open and has a viewpoint, or a
    /// passable neighbour without a view cone: [`viewpoints`]).
    #[must_use]
    pub fn seeds(&self, f: CellKey) -> bool {
        self.seeded.contains(&f)
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
        if let Some((goal_m, goal)) = self.goal.filter(|_| self.near_goal(p, 1)) {
            return ((p - goal_m).norm(), Some(goal));
        }
        self.entry_at(p)
            .map_or((f64::INFINITY, None), |e| (e.cost_m, Some(e.target)))
    }

    /// The reached cell `n` among the cell holding `p` and its 26 neighbours with the
    /// least `d(n) + |p − centre(n)|` (that sum as `cost_m`; ties by frontier, then by
    /// cell), where the route from `p` enters the field.
    fn entry_at(&self, p: &Point3<f64>) -> Option<Entry> {
        let key = self.key_of(p)?;
        std::iter::once((key, 0.0))
            .chain(neighbours(key))
            .filter_map(|(n, _)| {
                self.distance_m.get(&n).map(|(d, target)| Entry {
                    cost_m: d + (p - self.centre(n)).norm(),
                    key: n,
                    target: *target,
                })
            })
            .min_by(|a, b| {
                a.cost_m
                    .total_cmp(&b.cost_m)
                    .then_with(|| a.target.cmp(&b.target))
                    .then_with(|| a.key.cmp(&b.key))
            })
    }

    /// Whether `p` lies within `reach` cells of the goal's (per axis) of a field
    /// [`Self::towards`] a point.
    fn near_goal(&self, p: &Point3<f64>, reach: i32) -> bool {
        match (self.goal, self.key_of(p)) {
            (Some((_, goal)), Some(key)) => (0..3).all(|i| (key[i] - goal[i]).abs() <= reach),
            _ => false,
        }
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
        // Within a look-ahead (and a cell) of a goal, the point ahead may lie past it,
        // where facing away and facing it measure alike: measure from `p`.
        let reach = 1 + (self.look_ahead_m * self.key_scale).ceil() as i32;
        if self.near_goal(p, reach) {
            return self.distance_m(p);
        }
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

    /// The route from `p` to the frontier [`Self::target_of`] gives, as the centres of
    /// the passable cells it crosses ending with the frontier cell's centre (empty off
    /// the field): from the cell where it enters the field next to `p`, each step goes to the neighbour the
    /// field reached that cell from (least distance plus step, towards the same
    /// frontier), down to the cell the frontier seeded. For showing where a robot is
    /// heading (recordings); the planner itself reads only the distances. Time and
    /// length: at most one step per reached cell.
    #[must_use]
    pub fn route_from(&self, p: &Point3<f64>) -> Vec<Point3<f64>> {
        let Some(Entry {
            key: mut here,
            target,
            ..
        }) = self.entry_at(p)
        else {
            return Vec::new();
        };
        let mut here_m = self.distance_m[&here].0;
        let mut route = vec![self.centre(here)];
        while route.len() <= self.distance_m.len() {
            let next = neighbours(here)
                .filter_map(|(n, step)| {
                    let (d, t) = self.distance_m.get(&n)?;
                    (*t == target && *d < here_m).then_some((n, *d, d + step * self.cell_m))
                })
                .min_by(|a, b| a.2.total_cmp(&b.2).then_with(|| a.0.cmp(&b.0)));
            let Some((n, d, _)) = next else {
                break;
            };
            (here, here_m) = (n, d);
            route.push(self.centre(here));
        }
        if here != target {
            // A passable frontier cell seeds itself; otherwise the frontier is one step on.
            route.push(self.centre(target));
        }
        route
    }
}

impl FrontierField for GuidanceField {
    fn pose_distance_m(&self, p: &Point3<f64>, yaw_rad: f64) -> f64 {
        GuidanceField::pose_distance_m(self, p, yaw_rad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// [`claimed_by_assignment`] as first written: every robot's full Dijkstra, every
    /// pair ranked.
    fn claimed_by_ranking_every_pair(
        (memory, passable): (&FrontierMemory, &dyn Fn(CellKey) -> bool),
        open: &[(CellKey, f64)],
        approaches: &[Vec<(CellKey, f64)>],
        robots: &[(RobotId, Point3<f64>)],
        own_extra_m: &dyn Fn(&CellKey) -> f64,
        claim_radius_m: f64,
    ) -> BTreeSet<CellKey> {
        let own = robots[0].0;
        let mut pairs: Vec<(f64, RobotId, CellKey)> = Vec::new();
        for &(id, position_m) in robots {
            let routes = routes_from(memory, &position_m, passable);
            for (&(f, extra_m), views) in open.iter().zip(approaches) {
                let mine_m = if id == own { own_extra_m(&f) } else { 0.0 };
                let cost_m = extra_m
                    + mine_m
                    + views
                        .iter()
                        .filter_map(|(n, view_m)| routes.get(n).map(|(d, _)| d + view_m))
                        .fold(f64::INFINITY, f64::min);
                if cost_m.is_finite() {
                    pairs.push((cost_m, id, f));
                }
            }
        }
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let mut owner: BTreeMap<CellKey, RobotId> = BTreeMap::new();
        let mut assigned: BTreeSet<RobotId> = BTreeSet::new();
        for (_, id, f) in pairs {
            if assigned.contains(&id) || owner.contains_key(&f) {
                continue;
            }
            assigned.insert(id);
            let centre = memory.centre(f);
            for &(g, _) in open {
                if (memory.centre(g) - centre).norm() <= claim_radius_m {
                    owner.entry(g).or_insert(id);
                }
            }
        }
        owner
            .into_iter()
            .filter_map(|(f, id)| (id != own).then_some(f))
            .collect()
    }

    fn cell() -> impl Strategy<Value = CellKey> {
        [0i32..12, 0i32..12, 0i32..3]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        /// Random passable cells (a few walls' worth missing), frontiers with region
        /// weights and approaches on the lattice (many equal costs), up to six robots,
        /// a switching cost on some of this robot's frontiers.
        #[test]
        fn the_assignment_claims_what_ranking_every_pair_of_full_routes_claims(
            walls in prop::collection::btree_set(cell(), 0..150),
            frontiers in prop::collection::btree_map(cell(), prop::sample::select(vec![0.0, 0.0, 5.0, f64::INFINITY]), 1..12),
            views in prop::collection::vec(prop::collection::vec((cell(), 0usize..3), 0..4), 12),
            robots in prop::collection::vec(([0.0..12.0f64, 0.0..12.0f64, 0.0..3.0f64], 0u32..8), 1..7),
            switching in prop::collection::btree_set(cell(), 0..4),
            claim_radius_m in prop::sample::select(vec![0.0, 1.0, 2.5]),
        ) {
            let memory = FrontierMemory::new(1.0, 10_000);
            let passable = |key: CellKey| {
                (0..12).contains(&key[0]) && (0..12).contains(&key[1]) && (0..3).contains(&key[2])
                    && !walls.contains(&key)
            };
            let open: Vec<(CellKey, f64)> = frontiers.into_iter().collect();
            let approaches: Vec<Vec<(CellKey, f64)>> = open
                .iter()
                .zip(&views)
                .map(|(_, v)| v.iter().map(|&(n, k)| (n, [0.0, 0.5, 1.0][k])).collect())
                .collect();
            let mut ids = BTreeSet::new();
            let robots: Vec<(RobotId, Point3<f64>)> = robots
                .into_iter()
                .filter(|(_, id)| ids.insert(*id))
                .map(|(p, id)| (RobotId(id), Point3::from(p)))
                .collect();
            let (own, own_m) = robots[0];
            let peers: BTreeMap<RobotId, PeerIntent> = robots[1..]
                .iter()
                .map(|&(id, position_m)| (id, PeerIntent { position_m, goal_m: position_m }))
                .collect();
            let own_extra_m = |f: &CellKey| if switching.contains(f) { 3.0 } else { 0.0 };
            // The reference ranks robots as the assignment lists them: own, then peers.
            let listed: Vec<(RobotId, Point3<f64>)> = std::iter::once((own, own_m))
                .chain(peers.iter().map(|(id, p)| (*id, p.position_m)))
                .collect();
            prop_assert_eq!(
                claimed_by_assignment(
                    (&memory, &passable),
                    &open,
                    &approaches,
                    (own, &own_m),
                    &own_extra_m,
                    &peers,
                    claim_radius_m,
                ),
                claimed_by_ranking_every_pair(
                    (&memory, &passable),
                    &open,
                    &approaches,
                    &listed,
                    &own_extra_m,
                    claim_radius_m,
                )
            );
        }
    }

    #[test]
    fn frontier_regions_smaller_than_the_minimum_are_dropped_or_made_longer() {
        // A region of three cells touching only diagonally, a pair, and a lone cell.
        let frontiers: std::collections::BTreeSet<_> = [
            [0, 0, 0],
            [1, 1, 1],
            [2, 2, 1],
            [10, 0, 0],
            [10, 0, 1],
            [20, 5, 5],
        ]
        .into_iter()
        .collect();
        let kept = |min| -> Vec<_> {
            weigh_regions(frontiers.clone(), min, None)
                .into_iter()
                .map(|(f, extra_m)| {
                    assert_eq!(extra_m, 0.0);
                    f
                })
                .collect()
        };
        assert_eq!(kept(1).len(), 6);
        assert_eq!(kept(2).len(), 5);
        assert_eq!(kept(3), vec![[0, 0, 0], [1, 1, 1], [2, 2, 1]]);
        assert!(kept(4).is_empty());
        // With a penalty the small regions stay, made longer.
        let weighed = weigh_regions(frontiers.clone(), 3, Some(15.0));
        assert_eq!(weighed.len(), 6);
        for (f, extra_m) in weighed {
            let small = f[0] >= 10;
            assert_eq!(extra_m, if small { 15.0 } else { 0.0 }, "{f:?}");
        }
    }
}
