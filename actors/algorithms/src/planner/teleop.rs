//! Teleoperation with motion primitives (thesis §5.1.2): a joystick or scripted
//! command a = (v_x, v_z, ω) is mapped, by grid search, to the closest primitive of a
//! forward-arc library around it that is feasible from the current reference state
//! and safe together with its stopping primitive; the forward speed bound adapts to
//! the free space ahead (Eq. 5.1).
//!
//! Eq. 5.1 bounds the forward speed by the map information ahead, z_eq, minus the
//! robot radius and collision tolerance. Here z_eq − (r_robot + r_coll) is measured
//! directly in the grid snapshot (the fixed-resolution window, or the
//! variable-resolution HCA map of Alg. 1 when the grid actor has it on, whose extent
//! ahead then limits it): the distance the robot centre can travel along its heading
//! while keeping the round's clearance margin from unsafe (occupied or unknown)
//! space. The speed therefore drops as the robot nears walls ahead or the edge of
//! what it has seen.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::primitives::{Action, FlatState, Primitive};
use super::round::RoundConfig;
use crate::grid::GridSnapshot;
use troupe_core::{Message, Time};

/// An operator's command in the body frame (thesis §5.1.2: a_t = {v_x, v_z, ω}).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TeleopCommand {
    /// When it was given.
    pub stamp: Time,
    /// Forward speed along body x, m/s.
    pub vx_mps: f64,
    /// Vertical speed, m/s.
    pub vz_mps: f64,
    /// Yaw rate, rad/s.
    pub yaw_rate_rad_s: f64,
}
impl Message for TeleopCommand {}

/// Settings of the teleoperation library and its speed adaptation.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TeleopParams {
    /// Forward speed bound V_x before adaptation, m/s.
    pub max_speed_mps: f64,
    /// Vertical speed bound V_z, m/s.
    pub vertical_speed_mps: f64,
    /// Yaw-rate bound Ω, rad/s.
    pub max_yaw_rate_rad_s: f64,
    /// Forward-speed samples of the library grid in [−V_x, V_x] (odd keeps 0).
    pub n_vx: usize,
    /// Vertical-speed samples in [−V_z, V_z].
    pub n_vz: usize,
    /// Yaw-rate samples in [−Ω, Ω].
    pub n_omega: usize,
    /// Deceleration A_x of Eq. 5.1, m/s².
    pub decel_mps2: f64,
    /// Latency Δt_l = Δt_s + Δt_m + 2Δt_p of Eq. 5.1, seconds.
    pub latency_s: f64,
    /// The constant δv subtracted from the Eq. 5.1 bound for unmodelled dynamics, m/s.
    pub speed_reduction_mps: f64,
    /// Commands older than this are treated as "stop", seconds.
    pub command_timeout_s: f64,
}

impl Default for TeleopParams {
    fn default() -> Self {
        TeleopParams {
            max_speed_mps: 1.5,
            vertical_speed_mps: 0.3,
            max_yaw_rate_rad_s: 0.6,
            n_vx: 9,
            n_vz: 3,
            n_omega: 5,
            decel_mps2: 3.0,
            latency_s: 0.4,
            speed_reduction_mps: 0.0,
            command_timeout_s: 2.0,
        }
    }
}

/// What one teleoperation round chose.
#[derive(Clone, Debug)]
pub struct TeleopChoice {
    /// The primitive closest to the command among the feasible, safe ones.
    pub primitive: Primitive,
    /// Its stopping primitive from the planning period on.
    pub stopping: Primitive,
    /// The adapted forward speed bound V_x (Eq. 5.1), m/s.
    pub speed_bound_mps: f64,
}

/// How far the robot centre can move from `from` along `direction` while keeping
/// `margin_m` from unsafe space, up to `max_m`, metres (marching in half cells).
#[must_use]
pub fn free_run_m(
    snapshot: &GridSnapshot,
    from: &Point3<f64>,
    direction: &Vector3<f64>,
    margin_m: f64,
    max_m: f64,
) -> f64 {
    let Some(unit) = direction.try_normalize(1e-12) else {
        return 0.0;
    };
    let step = snapshot.grid.resolution_m() / 2.0;
    let mut travelled = 0.0;
    while travelled < max_m {
        let next = (travelled + step).min(max_m);
        if snapshot.clearance_m(&(from + unit * next)) < margin_m {
            break;
        }
        travelled = next;
    }
    travelled
}

