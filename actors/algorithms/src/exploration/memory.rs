//! The team frontier memory: a coarse world-fixed hash of cells that remembers, beyond
//! the moving grid window, what was seen, where a robot can be and where frontiers
//! are (paper V-B's frontiers of the explored map; thesis §6.1.4 for sampling a GMM at
//! any resolution).

use std::collections::{BTreeMap, BTreeSet};

use nalgebra::{Isometry3, Point3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::grid::{CellState, GridSnapshot};
use crate::keyframe::Keyframe;

/// Integer coordinates of a memory cell: `floor(p / cell_m)` per axis.
pub type CellKey = [i32; 3];

/// What the memory holds about one cell.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CellRecord {
    /// Someone observed (part of) it.
    pub seen: bool,
    /// A robot centre fits in it with the planner's clearance, or a robot was there.
    pub passable: bool,
    /// It holds a frontier: free space next to unknown space, not yet observed beyond.
    pub frontier: bool,
    /// A window once showed free space in it and not one fine frontier cell (no free
    /// cell next to an unknown one): it is explored, and no later view makes it a
    /// frontier again. (Cells seen only as surface are not settled: free space found
    /// in them later may border the unknown.) A window that moves back over
    /// explored space is rebuilt from keyframe samples (thesis §3.2.3), sparser than
    /// the frames that first filled it, and its gaps would otherwise come back as
    /// frontiers all along a flown tunnel.
    pub settled: bool,
}

impl CellRecord {
    /// The record as four bits (seen 1, passable 2, frontier 4, settled 8), as peers
    /// exchange it ([`FrontierMemory::take_changes`]).
    #[must_use]
    pub fn to_bits(self) -> u8 {
        u8::from(self.seen)
            | u8::from(self.passable) << 1
            | u8::from(self.frontier) << 2
            | u8::from(self.settled) << 3
    }

    /// The record of [`Self::to_bits`]; `None` for bits above the four.
    #[must_use]
    pub fn from_bits(bits: u8) -> Option<Self> {
        (bits < 16).then_some(CellRecord {
            seen: bits & 1 != 0,
            passable: bits & 2 != 0,
            frontier: bits & 4 != 0,
            settled: bits & 8 != 0,
        })
    }
}

/// What one update changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MemoryUpdate {
    /// Cells written.
    pub cells: usize,
    /// Frontiers that were remembered and are no more.
    pub retired: usize,
    /// New cells not remembered because the memory was full.
    pub dropped: usize,
}

/// A sparse, world-fixed map of coarse cells (a `BTreeMap`, so iteration and every
/// decision built on it are deterministic).
///
/// Bounds: at most `max_cells` cells (about 64 bytes each with the map's overhead,
/// 16 MiB at the default 262 144); [`Self::observe_window`] takes time linear in the
/// window's fine cells plus `log n` per coarse cell of the window;
/// [`Self::observe_keyframe`] `samples × (ray length / cell_m) × 4 × log n`;
/// [`Self::observe_cells`] `log n` per cell given.
#[derive(Clone, Debug, PartialEq)]
pub struct FrontierMemory {
    cell_m: f64,
    max_cells: usize,
    cells: BTreeMap<CellKey, CellRecord>,
    dropped: u64,
    /// Cells whose record this robot's own observations changed since
    /// [`Self::take_changes`] last ran (bounded by the memory: at most `max_cells` keys);
    /// kept only when [`Self::tracking_changes`].
    changed: BTreeSet<CellKey>,
    track_changes: bool,
    /// Cells this robot's body has passed through, joined without gaps
    /// ([`Self::mark_trail`]): the way it came, a way for routes even where no window
    /// showed a robot centre the clearance it needs. At most `max_cells` of them.
    trail: BTreeSet<CellKey>,
    /// Cells a peer's keyframe rays or change sets showed ([`Self::observe_keyframe`],
    /// [`Self::observe_cells`]), at most `max_cells` of them, when
    /// [`Self::tracking_peer_sight`]: a frontier this robot's window shows there later
    /// lies in space its peer has looked through.
    seen_by_peers: Option<BTreeSet<CellKey>>,
}

