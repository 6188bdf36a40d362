//! Steady-state velocity bounds for reconstruction (thesis §4.1.1).

/// Maximum speed towards a frontier, thesis Eq. 4.2:
/// `V⊥ = min(V_max, A_max (√(Δt_l² + 2 (z_max − r_coll) / A_max) − Δt_l))`, where the
/// total latency is `Δt_l = Δt_m + 2 Δt_p` (mapping latency plus two planning periods).
#[must_use]
pub fn perpendicular_speed_bound_mps(
    max_speed_mps: f64,
    max_accel_mps2: f64,
    sensor_range_m: f64,
    collision_radius_m: f64,
    latency_s: f64,
) -> f64 {
    let reach = (sensor_range_m - collision_radius_m).max(0.0);
    let v = max_accel_mps2
        * ((latency_s * latency_s + 2.0 * reach / max_accel_mps2).sqrt() - latency_s);
    v.min(max_speed_mps)
}

/// Total latency `Δt_l = Δt_m + 2 Δt_p` of thesis §4.1.1.
#[must_use]
pub fn total_latency_s(mapping_latency_s: f64, planning_period_s: f64) -> f64 {
    mapping_latency_s + 2.0 * planning_period_s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_4_1_parameters_give_1_77_mps() {
        // Table 4.1: 1 Hz planning, 0.4 s mapping latency, z_max = 5 m, r_coll = 0.6 m,
        // V_max = 4 m/s; A_max = 10 m/s² (§4.2).
        let latency = total_latency_s(0.4, 1.0);
        let v = perpendicular_speed_bound_mps(4.0, 10.0, 5.0, 0.6, latency);
        assert!((v - 1.77).abs() < 0.005, "{v}");
        // Parallel motion is bounded by V_max alone; a long range saturates the bound.
        assert_eq!(
            perpendicular_speed_bound_mps(4.0, 10.0, 100.0, 0.6, latency),
            4.0
        );
    }
}