/// The forward speed bound of Eq. 5.1 for a free run `run_m` (= z_eq − (r_robot +
/// r_coll)) ahead: V_x = A_x (√(Δt_l² + 2 run / A_x) − Δt_l) − δv, clamped to
/// [0, `max_speed_mps`].
#[must_use]
pub fn speed_bound_mps(params: &TeleopParams, run_m: f64) -> f64 {
    let a = params.decel_mps2.max(1e-9);
    let dt = params.latency_s.max(0.0);
    let v = a * ((dt * dt + 2.0 * run_m.max(0.0) / a).sqrt() - dt) - params.speed_reduction_mps;
    v.clamp(0.0, params.max_speed_mps.max(0.0))
}

/// `n` evenly spaced values in [−bound, bound] (just 0 for n ≤ 1).
fn symmetric(n: usize, bound: f64) -> Vec<f64> {
    if n <= 1 {
        return vec![0.0];
    }
    (0..n)
        .map(|i| -bound + 2.0 * bound * i as f64 / (n - 1) as f64)
        .collect()
}

/// Maps `command` (or "stop" for `None`) to the closest feasible, safe primitive
/// from `from` (thesis §5.1.2, Alg. 1 lines 5–7 at one resolution): the library
/// grid is built with the adapted forward bound V_x, its actions are tried in order
/// of normalised distance to the clamped command, and the first whose primitive
/// (minimum duration by line search) passes the limits and whose primitive and
/// stopping primitive keep the clearance is returned. `None`: nothing is safe (the
/// caller sends the stopping trajectory).
#[must_use]
pub fn closest_safe_primitive(
    round: &RoundConfig,
    params: &TeleopParams,
    snapshot: &GridSnapshot,
    from: &FlatState,
    command: Option<&TeleopCommand>,
) -> Option<TeleopChoice> {
    let margin_m = round.margin_m(snapshot.grid.resolution_m());
    let heading = Vector3::new(from.yaw_rad().cos(), from.yaw_rad().sin(), 0.0);
    let position = Point3::from(from.position_m());
    let reach_m = params.max_speed_mps * (params.latency_s + 4.0);
    let forward_bound = speed_bound_mps(
        params,
        free_run_m(snapshot, &position, &heading, margin_m, reach_m),
    );
    let backward_bound = speed_bound_mps(
        params,
        free_run_m(snapshot, &position, &(-heading), margin_m, reach_m),
    );
    let (vx, vz, w) = command.map_or((0.0, 0.0, 0.0), |c| (c.vx_mps, c.vz_mps, c.yaw_rate_rad_s));
    let target = (
        vx.clamp(-backward_bound, forward_bound),
        vz.clamp(-params.vertical_speed_mps, params.vertical_speed_mps),
        w.clamp(-params.max_yaw_rate_rad_s, params.max_yaw_rate_rad_s),
    );
    let scale = |v: f64| v.abs().max(1e-9);
    let mut grid: Vec<(f64, Action)> = Vec::new();
    for &gx in &symmetric(params.n_vx, params.max_speed_mps) {
        // The library is redesigned for the adapted bound (§5.1.2): speeds above it
        // are scaled into it.
        let gx = if gx >= 0.0 {
            gx * forward_bound / scale(params.max_speed_mps)
        } else {
            gx * backward_bound / scale(params.max_speed_mps)
        };
        for &gz in &symmetric(params.n_vz, params.vertical_speed_mps) {
            for &gw in &symmetric(params.n_omega, params.max_yaw_rate_rad_s) {
                let d = ((gx - target.0) / scale(params.max_speed_mps)).powi(2)
                    + ((gz - target.1) / scale(params.vertical_speed_mps)).powi(2)
                    + ((gw - target.2) / scale(params.max_yaw_rate_rad_s)).powi(2);
                grid.push((
                    d,
                    Action {
                        vx_mps: gx,
                        vy_mps: 0.0,
                        vz_mps: gz,
                        yaw_rate_rad_s: gw,
                    },
                ));
            }
        }
    }
    grid.sort_by(|a, b| a.0.total_cmp(&b.0));
    grid.into_iter().find_map(|(_, action)| {
        let primitive = round.limits.shortest(from, action)?;
        let stopping = round.safe_with_stop(&primitive, snapshot)?;
        Some(TeleopChoice {
            primitive,
            stopping,
            speed_bound_mps: forward_bound,
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planner::scenes;

    #[test]
    fn speed_bound_follows_eq_5_1_and_shrinks_with_the_free_run() {
        let params = TeleopParams {
            max_speed_mps: 10.0,
            ..TeleopParams::default()
        };
        // Eq. 5.1 is the speed from which the robot stops within the run after the
        // latency: v Δt_l + v² / (2 A_x) = run.
        for run in [0.5, 1.0, 3.0, 8.0] {
            let v = speed_bound_mps(&params, run);
            let travelled = v * params.latency_s + v * v / (2.0 * params.decel_mps2);
            assert!((travelled - run).abs() < 1e-9, "{run}: {travelled}");
        }
        let mut previous = f64::INFINITY;
        for run in [8.0, 4.0, 2.0, 1.0, 0.5, 0.0] {
            let v = speed_bound_mps(&TeleopParams::default(), run);
            assert!(v <= previous && v >= 0.0);
            previous = v;
        }
        assert_eq!(speed_bound_mps(&TeleopParams::default(), 0.0), 0.0);
    }

    /// Flies the teleoperation loop on a fixed grid: each round commits the chosen
    /// primitive for the planning period and replans from the reference there.
    #[test]
    fn forward_commands_in_a_corridor_move_forward_and_stay_safe() {
        let snapshot = scenes::corridor(6.0, 1.4, 1.4);
        let round = RoundConfig::default();
        let params = TeleopParams::default();
        let margin = round.margin_m(snapshot.grid.resolution_m());
        let command = TeleopCommand {
            stamp: Time::ZERO,
            vx_mps: 1.5,
            vz_mps: 0.0,
            yaw_rate_rad_s: 0.0,
        };
        let mut state = FlatState::at_rest(Vector3::zeros(), 0.0);
        let mut xs = vec![0.0];
        let mut speeds = Vec::new();
        for _ in 0..25 {
            let Some(choice) =
                closest_safe_primitive(&round, &params, &snapshot, &state, Some(&command))
            else {
                // Nothing safe: follow the stopping trajectory from here.
                let stop = round.limits.stopping(&state).expect("a stop exists");
                for i in 0..=20 {
                    let p = stop.state_at(stop.duration_s() * f64::from(i) / 20.0);
                    assert!(snapshot.clearance_m(&Point3::from(p.position_m())) >= margin - 0.2);
                }
                state = stop.end_state();
                continue;
            };
            // Committed part and stopping primitive keep the clearance.
            let switch = round.planning_period_s.min(choice.primitive.duration_s());
            for i in 0..=50 {
                let t = switch * f64::from(i) / 50.0;
                let p = Point3::from(choice.primitive.state_at(t).position_m());
                assert!(snapshot.clearance_m(&p) >= margin, "unsafe at {p}");
                let s = choice.stopping.duration_s() * f64::from(i) / 50.0;
                let q = Point3::from(choice.stopping.state_at(s).position_m());
                assert!(snapshot.clearance_m(&q) >= margin, "unsafe stop at {q}");
            }
            assert!(choice.primitive.action().vx_mps >= 0.0);
            speeds.push(choice.speed_bound_mps);
            state = choice.primitive.state_at(switch);
            xs.push(state.position_m().x);
        }
        // Forward motion, never backwards, and not sideways.
        assert!(xs.windows(2).all(|w| w[1] >= w[0] - 1e-9), "{xs:?}");
        let end = *xs.last().expect("positions");
        assert!(end > 2.5, "travelled only {end} m");
        assert!(state.position_m().y.abs() < 0.5);
        // The corridor ends in unknown space: the speed bound falls towards the end
        // and the robot never reaches the unknown.
        assert!(end < 6.0);
        let first = speeds.first().copied().unwrap_or(0.0);
        let last = speeds.last().copied().unwrap_or(0.0);
        assert!(last < first, "{speeds:?}");
    }

    #[test]
    fn no_command_means_hover() {
        let snapshot = scenes::corridor(6.0, 1.4, 1.4);
        let round = RoundConfig::default();
        let state = FlatState::at_rest(Vector3::zeros(), 0.0);
        let choice =
            closest_safe_primitive(&round, &TeleopParams::default(), &snapshot, &state, None)
                .expect("hovering is safe");
        assert_eq!(choice.primitive.action().vx_mps, 0.0);
        assert!(choice.primitive.end_state().velocity_mps().norm() < 1e-9);
    }
}