/// Per-cell tallies of the fine cells of a window.
#[derive(Clone, Copy, Default)]
struct Tally {
    known: u32,
    free: u32,
    frontier: u32,
    max_clearance_m: f64,
}

impl FrontierMemory {
    /// An empty memory of `cell_m` cells holding at most `max_cells` of them.
    #[must_use]
    pub fn new(cell_m: f64, max_cells: usize) -> Self {
        FrontierMemory {
            cell_m: if cell_m.is_finite() && cell_m > 0.0 {
                cell_m
            } else {
                1.0
            },
            max_cells: max_cells.max(1),
            cells: BTreeMap::new(),
            dropped: 0,
            changed: BTreeSet::new(),
            track_changes: false,
            trail: BTreeSet::new(),
            seen_by_peers: None,
        }
    }

    /// The same memory keeping the set of cells its own observations change, for
    /// [`Self::take_changes`] (memory sharing between robots).
    #[must_use]
    pub fn tracking_changes(mut self) -> Self {
        self.track_changes = true;
        self
    }

    /// The same memory keeping the cells its peers' keyframes and change sets showed,
    /// for [`Self::seen_by_peers`].
    #[must_use]
    pub fn tracking_peer_sight(mut self) -> Self {
        self.seen_by_peers = Some(BTreeSet::new());
        self
    }

    /// Edge of a cell, metres.
    #[must_use]
    pub fn cell_m(&self) -> f64 {
        self.cell_m
    }

    /// The cell holding `p` (`None` for non-finite points or points too far out).
    #[must_use]
    pub fn key_of(&self, p: &Point3<f64>) -> Option<CellKey> {
        let k = p.coords.map(|v| (v / self.cell_m).floor());
        k.iter()
            .all(|v| v.is_finite() && v.abs() < 1e9)
            .then(|| [k.x as i32, k.y as i32, k.z as i32])
    }

    /// Centre of a cell.
    #[must_use]
    pub fn centre(&self, key: CellKey) -> Point3<f64> {
        Point3::from(Vector3::new(
            (f64::from(key[0]) + 0.5) * self.cell_m,
            (f64::from(key[1]) + 0.5) * self.cell_m,
            (f64::from(key[2]) + 0.5) * self.cell_m,
        ))
    }

    /// Our cell holding the centre of a peer's cell `key` moved by `frame` (the peer's
    /// world frame in ours); `None` beyond the key range.
    #[must_use]
    pub fn moved_key(&self, key: CellKey, frame: &Isometry3<f64>) -> Option<CellKey> {
        self.key_of(&(frame * self.centre(key)))
    }

    /// The record of a cell (default: never seen).
    #[must_use]
    pub fn record(&self, key: CellKey) -> CellRecord {
        self.cells.get(&key).copied().unwrap_or_default()
    }

    /// Cells held.
    #[must_use]
    pub fn cell_count(&self) -> usize {
        self.cells.len()
    }

    /// New cells not remembered since the start because the memory was full.
    #[must_use]
    pub fn dropped_cells(&self) -> u64 {
        self.dropped
    }

