//! The robot-centred local occupancy grid and what the planner reads from it
//! (thesis §3.2.3, paper IV-B).
//!
//! - [`LocalGrid`]: log-odds cells in a box that moves with the robot; rays are
//!   inserted with an exact 3D DDA on a world-fixed lattice, so two grids at different
//!   positions agree cell for cell on what they share.
//! - [`LocalGrid::shift_to`]: the moving window — copy the overlap, return the (at
//!   most three) novel boxes to rebuild (Fig. 3.2).
//! - [`ComponentStore`]: the keyframe GMM components the novel boxes are rebuilt
//!   from, sampled deterministically, with a spatial index over their means.
//! - [`ScanScratch`]: a whole scan inserted at once, each cell updated once (OctoMap's
//!   semantics, [`UpdateRule::PerScan`]), rays walked in parallel.
//! - [`EndVoxelScratch`]: a whole scan with one ray per distinct end voxel, to its
//!   centre ([`UpdateRule::PerEndVoxel`], OctoMap's `discretize`), on one thread.
//! - [`hca`]: variable resolution and Hierarchical Collision Avoidance (§5.1).
//! - [`distance`]: exact Euclidean distance transform over unsafe space.
//! - [`frontier`]: frontier cells and map entropy; [`FrontierSet`]: the distance to
//!   the nearest frontier, found on demand.
//! - [`meter`]: the bytes that baseline would send for a robot's frames at any
//!   resolution, without flying it (§8.2.6, Table 8.1).

mod config;
pub mod distance;
mod endvoxel;
pub mod frontier;
mod frontier_set;
pub mod hca;
mod insert;
mod local;
pub mod meter;
mod scan;
mod snapshot;
mod store;
pub mod window_scene;

pub use config::GridConfig;
pub use endvoxel::EndVoxelScratch;
pub use frontier_set::FrontierSet;
pub use insert::{
    FrameScans, frame_scans, free_range_m, insert_frame, insert_frame_with, insert_keyframe,
};
pub use local::{CellBox, CellState, LocalGrid, LogOddsParams, RayStep, RayWalk};
pub use meter::MAX_CHANGES_PER_SET;
pub use scan::{ScanScratch, UpdateRule};
pub use snapshot::GridSnapshot;
pub use store::{ComponentStore, KeyframeSource, RebuildStats};

#[cfg(test)]
mod endvoxel_tests;
#[cfg(test)]
mod hca_tests;
#[cfg(test)]
mod store_tests;
#[cfg(test)]
mod tests;
