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

use super::changeset::{OwnChanges, PeerCells};
use crate::msgs::{
    DEPTH_FRAME, GRID_CHANGES, GRID_SNAPSHOT, GridChanges, KEYFRAME, ODOMETRY, PEER_GRID_CHANGES,
    PEER_KEYFRAME,
};
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::grid::distance::unsafe_distance;
use troupe_algorithms::grid::hca::{
    KeyframePair, hca_round, regenerate, straight_path_in_collision,
};
use troupe_algorithms::grid::{
    CellBox, ComponentStore, GridConfig, KeyframeSource, LocalGrid, ScanScratch, insert_frame_with,
};
use troupe_algorithms::grid::{FrontierSet, GridSnapshot};
use troupe_algorithms::keyframe::Keyframe;
use troupe_runtime::{Actor, ActorError, ActorResult, Context, Event, QueuePolicy, TimerId};

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

    /// Stores a keyframe's components and, when `trace` is set, ray-traces them into
    /// the grid (if there is one yet: otherwise they enter when the first pose creates
    /// it). Stored components rebuild the novel boxes whenever the window moves.
    fn on_keyframe(&mut self, source: KeyframeSource, keyframe: &Keyframe, trace: bool) {
        let Some(k) = self.store.insert(source, keyframe) else {
            return;
        };
        if trace && let Some(grid) = self.grid.as_mut() {
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
    fn hca_snapshot(&mut self, stamp: troupe_runtime::Time) -> Option<GridSnapshot> {
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
            frontiers: FrontierSet::of(&round.grid),
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
                    ctx.bookkeeping_only();
                } else if let Some(peer) = m.get(&PEER_KEYFRAME) {
                    self.on_keyframe(KeyframeSource::Peer(peer.robot), &peer.keyframe, true);
                } else if let Some(own) = m.get(&KEYFRAME) {
                    self.pair.push(own);
                    // With its depth frames traced, the robot's own view is already in
                    // the grid: its keyframe is kept for rebuilding novel boxes only, so
                    // that each view enters the grid once.
                    let trace = !self.config.trace_depth_frames;
                    self.on_keyframe(KeyframeSource::Own, own, trace);
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
                    // Fusing a peer's set is one log-odds addition per cell its frame
                    // changed, far less work than tracing a depth frame's rays, which
                    // the modelled latency stands for. Charged that latency, a peer's
                    // sets at the camera's rate kept this actor busy: it dropped its
                    // own odometry and frames, and its frontiers vanished.
                    ctx.bookkeeping_only();
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
                    let (unsafe_distance_m, frontiers) =
                        rayon::join(|| unsafe_distance(grid), || FrontierSet::of(grid));
                    let snapshot = GridSnapshot {
                        stamp: ctx.now(),
                        unsafe_distance_m,
                        frontiers,
                        grid: grid.clone(),
                    };
                    ctx.publish_arc(&GRID_SNAPSHOT, Arc::new(snapshot));
                }
            }
        }
        Ok(())
    }
}
