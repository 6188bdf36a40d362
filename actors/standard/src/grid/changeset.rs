//! Occupancy-grid map sharing, the baseline the thesis compares GMM keyframes with
//! (§8.2.5, "OG"; §8.2.7): each robot sends the cells its own observations changed,
//! one `u32` index and one `f32` log-odds each ([`GridChangeSet`]), and peers fuse them
//! into their local grids.
//!
//! - [`OwnChanges`] (sender) keeps the log-odds that this robot's own depth frames
//!   contributed to each world-lattice cell, and which cells changed since the last
//!   set. What peers shared is never sent on: sets carry own evidence only, so no
//!   evidence goes round in circles.
//! - [`PeerCells`] (receiver) remembers the last value each peer sent for each cell
//!   and adds only the difference to the grid: log-odds of independent evidence add
//!   (§3.2.3), and a cell resent with a new value replaces that peer's old
//!   contribution instead of counting twice. The sum over peers is kept per cell so
//!   that cells entering the moving window later get it back.

use std::collections::{BTreeSet, HashMap};

use nalgebra::{Isometry3, Point3, Vector3};
use troupe_comms::wire::{CellChange, ContentError, GridChangeSet, GridDims};

use troupe_algorithms::grid::{CellBox, LocalGrid, MAX_CHANGES_PER_SET};
use troupe_runtime::RobotId;

/// A world-lattice cell (see [`LocalGrid::lattice_cell`]).
type LatticeCell = [usize; 3];

/// The sender's side (module docs).
#[derive(Clone, Debug, Default)]
pub struct OwnChanges {
    /// Own-evidence log-odds per cell ever observed.
    own: HashMap<LatticeCell, f32>,
    /// Cells changed since the last set.
    dirty: BTreeSet<LatticeCell>,
    /// The grid's values before the frame being recorded.
    before: Vec<f32>,
}

impl OwnChanges {
    /// Call before inserting an own observation into `grid`.
    pub fn begin(&mut self, grid: &LocalGrid) {
        self.before.clear();
        self.before.extend_from_slice(grid.values());
    }

    /// Call after inserting it: every cell whose value moved takes the same change
    /// into its own evidence (clamped like the grid) and is marked for the next set.
    pub fn end(&mut self, grid: &LocalGrid) {
        if self.before.len() != grid.values().len() {
            return;
        }
        let (min, max) = (grid.params().min, grid.params().max);
        for (i, (after, before)) in grid.values().iter().zip(&self.before).enumerate() {
            if after != before {
                let cell = grid.lattice_cell(grid.cell_at(i));
                let own = self.own.entry(cell).or_insert(0.0);
                *own = (*own + (after - before)).clamp(min, max);
                self.dirty.insert(cell);
            }
        }
    }

    /// Cells waiting for the next set.
    #[must_use]
    pub fn pending(&self) -> usize {
        self.dirty.len()
    }

    /// The sets for the changed cells inside `grid`'s window (indexed in it, at most
    /// [`MAX_CHANGES_PER_SET`] each); changed cells outside it are dropped until
    /// they change again.
    pub fn take_sets(&mut self, grid: &LocalGrid) -> Vec<GridChangeSet> {
        let dims = grid.dims();
        let origin = grid.geometry().origin;
        let mut changes: Vec<CellChange> = std::mem::take(&mut self.dirty)
            .into_iter()
            .filter_map(|cell| {
                let local = grid.local_of_lattice(cell)?;
                let index = u32::try_from(grid.index(local)).ok()?;
                Some(CellChange {
                    index,
                    log_odds: *self.own.get(&cell)?,
                })
            })
            .collect();
        changes.sort_by_key(|c| c.index);
        let set_of = |changes: &[CellChange]| GridChangeSet {
            dims: GridDims {
                width: u32::try_from(dims[0]).unwrap_or(u32::MAX),
                height: u32::try_from(dims[1]).unwrap_or(u32::MAX),
                length: u32::try_from(dims[2]).unwrap_or(u32::MAX),
            },
            origin_m: [origin.x as f32, origin.y as f32, origin.z as f32],
            changes: changes.to_vec(),
        };
        changes.chunks(MAX_CHANGES_PER_SET).map(set_of).collect()
    }
}

