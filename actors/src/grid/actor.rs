//! The local grid actor: keeps a [`LocalGrid`] centred on the robot and publishes
//! snapshots (grid + distance fields) for the planner and the collision checker.
//!
//! Inputs today are the robot's own depth frames, ray-traced directly (the
//! occupancy-grid baseline of thesis §8.2.5); rebuilding from GMMs (own and peers'
//! keyframes, §3.2.3) plugs in here when the mapper publishes them.

use std::sync::Arc;
use std::time::Duration;

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::distance::unsafe_distance;
use super::frontier::frontier_distance;
use super::{LocalGrid, LogOddsParams};
use crate::msgs::{
    DEPTH_FRAME, DepthFrame, GRID_SNAPSHOT, GridSnapshot, Keyframe, ODOMETRY, Odometry,
    PEER_KEYFRAME,
};
use crate::runtime::{Actor, ActorError, ActorResult, Context, Event, QueuePolicy, TimerId};

/// Settings of the local grid (paper VI: 20 m × 20 m × 12 m at 0.2 m).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GridConfig {
    /// Extent along x, y, z, metres.
    pub size_m: [f64; 3],
    /// Cell edge, metres.
    pub resolution_m: f64,
    /// Log-odds rules.
    pub logodds: LogOddsParams,
    /// Snapshots per second.
    pub publish_rate_hz: f64,
    /// Every n-th pixel in u and v of a depth frame becomes a ray.
    pub pixel_stride: u32,
    /// Unknown cells within this distance of the robot's centre become free whenever
    /// odometry arrives (the body is there; observed cells are never overridden).
    pub body_radius_m: f64,
    /// Most points sampled from one peer keyframe (at most its support size).
    pub peer_keyframe_samples: usize,
    /// Unknown cells within this distance of the first pose become free: the robot
    /// starts in a clear spot (without it, nothing would be safe before the first look
    /// around).
    pub start_clearance_m: f64,
}

impl Default for GridConfig {
    fn default() -> Self {
        GridConfig {
            size_m: [20.0, 20.0, 12.0],
            resolution_m: 0.2,
            logodds: LogOddsParams::default(),
            publish_rate_hz: 1.0,
            pixel_stride: 2,
            body_radius_m: 0.3,
            start_clearance_m: 1.2,
            peer_keyframe_samples: 2000,
        }
    }
}

impl GridConfig {
    /// Checks the numbers; the error names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.resolution_m.is_finite() && self.resolution_m >= 0.01) {
            return Err(format!(
                "resolution_m must be ≥ 0.01, got {}",
                self.resolution_m
            ));
        }
        if self
            .size_m
            .iter()
            .any(|s| !(s.is_finite() && *s >= 2.0 * self.resolution_m))
        {
            return Err(format!(
                "size_m must be finite and at least two cells, got {:?}",
                self.size_m
            ));
        }
        let cells: f64 = self.size_m.iter().map(|s| s / self.resolution_m).product();
        if cells > 64e6 {
            return Err(format!(
                "size_m / resolution_m gives {cells:.0} cells; at most 64 million"
            ));
        }
        if !(self.publish_rate_hz.is_finite() && self.publish_rate_hz > 0.0) {
            return Err(format!(
                "publish_rate_hz must be > 0, got {}",
                self.publish_rate_hz
            ));
        }
        if self.pixel_stride == 0 {
            return Err("pixel_stride must be ≥ 1".into());
        }
        for (key, value) in [
            ("body_radius_m", self.body_radius_m),
            ("start_clearance_m", self.start_clearance_m),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(format!("{key} must be ≥ 0, got {value}"));
            }
        }
        self.logodds.validate().map_err(|e| format!("logodds: {e}"))
    }
}

/// Ray-traces a depth frame into a grid: a hit at every valid pixel (every
/// `stride`-th in u and v), free space up to the range where a pixel has no return.
pub fn insert_frame(grid: &mut LocalGrid, frame: &DepthFrame, stride: u32) {
    let k = &frame.intrinsics;
    let origin = Point3::from(frame.pose.translation.vector);
    let stride = stride.max(1) as usize;
    for row in (0..k.height as usize).step_by(stride) {
        for col in (0..k.width as usize).step_by(stride) {
            let Some(&depth) = frame.depth_m.get(row * k.width as usize + col) else {
                continue;
            };
            let (u, v) = (col as f64 + 0.5, row as f64 + 0.5);
            let ray = Vector3::new(1.0, -(u - k.cx) / k.fx, -(v - k.cy) / k.fy);
            let (z, hit) = if depth > 0.0 {
                (f64::from(depth), true)
            } else {
                (k.max_depth_m, false)
            };
            let end = origin + frame.pose.rotation * (ray * z);
            grid.insert_ray(&origin, &end, hit, None);
        }
    }
}

