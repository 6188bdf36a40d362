//! A team of simulated robots in one process, under the sim-time executor.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::Serialize;
use troupe_actors::link::LinkJournal;
use troupe_algorithms::exploration::{MissionPhase, MissionStatus};
use troupe_algorithms::mapfile::GmmMap;
use troupe_comms::simnet::{NetStats, Partition};
use troupe_comms::wire::Class;
use troupe_core::Time;
use troupe_robot::AssembleError;
use troupe_robot::registry::{Placement, Registry};
use troupe_runtime::{LatencySummary, RobotReport, RobotSpec, SimExecutor, TopicStats};

use crate::artifact_score::{ArtifactCollector, ArtifactScore, ScoredArtifact};
use crate::camera::{CameraBackend, gpu_camera_available, resolve_backend};
use crate::faults::{FaultCounters, FaultEffect, LossBurst, PanicOnce, crashing_factory};
use crate::maps::MapCollector;
use crate::monitor::{GroundTruthMonitor, RobotTruth, Truth, lock_truth};
use crate::network::ScenarioNetwork;
use crate::og_meter::{OgChangeSets, OgMeterTap, OgMeters};
use crate::parts::SimEnvironment;
use crate::reexploration::TeamReExploration;
use crate::scenario::{Fault, Scenario};
use crate::world::{DEPARTURE_INTERVAL_S, Site, World};

/// A team ready to run.
pub struct Team {
    scenario: Scenario,
    world: Arc<dyn Site>,
    executor: SimExecutor,
    truth: Arc<Mutex<Truth>>,
    maps: Arc<Mutex<Vec<GmmMap>>>,
    og_meters: Option<OgMeters>,
    network_stats: Arc<Mutex<NetStats>>,
    fault_counters: Vec<Arc<FaultCounters>>,
    /// Where the world's artifacts are (empty without).
    artifact_truth: Vec<Point3<f64>>,
    /// Each robot's latest artifact list.
    artifact_lists: Arc<Mutex<Vec<troupe_actors::artifacts::ArtifactList>>>,
}

/// Everything a run produced.
pub struct RunOutput {
    /// Deterministic results (`summary.json`).
    pub summary: Summary,
    /// Wall-clock figures (`timing.json`).
    pub timing: Timing,
    /// One row per robot per sample period (`timeseries.csv`).
    pub timeseries: Vec<SeriesRow>,
    /// Each robot's published keyframes (`maps/robot<i>.troupe`, `merged_map.ply`).
    pub maps: Vec<GmmMap>,
}

/// One row of the time series (also recorded in `run.mcap`, and read back from it).
#[derive(Clone, Debug, Serialize, serde::Deserialize, PartialEq)]
pub struct SeriesRow {
    /// Sim time, seconds.
    pub time_s: f64,
    /// Robot index.
    pub robot: usize,
    /// Position x, metres.
    pub x_m: f64,
    /// Position y, metres.
    pub y_m: f64,
    /// Position z, metres.
    pub z_m: f64,
    /// Heading, radians.
    pub yaw_rad: f64,
    /// Speed, m/s.
    pub speed_mps: f64,
    /// Path length so far, metres.
    pub distance_m: f64,
    /// Frames so far.
    pub frames: u64,
    /// Team coverage of the free volume, fraction.
    pub team_coverage: f64,
    /// Team explored volume, m³.
    pub team_explored_m3: f64,
    /// Distance to the nearest other robot, metres (empty with one robot).
    pub nearest_robot_m: Option<f64>,
    /// Link bytes sent so far per class: odometry, plans, keyframes, bulk.
    pub sent_bytes: [u64; 4],
    /// Link bytes received so far.
    pub received_bytes: u64,
    /// Of those, bytes of keyframe-class frames (map data) so far.
    pub received_bytes_keyframe: u64,
    /// Map data (the keyframe class) offered to the link so far, bytes: what the
    /// robot asked to send, whether or not the link could carry it.
    pub offered_bytes_keyframe: u64,
    /// Volume this robot saw first so far, m³.
    pub discovered_m3: f64,
    /// Time spent moving without seeing new volume so far, seconds
    /// ([`crate::monitor::UnproductiveTime`]).
    pub unproductive_s: f64,
    /// The longest unproductive interval so far, seconds.
    pub longest_unproductive_s: f64,
    /// The longest unproductive interval so far counting only the time while the robot
    /// remembered a frontier to go to, seconds.
    pub longest_unproductive_with_frontiers_s: f64,
    /// Volume this robot's frames observed so far, m³ ([`crate::reexploration`]).
    #[serde(default)]
    pub observed_m3: f64,
    /// Volume this robot observed no later than any other robot so far, m³.
    #[serde(default)]
    pub first_observed_m3: f64,
    /// Volume this robot observed after another robot had observed it so far, m³
    /// (thesis §8.2.7's re-exploration).
    #[serde(default)]
    pub reexplored_m3: f64,
    /// Volume only this robot has observed so far, m³.
    #[serde(default)]
    pub exclusive_m3: f64,
    /// Time spent moving between frames that observed nothing new to the team so far,
    /// seconds.
    #[serde(default)]
    pub redundant_flight_s: f64,
    /// The robot's mission phase (exploring before its planner's first round).
    #[serde(default)]
    pub phase: MissionPhase,
}

