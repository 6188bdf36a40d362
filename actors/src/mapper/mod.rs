//! Map models built from depth + intensity frames.
//!
//! - [`sogmm`]: self-organizing 4D Gaussian mixtures (thesis §6, App. A): fit one frame,
//!   evaluate, marginalise, sample, and regress intensity.
//! - [`windowed`]: the windowed fixed-size occupied + free-space GMMs (paper §IV-A,
//!   thesis §3.2.1–3.2.2).
//! - [`model`]: [`MapModel`] (which of the two) and [`fit_keyframe`].
//! - [`merge`]: support-weighted merging of mixtures (Eqs. 3.4–3.5).
//! - [`mapfile`]: saving and loading a map (versioned binary layout), PLY export.
//! - [`global`]: the incremental global map (§6.1.4) and [`hash`], its spatial hash
//!   (§6.1.4.3).
//! - [`keyframe`]: keyframe selection by frustum overlap (§8.2.2).
//! - [`MapperActor`]: fits a SOGMM to each keyframe and publishes it for sharing,
//!   maintains the global map and publishes [`MapStats`] on [`MAPPER_STATS`].
mod actor;
pub mod global;
pub mod hash;
pub mod keyframe;
pub mod mapfile;
pub mod merge;
pub mod model;
pub mod sogmm;
pub mod windowed;

pub use actor::{
    MAPPER_STATS, MIN_KEYFRAME_POINTS, MapStats, MapUpdateStats, MapperActor, MapperConfig,
    decimate,
};
pub use model::{KeyframeFit, MapModel, fit_keyframe};
