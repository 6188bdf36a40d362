//! Cauchy–Schwarz quadratic mutual information (CSQMI) between the map and a range
//! beam (Charrow et al., RSS 2015), the local information reward of thesis §4.1.3
//! and paper V-B; the formula is written out in DESIGN §6.
//!
//! For a beam crossing cells with occupancy o₁ … o_C at distances u₁ … u_C, event
//! e_j (j ≥ 1) is "cell j is the first hit", p(e_j) = o_j ∏_{i<j}(1 − o_i), and e₀ is
//! "no hit", p(e₀) = ∏_i (1 − o_i), measured at the range end. With
//! w_j = p(e_j)² ∏_{k>j}(o_k² + (1 − o_k)²) and N a zero-mean Gaussian of variance 2σ²:
//!
//! I = log Σ_l w_l N(0) + log[∏_i (o_i² + (1 − o_i)²) Σ_j Σ_l p(e_j) p(e_l) N(u_l − u_j)]
//!     − 2 log Σ_j Σ_l p(e_j) w_l N(u_l − u_j).
//!
//! It is 0 when every cell is known (o ∈ {0, 1}) and never negative (Cauchy–Schwarz).
//! Certain cells carry nothing and uncertain ones carry most: a single cell peaks
//! near o = ½ (at o ≈ 0.41 when hit and no-hit are far apart). For a whole beam the
//! all-unknown one is not the maximum: a beam whose first cells are likely free
//! reaches further, and can carry more than one that an unknown first cell probably
//! stops.

use nalgebra::{Isometry3, Point3};

use crate::camera::PinholeIntrinsics;
use crate::grid::LocalGrid;

/// Zero-mean Gaussian density with variance 2σ² at `d`.
fn gauss(d: f64, sigma_m: f64) -> f64 {
    let var = 2.0 * sigma_m * sigma_m;
    (-d * d / (2.0 * var)).exp() / (2.0 * std::f64::consts::PI * var).sqrt()
}

/// CSQMI of one beam, in nats. `occupancy[i]` ∈ [0, 1] and `distance_m[i]` belong to
/// the i-th cell along the beam; `range_m` is where a beam that hits nothing ends;
/// `sigma_m` is the range noise. Returns 0 for an empty beam.
#[must_use]
pub fn beam_information(occupancy: &[f64], distance_m: &[f64], range_m: f64, sigma_m: f64) -> f64 {
    let c = occupancy.len().min(distance_m.len());
    if c == 0 {
        return 0.0;
    }
    let o: Vec<f64> = occupancy[..c].iter().map(|v| v.clamp(0.0, 1.0)).collect();
    // Events: index 0 = no hit, index j = first hit at cell j (1-based).
    let mut p = vec![0.0; c + 1];
    let mut u = vec![0.0; c + 1];
    let mut free_so_far = 1.0;
    for j in 0..c {
        p[j + 1] = o[j] * free_so_far;
        u[j + 1] = distance_m[j];
        free_so_far *= 1.0 - o[j];
    }
    p[0] = free_so_far;
    u[0] = range_m;
    // q_i = o_i² + (1 − o_i)²; suffix[j] = ∏_{k ≥ j} q_k over cells (0-based).
    let q: Vec<f64> = o.iter().map(|v| v * v + (1.0 - v) * (1.0 - v)).collect();
    let mut suffix = vec![1.0; c + 1];
    for j in (0..c).rev() {
        suffix[j] = suffix[j + 1] * q[j];
    }
    let mut w = vec![0.0; c + 1];
    w[0] = p[0] * p[0] * suffix[0];
    for j in 1..=c {
        // Cells after cell j (1-based) are 0-based indices j..c.
        w[j] = p[j] * p[j] * suffix[j];
    }
    let n0 = gauss(0.0, sigma_m);
    let sum_w: f64 = w.iter().sum::<f64>() * n0;
    let mut pp = 0.0;
    let mut pw = 0.0;
    for j in 0..=c {
        if p[j] == 0.0 {
            continue;
        }
        for l in 0..=c {
            let n = gauss(u[l] - u[j], sigma_m);
            pp += p[j] * p[l] * n;
            pw += p[j] * w[l] * n;
        }
    }
    if sum_w <= 0.0 || pp <= 0.0 || pw <= 0.0 {
        return 0.0;
    }
    let info = sum_w.ln() + (suffix[0] * pp).ln() - 2.0 * pw.ln();
    info.max(0.0)
}

/// Settings of the view reward.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ViewRewardParams {
    /// Use every n-th pixel in u and v as a beam.
    pub pixel_stride: u32,
    /// Range noise σ, metres.
    pub sigma_m: f64,
}

impl Default for ViewRewardParams {
    fn default() -> Self {
        ViewRewardParams {
            pixel_stride: 16,
            sigma_m: 0.1,
        }
    }
}