/// Counters of one actor.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ActorSummary {
    /// Actor name.
    pub name: String,
    /// Events handled.
    pub handled: u64,
    /// Hooks that returned an error.
    pub errors: u64,
    /// Handler panics.
    pub panics: u64,
    /// Restarts after panics.
    pub restarts: u64,
    /// Stopped for good.
    pub stopped: bool,
    /// Timer ticks coalesced while busy.
    pub timer_overruns: u64,
    /// Messages dropped by queue policy, by topic.
    pub dropped: BTreeMap<String, u64>,
}

/// Per-robot results.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct RobotSummary {
    /// Robot name.
    pub name: String,
    /// Ground truth.
    #[serde(flatten)]
    pub truth: RobotTruth,
    /// Actors.
    pub actors: Vec<ActorSummary>,
    /// Messages and bytes per topic.
    pub topics: BTreeMap<String, TopicStats>,
}

/// The deterministic results of a run (`summary.json`).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Summary {
    /// Scenario name.
    pub scenario: String,
    /// Run seed.
    pub seed: u64,
    /// Simulated seconds.
    pub duration_s: f64,
    /// Number of robots.
    pub robots: usize,
    /// The camera backend the robots render on (`auto` resolved on this machine):
    /// `f32` GPU images differ from CPU images in rounding, which changes flights.
    pub camera_backend: CameraBackend,
    /// The world.
    pub world: WorldSummary,
    /// Coverage of the free volume by the team's cameras.
    pub coverage: CoverageSummary,
    /// Volume the robots re-explored (observed after a peer had) and observed alone, and
    /// their redundant flight time, summed over the team (thesis §8.2.7's mechanism; per
    /// robot in `per_robot`; see [`crate::reexploration`]).
    pub reexploration: TeamReExploration,
    /// When the team's mission ended: every robot's exploring, and every robot home
    /// (each `null` until the last robot got there; per robot in `per_robot`'s
    /// `mission`).
    pub mission: TeamMission,
    /// Collisions with the world over all robots.
    pub collisions: u64,
    /// Episodes of two robot bodies overlapping (ground truth).
    pub robot_contacts: u64,
    /// Smallest distance between two robot centres, metres (null with one robot).
    pub min_inter_robot_distance_m: Option<f64>,
    /// Events processed by the executor.
    pub events: u64,
    /// The simulated network: frames routed, delivered, dropped by reason.
    pub network: NetStats,
    /// Scheduled faults and what each did.
    pub faults: Vec<FaultReport>,
    /// Per robot.
    pub per_robot: Vec<RobotSummary>,
    /// Messages and bytes per topic, summed over robots.
    pub topics: BTreeMap<String, TopicStats>,
    /// Each robot's map as published by its mapper (empty without a mapper).
    pub maps: Vec<MapSummary>,
    /// The team's artifact list (the union of the robots' lists), scored against the
    /// world's artifacts (absent when no robot reported one and none were placed).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub artifacts: Vec<ScoredArtifact>,
    /// Artifacts found / placed and false reports, for the team and per robot
    /// (absent when the world has no artifacts).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub artifact_score: Option<ArtifactScore>,
    /// What each robot's own frames would have cost as occupancy-grid change sets at
    /// each of `metrics.og_change_set_resolutions_m` (absent when none).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub og_change_sets: Vec<OgChangeSets>,
}

