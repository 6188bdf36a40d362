//! Forward-arc motion primitives (thesis §4.1.2, Eq. 4.4; paper V-A).
//!
//! A primitive moves the differentially flat state ξ = (x, y, z, ψ) from the current
//! state (position, velocity, acceleration, jerk and snap all given) to an end
//! velocity obtained by propagating unicycle kinematics under the action
//! a = (v_x, v_y, v_z, ω) in the body frame for the duration τ, with acceleration,
//! jerk and snap zero at the end and the end position free. Per axis that is nine
//! conditions, met exactly by an 8th-order polynomial. After τ the primitive holds
//! its end velocity.

use nalgebra::{Matrix4, Vector3, Vector4};

/// Number of derivatives of the flat state carried (position … snap).
pub const DERIVATIVES: usize = 5;

/// The flat state and its derivatives: `derivatives[k]` is the k-th time derivative
/// of (x, y, z, ψ) (0 position/yaw, 1 velocity/yaw rate, 2 acceleration, 3 jerk, 4 snap).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlatState {
    /// Derivatives 0 to 4.
    pub derivatives: [Vector4<f64>; DERIVATIVES],
}

impl FlatState {
    /// At rest at a position and heading.
    #[must_use]
    pub fn at_rest(position_m: Vector3<f64>, yaw_rad: f64) -> Self {
        let mut derivatives = [Vector4::zeros(); DERIVATIVES];
        derivatives[0] = Vector4::new(position_m.x, position_m.y, position_m.z, yaw_rad);
        FlatState { derivatives }
    }

    /// Position, metres.
    #[must_use]
    pub fn position_m(&self) -> Vector3<f64> {
        self.derivatives[0].xyz()
    }

    /// Heading, radians.
    #[must_use]
    pub fn yaw_rad(&self) -> f64 {
        self.derivatives[0].w
    }

    /// Linear velocity, m/s.
    #[must_use]
    pub fn velocity_mps(&self) -> Vector3<f64> {
        self.derivatives[1].xyz()
    }

    /// Linear acceleration, m/s².
    #[must_use]
    pub fn acceleration_mps2(&self) -> Vector3<f64> {
        self.derivatives[2].xyz()
    }

    /// Linear jerk, m/s³.
    #[must_use]
    pub fn jerk_mps3(&self) -> Vector3<f64> {
        self.derivatives[3].xyz()
    }
}

/// An action: body-frame velocities and yaw rate to reach (thesis Eq. 4.3; `v_y` ≠ 0
/// gives the lateral "parallel" libraries of Table 4.2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Action {
    /// Forward speed along body x, m/s.
    pub vx_mps: f64,
    /// Lateral speed along body y, m/s.
    pub vy_mps: f64,
    /// Vertical speed, m/s.
    pub vz_mps: f64,
    /// Yaw rate, rad/s.
    pub yaw_rate_rad_s: f64,
}

impl Action {
    /// Standing still (used for stopping primitives).
    pub const STOP: Action = Action {
        vx_mps: 0.0,
        vy_mps: 0.0,
        vz_mps: 0.0,
        yaw_rate_rad_s: 0.0,
    };

    /// The world-frame end velocity after `duration_s` from heading `yaw_rad`
    /// (unicycle propagation, Eq. 4.4: ψ_τ = ψ₀ + ωτ).
    #[must_use]
    pub fn end_velocity(&self, yaw_rad: f64, duration_s: f64) -> Vector4<f64> {
        let psi = yaw_rad + self.yaw_rate_rad_s * duration_s;
        let (s, c) = psi.sin_cos();
        Vector4::new(
            self.vx_mps * c - self.vy_mps * s,
            self.vx_mps * s + self.vy_mps * c,
            self.vz_mps,
            self.yaw_rate_rad_s,
        )
    }
}

/// Falling factorial k!/(k−r)! (0 when r > k).
fn falling(k: usize, r: usize) -> f64 {
    if r > k {
        0.0
    } else {
        ((k - r + 1)..=k).map(|v| v as f64).product()
    }
}

/// A primitive: an 8th-order polynomial per flat axis over `[0, duration_s]`,
/// evaluated in time since its start.
#[derive(Clone, Debug, PartialEq)]
pub struct Primitive {
    /// Coefficients of t⁰ … t⁸ per axis.
    coefficients: [Vector4<f64>; 9],
    duration_s: f64,
    action: Action,
}

