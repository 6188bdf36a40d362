//! The mapper actor: decides keyframes by frustum overlap (§8.2.2), fits a SOGMM to
//! each keyframe (§6) and publishes it on [`KEYFRAME`] for the link to share; feeds
//! every keyframe into the robot's incremental global map (§6.1.4, [`GlobalMap`]) and
//! publishes the map's statistics on [`MAPPER_STATS`].

use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::msgs::{DEPTH_FRAME, KEYFRAME};
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_algorithms::frame::DepthFrame;
use troupe_algorithms::global_map::{FrameUpdate, GlobalMap, GlobalMapConfig};
use troupe_algorithms::keyframe::Keyframe;
use troupe_algorithms::keyframe::{Frustum, KeyframeSelector};
use troupe_algorithms::sogmm::{
    FramePoints, MeanShiftConfig, MeanShiftKind, SogmmConfig, fit_points, frame_points,
};
use troupe_runtime::{
    Actor, ActorError, ActorResult, ConfigError, Context, Event, Message, QueuePolicy, Time, Topic,
};

/// Statistics of the mapper after a keyframe (published on [`MAPPER_STATS`]).
///
/// The `_s` fields are wall-clock seconds measured on this machine, for monitoring: they
/// differ between runs, unlike everything else the simulation produces.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MapStats {
    /// Time of the keyframe's observation.
    pub stamp: Time,
    /// Keyframes fitted so far.
    pub keyframes: u32,
    /// Components of the keyframe's mixture.
    pub keyframe_components: usize,
    /// Wall-clock seconds of the keyframe fit.
    pub keyframe_fit_s: f64,
    /// Frames skipped so far for having fewer than [`MIN_KEYFRAME_POINTS`] valid
    /// pixels after decimation.
    pub sparse_frames: u64,
    /// Components of the global map `|K|` (0 when it is disabled).
    pub components: usize,
    /// Points represented by the global map (`Σ n_k`).
    pub support_points: f64,
    /// Bytes of the global map's parameters.
    pub bytes: usize,
    /// Relevant points cached for a later local fit.
    pub cached_points: usize,
    /// What the global map did with this keyframe (`None` when it is disabled or the
    /// update failed).
    pub update: Option<MapUpdateStats>,
}

/// One global-map update (a summary of [`FrameUpdate`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MapUpdateStats {
    /// Points tested for relevance (cached + new).
    pub tested_points: usize,
    /// Relevant points (Eq. 6.9).
    pub relevant_points: usize,
    /// Points fitted into a local model.
    pub fitted_points: usize,
    /// Components added.
    pub new_components: usize,
    /// Wall-clock seconds: relevant subset, local fit, merge.
    pub relevant_s: f64,
    /// Wall-clock seconds of the local fit.
    pub fit_s: f64,
    /// Wall-clock seconds of the merge and hashing.
    pub merge_s: f64,
}

impl From<&FrameUpdate> for MapUpdateStats {
    fn from(u: &FrameUpdate) -> Self {
        MapUpdateStats {
            tested_points: u.tested_points,
            relevant_points: u.relevant_points,
            fitted_points: u.fitted_points,
            new_components: u.new_components,
            relevant_s: u.relevant_s,
            fit_s: u.fit_s,
            merge_s: u.merge_s,
        }
    }
}

impl Message for MapStats {}

/// The mapper's statistics, one message per keyframe.
pub const MAPPER_STATS: Topic<MapStats> = Topic::new("mapper/stats");

/// Mapper settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapperConfig {
    /// Run the mapper at all (fitting costs 0.1–1 s of CPU per keyframe).
    pub enabled: bool,
    /// Mean-shift bandwidth σ (thesis §6: 0.02–0.03).
    pub bandwidth: f64,
    /// Which mean shift chooses the number of components: `"reference"` (the authors'
    /// published implementation, scikit-learn's `MeanShift(bin_seeding=True)`) or
    /// `"blurring"` (the thesis text's, coarser); see `sogmm::mean_shift`.
    pub mean_shift: MeanShiftKind,
    /// Fit every n-th pixel in u and v (the thesis fits 128×96 images).
    pub pixel_stride: u32,
    /// Overlap threshold λ: an observation is a keyframe when less than this fraction
    /// of its view is covered by earlier keyframes (their union, §8.2.2).
    pub overlap_threshold: f64,
    /// Earlier keyframes compared against.
    pub remembered_keyframes: usize,
    /// Maintain the incremental global map (§6.1.4) from the keyframes.
    pub global_map: bool,
    /// Cell side α of the global map's spatial hash, metres (§6.1.4.3).
    pub hash_cell_m: f64,
    /// Relevance threshold φ (ln points per m³, see [`GlobalMapConfig`]).
    pub relevance_threshold: f64,
    /// Fit a local model once this many relevant points are at hand (§6.1.4.1).
    pub min_relevant_points: usize,
    /// Most relevant points cached between keyframes.
    pub max_cached_points: usize,
}

