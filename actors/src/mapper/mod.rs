//! Map models built from depth + intensity frames.
//!
//! - [`sogmm`]: self-organizing 4D Gaussian mixtures (thesis §6, App. A): fit one frame,
//!   evaluate, marginalise, sample, and regress intensity.
//! - [`global`]: the incremental global map (§6.1.4) and [`hash`], its spatial hash
//!   (§6.1.4.3).
//! - [`keyframe`]: keyframe selection by frustum overlap (§8.2.2).
//! - [`MapperActor`]: fits a SOGMM to each keyframe and publishes it for sharing,
//!   maintains the global map and publishes [`MapStats`] on [`MAPPER_STATS`].
mod actor;
pub mod global;
pub mod hash;
pub mod keyframe;
pub mod sogmm;

pub use actor::{MAPPER_STATS, MapStats, MapUpdateStats, MapperActor, MapperConfig, decimate};