impl Primitive {
    /// The primitive from `start` that reaches the end velocity of `action` after
    /// `duration_s` (> 0) with zero acceleration, jerk and snap (Eq. 4.4).
    #[must_use]
    pub fn forward_arc(start: &FlatState, action: Action, duration_s: f64) -> Self {
        let tau = duration_s.max(1e-6);
        let end_velocity = action.end_velocity(start.yaw_rad(), tau);
        // Scaled coefficients d_k = c_k τ^k; the first five follow from the start state.
        let mut scaled = [Vector4::zeros(); 9];
        for (k, d) in scaled.iter_mut().enumerate().take(DERIVATIVES) {
            *d = start.derivatives[k] * (tau.powi(k as i32) / falling(k, k));
        }
        // End conditions r = 1..4: Σ_k falling(k, r) d_k = target_r τ^r.
        let m = Matrix4::from_fn(|r, j| falling(j + 5, r + 1));
        let lu = m.lu();
        for axis in 0..4 {
            let rhs = Vector4::from_fn(|r, _| {
                let r = r + 1;
                let target = if r == 1 {
                    end_velocity[axis] * tau
                } else {
                    0.0
                };
                target
                    - (0..DERIVATIVES)
                        .map(|k| falling(k, r) * scaled[k][axis])
                        .sum::<f64>()
            });
            // The matrix is constant and invertible (a scaled Vandermonde block).
            let solution = lu.solve(&rhs).unwrap_or_else(Vector4::zeros);
            for j in 0..4 {
                scaled[j + 5][axis] = solution[j];
            }
        }
        let coefficients = std::array::from_fn(|k| scaled[k] / tau.powi(k as i32));
        Primitive {
            coefficients,
            duration_s: tau,
            action,
        }
    }

    /// Duration τ, seconds.
    #[must_use]
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// The action it was built from.
    #[must_use]
    pub fn action(&self) -> Action {
        self.action
    }

    /// State at `t` seconds after the start (clamped at 0); after τ the end velocity
    /// is held with zero higher derivatives.
    #[must_use]
    pub fn state_at(&self, t: f64) -> FlatState {
        let t = t.max(0.0);
        if t > self.duration_s {
            let end = self.evaluate(self.duration_s);
            let mut derivatives = [Vector4::zeros(); DERIVATIVES];
            derivatives[0] = end.derivatives[0] + end.derivatives[1] * (t - self.duration_s);
            derivatives[1] = end.derivatives[1];
            return FlatState { derivatives };
        }
        self.evaluate(t)
    }

    fn evaluate(&self, t: f64) -> FlatState {
        let mut derivatives = [Vector4::zeros(); DERIVATIVES];
        for (r, d) in derivatives.iter_mut().enumerate() {
            // Horner on Σ_{k≥r} falling(k, r) c_k t^(k−r).
            let mut acc = Vector4::zeros();
            for k in (r..9).rev() {
                acc = acc * t + self.coefficients[k] * falling(k, r);
            }
            *d = acc;
        }
        FlatState { derivatives }
    }

    /// The state at the end (t = τ).
    #[must_use]
    pub fn end_state(&self) -> FlatState {
        self.evaluate(self.duration_s)
    }

    /// Largest acceleration and jerk L2 norms (linear part) over `samples` + 1
    /// evenly spaced times in [0, τ].
    #[must_use]
    pub fn peak_accel_jerk(&self, samples: usize) -> (f64, f64) {
        let n = samples.max(1);
        (0..=n).fold((0.0f64, 0.0f64), |(a, j), i| {
            let s = self.evaluate(self.duration_s * i as f64 / n as f64);
            (
                a.max(s.acceleration_mps2().norm()),
                j.max(s.jerk_mps3().norm()),
            )
        })
    }
}

/// Limits and search settings for building primitives. The defaults are the standard
/// robot's (A_max = 3 m/s², J_max = 10 m/s³), so that a `[robot.planner.round.limits]`
/// table changes only the keys it names; the thesis' are [`DynamicLimits::THESIS`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DynamicLimits {
    /// Acceleration bound (L2 norm), m/s².
    pub max_accel_mps2: f64,
    /// Jerk bound (L2 norm), m/s³.
    pub max_jerk_mps3: f64,
    /// Shortest duration tried (the planning period Δt_p), seconds.
    pub min_duration_s: f64,
    /// Longest duration tried (τ_max), seconds.
    pub max_duration_s: f64,
    /// Line-search step, seconds.
    pub duration_step_s: f64,
    /// Samples per primitive for the feasibility check.
    pub check_samples: usize,
}

impl Default for DynamicLimits {
    fn default() -> Self {
        DynamicLimits {
            max_accel_mps2: 3.0,
            max_jerk_mps3: 10.0,
            ..DynamicLimits::THESIS
        }
    }
}