/// Why a peer's set was not applied.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ChangeSetError {
    /// The set fails [`GridChangeSet::validate`] (the decoder's own check).
    #[error("invalid change set: {0}")]
    Invalid(#[from] ContentError),
}

/// The centres of the changed cells of `set` (a peer's, at the team's voxel size
/// `resolution_m`), in order, moved into our world frame by `frame` (Eq. 8.1) when the
/// peer's differs. `set` must be valid ([`GridChangeSet::validate`]).
pub fn cell_centres<'a>(
    set: &'a GridChangeSet,
    resolution_m: f64,
    frame: Option<&'a Isometry3<f64>>,
) -> impl Iterator<Item = Point3<f64>> + 'a {
    let [w, h] = [set.dims.width, set.dims.height].map(|v| v as usize);
    let origin = Vector3::from(set.origin_m.map(f64::from));
    set.changes.iter().map(move |c| {
        let i = c.index as usize;
        let local = Vector3::new((i % w) as f64, ((i / w) % h) as f64, (i / (w * h)) as f64);
        let centre = Point3::from(origin + (local + Vector3::repeat(0.5)) * resolution_m);
        frame.map_or(centre, |t| t * centre)
    })
}

/// The receiver's side (module docs).
#[derive(Clone, Debug, Default)]
pub struct PeerCells {
    /// The last value each peer sent per cell.
    last: HashMap<(RobotId, LatticeCell), f32>,
    /// Sum over peers of their last values per cell.
    sum: HashMap<LatticeCell, f32>,
}

impl PeerCells {
    /// Applies a peer's set to `grid`: each cell centre (moved by `frame`, Eq. 8.1, if
    /// the peer's world frame differs from ours) lands in our lattice cell, which gets
    /// the difference to what that peer sent for it before. Returns the number of
    /// cells that changed inside the window. Nothing is applied from an invalid set.
    pub fn apply(
        &mut self,
        peer: RobotId,
        set: &GridChangeSet,
        frame: Option<&Isometry3<f64>>,
        grid: &mut LocalGrid,
    ) -> Result<usize, ChangeSetError> {
        set.validate()?;
        let mut applied = 0;
        for (c, centre) in set
            .changes
            .iter()
            .zip(cell_centres(set, grid.resolution_m(), frame))
        {
            let Some(cell) = grid.lattice_cell_of(&centre) else {
                continue;
            };
            let previous = self.last.insert((peer, cell), c.log_odds).unwrap_or(0.0);
            let delta = c.log_odds - previous;
            *self.sum.entry(cell).or_insert(0.0) += delta;
            if let Some(local) = grid.local_of_lattice(cell) {
                let index = grid.index(local);
                grid.update(index, delta);
                applied += 1;
            }
        }
        Ok(applied)
    }

    /// After a window move: gives the cells of the novel boxes what peers sent for
    /// them.
    pub fn restore(&self, grid: &mut LocalGrid, boxes: &[CellBox]) {
        if self.sum.is_empty() {
            return;
        }
        for b in boxes {
            for z in b.min[2]..b.max[2] {
                for y in b.min[1]..b.max[1] {
                    for x in b.min[0]..b.max[0] {
                        if let Some(v) = self.sum.get(&grid.lattice_cell([x, y, z])) {
                            let index = grid.index([x, y, z]);
                            grid.update(index, *v);
                        }
                    }
                }
            }
        }
    }

    /// Cells any peer has sent.
    #[must_use]
    pub fn len(&self) -> usize {
        self.sum.len()
    }

    /// Whether no peer has sent anything.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.sum.is_empty()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use troupe_algorithms::grid::{CellState, LogOddsParams};

    fn grid_at(x: f64) -> LocalGrid {
        LocalGrid::centred(
            &Point3::new(x, 0.0, 0.0),
            &Vector3::new(6.0, 6.0, 4.0),
            0.2,
            LogOddsParams::default(),
        )
    }

    fn observe(grid: &mut LocalGrid, own: &mut OwnChanges, from: [f64; 3], to: [f64; 3]) {
        own.begin(grid);
        grid.insert_ray(&Point3::from(from), &Point3::from(to), true, None);
        own.end(grid);
    }

