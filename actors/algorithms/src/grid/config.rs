//! Settings of the local grid.

use serde::{Deserialize, Serialize};
use troupe_core::ConfigError;

use super::hca::HcaConfig;
use super::{LogOddsParams, UpdateRule};

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
    /// Most points sampled from one keyframe, own or a peer's (at most its support
    /// size), split over its components by weight.
    pub peer_keyframe_samples: usize,
    /// Ray-trace the robot's own depth frames directly (the occupancy-grid baseline).
    /// With the mapper on, turn this off to build the grid from GMMs only (§3.2.3);
    /// with both, the robot's own keyframes only rebuild the boxes the moving window
    /// uncovers (each view enters the grid once).
    pub trace_depth_frames: bool,
    /// Most keyframes kept for rebuilding novel boxes; the oldest goes first.
    pub max_stored_keyframes: usize,
    /// Bucket edge of the spatial index over component means, metres.
    pub index_cell_m: f64,
    /// How the rays of one frame or keyframe update the grid: `per_ray` (every ray
    /// updates every cell it crosses), `per_scan` (each cell once per scan, hits
    /// first, as OctoMap's `insertPointCloud`; parallel over rays) or `per_end_voxel`
    /// (as `per_scan` with one ray per distinct end voxel, to its centre, as OctoMap's
    /// `discretize`; one thread).
    pub update_rule: UpdateRule,
    /// Variable resolution and Hierarchical Collision Avoidance (thesis §5.1); off by
    /// default.
    pub hca: HcaConfig,
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
            trace_depth_frames: true,
            max_stored_keyframes: 256,
            index_cell_m: 4.0,
            update_rule: UpdateRule::PerRay,
            hca: HcaConfig::default(),
        }
    }
}

impl GridConfig {
    /// Checks the numbers; the error names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.resolution_m.is_finite() && self.resolution_m >= 0.01) {
            return Err(ConfigError::new(
                "resolution_m",
                "must be ≥ 0.01",
                self.resolution_m,
            ));
        }
        if self
            .size_m
            .iter()
            .any(|s| !(s.is_finite() && *s >= 2.0 * self.resolution_m))
        {
            return Err(ConfigError::new(
                "size_m",
                "must be finite and at least two cells per axis",
                format!("{:?}", self.size_m),
            ));
        }
        let cells: f64 = self.size_m.iter().map(|s| s / self.resolution_m).product();
        if cells > 64e6 {
            return Err(ConfigError::new(
                "size_m",
                format!("must hold at most 64 million cells of resolution_m (it holds {cells:.0})"),
                format!("{:?}", self.size_m),
            ));
        }
        ConfigError::positive("publish_rate_hz", self.publish_rate_hz)?;
        if self.pixel_stride == 0 {
            return Err(ConfigError::new("pixel_stride", "must be ≥ 1", 0));
        }
        if self.max_stored_keyframes == 0 {
            return Err(ConfigError::new("max_stored_keyframes", "must be ≥ 1", 0));
        }
        ConfigError::positive("index_cell_m", self.index_cell_m)?;
        ConfigError::non_negative("body_radius_m", self.body_radius_m)?;
        ConfigError::non_negative("start_clearance_m", self.start_clearance_m)?;
        self.hca.validate().map_err(|e| e.within("hca"))?;
        self.logodds.validate().map_err(|e| e.within("logodds"))
    }
}