impl DynamicLimits {
    /// The thesis' limits (§4.2: A_max = 10 m/s², J_max = 35 m/s³).
    pub const THESIS: DynamicLimits = DynamicLimits {
        max_accel_mps2: 10.0,
        max_jerk_mps3: 35.0,
        min_duration_s: 1.0,
        max_duration_s: 6.0,
        duration_step_s: 0.1,
        check_samples: 64,
    };

    /// Whether a primitive respects the limits at the check samples.
    #[must_use]
    pub fn admits(&self, primitive: &Primitive) -> bool {
        let (a, j) = primitive.peak_accel_jerk(self.check_samples);
        a <= self.max_accel_mps2 && j <= self.max_jerk_mps3
    }

    /// The shortest feasible primitive for `action` from `start`, by line search over
    /// durations from `min_duration_s` to `max_duration_s` (thesis §4.1.2); `None` if
    /// none is feasible.
    #[must_use]
    pub fn shortest(&self, start: &FlatState, action: Action) -> Option<Primitive> {
        let step = self.duration_step_s.max(1e-3);
        let steps = ((self.max_duration_s - self.min_duration_s) / step)
            .floor()
            .max(0.0) as usize;
        (0..=steps)
            .map(|i| self.min_duration_s + step * i as f64)
            .map(|tau| Primitive::forward_arc(start, action, tau))
            .find(|p| self.admits(p))
    }

    /// The shortest feasible stopping primitive from `start` (end velocity zero).
    #[must_use]
    pub fn stopping(&self, start: &FlatState) -> Option<Primitive> {
        self.shortest(start, Action::STOP)
    }

