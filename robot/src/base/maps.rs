//! What the base station holds of the team: every robot's keyframes, odometry and
//! plans as they arrived ([`BaseMaps`]), and the team's merged map as points
//! ([`merged_points`], also what `troupe run` writes as `merged_map.ply`).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use troupe_actors::msgs::{PEER_KEYFRAME, PEER_ODOMETRY, PEER_PLAN};
use troupe_actors::planner::MISSION_STATUS;
use troupe_algorithms::exploration::MissionStatus;
use troupe_algorithms::mapfile::{
    GmmMap, MapKeyframe, SurfacePoint, sample_surface, write_atomically, write_ply,
    write_ply_with_source,
};
use troupe_algorithms::model::MapModel;
use troupe_algorithms::sogmm::SogmmError;
use troupe_algorithms::team::PeerKeyframe;
use troupe_runtime::{LINK_RX, Publication};

use super::{BaseError, BaseRobotSummary};

/// What the base holds of one robot.
#[derive(Clone, Debug)]
pub struct RobotRecord {
    /// The robot's keyframes, in arrival order.
    pub map: GmmMap,
    /// (keyframe id, team-clock stamp ns) of every keyframe kept: a repeat is not kept
    /// twice.
    seen: BTreeSet<(u32, u64)>,
    /// Link frames received from it.
    pub frames: u64,
    /// Bytes of those frames.
    pub bytes: u64,
    /// Odometry messages received.
    pub odometry: u64,
    /// When the last odometry message arrived.
    pub last_odometry: Option<Instant>,
    /// Committed plans received.
    pub plans: u64,
    /// Speed of the last odometry, m/s.
    pub speed_mps: Option<f64>,
    /// Its mission as it last reported it (exploring, returning, home).
    pub mission: Option<MissionStatus>,
}

impl Default for RobotRecord {
    fn default() -> Self {
        RobotRecord {
            map: GmmMap {
                model: MapModel::Sogmm,
                keyframes: Vec::new(),
            },
            seen: BTreeSet::new(),
            frames: 0,
            bytes: 0,
            odometry: 0,
            last_odometry: None,
            plans: 0,
            speed_mps: None,
            mission: None,
        }
    }
}

/// Every robot's keyframes, odometry and plans as the base received them, by robot id.
#[derive(Clone, Debug, Default)]
pub struct BaseMaps {
    /// Per robot id.
    pub robots: BTreeMap<u32, RobotRecord>,
}

impl BaseMaps {
    /// Keeps a robot's keyframe (already validated by the link); returns whether it
    /// was new.
    pub fn add_keyframe(&mut self, peer: &PeerKeyframe) -> bool {
        let k = &peer.keyframe;
        let record = self.robots.entry(peer.robot.0).or_default();
        if !record.seen.insert((k.id, peer.made_ns)) {
            return false;
        }
        record.map.keyframes.push(MapKeyframe {
            // On the team clock, so that a restarted base's map keeps the times of
            // what it had received before.
            stamp_s: peer.made_ns as f64 * 1e-9,
            pose: k.pose,
            support: u64::from(k.support_size),
            occupied: k.gmm.clone(),
            free: None,
            free_support: 0,
        });
        true
    }

    /// Records an observed publication of the base's link (the [`Tap`] body).
    ///
    /// [`Tap`]: troupe_runtime::Tap
    pub fn observe(&mut self, p: &Publication<'_>, now: Instant) {
        if let Some(rx) = p.get(&LINK_RX) {
            let record = self.robots.entry(rx.from.0).or_default();
            record.frames += 1;
            record.bytes += rx.bytes.len() as u64;
        } else if let Some(k) = p.get(&PEER_KEYFRAME) {
            self.add_keyframe(k);
        } else if let Some(o) = p.get(&PEER_ODOMETRY) {
            let record = self.robots.entry(o.robot.0).or_default();
            record.odometry += 1;
            record.last_odometry = Some(now);
            record.speed_mps = Some(o.odometry.velocity_mps.norm());
        } else if let Some(plan) = p.get(&PEER_PLAN) {
            self.robots.entry(plan.robot.0).or_default().plans += 1;
        } else if let Some(status) = p.get(&MISSION_STATUS.peer_topic()) {
            self.robots.entry(status.robot.0).or_default().mission = Some(status.message);
        }
    }

