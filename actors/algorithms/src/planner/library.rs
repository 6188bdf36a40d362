//! Motion primitive libraries (MPLs): thesis Eq. 4.3 and Table 4.2, paper Table I.

use serde::{Deserialize, Serialize};

use super::primitives::Action;

/// Which way a library's primitives head, in the body frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Heading {
    /// Turn in place.
    Yaw,
    /// Along +x_B (perpendicular to the sensor scans).
    Forward,
    /// Along −x_B.
    Backward,
    /// Along +y_B (parallel to the scans).
    Left,
    /// Along −y_B.
    Right,
    /// Along z only.
    Vertical,
}

/// Which speed bound a library uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpeedBound {
    /// No translation.
    Zero,
    /// V⊥,max from Eq. 4.2.
    Perpendicular,
    /// V_max.
    Max,
}

/// One library: a heading, a speed bound and a discretisation (N_ω × N_z primitives).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LibrarySpec {
    /// Heading.
    pub heading: Heading,
    /// Speed bound.
    pub speed: SpeedBound,
    /// Yaw-rate samples (N_ω).
    pub n_omega: usize,
    /// Vertical-speed samples (N_z).
    pub n_z: usize,
    /// Fixed duration as a multiple of the base duration (paper Table I); `None`:
    /// minimum duration by line search (thesis §4.1.2).
    pub duration_factor: Option<f64>,
}

/// The numbers a library needs. The defaults are the standard robot's (V_max =
/// 1.5 m/s, V⊥,max = 1.0 m/s), so that a `[robot.planner.round.library_params]` table
/// changes only the keys it names.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LibraryParams {
    /// Speed bound in the x_B–y_B plane, V_max, m/s (Table 4.2: 4.0).
    pub max_speed_mps: f64,
    /// Speed bound towards a frontier, V⊥,max, m/s (Eq. 4.2; 1.77 for Table 4.1).
    pub perpendicular_speed_mps: f64,
    /// Vertical speed bound V_z, m/s (Table 4.2: 0.3).
    pub vertical_speed_mps: f64,
    /// Yaw-rate bound Ω_max, rad/s.
    pub max_yaw_rate_rad_s: f64,
    /// Base duration τ for fixed-duration libraries, seconds (paper Table I: 3 s).
    pub base_duration_s: f64,
    /// The Yaw row turns in place both ways (two primitives, ±Ω_max; the default);
    /// `false`: one, +Ω_max, as Table 4.2 counts it (N_ω = 1). Turning one way only,
    /// a robot whose route lay just to its right had to begin a 5 rad turn the other
    /// way, which greedy choice never does: a return home stalled 30.7 m out on seed 5
    /// at 700 s. Measured in docs/results/exploration.md.
    pub yaw_both_ways: bool,
}

impl Default for LibraryParams {
    fn default() -> Self {
        LibraryParams {
            max_speed_mps: 1.5,
            perpendicular_speed_mps: 1.0,
            vertical_speed_mps: 0.3,
            max_yaw_rate_rad_s: 0.6,
            base_duration_s: 3.0,
            yaw_both_ways: true,
        }
    }
}

const fn spec(heading: Heading, speed: SpeedBound, n_omega: usize, n_z: usize) -> LibrarySpec {
    LibrarySpec {
        heading,
        speed,
        n_omega,
        n_z,
        duration_factor: None,
    }
}

/// Thesis Table 4.2a, the large library (186 primitives).
#[must_use]
pub fn large() -> Vec<LibrarySpec> {
    table_4_2(9, 5)
}

/// Thesis Table 4.2b, the minimal library (40 primitives).
#[must_use]
pub fn minimal() -> Vec<LibrarySpec> {
    table_4_2(3, 3)
}

/// The rows of thesis Table 4.2, which its two libraries share: `n_omega` yaw rates
/// and `n_z` vertical speeds per moving row.
fn table_4_2(n_omega: usize, n_z: usize) -> Vec<LibrarySpec> {
    use Heading::*;
    use SpeedBound::*;
    vec![
        spec(Yaw, Zero, 1, 1),
        spec(Forward, Perpendicular, n_omega, n_z),
        spec(Forward, Max, n_omega, n_z),
        spec(Left, Max, n_omega, n_z),
        spec(Right, Max, n_omega, n_z),
        spec(Vertical, Zero, 1, n_z),
    ]
}

