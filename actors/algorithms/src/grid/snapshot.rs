//! The grid as the planner and the collision checker read it.

use troupe_core::{Message, Time};

use super::LocalGrid;
use super::distance::DistanceField;
use super::frontier_set::FrontierSet;

/// The local grid, its distance to unsafe space and its frontier cells, as the planner
/// and collision checker read them. Published shared (one `Arc`, no copies per subscriber).
#[derive(Clone, Debug, PartialEq)]
pub struct GridSnapshot {
    /// When it was taken.
    pub stamp: Time,
    /// The grid.
    pub grid: LocalGrid,
    /// Distance from each cell to unsafe (occupied or unknown) space.
    pub unsafe_distance_m: DistanceField,
    /// The frontier cells, and the distance to the nearest one.
    pub frontiers: FrontierSet,
}

impl Message for GridSnapshot {
    fn payload_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + 4 * self.grid.values().len()
            + self.unsafe_distance_m.heap_bytes()
            + self.frontiers.heap_bytes()
    }
}

impl GridSnapshot {
    /// Voxel size of this snapshot's grid, metres: fixed, or adapted between α_min
    /// and α_max by Hierarchical Collision Avoidance (thesis §5.1) when it is on.
    #[must_use]
    pub fn resolution_m(&self) -> f64 {
        self.grid.resolution_m()
    }

    /// Distance to unsafe space at a world point (0 outside the grid: unknown).
    #[must_use]
    pub fn clearance_m(&self, p: &nalgebra::Point3<f64>) -> f64 {
        self.grid
            .cell_of(p)
            .map_or(0.0, |c| self.unsafe_distance_m.metres(self.grid.index(c)))
    }

    /// Distance to the nearest frontier at a world point (∞ outside the grid).
    #[must_use]
    pub fn frontier_distance(&self, p: &nalgebra::Point3<f64>) -> f64 {
        self.grid
            .cell_of(p)
            .map_or(f64::INFINITY, |c| self.frontiers.distance_m(c))
    }
}
