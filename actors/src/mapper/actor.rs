//! The mapper actor: decides keyframes by frustum overlap (§8.2.2), fits a SOGMM to
//! each keyframe (§6) and publishes it on [`KEYFRAME`] for the link to share.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::keyframe::{Frustum, KeyframeSelector};
use super::sogmm::{SogmmConfig, fit_depth_frame};
use crate::msgs::{DEPTH_FRAME, DepthFrame, KEYFRAME, Keyframe, PinholeIntrinsics};
use crate::runtime::{Actor, ActorError, ActorResult, Context, Event, QueuePolicy};

/// Mapper settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapperConfig {
    /// Run the mapper at all (fitting costs 0.1–1 s of CPU per keyframe).
    pub enabled: bool,
    /// Mean-shift bandwidth σ (thesis §6: 0.02–0.03).
    pub bandwidth: f64,
    /// Fit every n-th pixel in u and v (the thesis fits 128×96 images).
    pub pixel_stride: u32,
    /// Overlap threshold λ: an observation is a keyframe when less than this fraction
    /// of its view is covered by an earlier keyframe.
    pub overlap_threshold: f64,
    /// Earlier keyframes compared against.
    pub remembered_keyframes: usize,
}

impl Default for MapperConfig {
    fn default() -> Self {
        MapperConfig {
            enabled: false,
            bandwidth: 0.03,
            pixel_stride: 2,
            overlap_threshold: 0.5,
            remembered_keyframes: 16,
        }
    }
}

impl MapperConfig {
    /// Checks the numbers; the error names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.bandwidth.is_finite() && self.bandwidth > 0.0) {
            return Err(format!("bandwidth must be > 0, got {}", self.bandwidth));
        }
        if self.pixel_stride == 0 {
            return Err("pixel_stride must be ≥ 1".into());
        }
        if !(0.0..=1.0).contains(&self.overlap_threshold) {
            return Err(format!(
                "overlap_threshold must be in [0, 1], got {}",
                self.overlap_threshold
            ));
        }
        if self.remembered_keyframes == 0 {
            return Err("remembered_keyframes must be ≥ 1".into());
        }
        Ok(())
    }
}

/// Every `stride`-th pixel of a frame, with the intrinsics scaled to match.
#[must_use]
pub fn decimate(frame: &DepthFrame, stride: u32) -> DepthFrame {
    let s = stride.max(1);
    if s == 1 {
        return frame.clone();
    }
    let k = &frame.intrinsics;
    let (w, h) = (k.width.div_ceil(s), k.height.div_ceil(s));
    let mut depth_m = Vec::with_capacity((w * h) as usize);
    let mut intensity = Vec::with_capacity((w * h) as usize);
    for row in (0..k.height).step_by(s as usize) {
        for col in (0..k.width).step_by(s as usize) {
            let i = (row * k.width + col) as usize;
            depth_m.push(frame.depth_m.get(i).copied().unwrap_or(0.0));
            intensity.push(frame.intensity.get(i).copied().unwrap_or(0.0));
        }
    }
    // Kept pixel col·s (centre col·s + 0.5) becomes col (centre col + 0.5); the ray
    // through it must not change: (u − cx) / fx is preserved with fx' = fx / s and
    // cx' = (cx − 0.5) / s + 0.5.
    let sf = f64::from(s);
    DepthFrame {
        stamp: frame.stamp,
        pose: frame.pose,
        intrinsics: PinholeIntrinsics {
            width: w,
            height: h,
            fx: k.fx / sf,
            fy: k.fy / sf,
            cx: (k.cx - 0.5) / sf + 0.5,
            cy: (k.cy - 0.5) / sf + 0.5,
            max_depth_m: k.max_depth_m,
        },
        depth_m,
        intensity,
    }
}

/// Decides keyframes by frustum overlap (§8.2.2), fits a SOGMM to each (§6) and
/// publishes it on [`KEYFRAME`].
pub struct MapperActor {
    config: MapperConfig,
    selector: KeyframeSelector,
    keyframes: u32,
}

impl MapperActor {
    /// A mapper with the given settings.
    #[must_use]
    pub fn new(config: MapperConfig) -> Self {
        MapperActor {
            config,
            selector: KeyframeSelector::new(config.overlap_threshold, config.remembered_keyframes),
            keyframes: 0,
        }
    }
}

impl Actor for MapperActor {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&DEPTH_FRAME, QueuePolicy::LATEST);
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let Some(frame) = event.message().and_then(|m| m.get(&DEPTH_FRAME)) else {
            return Ok(());
        };
        if !self
            .selector
            .offer(Frustum::new(frame.pose, &frame.intrinsics))
        {
            return Ok(());
        }
        let small = decimate(frame, self.config.pixel_stride);
        let support = small.valid_pixels();
        let config = SogmmConfig {
            bandwidth: self.config.bandwidth,
            seed: u64::from(self.keyframes) ^ (u64::from(ctx.robot().0) << 32),
            ..SogmmConfig::default()
        };
        let fit = fit_depth_frame(&small, &config)
            .map_err(|e| ActorError::with_source("fitting a keyframe SOGMM", e))?;
        ctx.publish_arc(
            &KEYFRAME,
            Arc::new(Keyframe {
                id: self.keyframes,
                stamp: frame.stamp,
                pose: frame.pose,
                support_size: support as u32,
                gmm: fit.gmm,
            }),
        );
        self.keyframes += 1;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, Vector3};

    use super::*;
    use crate::runtime::Time;

    #[test]
    fn decimation_keeps_every_ray() {
        let k = PinholeIntrinsics {
            width: 8,
            height: 6,
            fx: 5.0,
            fy: 4.0,
            cx: 4.0,
            cy: 3.0,
            max_depth_m: 5.0,
        };
        let frame = DepthFrame {
            stamp: Time::ZERO,
            pose: Isometry3::identity(),
            intrinsics: k,
            depth_m: (0..48).map(|i| i as f32).collect(),
            intensity: vec![0.5; 48],
        };
        let small = decimate(&frame, 2);
        assert_eq!((small.intrinsics.width, small.intrinsics.height), (4, 3));
        let ray = |k: &PinholeIntrinsics, col: u32, row: u32| {
            Vector3::new(
                1.0,
                -(f64::from(col) + 0.5 - k.cx) / k.fx,
                -(f64::from(row) + 0.5 - k.cy) / k.fy,
            )
        };
        for (row, col) in [(0, 0), (1, 2), (2, 3)] {
            let original = ray(&k, col * 2, row * 2);
            let kept = ray(&small.intrinsics, col, row);
            assert!((original - kept).norm() < 1e-12);
            assert_eq!(
                small.depth_m[(row * 4 + col) as usize],
                frame.depth_m[(row * 2 * 8 + col * 2) as usize]
            );
        }
    }
}
