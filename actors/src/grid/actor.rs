//! The local grid actor: keeps a [`LocalGrid`] centred on the robot and publishes
//! snapshots (grid + distance fields) for the planner and the collision checker.
//!
//! Inputs: the robot's own keyframe GMMs (`msgs::KEYFRAME`, when the mapper is on) and
//! its peers' (`msgs::PEER_KEYFRAME`), kept in a [`ComponentStore`] and ray-traced from
//! their sensor origins; when the window moves, the novel boxes are rebuilt from the
//! stored components that can reach them (thesis §3.2.3, Fig. 3.2). The robot's own
//! depth frames can also be ray-traced directly (the occupancy-grid baseline of
//! §8.2.5; on by default so that the grid works without the mapper). With
//! [`GridActor::sharing_changes`] the cells those frames changed go to peers as
//! change sets ([`super::changeset`]); peers' change sets are always fused.

use std::sync::Arc;
use std::time::Duration;

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::changeset::{OwnChanges, PeerCells};
use super::distance::unsafe_distance;
use super::frontier::frontier_distance;
use super::hca::{HcaConfig, KeyframePair, hca_round, regenerate, straight_path_in_collision};
use super::{
    CellBox, ComponentStore, KeyframeSource, LocalGrid, LogOddsParams, ScanScratch, UpdateRule,
};
use crate::msgs::{
    DEPTH_FRAME, DepthFrame, GRID_CHANGES, GRID_SNAPSHOT, GridChanges, GridSnapshot, KEYFRAME,
    Keyframe, ODOMETRY, Odometry, PEER_GRID_CHANGES, PEER_KEYFRAME,
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
    /// Most points sampled from one keyframe, own or a peer's (at most its support
    /// size), split over its components by weight.
    pub peer_keyframe_samples: usize,
    /// Ray-trace the robot's own depth frames directly (the occupancy-grid baseline).
    /// With the mapper on, turn this off to build the grid from GMMs only (§3.2.3);
    /// with both, a keyframe's observations count twice.
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
        if self.max_stored_keyframes == 0 {
            return Err("max_stored_keyframes must be ≥ 1".into());
        }
        if !(self.index_cell_m.is_finite() && self.index_cell_m > 0.0) {
            return Err(format!(
                "index_cell_m must be > 0, got {}",
                self.index_cell_m
            ));
        }
        for (key, value) in [
            ("body_radius_m", self.body_radius_m),
            ("start_clearance_m", self.start_clearance_m),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(format!("{key} must be ≥ 0, got {value}"));
            }
        }
        self.hca.validate().map_err(|e| format!("hca: {e}"))?;
        self.logodds.validate().map_err(|e| format!("logodds: {e}"))
    }
}

/// How far a pixel without a return may be taken as free space, metres: the sensor's
/// range when none of its eight neighbours has a return either (open space), else the
/// nearest neighbouring return less `margin_m` (a dropout, or a sphere-traced ray that
/// gave up at a grazing surface, inside a surface the neighbours did see: the ray
/// certainly crosses free space that far, and taking it to the range would clear a
/// ray straight through that surface — the safety study found robots flying into
/// boxes that such rays had cleared). `None` for a pixel with a return.
#[must_use]
pub fn free_range_m(frame: &DepthFrame, row: usize, col: usize, margin_m: f64) -> Option<f64> {
    let (w, h) = (
        frame.intrinsics.width as usize,
        frame.intrinsics.height as usize,
    );
    if frame.depth_m.get(row * w + col).is_none_or(|d| *d > 0.0) {
        return None;
    }
    let rows = row.saturating_sub(1)..=(row + 1).min(h.saturating_sub(1));
    let nearest = rows
        .flat_map(|r| {
            (col.saturating_sub(1)..=(col + 1).min(w.saturating_sub(1))).map(move |c| r * w + c)
        })
        .filter_map(|i| frame.depth_m.get(i).copied())
        .filter(|d| *d > 0.0)
        .fold(f32::INFINITY, f32::min);
    if nearest.is_finite() {
        Some(f64::from(nearest) - margin_m).filter(|r| *r > 0.0)
    } else {
        Some(frame.intrinsics.max_depth_m)
    }
}

