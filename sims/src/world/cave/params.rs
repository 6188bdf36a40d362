//! Parameters of the procedural cave.

use serde::{Deserialize, Serialize};
use troupe_core::ConfigError;

/// Shape parameters of [`super::CaveWorld`]; lengths in metres, angles in degrees.
///
/// The defaults give a tree of about twelve tunnels spanning 60–100 m with three chambers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CaveParams {
    /// Number of tunnels (edges of the tunnel tree), the entrance tunnel included.
    pub tunnel_count: usize,
    /// Length of the entrance tunnel, where the robots start.
    pub entrance_tunnel_length_m: f64,
    /// Shortest length of the other tunnels.
    pub tunnel_length_min_m: f64,
    /// Longest length of the other tunnels.
    pub tunnel_length_max_m: f64,
    /// Smallest tunnel radius (before wall roughness).
    pub tunnel_radius_min_m: f64,
    /// Largest tunnel radius (before wall roughness).
    pub tunnel_radius_max_m: f64,
    /// Distance between centre-line polyline points.
    pub segment_length_m: f64,
    /// Largest change of heading between consecutive centre-line segments.
    pub wiggle_deg: f64,
    /// Largest slope of a tunnel (rise over run, dimensionless).
    pub max_grade: f64,
    /// Largest horizontal distance of a centre-line point from the entrance.
    pub max_reach_m: f64,
    /// Least rock thickness kept between tunnels that do not meet.
    pub min_wall_gap_m: f64,
    /// Number of chambers wanted (fewer are built when they do not fit).
    pub chamber_count: usize,
    /// Smallest chamber radius.
    pub chamber_radius_min_m: f64,
    /// Largest chamber radius.
    pub chamber_radius_max_m: f64,
    /// Amplitude of the wall roughness (displacement of the surface).
    pub wall_noise_amplitude_m: f64,
    /// Spatial wavelength of the wall roughness.
    pub wall_noise_wavelength_m: f64,
}

impl Default for CaveParams {
    fn default() -> Self {
        Self {
            tunnel_count: 12,
            entrance_tunnel_length_m: 20.0,
            tunnel_length_min_m: 12.0,
            tunnel_length_max_m: 20.0,
            tunnel_radius_min_m: 1.6,
            tunnel_radius_max_m: 2.4,
            segment_length_m: 2.5,
            wiggle_deg: 15.0,
            max_grade: 0.12,
            max_reach_m: 55.0,
            min_wall_gap_m: 2.0,
            chamber_count: 3,
            chamber_radius_min_m: 4.0,
            chamber_radius_max_m: 6.0,
            wall_noise_amplitude_m: 0.15,
            wall_noise_wavelength_m: 1.6,
        }
    }
}

/// Clearance the centre-line route must keep from the walls, in metres.
pub const ROUTE_CLEARANCE_M: f64 = 1.0;

impl CaveParams {
    /// Checks every field; the error names the field (relative to `[world.cave]`), the
    /// rule and the value.
    ///
    /// # Errors
    ///
    /// A length that is not finite and positive, a negative angle or roughness, a
    /// minimum above its maximum, no tunnels, or tunnels too narrow for the route's
    /// clearance ([`ROUTE_CLEARANCE_M`]).
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (key, v) in [
            ("entrance_tunnel_length_m", self.entrance_tunnel_length_m),
            ("tunnel_length_min_m", self.tunnel_length_min_m),
            ("tunnel_length_max_m", self.tunnel_length_max_m),
            ("tunnel_radius_min_m", self.tunnel_radius_min_m),
            ("tunnel_radius_max_m", self.tunnel_radius_max_m),
            ("segment_length_m", self.segment_length_m),
            ("max_reach_m", self.max_reach_m),
            ("min_wall_gap_m", self.min_wall_gap_m),
            ("chamber_radius_min_m", self.chamber_radius_min_m),
            ("chamber_radius_max_m", self.chamber_radius_max_m),
            ("wall_noise_wavelength_m", self.wall_noise_wavelength_m),
        ] {
            ConfigError::positive(key, v)?;
        }
        for (key, v) in [
            ("wiggle_deg", self.wiggle_deg),
            ("max_grade", self.max_grade),
            ("wall_noise_amplitude_m", self.wall_noise_amplitude_m),
        ] {
            ConfigError::non_negative(key, v)?;
        }
        for (name, lo, hi) in [
            (
                "tunnel_length",
                self.tunnel_length_min_m,
                self.tunnel_length_max_m,
            ),
            (
                "tunnel_radius",
                self.tunnel_radius_min_m,
                self.tunnel_radius_max_m,
            ),
            (
                "chamber_radius",
                self.chamber_radius_min_m,
                self.chamber_radius_max_m,
            ),
        ] {
            if lo > hi {
                return Err(ConfigError::new(
                    format!("{name}_min_m"),
                    format!("must not exceed `{name}_max_m` ({hi})"),
                    lo,
                ));
            }
        }
        if self.tunnel_count == 0 {
            return Err(ConfigError::new("tunnel_count", "must be at least 1", 0));
        }
        if self.wiggle_deg >= 90.0 {
            return Err(ConfigError::new(
                "wiggle_deg",
                "must be < 90",
                self.wiggle_deg,
            ));
        }
        let clearance = self.tunnel_radius_min_m - self.wall_noise_amplitude_m;
        if clearance < ROUTE_CLEARANCE_M + 0.1 {
            return Err(ConfigError::new(
                "tunnel_radius_min_m",
                format!(
                    "minus `wall_noise_amplitude_m` must be at least {} m (the route keeps \
                     {ROUTE_CLEARANCE_M} m from the walls)",
                    ROUTE_CLEARANCE_M + 0.1
                ),
                clearance,
            ));
        }
        if self.chamber_radius_min_m < self.tunnel_radius_max_m {
            return Err(ConfigError::new(
                "chamber_radius_min_m",
                format!(
                    "must be at least `tunnel_radius_max_m` ({})",
                    self.tunnel_radius_max_m
                ),
                self.chamber_radius_min_m,
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_errors_name_the_field() {
        assert_eq!(CaveParams::default().validate(), Ok(()));
        let p = CaveParams {
            segment_length_m: f64::NAN,
            ..CaveParams::default()
        };
        assert_eq!(p.validate().unwrap_err().key, "segment_length_m");
        let p = CaveParams {
            tunnel_radius_min_m: -1.0,
            ..CaveParams::default()
        };
        assert_eq!(p.validate().unwrap_err().key, "tunnel_radius_min_m");
        let p = CaveParams {
            chamber_radius_min_m: 7.0,
            ..CaveParams::default()
        };
        assert_eq!(p.validate().unwrap_err().key, "chamber_radius_min_m");
    }

    #[test]
    fn unknown_keys_are_rejected() {
        let err = serde_json::from_str::<CaveParams>(r#"{"tunnel_cuont": 3}"#).unwrap_err();
        assert!(err.to_string().contains("tunnel_cuont"));
        let p: CaveParams = serde_json::from_str(r#"{"tunnel_count": 3}"#).expect("parses");
        assert_eq!(p.tunnel_count, 3);
        assert_eq!(p.segment_length_m, CaveParams::default().segment_length_m);
    }
}