    /// One status line per robot (every robot of `team` first, then any other sender
    /// heard), e.g. `robot0 keyframes=12 components=3456 bytes=812345
    /// odometry_age_s=0.08 plans=9 speed_mps=0.42 phase=exploring` (`none` before the
    /// first odometry, or the first mission status).
    #[must_use]
    pub fn status_lines(&self, team: u32, now: Instant) -> Vec<String> {
        let ids: BTreeSet<u32> = (0..team).chain(self.robots.keys().copied()).collect();
        let empty = RobotRecord::default();
        ids.into_iter()
            .map(|id| {
                let r = self.robots.get(&id).unwrap_or(&empty);
                let age = r.last_odometry.map_or("none".into(), |t| {
                    format!("{:.2}", now.saturating_duration_since(t).as_secs_f64())
                });
                let speed = r.speed_mps.map_or("none".into(), |v| format!("{v:.2}"));
                let phase = r.mission.map_or("none", |m| m.phase.as_str());
                format!(
                    "robot{id} keyframes={} components={} bytes={} odometry_age_s={age} plans={} \
                     speed_mps={speed} phase={phase}",
                    r.map.keyframes.len(),
                    r.map.occupied_components(),
                    r.bytes,
                    r.plans
                )
            })
            .collect()
    }

    /// Per robot id, what the base kept of it; `written` are the points of each
    /// robot's PLY ([`Self::write`]).
    #[must_use]
    pub fn summaries(&self, written: &BTreeMap<u32, usize>) -> BTreeMap<u32, BaseRobotSummary> {
        self.robots
            .iter()
            .map(|(robot, r)| {
                let summary = BaseRobotSummary {
                    keyframes: r.map.keyframes.len(),
                    components: r.map.occupied_components(),
                    frames: r.frames,
                    bytes: r.bytes,
                    odometry: r.odometry,
                    plans: r.plans,
                    mission: r.mission,
                    ply_points: written.get(robot).copied().unwrap_or(0),
                };
                (*robot, summary)
            })
            .collect()
    }

    /// Every robot's keyframes in one map: its surface is the support-weighted merge of
    /// all of them (Eq. 3.5, [`GmmMap::merged_occupied`]).
    #[must_use]
    pub fn merged(&self) -> GmmMap {
        GmmMap {
            model: MapModel::Sogmm,
            keyframes: self
                .robots
                .values()
                .flat_map(|r| r.map.keyframes.iter().cloned())
                .collect(),
        }
    }

    /// Writes the maps into `dir` (see the module docs): `total_points` are drawn
    /// for `merged_map.ply` in proportion to each robot's support, and each robot's
    /// PLY holds its share. Robots without keyframes get no files. Returns the
    /// points written per robot.
    pub fn write(
        &self,
        dir: &Path,
        total_points: usize,
        seed: u64,
    ) -> Result<BTreeMap<u32, usize>, BaseError> {
        let write_error = |path: &Path| {
            let path = path.to_path_buf();
            move |source| BaseError::Write { path, source }
        };
        let map_error = |path: &Path| {
            let path = path.to_path_buf();
            move |source| BaseError::Map { path, source }
        };
        let maps_dir = dir.join("maps");
        std::fs::create_dir_all(&maps_dir).map_err(write_error(&maps_dir))?;
        let mapped: Vec<(u32, &GmmMap)> = self
            .robots
            .iter()
            .filter(|(_, r)| !r.map.keyframes.is_empty())
            .map(|(id, r)| (*id, &r.map))
            .collect();
        let maps: Vec<GmmMap> = mapped.iter().map(|(_, m)| (*m).clone()).collect();
        let (points, source) =
            merged_points(&maps, total_points, seed).map_err(BaseError::Sample)?;
        let mut written = BTreeMap::new();
        for (index, (id, map)) in mapped.iter().enumerate() {
            let path = maps_dir.join(format!("robot{id}.troupe"));
            map.save(&path).map_err(map_error(&path))?;
            let own: Vec<SurfacePoint> = points
                .iter()
                .zip(&source)
                .filter(|(_, s)| usize::from(**s) == index)
                .map(|(p, _)| *p)
                .collect();
            let path = maps_dir.join(format!("robot{id}.ply"));
            let mut ply = Vec::with_capacity(256 + 19 * own.len());
            write_ply(&mut ply, &own).map_err(write_error(&path))?;
            write_atomically(&path, &ply).map_err(map_error(&path))?;
            written.insert(*id, own.len());
        }
        let path = dir.join("merged_map.troupe");
        self.merged().save(&path).map_err(map_error(&path))?;
        // Tag each point with the robot's id (ids above 254 share the tag 255).
        let tags: Vec<u8> = source
            .iter()
            .map(|s| {
                mapped
                    .get(usize::from(*s))
                    .and_then(|(id, _)| u8::try_from(*id).ok())
                    .unwrap_or(u8::MAX)
            })
            .collect();
        let path = dir.join("merged_map.ply");
        let mut ply = Vec::with_capacity(256 + 20 * points.len());
        write_ply_with_source(&mut ply, &points, Some(&tags)).map_err(write_error(&path))?;
        write_atomically(&path, &ply).map_err(map_error(&path))?;
        Ok(written)
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