/// The team's mission times (issue 43), seconds.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct TeamMission {
    /// When the last robot's exploring ended.
    pub complete_s: Option<f64>,
    /// When the last robot got home.
    pub home_s: Option<f64>,
}

impl TeamMission {
    /// The latest of the robots' times, if every robot has one.
    fn of(robots: &[RobotTruth]) -> Self {
        let last = |time: fn(&MissionStatus) -> Option<f64>| {
            robots
                .iter()
                .map(|r| r.mission.as_ref().and_then(time))
                .try_fold(0.0f64, |latest, t| t.map(|t| latest.max(t)))
                .filter(|_| !robots.is_empty())
        };
        TeamMission {
            complete_s: last(|m| m.ended_s),
            home_s: last(|m| m.home_s),
        }
    }
}

/// One robot's published map.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct MapSummary {
    /// Keyframes published.
    pub keyframes: usize,
    /// Mixture components over all keyframes.
    pub components: usize,
    /// Points the keyframes were fitted to.
    pub support_points: u64,
}

impl MapSummary {
    /// The figures of `map`.
    #[must_use]
    pub fn of(map: &GmmMap) -> Self {
        MapSummary {
            keyframes: map.keyframes.len(),
            components: map.occupied_components(),
            support_points: map.keyframes.iter().map(|k| k.support).sum(),
        }
    }
}

/// A scheduled fault and its effect.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct FaultReport {
    /// The fault as scheduled.
    pub fault: Fault,
    /// What it did.
    #[serde(flatten)]
    pub effect: FaultEffect,
}

/// The world, as reported.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct WorldSummary {
    /// Generator.
    pub kind: crate::world::WorldKind,
    /// Generator seed.
    pub seed: u64,
    /// Free volume (coverage denominator), m³.
    pub free_volume_m3: f64,
    /// Length scale of the world: all tunnel centre lines of a cave, one robot's
    /// waypoint route elsewhere, metres.
    pub route_length_m: f64,
    /// Coverage cell edge, metres.
    pub coverage_cell_m: f64,
}

/// Coverage results.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct CoverageSummary {
    /// Final explored fraction.
    pub final_fraction: f64,
    /// Final explored volume, m³.
    pub explored_volume_m3: f64,
    /// `[time_s, fraction]` at every sample period.
    pub over_time: Vec<[f64; 2]>,
}

/// Wall-clock figures (`timing.json`): they vary from machine to machine and run to run.
#[derive(Clone, Debug, Serialize)]
pub struct Timing {
    /// Wall seconds the run took.
    pub wall_s: f64,
    /// Simulated seconds.
    pub sim_s: f64,
    /// Simulated seconds per wall second.
    pub sim_seconds_per_wall_second: f64,
    /// Executor events per wall second.
    pub events_per_wall_second: f64,
    /// Handler wall time per robot and actor.
    pub handler_latency: BTreeMap<String, BTreeMap<String, LatencySummary>>,
}

impl Team {
    /// Builds the world, the robots and the monitor of a scenario.
    pub fn new(scenario: &Scenario) -> Result<Team, AssembleError> {
        Team::new_with(scenario, |_, _| {})
    }

    /// Like [`Team::new`], and lets `customize` change each assembled robot (by
    /// index) before the run — this is how user-written actors join a simulated team:
    ///
    /// ```no_run
    /// # use troupe_sims::{scenario::Scenario, team::Team};
    /// # use troupe_runtime::*;
    /// # struct MyActor;
    /// # impl Actor for MyActor { fn handle(&mut self, _: &Event, _: &mut Context<'_>) -> ActorResult { Ok(()) } }
    /// let team = Team::new_with(&Scenario::default(), |_index, robot| {
    ///     robot.add(ActorSpec::new("mine", || MyActor));
    /// })?;
    /// # Ok::<(), troupe_robot::AssembleError>(())
    /// ```
    pub fn new_with(
        scenario: &Scenario,
        customize: impl FnMut(usize, &mut RobotSpec),
    ) -> Result<Team, AssembleError> {
        Team::with_parts(scenario, &crate::parts::registry(), customize)
    }

