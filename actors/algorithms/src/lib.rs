//! troupe-algorithms: the science of a troupe robot as plain types and functions.
//!
//! Nothing here knows about actors, topics or executors (this crate does not depend
//! on `troupe-runtime`): every core takes its inputs and returns its outputs, so it
//! can be tested, benchmarked and reused on its own. The actor wrappers that connect
//! these cores to a robot's topics live in `troupe-actors`.
//!
//! - Sensing: [`camera`] (pinhole intrinsics, back-projection), [`frame`] (depth +
//!   intensity frames with their pose, odometry).
//! - Mixtures and maps: [`mixture`] (Gmm4/Gmm3, Cholesky, sampling, merging by
//!   Eqs. 3.4–3.5), [`sogmm`] (self-organizing GMMs, thesis §6), [`windowed`]
//!   (fixed-size windowed GMMs, paper §IV-A), [`model`],
//!   [`global_map`] (§6.1.4) with its spatial [`hash`], [`keyframe`] (§8.2.2),
//!   [`mapfile`] (map files and PLY export).
//! - The local occupancy [`grid`] (§3.2.3, §5.1), distance fields and frontiers.
//! - Planning: motion primitives, libraries, CSQMI reward and planning rounds
//!   ([`planner`], §4, paper V), the team frontier memory and global guidance
//!   beyond the window ([`exploration`], paper V-B), sampled [`trajectory`]s, the committed [`plan`].
//! - Safety: ellipsoid distance and collision probability ([`collision`], §7) and
//!   what is known of teammates ([`team`], §8.2.3).
//! - [`geometry`]: boxes and voxel lattices.
//!
//! ```
//! use nalgebra::{Isometry3, Point3, Vector3};
//! use troupe_algorithms::camera::PinholeIntrinsics;
//! use troupe_algorithms::grid::{CellState, LocalGrid, LogOddsParams};
//! use troupe_algorithms::planner::csqmi::{ViewRewardParams, view_information};
//!
//! // A 4 m grid, all unknown: a view from its centre is worth information.
//! let grid = LocalGrid::centred(&Point3::origin(), &Vector3::repeat(4.0), 0.2, LogOddsParams::default());
//! let camera = PinholeIntrinsics { width: 16, height: 12, fx: 8.0, fy: 8.0, cx: 8.0, cy: 6.0, max_depth_m: 1.5 };
//! let reward = view_information(&grid, &Isometry3::identity(), &camera, &ViewRewardParams::default());
//! assert!(reward > 0.0);
//! let centre = grid.cell_of(&Point3::origin()).unwrap();
//! assert_eq!(grid.classify(grid.values()[grid.index(centre)]), CellState::Unknown);
//! ```
#![deny(missing_docs)]

pub mod camera;
pub mod collision;
pub mod exploration;
pub mod frame;
pub mod geometry;
pub mod global_map;
pub mod grid;
pub mod hash;
pub mod keyframe;
pub mod mapfile;
pub mod mixture;
pub mod model;
pub mod plan;
pub mod planner;
pub mod sogmm;
pub mod team;
pub mod trajectory;
pub mod windowed;