/// Ray-traces a depth frame into a grid: a hit at every valid pixel (every
/// `stride`-th in u and v), free space as far as [`free_range_m`] allows (two cells
/// short of a neighbouring return) where a pixel has none.
pub fn insert_frame(grid: &mut LocalGrid, frame: &DepthFrame, stride: u32) {
    let k = &frame.intrinsics;
    let origin = Point3::from(frame.pose.translation.vector);
    let margin_m = 2.0 * grid.resolution_m();
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
            } else if let Some(range_m) = free_range_m(frame, row, col, margin_m) {
                (range_m, false)
            } else {
                continue;
            };
            let end = origin + frame.pose.rotation * (ray * z);
            grid.insert_ray(&origin, &end, hit, None);
        }
    }
}

/// The two scans a depth frame makes under the per-scan rules, as world points: its
/// returns (`hits`) and its no-return pixels, free as far as [`free_range_m`] allows
/// with `margin_m` (`misses`); every `stride`-th pixel in u and v.
#[must_use]
pub fn frame_scans(frame: &DepthFrame, stride: u32, margin_m: f64) -> FrameScans {
    let k = &frame.intrinsics;
    let origin = Point3::from(frame.pose.translation.vector);
    let stride = stride.max(1) as usize;
    let (mut hits, mut misses) = (Vec::new(), Vec::new());
    for row in (0..k.height as usize).step_by(stride) {
        for col in (0..k.width as usize).step_by(stride) {
            let Some(&depth) = frame.depth_m.get(row * k.width as usize + col) else {
                continue;
            };
            let (u, v) = (col as f64 + 0.5, row as f64 + 0.5);
            let ray = Vector3::new(1.0, -(u - k.cx) / k.fx, -(v - k.cy) / k.fy);
            if depth > 0.0 {
                hits.push(origin + frame.pose.rotation * (ray * f64::from(depth)));
            } else if let Some(range_m) = free_range_m(frame, row, col, margin_m) {
                misses.push(origin + frame.pose.rotation * (ray * range_m));
            }
        }
    }
    FrameScans {
        origin,
        hits,
        misses,
    }
}

/// A depth frame as two scans from its sensor position ([`frame_scans`]).
#[derive(Clone, Debug, PartialEq)]
pub struct FrameScans {
    /// The sensor position, where every ray starts.
    pub origin: Point3<f64>,
    /// Ends of the rays that hit a surface.
    pub hits: Vec<Point3<f64>>,
    /// Ends of the free-space rays of pixels without a return.
    pub misses: Vec<Point3<f64>>,
}