    /// Like [`Team::new_with`], with each robot's sensor and vehicle drivers and extra
    /// actors — those its `[robot]` table names — from `registry` (a user's parts
    /// beside the simulator's: [`crate::parts::registry`] extended). Unknown names
    /// are an error before anything is built.
    pub fn with_parts(
        scenario: &Scenario,
        registry: &Registry,
        mut customize: impl FnMut(usize, &mut RobotSpec),
    ) -> Result<Team, AssembleError> {
        registry
            .check(&scenario.robot)
            .map_err(|e| AssembleError::Config(e.within("robot")))?;
        scenario.check_render_stride()?;
        let (world, artifact_truth) = scenario.world.build_with_artifacts().map_err(|e| {
            AssembleError::Config(troupe_robot::ConfigError::new(
                "world.mesh.path",
                "must be a readable PLY or OBJ mesh",
                e,
            ))
        })?;
        let shared_world: Arc<dyn World> = world.clone();
        // Reported in the summary; the robots' cameras resolve `auto` the same way.
        let mut resolved = scenario.clone();
        resolved.camera.backend = resolve_backend(shared_world.as_ref(), scenario.camera.backend);
        let count = scenario.robots as usize;
        let fault_counters: Vec<Arc<FaultCounters>> =
            scenario.faults.iter().map(|_| Arc::default()).collect();
        let mut team = Vec::with_capacity(count);
        for i in 0..count {
            let mut robot = simulated_robot(scenario, &world, i, LinkJournal::default(), registry)?;
            for (fault, counters) in scenario.faults.iter().zip(&fault_counters) {
                robot = inject_fault(robot, i, fault, counters);
            }
            customize(i, &mut robot);
            team.push(robot);
        }
        let monitor = GroundTruthMonitor::new(
            shared_world,
            scenario.metrics.coverage_cell_m,
            scenario.metrics.coverage_pixel_stride,
            count,
            scenario.robot.radius_m,
        );
        let truth = monitor.truth();
        let mut network_config = scenario.network.clone();
        let mut bursts = Vec::new();
        for (k, (fault, counters)) in scenario.faults.iter().zip(&fault_counters).enumerate() {
            match fault {
                Fault::LinkPartition {
                    robots,
                    at_s,
                    until_s,
                } => network_config.partitions.push(Partition {
                    start_s: *at_s,
                    end_s: *until_s,
                    groups: Vec::new(),
                    cut: vec![*robots],
                }),
                Fault::LossBurst {
                    robots,
                    at_s,
                    until_s,
                    loss_probability,
                } => bursts.push(LossBurst::new(
                    robots.clone(),
                    [*at_s, *until_s],
                    *loss_probability,
                    scenario.seed ^ (0x6c6f_7373 + k as u64),
                    counters.clone(),
                )),
                Fault::ActorPanic { .. } | Fault::RobotCrash { .. } => {}
            }
        }
        let network = ScenarioNetwork::new(
            network_config,
            scenario.seed ^ 0x6e65_7477,
            monitor.positions(),
        )
        .map_err(|e| AssembleError::Config(e.within("network")))?;
        let network_stats = network.stats();
        let network = network
            .with_loss_bursts(bursts)
            .with_subscription(scenario.robot.link.subscribe);
        let mut executor = SimExecutor::new(team, scenario.seed).with_network(network);
        executor.add_tap(monitor);
        let map_collector = MapCollector::new(count);
        let maps = map_collector.maps();
        executor.add_tap(map_collector);
        let artifact_collector = ArtifactCollector::new(count);
        let artifact_lists = artifact_collector.lists();
        executor.add_tap(artifact_collector);
        let resolutions_m = &scenario.metrics.og_change_set_resolutions_m;
        let og_meters = (!resolutions_m.is_empty()).then(|| {
            let tap = OgMeterTap::new(count, resolutions_m, &scenario.robot.grid);
            let handle = tap.handle();
            executor.add_tap(tap);
            handle
        });
        Ok(Team {
            scenario: resolved,
            world,
            executor,
            truth,
            maps,
            og_meters,
            network_stats,
            fault_counters,
            artifact_truth,
            artifact_lists,
        })
    }