    /// The remembered frontier cells, in key order.
    pub fn frontiers(&self) -> impl Iterator<Item = CellKey> + '_ {
        self.cells
            .iter()
            .filter(|(_, r)| r.frontier)
            .map(|(k, _)| *k)
    }

    /// The passable cells, in key order.
    pub fn passable(&self) -> impl Iterator<Item = CellKey> + '_ {
        self.cells
            .iter()
            .filter(|(_, r)| r.passable)
            .map(|(k, _)| *k)
    }

    /// Writes a cell from this robot's own observations, unless it is new and the
    /// memory is full; `true` if written. A change is kept for the peers when the
    /// memory is [`tracking_changes`](Self::tracking_changes).
    fn write(&mut self, key: CellKey, record: CellRecord, update: &mut MemoryUpdate) -> bool {
        let old = self.cells.get(&key).copied();
        let written = self.store(key, old, record, update);
        if written && self.track_changes && old != Some(record) {
            self.changed.insert(key);
        }
        written
    }

    /// Stores `record` over `old` (the cell's record now), unless the cell is new and
    /// the memory is full (dropped and counted); counts a retired frontier; `true` if
    /// stored.
    fn store(
        &mut self,
        key: CellKey,
        old: Option<CellRecord>,
        record: CellRecord,
        update: &mut MemoryUpdate,
    ) -> bool {
        if old.is_none() && self.cells.len() >= self.max_cells {
            self.dropped += 1;
            update.dropped += 1;
            return false;
        }
        if old.is_some_and(|o| o.frontier) && !record.frontier {
            update.retired += 1;
        }
        self.cells.insert(key, record);
        update.cells += 1;
        true
    }

    /// Folds a grid snapshot into the memory. Every memory cell that lies wholly inside
    /// the window takes the window's view of it (the window holds the robot's own
    /// frames and the peers' keyframes near it, so it is the best knowledge there):
    /// seen if any fine cell is known, passable once a window shows a fine cell that
    /// keeps `margin_m` from unsafe space (a later window does not take that back: one
    /// rebuilt from keyframe samples has unknown gaps, which count as unsafe, and on
    /// seed 14 such windows cut the team's route to its last frontier), a frontier if
    /// it holds at least `min_frontier_cells` fine frontier
    /// cells ([`frontier_mask`](crate::grid::frontier::frontier_mask)) and was never
    /// [`settled`](CellRecord::settled). A remembered frontier the window no longer
    /// shows is retired. With `retire_within` (the robot's position and a radius), only
    /// cells within it are retired or settled: farther ones may become frontiers but
    /// keep those they are. Cells beyond the window keep what the memory knew.
    pub fn observe_window(
        &mut self,
        snapshot: &GridSnapshot,
        margin_m: f64,
        min_frontier_cells: usize,
        retire_within: Option<(Point3<f64>, f64)>,
    ) -> MemoryUpdate {
        let grid = &snapshot.grid;
        let geometry = grid.geometry();
        let dims = grid.dims();
        let res = grid.resolution_m();
        let lo = geometry.origin;
        let hi = lo + Vector3::from(dims.map(|d| d as f64)) * res;
        // Memory cells wholly inside the window, per axis (a small tolerance for
        // lattices that share faces).
        let eps = 1e-6 * self.cell_m;
        let range = |i: usize| -> (i64, i64) {
            let first = ((lo[i] - eps) / self.cell_m).ceil() as i64;
            let end = ((hi[i] + eps) / self.cell_m).floor() as i64;
            (first, end.max(first))
        };
        let (rx, ry, rz) = (range(0), range(1), range(2));
        let n = [rx.1 - rx.0, ry.1 - ry.0, rz.1 - rz.0].map(|v| v.max(0) as usize);
        let mut tallies = vec![Tally::default(); n[0] * n[1] * n[2]];
        let mut update = MemoryUpdate::default();
        if tallies.is_empty() {
            return update;
        }
        // The memory cell of each fine cell along each axis (by its centre), relative
        // to the first one in the window; `None` outside it.
        let coarse = |axis: usize, first: i64| -> Vec<Option<usize>> {
            (0..dims[axis])
                .map(|c| {
                    let centre_m = lo[axis] + (c as f64 + 0.5) * res;
                    let k = (centre_m / self.cell_m).floor() as i64 - first;
                    (0..n[axis] as i64).contains(&k).then_some(k as usize)
                })
                .collect()
        };
        let (kx, ky, kz) = (coarse(0, rx.0), coarse(1, ry.0), coarse(2, rz.0));
        let values = grid.values();
        for (z, cz) in kz.iter().enumerate() {
            for (y, cy) in ky.iter().enumerate() {
                let (Some(cy), Some(cz)) = (*cy, *cz) else {
                    continue;
                };
                let row = dims[0] * (y + dims[1] * z);
                for (x, cx) in kx.iter().enumerate() {
                    let Some(cx) = *cx else { continue };
                    let i = row + x;
                    let t = &mut tallies[cx + n[0] * (cy + n[1] * cz)];
                    match grid.classify(values[i]) {
                        CellState::Unknown => {}
                        CellState::Free => {
                            t.known += 1;
                            t.free += 1;
                        }
                        CellState::Occupied => t.known += 1,
                    }
                    if snapshot.frontiers.contains(i) {
                        t.frontier += 1;
                    }
                    let clearance = snapshot.unsafe_distance_m.get(i).unwrap_or(0.0);
                    t.max_clearance_m = t.max_clearance_m.max(clearance);
                }
            }
        }
        for z in 0..n[2] {
            for y in 0..n[1] {
                for x in 0..n[0] {
                    let t = tallies[x + n[0] * (y + n[1] * z)];
                    let key = [
                        (rx.0 + x as i64) as i32,
                        (ry.0 + y as i64) as i32,
                        (rz.0 + z as i64) as i32,
                    ];
                    let old = self.record(key);
                    let near =
                        retire_within.is_none_or(|(p, r)| (self.centre(key) - p).norm() <= r);
                    let settled = old.settled || (near && t.free > 0 && t.frontier == 0);
                    let shown = t.frontier as usize >= min_frontier_cells;
                    let record = CellRecord {
                        seen: t.known > 0 || settled || (!near && old.seen),
                        passable: old.passable || t.max_clearance_m >= margin_m,
                        frontier: !settled && (shown || (!near && old.frontier)),
                        settled,
                    };
                    if record == CellRecord::default() {
                        // Nothing known: forget it (a frontier here is retired).
                        if let Some(old) = self.cells.remove(&key) {
                            update.retired += usize::from(old.frontier);
                        }
                    } else {
                        self.write(key, record, &mut update);
                    }
                }
            }
        }
        update
    }

    /// Folds a keyframe (a peer's, or any robot's) into the memory: `samples` points
    /// drawn from its spatial GMM (§6.1.5, with a generator seeded by `seed`, so the
    /// same keyframe always gives the same points) are the ends of rays from its sensor
    /// position; every cell a ray crosses or ends in is seen, and a frontier there is
    /// retired (someone has looked into it). The sensor's cell is passable (a robot was
    /// there). Keyframes with a non-finite pose or no component change nothing.
    pub fn observe_keyframe(
        &mut self,
        keyframe: &Keyframe,
        samples: usize,
        seed: u64,
    ) -> MemoryUpdate {
        let mut update = MemoryUpdate::default();
        let origin = Point3::from(keyframe.pose.translation.vector);
        let Some(origin_key) = self.key_of(&origin) else {
            return update;
        };
        if keyframe.gmm.is_empty() {
            return update;
        }
        let passable = CellRecord {
            seen: true,
            passable: true,
            ..self.record(origin_key)
        };
        self.write(origin_key, passable, &mut update);
        let spatial = keyframe.gmm.marginal_spatial();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let step_m = self.cell_m / 4.0;
        let mut crossed: Vec<CellKey> = Vec::new();
        for end in spatial.sample(samples, &mut rng) {
            let end = Point3::from(end);
            let length_m = (end - origin).norm();
            // A sensor sees a few metres; a sample far beyond is not a ray.
            if !length_m.is_finite() || length_m > 50.0 {
                continue;
            }
            let steps = (length_m / step_m).ceil().max(1.0) as usize;
            let mut last = None;
            for s in 0..=steps {
                let p = origin + (end - origin) * (s as f64 / steps as f64);
                let Some(key) = self.key_of(&p) else { break };
                if last != Some(key) {
                    crossed.push(key);
                    last = Some(key);
                }
            }
        }
        self.mark_seen(crossed, &mut update);
        update
    }

    /// Folds cells a peer observed in (its occupancy-grid change sets: thesis §8.2.5's
    /// "OG" sharing), given by their centres: each memory cell holding one is seen and
    /// no longer a frontier, as with the cells a peer keyframe's rays cross
    /// ([`Self::observe_keyframe`]). A change set holds the free cells along the peer's
    /// rays and the surfaces they end on, so it retires what its rays crossed. Time
    /// `O(c log c + c log n)` for `c` centres.
    pub fn observe_cells(
        &mut self,
        centres: impl IntoIterator<Item = Point3<f64>>,
    ) -> MemoryUpdate {
        let mut update = MemoryUpdate::default();
        let keys: Vec<CellKey> = centres
            .into_iter()
            .filter_map(|c| self.key_of(&c))
            .collect();
        self.mark_seen(keys, &mut update);
        update
    }

    /// Marks `keys` seen and not frontiers (each once, in key order).
    fn mark_seen(&mut self, mut keys: Vec<CellKey>, update: &mut MemoryUpdate) {
        keys.sort_unstable();
        keys.dedup();
        for key in keys {
            if let Some(seen) = &mut self.seen_by_peers
                && seen.len() < self.max_cells
            {
                seen.insert(key);
            }
            let old = self.record(key);
            let seen = CellRecord {
                seen: true,
                frontier: false,
                ..old
            };
            if seen != old {
                self.write(key, seen, update);
            }
        }
    }

    /// The cells whose record this robot's own observations changed since the last
    /// call, with their records now, in key order (cells forgotten since are left out):
    /// what a robot tells its peers of its memory each round. Empty unless the memory
    /// is [`tracking_changes`](Self::tracking_changes). Cells merged from peers
    /// ([`Self::merge_peer_cells`]) are not among them, so nothing is echoed back.
    pub fn take_changes(&mut self) -> Vec<(CellKey, CellRecord)> {
        let changed = std::mem::take(&mut self.changed);
        changed
            .into_iter()
            .filter_map(|k| self.cells.get(&k).map(|r| (k, *r)))
            .collect()
    }

    /// Folds in cells a peer's memory holds (its [`Self::take_changes`], in the same
    /// world frame and cell size): a cell this memory knows nothing of takes the peer's
    /// record — its frontiers, passable and settled cells beyond this robot's window;
    /// a cell the peer settled is settled here too (explored by the team: a frontier
    /// here, the peer's own taken earlier included, is retired); and a cell the peer
    /// found passable becomes passable here (the route to the peer's frontiers goes
    /// through it). What this robot saw itself otherwise stands. New cells beyond
    /// `max_cells` are dropped and counted.
    pub fn merge_peer_cells(
        &mut self,
        cells: impl IntoIterator<Item = (CellKey, CellRecord)>,
    ) -> MemoryUpdate {
        let mut update = MemoryUpdate::default();
        for (key, peer) in cells {
            let old = self.cells.get(&key).copied();
            let record = match old {
                None if peer != CellRecord::default() => peer,
                Some(old) if peer.settled && !old.settled => CellRecord {
                    seen: true,
                    passable: old.passable || peer.passable,
                    frontier: false,
                    settled: true,
                },
                Some(old) if peer.passable && !old.passable => CellRecord {
                    passable: true,
                    ..old
                },
                _ => continue,
            };
            // Not `write`: what came from a peer is not sent on.
            self.store(key, old, record, &mut update);
        }
        update
    }

    /// Adds the cells the straight segment `from`–`to` of this robot's own flight
    /// crosses to its trail (sampled every quarter cell; non-finite points and cells
    /// beyond `max_cells` are left out).
    pub fn mark_trail(&mut self, from: &Point3<f64>, to: &Point3<f64>) {
        let length_m = (to - from).norm();
        if !length_m.is_finite() {
            return;
        }
        let steps = (length_m / (self.cell_m / 4.0)).ceil().max(1.0) as usize;
        for s in 0..=steps {
            let p = from + (to - from) * (s as f64 / steps as f64);
            if let Some(key) = self.key_of(&p)
                && self.trail.len() < self.max_cells
            {
                self.trail.insert(key);
            }
        }
    }

    /// Whether this robot's body passed through a cell ([`Self::mark_trail`]).
    #[must_use]
    pub fn on_trail(&self, key: CellKey) -> bool {
        self.trail.contains(&key)
    }

    /// Whether a peer's keyframe rays or change set showed the cell (before or after
    /// this robot's own windows did); `false` unless [`Self::tracking_peer_sight`].
    #[must_use]
    pub fn seen_by_peers(&self, key: CellKey) -> bool {
        self.seen_by_peers
            .as_ref()
            .is_some_and(|seen| seen.contains(&key))
    }

    /// Marks the cell of a body position passable and seen (a robot is there: own or a
    /// peer's odometry).
    pub fn mark_body(&mut self, p: &Point3<f64>) -> MemoryUpdate {
        let mut update = MemoryUpdate::default();
        if let Some(key) = self.key_of(p) {
            let old = self.record(key);
            let record = CellRecord {
                seen: true,
                passable: true,
                ..old
            };
            if record != old {
                self.write(key, record, &mut update);
            }
        }
        update
    }
}