/// CSQMI summed over a subsampled set of the camera's beams from `pose` (camera
/// along body +x, image x = body −y, image y = body −z), through the local grid, in
/// nats. Cells outside the grid end a beam. Cells at the log-odds clamping bounds
/// count as known (o = 0 or 1): they are as certain as the grid can be, and would
/// otherwise look informative forever.
#[must_use]
pub fn view_information(
    grid: &LocalGrid,
    pose: &Isometry3<f64>,
    camera: &PinholeIntrinsics,
    params: &ViewRewardParams,
) -> f64 {
    let stride = params.pixel_stride.max(1);
    let origin = Point3::from(pose.translation.vector);
    let half_cell = grid.resolution_m() / 2.0;
    let values = grid.values();
    let clamp = grid.params();
    let mut occupancy = Vec::new();
    let mut distance = Vec::new();
    let mut total = 0.0;
    for row in (stride / 2..camera.height).step_by(stride as usize) {
        for col in (stride / 2..camera.width).step_by(stride as usize) {
            let body = camera.pixel_ray(col, row).normalize();
            let end = origin + pose.rotation * body * camera.max_depth_m;
            let Some(walk) = grid.walk(&origin, &end) else {
                continue;
            };
            occupancy.clear();
            distance.clear();
            for step in walk {
                let Some(i) = step.index else { break };
                let value = values[i];
                occupancy.push(if value <= clamp.min {
                    0.0
                } else if value >= clamp.max {
                    1.0
                } else {
                    1.0 / (1.0 + (-f64::from(value)).exp())
                });
                distance.push(step.t_enter * camera.max_depth_m + half_cell);
            }
            total += beam_information(&occupancy, &distance, camera.max_depth_m, params.sigma_m);
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;
    use nalgebra::Vector3;

    fn distances(n: usize) -> Vec<f64> {
        (0..n).map(|i| 0.1 + 0.2 * i as f64).collect()
    }

    #[test]
    fn known_beams_carry_no_information() {
        let d = distances(10);
        assert!(beam_information(&[0.0; 10], &d, 2.0, 0.1).abs() < 1e-12);
        let mut hit = vec![0.0; 10];
        hit[6] = 1.0;
        hit[8] = 1.0;
        assert!(beam_information(&hit, &d, 2.0, 0.1).abs() < 1e-12);
        assert_eq!(beam_information(&[], &[], 2.0, 0.1), 0.0);
    }

    #[test]
    fn uncertain_cells_are_informative_certain_ones_are_not() {
        // One cell: CSQMI peaks near o = ½ (at o ≈ 0.41 when hit and no-hit are far
        // apart, 13% above o = ½) and vanishes as the cell becomes certain.
        let d = distances(1);
        let info = |o: f64| beam_information(&[o], &d, 2.0, 0.1);
        let peak = (1..100)
            .map(|i| info(f64::from(i) / 100.0))
            .fold(0.0, f64::max);
        assert!(info(0.5) > 0.85 * peak, "{} vs {peak}", info(0.5));
        assert!(info(0.5) > 10.0 * info(0.01) && info(0.5) > 10.0 * info(0.99));
        // A whole beam of nearly certain cells is nearly worthless.
        let d = distances(8);
        assert!(beam_information(&[1e-6; 8], &d, 2.0, 0.1) < 1e-4);
        assert!(beam_information(&[1.0 - 1e-6; 8], &d, 2.0, 0.1) < 1e-4);
        // Unknown cells behind known free ones are still worth something.
        let mut tail = [0.0; 8];
        tail[5..].fill(0.5);
        assert!(beam_information(&tail, &d, 2.0, 0.1) > 0.5);
    }

    #[test]
    fn observing_a_view_reduces_its_information() {
        use crate::grid::LogOddsParams;
        let camera = PinholeIntrinsics {
            width: 64,
            height: 48,
            fx: 32.0,
            fy: 32.0,
            cx: 32.0,
            cy: 24.0,
            max_depth_m: 3.0,
        };
        let mut grid = LocalGrid::centred(
            &Point3::origin(),
            &Vector3::new(8.0, 8.0, 4.0),
            0.2,
            LogOddsParams::default(),
        );
        let pose = Isometry3::identity();
        let params = ViewRewardParams {
            pixel_stride: 8,
            sigma_m: 0.1,
        };
        let before = view_information(&grid, &pose, &camera, &params);
        assert!(before > 1.0, "{before}");
        // Observe free space along every beam of the view, several times.
        for _ in 0..10 {
            for row in 0..camera.height {
                for col in 0..camera.width {
                    let dir = camera.pixel_ray(col, row).normalize();
                    grid.insert_ray(
                        &Point3::origin(),
                        &(Point3::origin() + dir * 3.0),
                        false,
                        None,
                    );
                }
            }
        }
        let after = view_information(&grid, &pose, &camera, &params);
        assert!(after < 0.5 * before, "{after} vs {before}");
        // Looking the other way, into unknown space, is still informative.
        let back = Isometry3::rotation(Vector3::z() * std::f64::consts::PI);
        assert!(view_information(&grid, &back, &camera, &params) > 0.9 * before);
    }

    proptest! {
        #[test]
        fn never_negative_and_zero_behind_a_certain_hit(
            occupancy in proptest::collection::vec(0.0f64..=1.0, 1..25),
            sigma in 0.05f64..0.5,
        ) {
            let d = distances(occupancy.len());
            let info = beam_information(&occupancy, &d, 5.0, sigma);
            prop_assert!(info >= 0.0 && info.is_finite());
            // A certainly occupied first cell hides everything behind it.
            let mut blocked = occupancy.clone();
            blocked[0] = 1.0;
            prop_assert!(beam_information(&blocked, &d, 5.0, sigma) < 1e-9);
        }
    }
}