    /// The simulated world (ground truth).
    #[must_use]
    pub fn world(&self) -> &dyn World {
        self.world.as_ref()
    }

    /// Adds an observer of every publication of every robot (custom metrics,
    /// recording); call before [`Team::run`].
    pub fn add_tap(&mut self, tap: impl troupe_runtime::Tap + 'static) {
        self.executor.add_tap(tap);
    }

    /// Runs the scenario to its end; `progress` is called after every sample period
    /// with the simulated seconds done.
    pub fn run(mut self, mut progress: impl FnMut(f64)) -> RunOutput {
        let started = Instant::now();
        let period = self.scenario.metrics.sample_period_s;
        let end = self.scenario.duration_s;
        let mut sample_times: Vec<f64> = (1..=(end / period).floor() as usize)
            .map(|k| k as f64 * period)
            .collect();
        if sample_times.last().is_none_or(|&t| t < end - 1e-9) {
            sample_times.push(end);
        }
        let mut timeseries = Vec::new();
        let mut over_time = Vec::new();
        for t in sample_times {
            self.executor.run_until(Time::from_secs_f64(t));
            let truth = lock_truth(&self.truth);
            let coverage = truth.coverage.coverage();
            over_time.push([t, coverage]);
            timeseries.extend((0..truth.robots.len()).map(|i| series_row(&truth, i, t, coverage)));
            drop(truth);
            progress(t);
        }
        let events = self.executor.events_processed();
        let reports = self.executor.finish();
        let wall_s = started.elapsed().as_secs_f64();
        let truth = lock_truth(&self.truth);
        let network = *self
            .network_stats
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let mut summary = summarise(
            &self.scenario,
            self.world.as_ref(),
            &truth,
            &reports,
            over_time,
            events,
            network,
        );
        summary.faults = self
            .scenario
            .faults
            .iter()
            .zip(&self.fault_counters)
            .map(|(fault, counters)| {
                let mut effect = counters.effect();
                // The network applies partitions itself; they strike when they begin.
                if let Fault::LinkPartition { at_s, .. } = fault {
                    effect.struck = *at_s < end;
                }
                FaultReport {
                    fault: fault.clone(),
                    effect,
                }
            })
            .collect();
        let timing = Timing::of(&reports, wall_s, end, events);
        let maps = std::mem::take(
            &mut *self
                .maps
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        );
        summary.maps = maps.iter().map(MapSummary::of).collect();
        summary.og_change_sets = self.og_meters.map(|m| m.totals()).unwrap_or_default();
        let lists = self
            .artifact_lists
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone();
        (summary.artifacts, summary.artifact_score) = crate::artifact_score::summarise(
            &lists,
            &self.artifact_truth,
            self.scenario.robot.artifacts.merge_radius_m,
        );
        RunOutput {
            summary,
            timing,
            timeseries,
            maps,
        }
    }
}

