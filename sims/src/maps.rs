//! The team's maps: every keyframe each robot's mapper published, collected by a
//! [`Tap`]; the report writes their merged map as a point cloud (thesis §6.1.5:
//! points sampled from the mixtures, with intensity) with
//! [`troupe_robot::base::merged_points`].

use std::sync::{Arc, Mutex};

use troupe_actors::msgs::KEYFRAME;
use troupe_algorithms::mapfile::{GmmMap, MapKeyframe};
use troupe_algorithms::model::MapModel;
use troupe_runtime::{Publication, Tap};

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
