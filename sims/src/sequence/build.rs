//! Building a map from a recorded sequence (`troupe map`): keyframes chosen by frustum
//! overlap (thesis §8.2.2), each fitted with the chosen model (SOGMM §6 or windowed
//! §3.2), collected into a [`GmmMap`] whose surface is the support-weighted union of
//! the keyframe mixtures (Eq. 3.5).

use std::time::Instant;

use serde::Serialize;
use troupe_actors::mapper::decimate;
use troupe_algorithms::keyframe::{Frustum, KeyframeSelector};
use troupe_algorithms::mapfile::{GmmMap, MapKeyframe};
use troupe_algorithms::model::{MapModel, fit_keyframe};
use troupe_algorithms::sogmm::{MeanShiftConfig, MeanShiftKind, SogmmConfig};
use troupe_algorithms::windowed::WindowedConfig;

use super::{Sequence, SequenceError};

/// How to build the map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapBuildOptions {
    /// The mixture model of each keyframe.
    pub model: MapModel,
    /// SOGMM mean-shift bandwidth σ (thesis §6: 0.02–0.03).
    pub bandwidth: f64,
    /// Which mean shift chooses the SOGMM's number of components.
    pub mean_shift: MeanShiftKind,
    /// Use every `frame_stride`-th frame of the sequence (≥ 1).
    pub frame_stride: usize,
    /// Fit every `pixel_stride`-th pixel in u and v (≥ 1).
    pub pixel_stride: u32,
    /// Keyframe overlap threshold λ (§8.2.2).
    pub overlap_threshold: f64,
    /// Earlier keyframes the overlap test compares against.
    pub remembered_keyframes: usize,
    /// Base seed of the fits (keyframe `k` uses `seed + k`).
    pub seed: u64,
    /// Settings of the windowed model.
    pub windowed: WindowedConfig,
}

impl Default for MapBuildOptions {
    /// SOGMM at σ = 0.02 with the reference mean shift, every frame, pixel stride 2, λ = 0.5 over 1024 keyframes
    /// (the mapper actor's defaults), seed 0, default windowed settings.
    fn default() -> Self {
        MapBuildOptions {
            model: MapModel::Sogmm,
            bandwidth: 0.02,
            mean_shift: MeanShiftKind::Reference,
            frame_stride: 1,
            pixel_stride: 2,
            overlap_threshold: 0.5,
            remembered_keyframes: 1024,
            seed: 0,
            windowed: WindowedConfig::default(),
        }
    }
}

/// Figures of a map build (the JSON line `troupe map` prints).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MapStats {
    /// The model used.
    pub model: String,
    /// Frames read (after the frame stride).
    pub frames: usize,
    /// Keyframes fitted into the map.
    pub keyframes: usize,
    /// Keyframes whose fit failed (e.g. no valid pixel) and were left out.
    pub failed_fits: usize,
    /// Occupied components in the map.
    pub components: usize,
    /// Free-space components (windowed model).
    pub free_components: usize,
    /// Size of the map file, bytes.
    pub bytes: usize,
    /// Mean wall time of one keyframe fit, seconds.
    pub fit_s_per_frame: f64,
    /// Total fit time, seconds.
    pub fit_s_total: f64,
}

/// Fold a fitted keyframe into the map. Today the map is the list of keyframe mixtures
/// (their union by Eq. 3.5 is [`GmmMap::merged_occupied`]); this is the one place where
/// the incremental global map of §6.1.4 (relevant subset, local fit, merge) plugs in
/// when it replaces the plain union.
pub fn integrate(map: &mut GmmMap, keyframe: MapKeyframe) {
    map.keyframes.push(keyframe);
}

/// Build a map from `sequence`; `progress(done, total)` is called after every frame.
/// Errors on an unreadable frame (naming its file) or bad options; a keyframe whose fit
/// fails is counted in [`MapStats::failed_fits`] and skipped.
pub fn build_map(
    sequence: &Sequence,
    options: &MapBuildOptions,
    mut progress: impl FnMut(usize, usize),
) -> Result<(GmmMap, MapStats), SequenceError> {
    let stride = options.frame_stride.max(1);
    let indices: Vec<usize> = (0..sequence.len()).step_by(stride).collect();
    let mut selector =
        KeyframeSelector::new(options.overlap_threshold, options.remembered_keyframes);
    let mut map = GmmMap {
        model: options.model,
        keyframes: Vec::new(),
    };
    let mut stats = MapStats {
        model: options.model.name().to_string(),
        ..MapStats::default()
    };
    for (done, &i) in indices.iter().enumerate() {
        let frame = sequence.frame(i)?;
        stats.frames += 1;
        if selector.offer(Frustum::new(frame.pose, &frame.intrinsics)) {
            let small = decimate(&frame, options.pixel_stride);
            let k = stats.keyframes + stats.failed_fits;
            let sogmm = SogmmConfig {
                bandwidth: options.bandwidth,
                seed: options.seed.wrapping_add(k as u64),
                mean_shift: MeanShiftConfig::of(options.mean_shift),
                ..SogmmConfig::default()
            };
            let windowed = WindowedConfig {
                seed: options.seed.wrapping_add(k as u64),
                ..options.windowed
            };
            let start = Instant::now();
            let fit = fit_keyframe(&small, options.model, &sogmm, &windowed);
            stats.fit_s_total += start.elapsed().as_secs_f64();
            match fit {
                Ok(fit) => {
                    stats.keyframes += 1;
                    integrate(
                        &mut map,
                        MapKeyframe {
                            stamp_s: sequence.entries()[i].stamp_s,
                            pose: frame.pose,
                            support: fit.support as u64,
                            occupied: fit.occupied,
                            free: fit.free,
                            free_support: fit.free_support as u64,
                        },
                    );
                }
                Err(error) => {
                    tracing::warn!(
                        frame = %sequence.entries()[i].depth.display(),
                        %error,
                        "keyframe fit failed; left out of the map"
                    );
                    stats.failed_fits += 1;
                }
            }
        }
        progress(done + 1, indices.len());
    }
    stats.components = map.occupied_components();
    stats.free_components = map.free_components();
    stats.bytes = map.encoded_len();
    let fits = stats.keyframes + stats.failed_fits;
    stats.fit_s_per_frame = if fits > 0 {
        stats.fit_s_total / fits as f64
    } else {
        0.0
    };
    Ok((map, stats))
}