/// [`insert_frame`] under an [`UpdateRule`]: with [`UpdateRule::PerScan`] or
/// [`UpdateRule::PerEndVoxel`] the frame's returns form one scan and its no-return
/// pixels (free up to the range) a second ([`frame_scans`]).
pub fn insert_frame_with(
    grid: &mut LocalGrid,
    frame: &DepthFrame,
    stride: u32,
    rule: UpdateRule,
    scratch: &mut ScanScratch,
) {
    if rule == UpdateRule::PerRay {
        insert_frame(grid, frame, stride);
        return;
    }
    let scans = frame_scans(frame, stride, 2.0 * grid.resolution_m());
    scratch.insert_by(rule, grid, &scans.origin, &scans.hits, true, None);
    scratch.insert_by(rule, grid, &scans.origin, &scans.misses, false, None);
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

/// Keeps a [`LocalGrid`] centred on the robot from its own and its peers' keyframes
/// (and optionally its depth frames), and publishes [`GridSnapshot`]s with the
/// distance fields.
pub struct GridActor {
    config: GridConfig,
    grid: Option<LocalGrid>,
    position: Option<Point3<f64>>,
    /// Direction of travel (or the body's x axis when hovering), for HCA.
    heading: Vector3<f64>,
    store: ComponentStore,
    scratch: ScanScratch,
    /// Own keyframes for the variable-resolution map (§5.1.1).
    pair: KeyframePair,
    /// HCA level of the last round (`α_prev`).
    hca_level: u32,
    /// Occupancy-grid map sharing: a change set after every own frame.
    share_changes: bool,
    own_changes: OwnChanges,
    peer_cells: PeerCells,
}

impl GridActor {
    /// A grid actor with the given settings.
    #[must_use]
    pub fn new(config: GridConfig) -> Self {
        GridActor {
            config,
            grid: None,
            position: None,
            heading: Vector3::x(),
            store: ComponentStore::new(
                config.peer_keyframe_samples,
                config.max_stored_keyframes,
                config.index_cell_m,
            )
            .with_rule(config.update_rule),
            scratch: ScanScratch::default(),
            pair: KeyframePair::default(),
            hca_level: config.hca.top_level(),
            share_changes: false,
            own_changes: OwnChanges::default(),
            peer_cells: PeerCells::default(),
        }
    }

    /// Shares the map as occupancy-grid change sets, as the thesis' OG baseline does
    /// (§8.2.5–8.2.6: "updating the map using the depth information for the current
    /// image and publishing the change set"): after every own depth frame the cells
    /// it changed go out on `grid/changes`. Peers' sets (`peer/grid_changes`) are
    /// fused whether or not this is on.
    #[must_use]
    pub fn sharing_changes(mut self) -> Self {
        self.share_changes = true;
        self
    }

    /// Stores a keyframe's components and ray-traces them into the grid (if there is
    /// one yet: otherwise they enter when the first pose creates it).
    fn on_keyframe(&mut self, source: KeyframeSource, keyframe: &Keyframe) {
        let Some(k) = self.store.insert(source, keyframe) else {
            return;
        };
        if let Some(grid) = self.grid.as_mut() {
            self.store.trace_keyframe(grid, k);
        }
    }

    fn grid_at(&mut self, position: Point3<f64>) -> &mut LocalGrid {
        let config = self.config;
        let store = &mut self.store;
        self.grid.get_or_insert_with(|| {
            let mut grid = LocalGrid::centred(
                &position,
                &Vector3::from(config.size_m),
                config.resolution_m,
                config.logodds,
            );
            let whole = CellBox {
                min: [0; 3],
                max: grid.dims(),
            };
            store.rebuild(&mut grid, &[whole]);
            grid
        })
    }

    fn on_odometry(&mut self, odometry: &Odometry) {
        let position = Point3::from(odometry.pose.translation.vector);
        if !position.coords.iter().all(|v| v.is_finite()) {
            return;
        }
        let speed = odometry.velocity_mps.norm();
        let body_x = odometry.pose.rotation * Vector3::x();
        self.heading = if speed.is_finite() && speed > 0.1 {
            odometry.velocity_mps / speed
        } else if body_x.iter().all(|v| v.is_finite()) {
            body_x
        } else {
            self.heading
        };
        let first = self.position.is_none();
        let (body, start) = (self.config.body_radius_m, self.config.start_clearance_m);
        self.grid_at(position);
        let (Some(grid), store) = (self.grid.as_mut(), &mut self.store) else {
            return;
        };
        // The window follows the robot; the novel boxes are rebuilt from the stored
        // keyframe components that can reach them (Fig. 3.2).
        let novel = grid.shift_to(&position);
        store.rebuild(grid, &novel);
        self.peer_cells.restore(grid, &novel);
        grid.clear_unknown_sphere(&position, if first { start.max(body) } else { body });
        self.position = Some(position);
    }
}

impl GridActor {
    /// One round of Hierarchical Collision Avoidance (thesis Alg. 1) when it is on
    /// and there is a pose and an own keyframe: the map regenerated from the latest
    /// and one past keyframe at the adapted voxel size, checked along the direction
    /// of travel.
    fn hca_snapshot(&mut self, stamp: crate::runtime::Time) -> Option<GridSnapshot> {
        let hca = self.config.hca;
        let position = self.position?;
        if !hca.enabled || self.pair.latest().is_none() {
            return None;
        }
        let mut store = self.pair.store(
            hca.past_keyframe_distance_m,
            self.config.peer_keyframe_samples,
            self.config.update_rule,
        );
        let (logodds, heading) = (self.config.logodds, self.heading);
        let body_radius_m = self.config.body_radius_m;
        let round = hca_round(
            &hca,
            self.hca_level,
            |alpha| {
                // Two keyframes of a forward camera do not show the space the body
                // occupies: free it as the moving window does, or the robot would
                // start every check in unknown space.
                let mut grid = regenerate(&hca, logodds, &position, alpha, &mut store);
                grid.clear_unknown_sphere(&position, body_radius_m);
                grid
            },
            |grid, distance| {
                straight_path_in_collision(
                    grid,
                    distance,
                    &position,
                    &heading,
                    hca.path_length_m(grid.resolution_m()),
                    hca.required_clearance_m(),
                )
            },
        );
        self.hca_level = round.level;
        Some(GridSnapshot {
            stamp,
            frontier_distance_m: frontier_distance(&round.grid),
            unsafe_distance_m: round.unsafe_distance_m,
            grid: round.grid,
        })
    }
}

impl Actor for GridActor {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        ctx.subscribe(&DEPTH_FRAME, QueuePolicy::KeepLatest { depth: 2 });
        ctx.subscribe(&PEER_KEYFRAME, QueuePolicy::fifo(32));
        ctx.subscribe(&KEYFRAME, QueuePolicy::fifo(32));
        ctx.subscribe(&PEER_GRID_CHANGES, QueuePolicy::fifo(64));
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
                    self.on_keyframe(KeyframeSource::Peer(peer.robot), &peer.keyframe);
                } else if let Some(own) = m.get(&KEYFRAME) {
                    self.pair.push(own);
                    self.on_keyframe(KeyframeSource::Own, own);
                } else if let Some(frame) = m.get(&DEPTH_FRAME) {
                    if !self.config.trace_depth_frames {
                        return Ok(());
                    }
                    let position = Point3::from(frame.pose.translation.vector);
                    if !position.coords.iter().all(|v| v.is_finite()) {
                        return Err(ActorError::msg("depth frame with a non-finite pose"));
                    }
                    let (stride, rule) = (self.config.pixel_stride, self.config.update_rule);
                    let sharing = self.share_changes;
                    self.grid_at(position);
                    if let Some(grid) = self.grid.as_mut() {
                        if sharing {
                            self.own_changes.begin(grid);
                        }
                        insert_frame_with(grid, frame, stride, rule, &mut self.scratch);
                        if sharing {
                            self.own_changes.end(grid);
                            for set in self.own_changes.take_sets(grid) {
                                ctx.publish(
                                    &GRID_CHANGES,
                                    GridChanges {
                                        stamp: frame.stamp,
                                        set,
                                    },
                                );
                            }
                        }
                    }
                } else if let Some(peer) = m.get(&PEER_GRID_CHANGES) {
                    let Some(grid) = self.grid.as_mut() else {
                        return Ok(());
                    };
                    self.peer_cells
                        .apply(peer.robot, &peer.set, peer.frame.as_ref(), grid)
                        .map_err(|e| {
                            ActorError::with_source(
                                format!("rejected a change set from {}", peer.robot),
                                e,
                            )
                        })?;
                }
            }
            Event::Timer(_) => {
                if let Some(snapshot) = self.hca_snapshot(ctx.now()) {
                    ctx.publish_arc(&GRID_SNAPSHOT, Arc::new(snapshot));
                } else if let Some(grid) = &self.grid {
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