    /// The feasible stopping primitive from `start` that strays least from it: the
    /// braking of a robot that must stop now (thesis §4.1.3's fail-safe commitment),
    /// with durations from one line-search step to `max_duration_s` (not only from the
    /// planning period: a stop may be quicker than a period). A stopping primitive
    /// carries the start's acceleration, jerk and snap and ends at rest, so from a
    /// robot speeding up it first speeds up further; the shortest one from the
    /// planning period on can fly far — 1.45 m from 0.22 m/s, accelerating at
    /// 1.9 m/s², in a cave run, into a peer's way — where a quicker one stops within
    /// centimetres. Ties go to the shorter duration; `None` when no stop is feasible.
    #[must_use]
    pub fn braking(&self, start: &FlatState) -> Option<Primitive> {
        let step = self.duration_step_s.max(1e-3);
        let steps = (self.max_duration_s / step).floor().max(1.0) as usize;
        let n = self.check_samples.max(1);
        let origin = start.position_m();
        let excursion = |p: &Primitive| {
            (0..=n)
                .map(|i| {
                    let s = p.state_at(p.duration_s() * i as f64 / n as f64);
                    (s.position_m() - origin).norm()
                })
                .fold(0.0, f64::max)
        };
        (1..=steps)
            .map(|i| Primitive::forward_arc(start, Action::STOP, step * i as f64))
            .filter(|p| self.admits(p))
            .map(|p| (excursion(&p), p))
            .reduce(|best, next| if next.0 < best.0 { next } else { best })
            .map(|(_, p)| p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moving_state() -> FlatState {
        FlatState {
            derivatives: [
                Vector4::new(1.0, -2.0, 1.5, 0.3),
                Vector4::new(1.2, 0.4, -0.1, 0.2),
                Vector4::new(0.5, -0.3, 0.2, 0.05),
                Vector4::new(-0.4, 0.2, 0.1, 0.0),
                Vector4::new(0.3, 0.1, -0.2, 0.01),
            ],
        }
    }

    #[test]
    fn boundary_conditions_hold_to_1e_9() {
        let start = moving_state();
        for (action, tau) in [
            (
                Action {
                    vx_mps: 2.0,
                    vy_mps: 0.0,
                    vz_mps: 0.3,
                    yaw_rate_rad_s: 0.4,
                },
                2.5,
            ),
            (
                Action {
                    vx_mps: 0.0,
                    vy_mps: -4.0,
                    vz_mps: 0.0,
                    yaw_rate_rad_s: -0.7,
                },
                6.0,
            ),
            (Action::STOP, 1.0),
        ] {
            let p = Primitive::forward_arc(&start, action, tau);
            let s0 = p.state_at(0.0);
            for k in 0..DERIVATIVES {
                assert!(
                    (s0.derivatives[k] - start.derivatives[k]).amax() < 1e-9,
                    "start derivative {k}"
                );
            }
            let end = p.end_state();
            let target = action.end_velocity(start.yaw_rad(), tau);
            assert!((end.derivatives[1] - target).amax() < 1e-9, "end velocity");
            for k in 2..DERIVATIVES {
                assert!(
                    end.derivatives[k].amax() < 1e-9,
                    "end derivative {k}: {}",
                    end.derivatives[k]
                );
            }
            // Beyond τ the end velocity is held.
            let later = p.state_at(tau + 1.0);
            assert!(
                (later.derivatives[0] - (end.derivatives[0] + end.derivatives[1])).amax() < 1e-9
            );
        }
    }

    #[test]
    fn derivatives_are_consistent_with_finite_differences() {
        let p = Primitive::forward_arc(
            &moving_state(),
            Action {
                vx_mps: 1.5,
                vy_mps: 0.0,
                vz_mps: 0.0,
                yaw_rate_rad_s: 0.5,
            },
            3.0,
        );
        let h = 1e-5;
        for t in [0.3, 1.1, 2.7] {
            let (a, b, c) = (p.state_at(t - h), p.state_at(t), p.state_at(t + h));
            for k in 0..DERIVATIVES - 1 {
                let fd = (c.derivatives[k] - a.derivatives[k]) / (2.0 * h);
                assert!(
                    (fd - b.derivatives[k + 1]).amax() < 1e-5,
                    "t = {t}, derivative {k}"
                );
            }
        }
    }

    #[test]
    fn line_search_returns_the_shortest_feasible_primitive() {
        let limits = DynamicLimits::THESIS;
        let start = FlatState::at_rest(Vector3::zeros(), 0.0);
        let action = Action {
            vx_mps: 4.0,
            vy_mps: 0.0,
            vz_mps: 0.0,
            yaw_rate_rad_s: 0.5,
        };
        let p = limits
            .shortest(&start, action)
            .expect("feasible within 6 s");
        // Every committed primitive respects the limits at dense samples.
        let (a, j) = p.peak_accel_jerk(2000);
        assert!(
            a <= limits.max_accel_mps2 * (1.0 + 1e-3) && j <= limits.max_jerk_mps3 * (1.0 + 1e-3),
            "{a} {j}"
        );
        // One step shorter is infeasible (or below the minimum).
        let shorter = p.duration_s() - limits.duration_step_s;
        if shorter >= limits.min_duration_s {
            assert!(!limits.admits(&Primitive::forward_arc(&start, action, shorter)));
        }
        // Stopping from the end of it comes to rest.
        let stop = limits.stopping(&p.end_state()).expect("stop feasible");
        assert!(stop.end_state().velocity_mps().norm() < 1e-9);
        // An impossible demand has no feasible primitive.
        let tight = DynamicLimits {
            max_duration_s: 1.0,
            ..limits
        };
        let fast = Action {
            vx_mps: 40.0,
            ..action
        };
        assert!(tight.shortest(&start, fast).is_none());
    }

    /// The greatest distance from the start over a primitive's duration, at dense samples.
    fn excursion_m(p: &Primitive) -> f64 {
        let origin = p.state_at(0.0).position_m();
        (0..=1000)
            .map(|i| {
                (p.state_at(p.duration_s() * f64::from(i) / 1000.0)
                    .position_m()
                    - origin)
                    .norm()
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn braking_strays_no_farther_than_the_shortest_stop_and_ends_at_rest() {
        let limits = DynamicLimits::THESIS;
        let rest = FlatState::at_rest(Vector3::zeros(), 0.0);
        let go = limits
            .shortest(
                &rest,
                Action {
                    vx_mps: 1.5,
                    vy_mps: 0.0,
                    vz_mps: 0.0,
                    yaw_rate_rad_s: 0.2,
                },
            )
            .expect("feasible");
        for k in 0..=12 {
            // Speeding up from rest (τ = 1 s), then at full speed.
            let root = go.state_at(0.1 * f64::from(k));
            let brake = limits.braking(&root).expect("a stop is feasible");
            let shortest = limits.stopping(&root).expect("a stop is feasible");
            assert!(limits.admits(&brake));
            assert!(brake.end_state().velocity_mps().norm() < 1e-9);
            assert!(
                excursion_m(&brake) <= excursion_m(&shortest) + 1e-6,
                "t = {:.1} s: brake strays {} m, the shortest stop {} m",
                0.1 * f64::from(k),
                excursion_m(&brake),
                excursion_m(&shortest)
            );
        }
        // 0.3 s into speeding up (0.19 m/s, 1.9 m/s²): the stop from the planning
        // period on flies on 0.43 m; braking stops within 0.15 m.
        let root = go.state_at(0.3);
        assert!(excursion_m(&limits.stopping(&root).unwrap()) > 0.4);
        assert!(excursion_m(&limits.braking(&root).unwrap()) < 0.15);
    }
}
