//! The team's maps: every keyframe each robot's mapper published, collected by a
//! [`Tap`], and the merged map of a run written as a point cloud (thesis §6.1.5:
//! points sampled from the mixtures, with intensity).

use std::sync::{Arc, Mutex};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use troupe_actors::mapper::MapModel;
use troupe_actors::mapper::mapfile::{GmmMap, MapKeyframe, SurfacePoint, sample_surface};
use troupe_actors::mapper::sogmm::SogmmError;
use troupe_actors::msgs::KEYFRAME;
use troupe_actors::runtime::{Publication, Tap};

/// Collects each robot's published keyframes into one [`GmmMap`] per robot.
pub struct MapCollector {
    maps: Arc<Mutex<Vec<GmmMap>>>,
}

impl MapCollector {
    /// A collector for `robots` robots.
    #[must_use]
    pub fn new(robots: usize) -> Self {
        let empty = GmmMap {
            model: MapModel::Sogmm,
            keyframes: Vec::new(),
        };
        MapCollector {
            maps: Arc::new(Mutex::new(vec![empty; robots])),
        }
    }

    /// Shared handle on the maps, to read after the run.
    #[must_use]
    pub fn maps(&self) -> Arc<Mutex<Vec<GmmMap>>> {
        self.maps.clone()
    }
}

impl Tap for MapCollector {
    fn on_publish(&mut self, p: &Publication<'_>) {
        let Some(keyframe) = p.get(&KEYFRAME) else {
            return;
        };
        let mut maps = self
            .maps
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(map) = maps.get_mut(p.robot.0 as usize) {
            map.keyframes.push(MapKeyframe {
                stamp_s: keyframe.stamp.as_secs_f64(),
                pose: keyframe.pose,
                support: u64::from(keyframe.support_size),
                occupied: keyframe.gmm.clone(),
                free: None,
                free_support: 0,
            });
        }
    }
}

/// Points of the team's merged map: `total_points` drawn from the robots' maps in
/// proportion to each map's support (the support-weighted union of Eq. 3.5), each
/// tagged with the index of the robot that mapped it. Deterministic for a seed.
pub fn merged_points(
    maps: &[GmmMap],
    total_points: usize,
    seed: u64,
) -> Result<(Vec<SurfacePoint>, Vec<u8>), SogmmError> {
    let support: Vec<f64> = maps
        .iter()
        .map(|m| m.keyframes.iter().map(|k| k.support as f64).sum())
        .collect();
    let total_support: f64 = support.iter().sum();
    let mut points = Vec::new();
    let mut source = Vec::new();
    if total_support <= 0.0 {
        return Ok((points, source));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for (robot, (map, s)) in maps.iter().zip(&support).enumerate() {
        let n = (total_points as f64 * s / total_support).round() as usize;
        if map.keyframes.is_empty() || n == 0 {
            continue;
        }
        let drawn = sample_surface(&map.merged_occupied()?, n, &mut rng);
        source.extend(std::iter::repeat_n(
            u8::try_from(robot).unwrap_or(u8::MAX),
            drawn.len(),
        ));
        points.extend(drawn);
    }
    Ok((points, source))
}
