//! Continuous-space collision checks against Gaussian surface models (thesis §7).
//!
//! - [`body`]: the robot body ellipsoid from configuration or as the minimum-volume
//!   enclosing ellipsoid of given points (Khachiyan), placed at a pose.
//! - [`ellipsoid`]: ellipsoids, the pair distance of Proposition 1 (Eq. 7.4) and its
//!   gradient (Eq. 7.7), through secular equations instead of 2q × 2q eigenproblems.
//! - [`geofence`]: the box a robot must stay in, checked on plans and setpoints.
//! - [`peers`]: what is known of teammates (odometry, plans, priorities) and the
//!   [`peers::PeerAvoidance`] trait of the inter-robot check (§8.2.3).
//! - [`probability`]: collision probability under Gaussian uncertainty of the robot
//!   centre (Eqs. 7.8–7.9, with the η rule of §7.1.4).
//! - [`surface`]: a set of surface ellipsoids from a GMM with a spatial index: the
//!   minimum distance (Eq. 7.6) and the blended collision probability (Eq. 7.10).

pub mod body;
pub mod ellipsoid;
pub mod geofence;
pub mod peers;
pub mod probability;
pub mod surface;

#[cfg(test)]
mod reference;
#[cfg(test)]
mod table72;
#[cfg(test)]
mod tests;
