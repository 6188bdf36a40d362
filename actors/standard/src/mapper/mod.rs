//! The mapper actor (thesis §6, §8.2.2); the map models are in
//! [`troupe_algorithms`] and re-exported here under their old names.
//!
//! - [`MapperActor`]: fits a SOGMM to each keyframe and publishes it for sharing,
//!   maintains the global map and publishes [`MapStats`] on [`MAPPER_STATS`].
mod actor;

pub use actor::{
    MAPPER_STATS, MIN_KEYFRAME_POINTS, MapStats, MapUpdateStats, MapperActor, MapperConfig,
    decimate,
};
pub use troupe_algorithms::model::{KeyframeFit, MapModel, fit_keyframe};
pub use troupe_algorithms::{
    global_map as global, hash, keyframe, mapfile, mixture, model, sogmm, windowed,
};
