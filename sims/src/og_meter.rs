//! The occupancy-grid baseline's bytes for every robot's own depth frames, at the
//! resolutions of `[metrics] og_change_set_resolutions_m`, whatever the robots share:
//! the thesis compares map sharing on the same depth images (§8.2.6, Table 8.1), and a
//! [`Tap`] sees exactly the frames each robot's sensor published.

use std::sync::{Arc, Mutex};

use serde::Serialize;
use troupe_actors::msgs::DEPTH_FRAME;
use troupe_algorithms::grid::GridConfig;
use troupe_algorithms::grid::meter::{ChangeSetMeter, ChangeSetTotals};
use troupe_runtime::{Publication, Tap};

/// One robot's totals at one resolution (`summary.json` → `og_change_sets[]`).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct OgChangeSets {
    /// Robot index.
    pub robot: usize,
    /// What the robot's frames would have cost as change sets.
    #[serde(flatten)]
    pub totals: ChangeSetTotals,
}

/// Feeds each robot's depth frames to one [`ChangeSetMeter`] per resolution.
pub struct OgMeterTap {
    /// `[robot][resolution]`.
    meters: Arc<Mutex<Vec<Vec<ChangeSetMeter>>>>,
}

impl OgMeterTap {
    /// Meters for `robots` robots at each of `resolutions_m`, with the log-odds rules
    /// and pixel stride of the robots' grid.
    ///
    /// The meters apply the per-scan rule whatever `grid.update_rule` says: that is
    /// how the baseline is flown (`sims/scenarios/link_constraint.toml`) and what its
    /// change sets mean (§8.2.5: what a frame changed).
    #[must_use]
    pub fn new(robots: usize, resolutions_m: &[f64], grid: &GridConfig) -> Self {
        let per_robot: Vec<ChangeSetMeter> = resolutions_m
            .iter()
            .map(|r| ChangeSetMeter::new(*r, grid.logodds, grid.pixel_stride))
            .collect();
        OgMeterTap {
            meters: Arc::new(Mutex::new(vec![per_robot; robots])),
        }
    }

    /// Shared handle on the meters, to read after the run.
    #[must_use]
    pub fn handle(&self) -> OgMeters {
        OgMeters(self.meters.clone())
    }
}

impl Tap for OgMeterTap {
    fn on_publish(&mut self, p: &Publication<'_>) {
        let Some(frame) = p.get(&DEPTH_FRAME) else {
            return;
        };
        let mut meters = self
            .meters
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(robot) = meters.get_mut(p.robot.0 as usize) {
            for meter in robot {
                meter.observe(frame);
            }
        }
    }
}

/// What the meters of an [`OgMeterTap`] counted.
#[derive(Clone)]
pub struct OgMeters(Arc<Mutex<Vec<Vec<ChangeSetMeter>>>>);

impl OgMeters {
    /// Every robot's totals at every resolution, robot by robot.
    #[must_use]
    pub fn totals(&self) -> Vec<OgChangeSets> {
        let meters = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        meters
            .iter()
            .enumerate()
            .flat_map(|(robot, per_robot)| {
                per_robot.iter().map(move |m| OgChangeSets {
                    robot,
                    totals: m.totals(),
                })
            })
            .collect()
    }
}