impl Default for MapperConfig {
    fn default() -> Self {
        MapperConfig {
            enabled: true,
            bandwidth: 0.03,
            mean_shift: MeanShiftKind::Reference,
            pixel_stride: 2,
            overlap_threshold: 0.5,
            remembered_keyframes: 1024,
            global_map: true,
            hash_cell_m: 0.2,
            relevance_threshold: 4.0,
            min_relevant_points: 500,
            max_cached_points: 20_000,
        }
    }
}

impl MapperConfig {
    /// Checks the numbers; the error names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        ConfigError::positive("bandwidth", self.bandwidth)?;
        if self.pixel_stride == 0 {
            return Err(ConfigError::new("pixel_stride", "must be ≥ 1", 0));
        }
        if !(0.0..=1.0).contains(&self.overlap_threshold) {
            return Err(ConfigError::new(
                "overlap_threshold",
                "must be in [0, 1]",
                self.overlap_threshold,
            ));
        }
        if self.remembered_keyframes == 0 {
            return Err(ConfigError::new("remembered_keyframes", "must be ≥ 1", 0));
        }
        // The global map's settings (GlobalMapConfig::validate, named by their keys here).
        ConfigError::positive("hash_cell_m", self.hash_cell_m)?;
        if self.relevance_threshold.is_nan() {
            return Err(ConfigError::new(
                "relevance_threshold",
                "must be a number",
                "NaN",
            ));
        }
        if self.min_relevant_points == 0 {
            return Err(ConfigError::new("min_relevant_points", "must be ≥ 1", 0));
        }
        Ok(())
    }

    /// The keyframe and local fits' settings, seeded from `seed`.
    #[must_use]
    pub fn sogmm_config(&self, seed: u64) -> SogmmConfig {
        SogmmConfig {
            bandwidth: self.bandwidth,
            seed,
            mean_shift: MeanShiftConfig::of(self.mean_shift),
            ..SogmmConfig::default()
        }
    }

    /// The settings of the global map, with local fits seeded from `seed`.
    #[must_use]
    pub fn global_map_config(&self, seed: u64) -> GlobalMapConfig {
        GlobalMapConfig {
            cell_m: self.hash_cell_m,
            relevance_threshold: self.relevance_threshold,
            min_relevant_points: self.min_relevant_points,
            max_cached_points: self.max_cached_points,
            sogmm: self.sogmm_config(seed),
        }
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
/// publishes it on [`KEYFRAME`]; maintains the global map (§6.1.4) from the keyframes
/// and publishes [`MapStats`] on [`MAPPER_STATS`].
pub struct MapperActor {
    config: MapperConfig,
    selector: KeyframeSelector,
    keyframes: u32,
    sparse_frames: u64,
    global: Option<GlobalMap>,
}

/// Fewest valid pixels (after decimation) a frame needs to become a keyframe.
pub const MIN_KEYFRAME_POINTS: usize = 100;

impl MapperActor {
    /// A mapper with the given settings.
    #[must_use]
    pub fn new(config: MapperConfig) -> Self {
        MapperActor {
            config,
            selector: KeyframeSelector::new(config.overlap_threshold, config.remembered_keyframes),
            keyframes: 0,
            sparse_frames: 0,
            global: None,
        }
    }

    /// The global map (`None` when disabled or before the actor started).
    #[must_use]
    pub fn global_map(&self) -> Option<&GlobalMap> {
        self.global.as_ref()
    }

    /// Feed a keyframe into the global map; a failed update is logged and skipped (the
    /// map keeps what it had), so one bad frame does not cost the whole map.
    fn update_global(&mut self, points: &FramePoints, ctx: &Context<'_>) -> Option<MapUpdateStats> {
        let map = self.global.as_mut()?;
        match map.insert_frame(points) {
            Ok(update) => Some(MapUpdateStats::from(&update)),
            Err(e) => {
                tracing::warn!(robot = ctx.robot_name(), error = %e, "global map update skipped");
                None
            }
        }
    }
}

impl Actor for MapperActor {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&DEPTH_FRAME, QueuePolicy::LATEST);
        self.global = if self.config.global_map {
            let seed = u64::from(ctx.robot().0) << 32;
            Some(
                GlobalMap::new(self.config.global_map_config(seed))
                    .map_err(|e| ActorError::with_source("creating the global map", e))?,
            )
        } else {
            None
        };
        Ok(())
    }

    /// Every call: a frame offered, perhaps a keyframe fitted and published.
    fn overlaps(&self, _: &Event) -> bool {
        true
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let Some(frame) = event.message().and_then(|m| m.get(&DEPTH_FRAME)) else {
            return Ok(());
        };
        let small = decimate(frame, self.config.pixel_stride);
        let support = small.valid_pixels();
        if support < MIN_KEYFRAME_POINTS {
            // Sky, a dropout-riddled or an empty frame: nothing to map, and its view
            // must not count as covered for the keyframe choice.
            self.sparse_frames += 1;
            return Ok(());
        }
        if !self
            .selector
            .offer(Frustum::new(frame.pose, &frame.intrinsics))
        {
            return Ok(());
        }
        let config = self
            .config
            .sogmm_config(u64::from(self.keyframes) ^ (u64::from(ctx.robot().0) << 32));
        let started = Instant::now();
        // Back-projected once: the keyframe fit and the global map use the same points.
        let points = frame_points(
            &small.depth_m,
            &small.intensity,
            &small.intrinsics,
            &small.pose,
        )
        .map_err(|e| ActorError::with_source("back-projecting a keyframe", e))?;
        let fit = fit_points(&points.points, &points.depth_intensity, &config)
            .map_err(|e| ActorError::with_source("fitting a keyframe SOGMM", e))?;
        let keyframe_fit_s = started.elapsed().as_secs_f64();
        let keyframe_components = fit.gmm.len();
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
        let update = self.update_global(&points, ctx);
        let map = self.global.as_ref();
        ctx.publish_arc(
            &MAPPER_STATS,
            Arc::new(MapStats {
                stamp: frame.stamp,
                keyframes: self.keyframes,
                keyframe_components,
                keyframe_fit_s,
                sparse_frames: self.sparse_frames,
                components: map.map_or(0, GlobalMap::len),
                support_points: map.map_or(0.0, GlobalMap::total_support),
                bytes: map.map_or(0, GlobalMap::parameter_bytes),
                cached_points: map.map_or(0, GlobalMap::cached_points),
                update,
            }),
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;
    use std::time::Duration;

    use nalgebra::{Isometry3, Vector3};

    use super::*;
    use troupe_algorithms::global_map::COMPONENT_BYTES;
    use troupe_algorithms::sogmm::synthetic;
    use troupe_runtime::{ActorSpec, RobotSpec, SimExecutor, TimerId};

    const TICK: TimerId = TimerId(0);
    const FLIGHT: usize = 16;

    /// Publishes the frames of a synthetic corridor flight, one per tick.
    struct Frames {
        next: usize,
        /// The first frames see nothing (sky).
        blank: usize,
    }

    impl Actor for Frames {
        fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
            ctx.set_timer(TICK, Duration::from_millis(500));
            Ok(())
        }
        fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
            if matches!(event, Event::Timer(TICK)) && self.next < FLIGHT {
                let intrinsics = synthetic::intrinsics(48, 36);
                let pose = synthetic::flight_pose(self.next * 8, FLIGHT * 8, 30.0);
                let (mut depth_m, intensity) =
                    synthetic::Scene::corridor(30.0).render(&intrinsics, &pose);
                if self.next < self.blank {
                    depth_m.fill(0.0);
                }
                ctx.publish(
                    &DEPTH_FRAME,
                    DepthFrame {
                        stamp: ctx.now(),
                        pose,
                        intrinsics,
                        depth_m,
                        intensity,
                    },
                );
                self.next += 1;
            }
            Ok(())
        }
    }

    type Seen = Arc<Mutex<Vec<(Option<u32>, Option<MapStats>)>>>;

    struct Recorder {
        seen: Seen,
    }

    impl Actor for Recorder {
        fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
            ctx.subscribe(&KEYFRAME, QueuePolicy::fifo(1024));
            ctx.subscribe(&MAPPER_STATS, QueuePolicy::fifo(1024));
            Ok(())
        }
        fn handle(&mut self, event: &Event, _ctx: &mut Context<'_>) -> ActorResult {
            let Some(m) = event.message() else {
                return Ok(());
            };
            let entry = (
                m.get(&KEYFRAME).map(|k| k.id),
                m.get(&MAPPER_STATS).cloned(),
            );
            if let Ok(mut seen) = self.seen.lock() {
                seen.push(entry);
            }
            Ok(())
        }
    }

    fn run(config: MapperConfig) -> (Vec<u32>, Vec<MapStats>) {
        run_with(config, 0).0
    }

    /// Also returns the mapper's error count.
    fn run_with(config: MapperConfig, blank: usize) -> ((Vec<u32>, Vec<MapStats>), u64) {
        let seen: Seen = Arc::default();
        let sink = seen.clone();
        let robot = RobotSpec::new("r0")
            .with(ActorSpec::new("frames", move || Frames { next: 0, blank }))
            .with(ActorSpec::new("mapper", move || MapperActor::new(config)))
            .with(ActorSpec::new("recorder", move || Recorder {
                seen: sink.clone(),
            }));
        let mut sim = SimExecutor::new(vec![robot], 1);
        sim.run_until(Time::from_secs_f64(0.5 * FLIGHT as f64 + 1.0));
        let errors = sim.finish()[0]
            .actors
            .iter()
            .find(|a| a.name == "mapper")
            .map_or(0, |a| a.stats.errors);
        let seen = seen.lock().unwrap();
        let ids = seen.iter().filter_map(|e| e.0).collect();
        let stats = seen.iter().filter_map(|e| e.1.clone()).collect();
        ((ids, stats), errors)
    }

    #[test]
    fn frames_that_see_nothing_are_skipped_not_errors() {
        let config = MapperConfig {
            enabled: true,
            pixel_stride: 1,
            ..MapperConfig::default()
        };
        let ((ids, stats), errors) = run_with(config, 4);
        assert_eq!(errors, 0);
        assert!(!ids.is_empty());
        assert_eq!(stats[0].sparse_frames, 4);
    }

    #[test]
    fn mapper_publishes_keyframes_and_global_map_stats() {
        let config = MapperConfig {
            enabled: true,
            pixel_stride: 1,
            min_relevant_points: 100,
            ..MapperConfig::default()
        };
        let (ids, stats) = run(config);
        assert!(ids.len() >= 3, "{} keyframes", ids.len());
        assert_eq!(ids, (0..ids.len() as u32).collect::<Vec<_>>());
        assert_eq!(stats.len(), ids.len(), "one stats message per keyframe");
        for (i, s) in stats.iter().enumerate() {
            assert_eq!(s.keyframes as usize, i + 1);
            assert!(s.keyframe_components > 0);
            assert!(s.update.is_some());
            assert_eq!(s.bytes, s.components * COMPONENT_BYTES);
        }
        assert!(stats.windows(2).all(|w| w[0].components <= w[1].components));
        let last = &stats[stats.len() - 1];
        assert!(last.components > stats[0].components, "the map grew");
        assert!(last.support_points > 0.0);
        // Disabled: keyframes as before, statistics without a map.
        let (ids_off, stats_off) = run(MapperConfig {
            global_map: false,
            ..config
        });
        assert_eq!(ids_off, ids);
        assert!(
            stats_off
                .iter()
                .all(|s| s.components == 0 && s.update.is_none())
        );
    }

    #[test]
    fn config_rejects_bad_global_map_settings() {
        assert!(MapperConfig::default().validate().is_ok());
        for bad in [
            MapperConfig {
                hash_cell_m: 0.0,
                ..MapperConfig::default()
            },
            MapperConfig {
                relevance_threshold: f64::NAN,
                ..MapperConfig::default()
            },
            MapperConfig {
                min_relevant_points: 0,
                ..MapperConfig::default()
            },
        ] {
            let e = bad.validate().unwrap_err();
            assert!(
                ["hash_cell_m", "relevance_threshold", "min_relevant_points"]
                    .contains(&e.key.as_str()),
                "{e}"
            );
            bad.global_map_config(0).validate().unwrap_err();
        }
    }

    #[test]
    fn mean_shift_variant_is_chosen_by_name() {
        let parse = |text: &str| toml::from_str::<MapperConfig>(text);
        assert_eq!(MapperConfig::default().mean_shift, MeanShiftKind::Reference);
        let blurring = parse("mean_shift = \"blurring\"").unwrap();
        assert_eq!(blurring.mean_shift, MeanShiftKind::Blurring);
        assert_eq!(
            blurring.sogmm_config(0).mean_shift,
            MeanShiftConfig::of(MeanShiftKind::Blurring)
        );
        let e = parse("mean_shift = \"gaussian\"").unwrap_err().to_string();
        assert!(
            e.contains("mean_shift") && e.contains("reference") && e.contains("gaussian"),
            "{e}"
        );
    }

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
