//! Finding artifacts in one depth + intensity frame.

use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use troupe_algorithms::frame::DepthFrame;
use troupe_runtime::ConfigError;

/// Settings of the artifact actor (`[robot.artifacts]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ArtifactsConfig {
    /// Run the artifact actor on this robot.
    pub enabled: bool,
    /// A pixel is an artifact when `intensity · (1 + (range / light_half_distance_m)²)`
    /// — its reflectance, undoing the light's fall-off — reaches this. Diffuse
    /// surfaces stay below 1 (the cave's rock below 0.95); retroreflectors exceed it.
    pub reflectance_threshold: f64,
    /// Distance at which the robot's light has half its intensity, metres (the
    /// simulator's camera: 2.5 m).
    pub light_half_distance_m: f64,
    /// Pixels beyond this range are not searched, metres.
    pub max_range_m: f64,
    /// Fewest bright pixels of one artifact in one frame.
    pub min_pixels: usize,
    /// Bright points closer than this belong to one artifact, metres.
    pub cluster_radius_m: f64,
    /// Detections and reports closer than this are the same artifact, metres.
    pub merge_radius_m: f64,
    /// Frames an artifact must be seen in before it is reported.
    pub confirm_frames: u32,
}

impl Default for ArtifactsConfig {
    fn default() -> Self {
        ArtifactsConfig {
            enabled: false,
            reflectance_threshold: 0.98,
            light_half_distance_m: 2.5,
            max_range_m: 6.0,
            min_pixels: 3,
            cluster_radius_m: 0.5,
            merge_radius_m: 1.0,
            confirm_frames: 2,
        }
    }
}

impl ArtifactsConfig {
    /// Checks the ranges; the key is relative to the `artifacts` table.
    pub fn validate(&self) -> Result<(), ConfigError> {
        ConfigError::positive("reflectance_threshold", self.reflectance_threshold)?;
        ConfigError::positive("light_half_distance_m", self.light_half_distance_m)?;
        ConfigError::positive("max_range_m", self.max_range_m)?;
        ConfigError::positive("cluster_radius_m", self.cluster_radius_m)?;
        ConfigError::positive("merge_radius_m", self.merge_radius_m)?;
        if self.min_pixels == 0 {
            return Err(ConfigError::new("min_pixels", "must be at least 1", 0));
        }
        if self.confirm_frames == 0 {
            return Err(ConfigError::new("confirm_frames", "must be at least 1", 0));
        }
        Ok(())
    }
}

/// One artifact seen in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Detection {
    /// Centroid of its bright surface points, world frame, metres.
    pub position_m: Point3<f64>,
    /// Bright pixels.
    pub pixels: usize,
}

/// The artifacts in a frame: bright pixels (reflectance at or above the threshold,
/// within range) back-projected into the world, grouped by distance, groups of at
/// least `min_pixels`. A frame whose buffers do not match its intrinsics, and
/// pixels with NaN, give nothing.
#[must_use]
pub fn detect(frame: &DepthFrame, config: &ArtifactsConfig) -> Vec<Detection> {
    if frame.validate().is_err() {
        return Vec::new();
    }
    let k = &frame.intrinsics;
    let mut clusters: Vec<(nalgebra::Vector3<f64>, usize)> = Vec::new();
    for row in 0..k.height {
        for col in 0..k.width {
            let i = (row * k.width + col) as usize;
            let (depth, intensity) = (f64::from(frame.depth_m[i]), f64::from(frame.intensity[i]));
            if !(depth > 0.0 && depth.is_finite() && intensity.is_finite()) {
                continue;
            }
            let body = k.back_project(col, row, depth);
            let range = body.coords.norm();
            if range > config.max_range_m {
                continue;
            }
            let reflectance = intensity * (1.0 + (range / config.light_half_distance_m).powi(2));
            if reflectance < config.reflectance_threshold {
                continue;
            }
            let p = (frame.pose * body).coords;
            match clusters
                .iter_mut()
                .find(|(sum, n)| (sum / *n as f64 - p).norm() <= config.cluster_radius_m)
            {
                Some((sum, n)) => {
                    *sum += p;
                    *n += 1;
                }
                None => clusters.push((p, 1)),
            }
        }
    }
    clusters
        .into_iter()
        .filter(|(_, n)| *n >= config.min_pixels)
        .map(|(sum, n)| Detection {
            position_m: Point3::from(sum / n as f64),
            pixels: n,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use nalgebra::Isometry3;
    use troupe_algorithms::camera::PinholeIntrinsics;
    use troupe_runtime::Time;

    use super::*;

    fn frame(bright: &[(u32, u32)], depth_m: f32, intensity: f32) -> DepthFrame {
        let intrinsics = PinholeIntrinsics {
            width: 20,
            height: 10,
            fx: 10.0,
            fy: 10.0,
            cx: 10.0,
            cy: 5.0,
            max_depth_m: 8.0,
        };
        let n = intrinsics.pixels();
        let mut f = DepthFrame {
            stamp: Time::ZERO,
            pose: Isometry3::translation(1.0, 2.0, 0.5),
            intrinsics,
            depth_m: vec![depth_m; n],
            intensity: vec![0.3; n],
        };
        for &(col, row) in bright {
            f.intensity[(row * 20 + col) as usize] = intensity;
        }
        f
    }

    #[test]
    fn a_bright_blob_is_found_where_it_is() {
        let blob = [(10, 5), (11, 5), (10, 4), (11, 4)];
        // At 2.5 m the light is at half: 0.5 intensity means reflectance 1.0.
        let found = detect(&frame(&blob, 2.5, 0.5), &ArtifactsConfig::default());
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].pixels, 4);
        let p = found[0].position_m;
        // Columns 10 and 11 are 0.5 and 1.5 px right of cx (body −y), rows 4 and
        // 5 straddle cy: 2.5 m ahead of (1, 2, 0.5), 0.25 m to the right.
        assert!((p - Point3::new(3.5, 1.75, 0.5)).norm() < 1e-6, "{p}");
    }

    #[test]
    fn diffuse_surfaces_small_blobs_and_bad_frames_give_nothing() {
        let config = ArtifactsConfig::default();
        let blob = [(10, 5), (11, 5), (10, 4), (11, 4)];
        // Reflectance 0.9: bright rock, not an artifact.
        assert!(detect(&frame(&blob, 2.5, 0.45), &config).is_empty());
        assert!(detect(&frame(&blob[..2], 2.5, 0.5), &config).is_empty());
        assert!(
            detect(&frame(&blob, 7.0, 0.5), &config).is_empty(),
            "beyond range"
        );
        let mut nan = frame(&blob, 2.5, 0.5);
        nan.depth_m.fill(f32::NAN);
        assert!(detect(&nan, &config).is_empty());
        let mut short = frame(&blob, 2.5, 0.5);
        short.intensity.pop();
        assert!(detect(&short, &config).is_empty());
        // Two blobs far apart are two artifacts.
        let two = [(1, 1), (2, 1), (1, 2), (18, 8), (17, 8), (18, 7)];
        assert_eq!(detect(&frame(&two, 2.5, 0.6), &config).len(), 2);
    }

    #[test]
    fn bad_settings_are_config_errors() {
        let mut c = ArtifactsConfig::default();
        c.validate().unwrap();
        c.merge_radius_m = f64::NAN;
        assert_eq!(c.validate().unwrap_err().key, "merge_radius_m");
        let c = ArtifactsConfig {
            min_pixels: 0,
            ..ArtifactsConfig::default()
        };
        assert_eq!(c.validate().unwrap_err().key, "min_pixels");
    }
}