/// Paper Table I (65 primitives, durations τ and 2τ).
#[must_use]
pub fn paper() -> Vec<LibrarySpec> {
    use Heading::*;
    use SpeedBound::*;
    let fixed = |heading, n_omega, n_z, factor| LibrarySpec {
        duration_factor: Some(factor),
        ..spec(heading, Max, n_omega, n_z)
    };
    vec![
        fixed(Forward, 3, 5, 1.0),
        fixed(Forward, 3, 5, 2.0),
        fixed(Backward, 3, 5, 1.0),
        fixed(Backward, 3, 5, 2.0),
        LibrarySpec {
            duration_factor: Some(1.0),
            ..spec(Vertical, Zero, 1, 5)
        },
    ]
}

/// `n` evenly spaced values in [−bound, bound] (just 0 for n = 1).
fn symmetric(n: usize, bound: f64) -> Vec<f64> {
    match n {
        0 => Vec::new(),
        1 => vec![0.0],
        _ => (0..n)
            .map(|i| -bound + 2.0 * bound * i as f64 / (n - 1) as f64)
            .collect(),
    }
}

/// The actions of one library (Eq. 4.3), with their fixed duration if any.
#[must_use]
pub fn actions(spec: &LibrarySpec, params: &LibraryParams) -> Vec<(Action, Option<f64>)> {
    let speed = match spec.speed {
        SpeedBound::Zero => 0.0,
        SpeedBound::Perpendicular => params.perpendicular_speed_mps.min(params.max_speed_mps),
        SpeedBound::Max => params.max_speed_mps,
    };
    let (vx, vy) = match spec.heading {
        Heading::Forward => (speed, 0.0),
        Heading::Backward => (-speed, 0.0),
        Heading::Left => (0.0, speed),
        Heading::Right => (0.0, -speed),
        Heading::Yaw | Heading::Vertical => (0.0, 0.0),
    };
    let omegas = if spec.heading == Heading::Yaw {
        if params.yaw_both_ways {
            vec![params.max_yaw_rate_rad_s, -params.max_yaw_rate_rad_s]
        } else {
            vec![params.max_yaw_rate_rad_s]
        }
    } else {
        symmetric(spec.n_omega, params.max_yaw_rate_rad_s)
    };
    let vzs = symmetric(spec.n_z, params.vertical_speed_mps);
    let duration = spec.duration_factor.map(|f| f * params.base_duration_s);
    omegas
        .iter()
        .flat_map(|&w| {
            vzs.iter().map(move |&vz| {
                (
                    Action {
                        vx_mps: vx,
                        vy_mps: vy,
                        vz_mps: vz,
                        yaw_rate_rad_s: w,
                    },
                    duration,
                )
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(specs: &[LibrarySpec], params: &LibraryParams) -> usize {
        specs.iter().map(|s| actions(s, params).len()).sum()
    }

    #[test]
    fn library_sizes_match_the_tables() {
        // Table 4.2 counts one turn in place (N_ω = 1).
        let table = LibraryParams {
            yaw_both_ways: false,
            ..LibraryParams::default()
        };
        assert_eq!(count(&large(), &table), 1 + 4 * 45 + 5);
        assert_eq!(count(&minimal(), &table), 1 + 4 * 9 + 3);
        assert_eq!(count(&paper(), &table), 4 * 15 + 5);
        for s in large() {
            let n = actions(&s, &table).len();
            assert_eq!(n, s.n_omega * s.n_z, "{s:?}");
        }
        // Turning in place both ways adds one primitive to the Yaw row.
        let both = LibraryParams {
            yaw_both_ways: true,
            ..table
        };
        assert_eq!(count(&large(), &both), count(&large(), &table) + 1);
        assert_eq!(count(&minimal(), &both), count(&minimal(), &table) + 1);
    }

    #[test]
    fn actions_respect_the_bounds_of_eq_4_3() {
        let params = LibraryParams::default();
        for s in large().iter().chain(&paper()) {
            for (a, _) in actions(s, &params) {
                assert!(a.vx_mps.hypot(a.vy_mps) <= params.max_speed_mps + 1e-12);
                assert!(a.vz_mps.abs() <= params.vertical_speed_mps + 1e-12);
                assert!(a.yaw_rate_rad_s.abs() <= params.max_yaw_rate_rad_s + 1e-12);
            }
        }
    }
}