    /// Every cell of `set` (indexed in `a`'s window) has the same value in `b`.
    fn assert_same_cells(a: &LocalGrid, b: &LocalGrid, set: &GridChangeSet) {
        for c in &set.changes {
            let la = a.cell_at(c.index as usize);
            let lb = b.local_of_lattice(a.lattice_cell(la)).unwrap();
            assert_eq!(a.value(la), b.value(lb));
        }
    }

    #[test]
    fn a_peers_observations_reach_our_grid_exactly_once() {
        let (mut a, mut b) = (grid_at(0.0), grid_at(1.0));
        let mut own = OwnChanges::default();
        observe(&mut a, &mut own, [0.0, 0.0, 0.0], [2.0, 0.3, 0.1]);
        let sets = own.take_sets(&a);
        assert_eq!(sets.len(), 1);
        assert!(sets[0].changes.len() > 5);
        assert_eq!(own.pending(), 0);
        let mut peers = PeerCells::default();
        let n = peers.apply(RobotId(0), &sets[0], None, &mut b).unwrap();
        assert_eq!(n, sets[0].changes.len());
        // Every cell the ray touched in `a` has the same state in `b`.
        assert_same_cells(&a, &b, &sets[0]);
        let end = b.lattice_cell_of(&Point3::new(2.0, 0.3, 0.1)).unwrap();
        assert_eq!(
            b.state(b.local_of_lattice(end).unwrap()),
            CellState::Occupied
        );
        // The same set again changes nothing; a second observation adds once.
        let before = b.values().to_vec();
        peers.apply(RobotId(0), &sets[0], None, &mut b).unwrap();
        assert_eq!(b.values(), &before[..]);
        observe(&mut a, &mut own, [0.0, 0.0, 0.0], [2.0, 0.3, 0.1]);
        let again = own.take_sets(&a);
        peers.apply(RobotId(0), &again[0], None, &mut b).unwrap();
        assert_same_cells(&a, &b, &again[0]);
    }

    #[test]
    fn cells_entering_the_window_later_get_the_peers_values() {
        let mut a = grid_at(0.0);
        let mut own = OwnChanges::default();
        observe(&mut a, &mut own, [0.0, 0.0, 0.0], [-2.5, 0.0, 0.0]);
        let set = own.take_sets(&a).remove(0);
        // B's window starts away from the observed cells, then moves over them.
        let mut b = grid_at(4.0);
        let mut peers = PeerCells::default();
        assert_eq!(peers.apply(RobotId(3), &set, None, &mut b).unwrap(), 0);
        let novel = b.shift_to(&Point3::new(0.0, 0.0, 0.0));
        peers.restore(&mut b, &novel);
        assert_same_cells(&a, &b, &set);
    }

    #[test]
    fn a_peer_with_another_world_frame_lands_in_our_cells() {
        let mut a = grid_at(0.0);
        let mut own = OwnChanges::default();
        observe(&mut a, &mut own, [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]);
        let set = own.take_sets(&a).remove(0);
        // The peer's frame is ours shifted by +1 m in x.
        let frame = Isometry3::translation(1.0, 0.0, 0.0);
        let mut b = grid_at(0.0);
        PeerCells::default()
            .apply(RobotId(1), &set, Some(&frame), &mut b)
            .unwrap();
        let end = b.lattice_cell_of(&Point3::new(2.0, 1.0, 0.0)).unwrap();
        assert_eq!(
            b.state(b.local_of_lattice(end).unwrap()),
            CellState::Occupied
        );
    }

    #[test]
    fn invalid_sets_are_rejected_whole() {
        let mut a = grid_at(0.0);
        let mut own = OwnChanges::default();
        observe(&mut a, &mut own, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]);
        let good = own.take_sets(&a).remove(0);
        let mut b = grid_at(0.0);
        let before = b.values().to_vec();
        let mut peers = PeerCells::default();
        let mut nan = good.clone();
        nan.changes[0].log_odds = f32::NAN;
        let mut outside = good.clone();
        outside.changes.last_mut().unwrap().index = u32::MAX;
        let mut zero = good;
        zero.dims.height = 0;
        for bad in [nan, outside, zero] {
            assert!(peers.apply(RobotId(1), &bad, None, &mut b).is_err());
        }
        assert_eq!(b.values(), &before[..]);
        assert!(peers.is_empty());
    }
}