/// Ray-traces a keyframe GMM into a grid (§8.2.2): `min(support, max_samples)`
/// points drawn from its spatial marginal, each a hit at the end of a ray from the
/// keyframe's sensor position.
pub fn insert_keyframe(
    grid: &mut LocalGrid,
    keyframe: &Keyframe,
    max_samples: usize,
    rng: &mut impl rand::Rng,
) {
    let origin = Point3::from(keyframe.pose.translation.vector);
    let n = (keyframe.support_size as usize).min(max_samples);
    for p in keyframe.gmm.marginal_spatial().sample(n, rng) {
        grid.insert_ray(&origin, &Point3::from(p), true, None);
    }
}

const PUBLISH: TimerId = TimerId(0);

/// Keeps a [`LocalGrid`] centred on the robot from its depth frames and its peers'
/// keyframes, and publishes [`GridSnapshot`]s with the distance fields.
pub struct GridActor {
    config: GridConfig,
    grid: Option<LocalGrid>,
    position: Option<Point3<f64>>,
}

impl GridActor {
    /// A grid actor with the given settings.
    #[must_use]
    pub fn new(config: GridConfig) -> Self {
        GridActor {
            config,
            grid: None,
            position: None,
        }
    }

    fn grid_at(&mut self, position: Point3<f64>) -> &mut LocalGrid {
        let config = self.config;
        self.grid.get_or_insert_with(|| {
            LocalGrid::centred(
                &position,
                &Vector3::from(config.size_m),
                config.resolution_m,
                config.logodds,
            )
        })
    }

    fn on_odometry(&mut self, odometry: &Odometry) {
        let position = Point3::from(odometry.pose.translation.vector);
        if !position.coords.iter().all(|v| v.is_finite()) {
            return;
        }
        let first = self.position.is_none();
        let (body, start) = (self.config.body_radius_m, self.config.start_clearance_m);
        let grid = self.grid_at(position);
        // The window follows the robot; novel boxes stay unknown until observed again
        // (rebuilding them from GMM keyframes comes with the mapper).
        grid.shift_to(&position);
        grid.clear_unknown_sphere(&position, if first { start.max(body) } else { body });
        self.position = Some(position);
    }
}

impl Actor for GridActor {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        ctx.subscribe(&DEPTH_FRAME, QueuePolicy::KeepLatest { depth: 2 });
        ctx.subscribe(&PEER_KEYFRAME, QueuePolicy::fifo(32));
        ctx.set_timer(
            PUBLISH,
            Duration::from_secs_f64(1.0 / self.config.publish_rate_hz),
        );
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(m) => {
                if let Some(odometry) = m.get(&ODOMETRY) {
                    self.on_odometry(odometry);
                } else if let Some(peer) = m.get(&PEER_KEYFRAME) {
                    if let Some(grid) = self.grid.as_mut() {
                        let n = self.config.peer_keyframe_samples;
                        insert_keyframe(grid, &peer.keyframe, n, ctx.rng());
                    }
                } else if let Some(frame) = m.get(&DEPTH_FRAME) {
                    let position = Point3::from(frame.pose.translation.vector);
                    if !position.coords.iter().all(|v| v.is_finite()) {
                        return Err(ActorError::msg("depth frame with a non-finite pose"));
                    }
                    let stride = self.config.pixel_stride;
                    insert_frame(self.grid_at(position), frame, stride);
                }
            }
            Event::Timer(_) => {
                if let Some(grid) = &self.grid {
                    let snapshot = GridSnapshot {
                        stamp: ctx.now(),
                        unsafe_distance_m: unsafe_distance(grid),
                        frontier_distance_m: frontier_distance(grid),
                        grid: grid.clone(),
                    };
                    ctx.publish_arc(&GRID_SNAPSHOT, Arc::new(snapshot));
                }
            }
        }
        Ok(())
    }
}
