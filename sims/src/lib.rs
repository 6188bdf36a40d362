//! troupe-sims: worlds, the simulated camera and vehicle, ground-truth metrics.
pub mod camera;
pub mod coverage;
pub mod world;
