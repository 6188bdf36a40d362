//! The mapper actor (thesis §6, §8.2.2); the map models are in
//! [`troupe_algorithms`] ([`model`](troupe_algorithms::model),
//! [`sogmm`](troupe_algorithms::sogmm), [`windowed`](troupe_algorithms::windowed),
//! [`global_map`](troupe_algorithms::global_map), [`mapfile`](troupe_algorithms::mapfile)).
//!
//! - [`MapperActor`]: fits a SOGMM to each keyframe and publishes it for sharing,
//!   maintains the global map and publishes [`MapStats`] on [`MAPPER_STATS`].
mod actor;

pub use actor::{
    MAPPER_STATS, MIN_KEYFRAME_POINTS, MapStats, MapUpdateStats, MapperActor, MapperConfig,
    decimate,
};