/// Robot `i`'s row of the time series at `t` seconds (team coverage `coverage`).
fn series_row(truth: &Truth, i: usize, t: f64, coverage: f64) -> SeriesRow {
    let r = &truth.robots[i];
    let p = r.position.unwrap_or_else(Point3::origin);
    let nearest_robot_m = truth
        .robots
        .iter()
        .enumerate()
        .filter(|(j, _)| *j != i)
        .filter_map(|(_, o)| Some((o.position? - r.position?).norm()))
        .reduce(f64::min);
    let sent_bytes =
        Class::ALL.map(|c| r.link.as_ref().map_or(0, |l| l.shaper.class(c).sent_bytes));
    SeriesRow {
        time_s: t,
        robot: i,
        x_m: p.x,
        y_m: p.y,
        z_m: p.z,
        yaw_rad: r.yaw_rad,
        speed_mps: r.speed_mps,
        distance_m: r.distance_m,
        frames: r.frames,
        team_coverage: coverage,
        team_explored_m3: truth.coverage.explored_volume_m3(),
        nearest_robot_m,
        sent_bytes,
        received_bytes: r.received_bytes,
        received_bytes_keyframe: r.received_bytes_keyframe,
        offered_bytes_keyframe: r
            .link
            .as_ref()
            .map_or(0, |l| l.shaper.class(Class::Keyframe).offered_bytes),
        discovered_m3: r.discovered_m3,
        unproductive_s: r.unproductive_s,
        longest_unproductive_s: r.longest_unproductive_s,
        longest_unproductive_with_frontiers_s: r.longest_unproductive_with_frontiers_s,
        observed_m3: r.reexploration.observed_m3,
        first_observed_m3: r.reexploration.first_observed_m3,
        reexplored_m3: r.reexploration.reexplored_m3,
        exclusive_m3: r.reexploration.exclusive_m3,
        redundant_flight_s: r.reexploration.redundant_flight_s,
        phase: r.mission.map(|m| m.phase).unwrap_or_default(),
    }
}

impl Timing {
    /// The run's speed and each actor's handler latency, from the executor's reports.
    fn of(reports: &[RobotReport], wall_s: f64, sim_s: f64, events: u64) -> Self {
        Timing {
            wall_s,
            sim_s,
            sim_seconds_per_wall_second: sim_s / wall_s.max(1e-9),
            events_per_wall_second: events as f64 / wall_s.max(1e-9),
            handler_latency: reports
                .iter()
                .map(|r| {
                    (
                        r.name.clone(),
                        r.actors
                            .iter()
                            .map(|a| (a.name.clone(), a.stats.handler_wall.summary()))
                            .collect(),
                    )
                })
                .collect(),
        }
    }
}

/// Robot `i` of a scenario's team, as the simulation builds it: the standard robot of
/// `scenario.robot` at the world's start position `i`, with the sensor and vehicle
/// drivers and extra actors its `[robot]` table names from `registry` (the simulated
/// camera and vehicle by default; [`crate::parts`]), keeping its link's durable state
/// in `link_journal` (used by [`Team`] and by the per-robot `troupe robot` process).
pub fn simulated_robot(
    scenario: &Scenario,
    world: &Arc<dyn Site>,
    i: usize,
    link_journal: LinkJournal,
    registry: &Registry,
) -> Result<RobotSpec, AssembleError> {
    let count = scenario.robots as usize;
    let start = world.start_position(i, count);
    let route = world.route(i, count);
    let heading = route
        .iter()
        .find(|p| (p.xy() - start.xy()).norm() > 0.1)
        .map_or(0.0, |p| (p.y - start.y).atan2(p.x - start.x));
    let start_pose = Isometry3::from_parts(
        Translation3::from(start.coords),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), heading),
    );
    if scenario.camera.backend == CameraBackend::Gpu {
        let camera_world: Arc<dyn World> = world.clone();
        gpu_camera_available(camera_world.as_ref()).map_err(|e| {
            AssembleError::Config(troupe_robot::ConfigError::new(
                "camera.backend",
                "= \"gpu\" needs a Vulkan adapter the camera can use (\"auto\" falls back to the CPU)",
                e,
            ))
        })?;
    }
    let environment = SimEnvironment {
        scenario: scenario.clone(),
        world: world.clone(),
        start_pose,
        noise_seed: scenario.seed.wrapping_mul(0x2545_f491_4f6c_dd1d) ^ (i as u64 + 1),
    };
    let mut config = scenario.robot.clone();
    config.link = config.link.with_team(scenario.robots);
    let name = format!("robot{i}");
    registry
        .assemble(
            &config,
            Placement {
                name: &name,
                index: i,
                environment: &environment,
                route,
                // The robot furthest into the tunnel leaves first; the others follow
                // at intervals so that robots sharing the first tunnel stay apart.
                depart_at_s: (count - 1 - i) as f64 * DEPARTURE_INTERVAL_S,
                link_journal,
            },
        )
        .map_err(|e| match e {
            AssembleError::Config(e) => AssembleError::Config(e.within("robot")),
            other => other,
        })
}

