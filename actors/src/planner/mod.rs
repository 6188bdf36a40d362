//! Motion primitives and their libraries (thesis §4.1, paper V-A).
//!
//! - [`primitives`]: snap-continuous forward-arc primitives as 8th-order polynomials
//!   per flat axis (x, y, z, yaw), with minimum-duration line search under
//!   acceleration and jerk limits, and stopping primitives.
//! - [`bounds`]: the steady-state velocity bound of Eq. 4.2.
//! - [`library`]: the motion primitive libraries of thesis Table 4.2 and paper Table I.

pub mod bounds;
pub mod csqmi;
pub mod library;
pub mod primitives;
