//! Geometry shared by the grid, the planner and the simulator: axis-aligned boxes
//! and uniform voxel grids with exact ray traversal.

mod aabb;
mod voxel;

pub use aabb::Aabb;
pub use voxel::VoxelGrid;

#[cfg(test)]
mod voxel_tests;