/// Applies one scheduled fault to robot `index` (faults aimed elsewhere, and network
/// faults, leave it as it is).
fn inject_fault(
    robot: RobotSpec,
    index: usize,
    fault: &Fault,
    counters: &Arc<FaultCounters>,
) -> RobotSpec {
    let (target, actor_name) = match fault {
        Fault::ActorPanic { robot, actor, .. } => (*robot, Some(actor.as_str())),
        Fault::RobotCrash { robot, .. } => (*robot, None),
        Fault::LinkPartition { .. } | Fault::LossBurst { .. } => return robot,
    };
    if target != index {
        return robot;
    }
    let name = robot.name().to_string();
    let mut rebuilt = RobotSpec::new(name);
    for spec in robot.into_actors() {
        let spec = match (fault, actor_name) {
            (Fault::ActorPanic { at_s, .. }, Some(actor)) if spec.name() == actor => {
                let at = Time::from_secs_f64(*at_s);
                let counters = counters.clone();
                spec.wrap(move |inner| Box::new(PanicOnce::new(inner, at, counters.clone())))
            }
            (Fault::RobotCrash { at_s, down_s, .. }, None) if spec.name() != "vehicle" => {
                let at = Time::from_secs_f64(*at_s);
                let reboot = Time::from_secs_f64(at_s + down_s);
                let counters = counters.clone();
                spec.map_factory(move |factory| crashing_factory(factory, at, reboot, counters))
            }
            _ => spec,
        };
        rebuilt.add(spec);
    }
    rebuilt
}

fn summarise(
    scenario: &Scenario,
    world: &dyn Site,
    truth: &Truth,
    reports: &[RobotReport],
    over_time: Vec<[f64; 2]>,
    events: u64,
    network: NetStats,
) -> Summary {
    let mut topics: BTreeMap<String, TopicStats> = BTreeMap::new();
    for r in reports {
        for (name, s) in &r.topics {
            let t = topics.entry(name.clone()).or_default();
            t.messages += s.messages;
            t.bytes += s.bytes;
            t.type_mismatches += s.type_mismatches;
        }
    }
    let per_robot = reports
        .iter()
        .zip(&truth.robots)
        .map(|(r, t)| RobotSummary {
            name: r.name.clone(),
            truth: t.clone(),
            actors: r
                .actors
                .iter()
                .map(|a| ActorSummary {
                    name: a.name.clone(),
                    handled: a.stats.handled,
                    errors: a.stats.errors,
                    panics: a.stats.panics,
                    restarts: a.stats.restarts,
                    stopped: a.stats.stopped,
                    timer_overruns: a.stats.timer_overruns,
                    dropped: a.dropped_by_topic.clone(),
                })
                .collect(),
            topics: r.topics.clone(),
        })
        .collect();
    Summary {
        scenario: scenario.name.clone(),
        seed: scenario.seed,
        duration_s: scenario.duration_s,
        robots: reports.len(),
        camera_backend: scenario.camera.backend,
        world: WorldSummary {
            kind: scenario.world.kind,
            seed: scenario.world.seed,
            free_volume_m3: truth.coverage.free_volume_m3(),
            route_length_m: world.route_length_m(),
            coverage_cell_m: scenario.metrics.coverage_cell_m,
        },
        coverage: CoverageSummary {
            final_fraction: truth.coverage.coverage(),
            explored_volume_m3: truth.coverage.explored_volume_m3(),
            over_time,
        },
        reexploration: truth.reexploration.team(),
        mission: TeamMission::of(&truth.robots),
        collisions: truth.robots.iter().map(|r| r.collisions).sum(),
        robot_contacts: truth.robot_contacts,
        min_inter_robot_distance_m: truth
            .min_inter_robot_distance_m
            .is_finite()
            .then_some(truth.min_inter_robot_distance_m),
        events,
        network,
        faults: Vec::new(),
        per_robot,
        topics,
        maps: Vec::new(),
        og_change_sets: Vec::new(),
        artifacts: Vec::new(),
        artifact_score: None,
    }
}
