//! Map models built from depth + intensity frames.
//!
//! - [`sogmm`]: self-organizing 4D Gaussian mixtures (thesis §6, App. A): fit one frame,
//!   evaluate, marginalise, sample, and regress intensity.
pub mod sogmm;
