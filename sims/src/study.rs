//! Studies: a grid of scenario variants × seeds, run in parallel, one CSV row per run
//! and aggregates with 95% confidence intervals (`troupe sweep STUDY.toml`).
//!
//! A study file names a base scenario and its axes. Each axis has levels; a level
//! overrides keys of the base scenario (dotted keys, as in the scenario file) and may
//! remove keys. Every combination of levels runs under every seed:
//!
//! ```toml
//! name = "link_constraint"
//! scenario = "../scenarios/link_constraint_base.toml"  # relative to this file
//! seeds = [1, 2, 3]
//!
//! [[axes]]                     # shorthand: one key, several values
//! key = "robot.speed_mps"
//! values = [1.0, 1.5]
//!
//! [[axes]]                     # full form: labelled levels with several keys each
//! name = "map_sharing"
//! [[axes.levels]]
//! label = "gmm"
//! set = { "robot.mapper.enabled" = true }
//! [[axes.levels]]
//! label = "none"
//! unset = ["robot.mapper"]
//! ```

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use serde::{Deserialize, Serialize};
use toml::{Table, Value};
use troupe_comms::wire::Class;
use troupe_core::ConfigError;
use troupe_robot::toml_file::{TomlFileError, read_toml};

use crate::monitor::ns_to_s;
use crate::plot::{Chart, Series, write_chart, write_panels};
use crate::reexploration::TeamReExploration;
use crate::scenario::{Scenario, ScenarioError};
use crate::team::{RunOutput, Summary, Team};

mod figure;
mod shard;

pub use figure::{
    BOOTSTRAP_RESAMPLES, Claim, Ratio, RatioSpec, RobotMapData, map_data_panels, ratios,
    ratios_csv, time_to_coverage_chart,
};
pub use shard::{MergeError, Merged, Shard, ShardError, merge_finished_runs};

/// One level of an axis.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Level {
    /// Short name used in run names and result columns.
    pub label: String,
    /// Keys to set (dotted keys or nested tables), merged into the base scenario.
    #[serde(default)]
    pub set: Table,
    /// Dotted keys to remove from the base scenario (they take their defaults).
    #[serde(default)]
    pub unset: Vec<String>,
}

/// An axis as written in the file: either `key` + `values` (+ optional `labels`), or
/// `name` + `levels`.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct AxisFile {
    name: Option<String>,
    key: Option<String>,
    values: Option<Vec<Value>>,
    labels: Option<Vec<String>>,
    levels: Option<Vec<Level>>,
}

/// A study file as written.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct StudyFile {
    name: String,
    scenario: Option<PathBuf>,
    seeds: Vec<u64>,
    duration_s: Option<f64>,
    #[serde(default = "default_coverage_levels")]
    coverage_levels: Vec<f64>,
    #[serde(default)]
    axes: Vec<AxisFile>,
    #[serde(default)]
    ratio: Option<RatioSpec>,
}

fn default_coverage_levels() -> Vec<f64> {
    vec![0.5, 0.85]
}

/// A named axis with its levels.
#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    /// Column name in the results.
    pub name: String,
    /// Levels, in file order.
    pub levels: Vec<Level>,
}

/// A parsed, checked study.
#[derive(Clone, Debug)]
pub struct Study {
    /// Name; outputs go to `OUT/<name>/`.
    pub name: String,
    /// Where it was read from (for messages).
    pub path: PathBuf,
    /// The base scenario as a TOML table.
    pub base: Table,
    /// Run seeds.
    pub seeds: Vec<u64>,
    /// Coverage fractions whose first-reach times are reported.
    pub coverage_levels: Vec<f64>,
    /// Axes.
    pub axes: Vec<Axis>,
    /// The ratio `ratios.csv` reports (`[ratio]`), if any.
    pub ratio: Option<RatioSpec>,
}

/// One run of a study: a combination of levels and a seed.
#[derive(Clone, Debug)]
pub struct Variant {
    /// Run name (`<study>-<label>-…-s<seed>`).
    pub name: String,
    /// Level label per axis.
    pub labels: Vec<String>,
    /// Seed.
    pub seed: u64,
    /// The scenario to run.
    pub scenario: Scenario,
}

/// Why a study could not be read.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// The study file cannot be read, is not TOML, or has an unknown key or a value
    /// of the wrong type.
    #[error("reading the study")]
    File(#[source] TomlFileError),
    /// The base scenario the study names cannot be read or is not TOML.
    #[error("study file `{path}`: its base scenario")]
    BaseScenario {
        /// Study file.
        path: PathBuf,
        /// Cause.
        source: TomlFileError,
    },
    /// A key of the study breaks a rule (no seeds, an empty axis, a bad label…).
    #[error("study file `{path}`")]
    Invalid {
        /// Study file.
        path: PathBuf,
        /// The key, the rule and the value.
        source: ConfigError,
    },
    /// A variant of the base scenario could not be written out as TOML to be read
    /// as a scenario.
    #[error("study file `{path}`, run {run}: the scenario cannot be written as TOML")]
    Encode {
        /// Study file.
        path: PathBuf,
        /// The variant.
        run: String,
        /// Cause.
        source: toml::ser::Error,
    },
    /// The base scenario or a variant of it is invalid.
    #[error("study file `{path}`, run {run}")]
    Scenario {
        /// Study file.
        path: PathBuf,
        /// The variant.
        run: String,
        /// The scenario error.
        source: ScenarioError,
    },
}

impl Study {
    /// Reads a study file and its base scenario, and checks every variant.
    pub fn load(path: &Path) -> Result<Study, StudyError> {
        let invalid = |source: ConfigError| StudyError::Invalid {
            path: path.to_owned(),
            source,
        };
        let file: StudyFile = read_toml(path).map_err(StudyError::File)?;
        let mut base = match &file.scenario {
            Some(relative) => {
                let scenario_path = path.parent().unwrap_or(Path::new(".")).join(relative);
                let mut table: Table =
                    read_toml(&scenario_path).map_err(|source| StudyError::BaseScenario {
                        path: path.to_owned(),
                        source,
                    })?;
                // A mesh file is named relative to the scenario file.
                if let Some(Value::String(mesh)) = table
                    .get_mut("world")
                    .and_then(|w| w.get_mut("mesh"))
                    .and_then(|m| m.get_mut("path"))
                    && Path::new(mesh.as_str()).is_relative()
                    && let Some(dir) = scenario_path.parent()
                {
                    *mesh = dir.join(mesh.as_str()).display().to_string();
                }
                table
            }
            None => Table::new(),
        };
        if let Some(d) = file.duration_s {
            base.insert("duration_s".into(), Value::Float(d));
        }
        let study = Study {
            name: file.name.clone(),
            path: path.to_owned(),
            base,
            seeds: file.seeds.clone(),
            coverage_levels: file.coverage_levels.clone(),
            axes: file
                .axes
                .into_iter()
                .enumerate()
                .map(|(i, a)| {
                    axis_from_file(a).map_err(|e| invalid(e.within(&format!("axes[{i}]"))))
                })
                .collect::<Result<_, _>>()?,
            ratio: file.ratio,
        };
        study.check().map_err(invalid)?;
        // Every variant must be a valid scenario before anything runs.
        study.variants()?;
        Ok(study)
    }

    fn check(&self) -> Result<(), ConfigError> {
        const NAME_RULE: &str =
            "must be non-empty, use only letters, digits, `-`, `_`, `.` and not start with `.`";
        let name_ok = |s: &str| {
            !s.is_empty()
                && !s.starts_with('.')
                && s.chars()
                    .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        };
        if !name_ok(&self.name) {
            return Err(ConfigError::new(
                "name",
                NAME_RULE,
                format!("{:?}", self.name),
            ));
        }
        if self.seeds.is_empty() {
            return Err(ConfigError::new(
                "seeds",
                "must list at least one seed",
                "[]",
            ));
        }
        if let Some(l) = self
            .coverage_levels
            .iter()
            .find(|l| !(l.is_finite() && **l > 0.0 && **l <= 1.0))
        {
            return Err(ConfigError::new(
                "coverage_levels",
                "must hold fractions in (0, 1]",
                l,
            ));
        }
        for (i, axis) in self.axes.iter().enumerate() {
            for (j, level) in axis.levels.iter().enumerate() {
                if !name_ok(&level.label) {
                    return Err(ConfigError::new(
                        format!("axes[{i}].levels[{j}].label"),
                        NAME_RULE,
                        format!("{:?}", level.label),
                    ));
                }
            }
        }
        if let Some(ratio) = &self.ratio {
            self.check_ratio(ratio)?;
        }
        Ok(())
    }

    /// `[ratio]` names an axis and two of its levels; each claim, other axes' levels
    /// and one of `coverage_levels`.
    fn check_ratio(&self, ratio: &RatioSpec) -> Result<(), ConfigError> {
        let levels_of = |name: &str| {
            self.axes
                .iter()
                .find(|a| a.name == name)
                .map(|a| a.levels.iter().map(|l| l.label.clone()).collect::<Vec<_>>())
        };
        let Some(labels) = levels_of(&ratio.axis) else {
            return Err(ConfigError::new(
                "ratio.axis",
                "must name an axis of the study",
                &ratio.axis,
            ));
        };
        for (key, level) in [
            ("ratio.numerator", &ratio.numerator),
            ("ratio.denominator", &ratio.denominator),
        ] {
            if !labels.contains(level) {
                return Err(ConfigError::new(
                    key,
                    "must be a level of `ratio.axis`",
                    level,
                ));
            }
        }
        for (i, claim) in ratio.thesis.iter().enumerate() {
            if !self
                .coverage_levels
                .iter()
                .any(|l| (l - claim.level).abs() < 1e-9)
            {
                return Err(ConfigError::new(
                    format!("ratio.thesis[{i}].level"),
                    "must be one of `coverage_levels`",
                    claim.level,
                ));
            }
            for (axis, value) in &claim.at {
                let known = (*axis != ratio.axis)
                    .then(|| levels_of(axis))
                    .flatten()
                    .is_some_and(|l| value.as_str().is_some_and(|v| l.iter().any(|x| x == v)));
                if !known {
                    return Err(ConfigError::new(
                        format!("ratio.thesis[{i}].at.{axis}"),
                        "must be a level of another axis",
                        value,
                    ));
                }
            }
        }
        Ok(())
    }

    /// Every combination of levels under every seed, in a fixed order: seed by seed, so a
    /// sweep cut short (and resumed later) holds about as many runs of each combination.
    pub fn variants(&self) -> Result<Vec<Variant>, StudyError> {
        let mut combos: Vec<Vec<&Level>> = vec![Vec::new()];
        for axis in &self.axes {
            combos = combos
                .into_iter()
                .flat_map(|c| {
                    axis.levels.iter().map(move |l| {
                        let mut c = c.clone();
                        c.push(l);
                        c
                    })
                })
                .collect();
        }
        let mut variants = Vec::new();
        for &seed in &self.seeds {
            for combo in &combos {
                let labels: Vec<String> = combo.iter().map(|l| l.label.clone()).collect();
                let mut name = self.name.clone();
                for l in &labels {
                    name.push('-');
                    name.push_str(l);
                }
                let _ = write!(name, "-s{seed}");
                let mut table = self.base.clone();
                for level in combo {
                    for key in &level.unset {
                        unset_dotted(&mut table, key);
                    }
                    merge_dotted(&mut table, &level.set);
                }
                table.insert("seed".into(), Value::Integer(seed as i64));
                table.insert("name".into(), Value::String(name.clone()));
                let text = toml::to_string(&table).map_err(|source| StudyError::Encode {
                    path: self.path.clone(),
                    run: name.clone(),
                    source,
                })?;
                let scenario =
                    Scenario::from_toml(&text, &PathBuf::from(format!("<study run {name}>")))
                        .map_err(|source| StudyError::Scenario {
                            path: self.path.clone(),
                            run: name.clone(),
                            source,
                        })?;
                variants.push(Variant {
                    name,
                    labels,
                    seed,
                    scenario,
                });
            }
        }
        Ok(variants)
    }
}

/// An axis as the study uses it; errors name keys relative to the axis.
fn axis_from_file(a: AxisFile) -> Result<Axis, ConfigError> {
    match (a.key, a.values, a.levels) {
        (Some(key), Some(values), None) => {
            if values.is_empty() {
                return Err(ConfigError::new(
                    "values",
                    "must list at least one value",
                    "[]",
                ));
            }
            let labels = match a.labels {
                Some(l) if l.len() == values.len() => l,
                Some(l) => {
                    return Err(ConfigError::new(
                        "labels",
                        format!("must give one label per value ({})", values.len()),
                        format!("{} labels", l.len()),
                    ));
                }
                None => values.iter().map(value_label).collect(),
            };
            Ok(Axis {
                name: a.name.unwrap_or_else(|| key.clone()),
                levels: values
                    .into_iter()
                    .zip(labels)
                    .map(|(v, label)| {
                        let mut set = Table::new();
                        set.insert(key.clone(), v);
                        Level {
                            label,
                            set,
                            unset: Vec::new(),
                        }
                    })
                    .collect(),
            })
        }
        (None, None, Some(levels)) => {
            let name = a.name.ok_or_else(|| {
                ConfigError::new("name", "must be given for an axis with `levels`", "nothing")
            })?;
            if levels.is_empty() {
                return Err(ConfigError::new(
                    "levels",
                    "must list at least one level",
                    "[]",
                ));
            }
            Ok(Axis { name, levels })
        }
        (key, values, levels) => {
            let given: Vec<&str> = [
                ("key", key.is_some()),
                ("values", values.is_some()),
                ("levels", levels.is_some()),
            ]
            .into_iter()
            .filter_map(|(k, given)| given.then_some(k))
            .collect();
            Err(ConfigError::new(
                "",
                "must give either `key` and `values`, or `name` and `levels`",
                if given.is_empty() {
                    "none of them".to_owned()
                } else {
                    given.join(" and ")
                },
            ))
        }
    }
}

fn value_label(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        other => other.to_string().replace(['"', ' '], ""),
    }
}

/// Sets `set`'s entries into `table`: dotted keys address nested tables, nested tables
/// merge recursively.
fn merge_dotted(table: &mut Table, set: &Table) {
    for (key, value) in set {
        let mut parts: Vec<&str> = key.split('.').collect();
        let Some(last) = parts.pop() else { continue };
        let mut target = &mut *table;
        for part in parts {
            let entry = target
                .entry(part.to_string())
                .or_insert_with(|| Value::Table(Table::new()));
            if !entry.is_table() {
                *entry = Value::Table(Table::new());
            }
            let Value::Table(t) = entry else {
                unreachable!("replaced by a table above")
            };
            target = t;
        }
        match (target.get_mut(last), value) {
            (Some(Value::Table(existing)), Value::Table(new)) => merge_dotted(existing, new),
            _ => {
                target.insert(last.to_string(), value.clone());
            }
        }
    }
}

fn unset_dotted(table: &mut Table, key: &str) {
    let mut parts: Vec<&str> = key.split('.').collect();
    let Some(last) = parts.pop() else { return };
    let mut target = table;
    for part in parts {
        match target.get_mut(part) {
            Some(Value::Table(t)) => target = t,
            _ => return,
        }
    }
    target.remove(last);
}

/// The numbers of one run that a study compares.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunRow {
    /// Run name.
    pub run: String,
    /// Level label per axis.
    pub labels: Vec<String>,
    /// Seed.
    pub seed: u64,
    /// Final coverage fraction.
    pub final_coverage: f64,
    /// First time each coverage level was reached, seconds (`None`: never).
    pub time_to_coverage_s: Vec<Option<f64>>,
    /// Ground-truth collisions with the world.
    pub collisions: u64,
    /// Robot-robot contact episodes.
    pub robot_contacts: u64,
    /// Smallest distance between two robot centres, metres.
    pub min_inter_robot_distance_m: Option<f64>,
    /// Committed plans that entered unsafe space.
    pub unsafe_plans: u64,
    /// Distance flown by all robots, metres.
    pub distance_m: f64,
    /// Map bytes offered to the link (keyframe and bulk classes), all robots: what
    /// the map sharing asked to send, whether or not the link could carry it.
    pub map_bytes_offered: u64,
    /// Map bytes sent over the link (keyframe and bulk classes), all robots.
    pub map_bytes_sent: u64,
    /// All bytes sent over the link, all robots.
    pub link_bytes_sent: u64,
    /// Coverage over time, `[time_s, fraction]`.
    pub coverage_over_time: Vec<[f64; 2]>,
    /// Wall seconds.
    pub wall_s: f64,
    /// What the robots' own frames would have cost as occupancy-grid change sets,
    /// `[resolution_m, bytes]` summed over robots, per resolution of
    /// `metrics.og_change_set_resolutions_m` (empty when none; see
    /// [`crate::og_meter`]).
    #[serde(default)]
    pub og_change_set_bytes: Vec<[f64; 2]>,
    /// Time the robots spent moving without seeing new volume, seconds, summed over
    /// robots (see [`crate::monitor::UnproductiveTime`]; `None` in records written
    /// before it was measured).
    #[serde(default)]
    pub unproductive_s: Option<f64>,
    /// The longest unproductive interval of any robot, seconds (`None` as above).
    #[serde(default)]
    pub longest_unproductive_s: Option<f64>,
    /// The longest unproductive interval of any robot counting only the time while it
    /// remembered a frontier to go to, seconds (`None` as above).
    #[serde(default)]
    pub longest_unproductive_with_frontiers_s: Option<f64>,
    /// Re-explored, exclusive and shared volume and redundant flight time, summed over
    /// robots (thesis §8.2.7's mechanism, see [`crate::reexploration`]; `None` in records
    /// written before they were measured).
    #[serde(default)]
    pub reexploration: Option<TeamReExploration>,
    /// Each robot's cumulative map data offered to the link and received over time
    /// (thesis Fig. 8.9 (a)–(f); empty in records written before it was kept).
    #[serde(default)]
    pub map_data: Vec<RobotMapData>,
}

impl RunRow {
    /// Extracts the row from a run's output.
    #[must_use]
    pub fn from_output(variant: &Variant, output: &RunOutput, levels: &[f64]) -> Self {
        let s: &Summary = &output.summary;
        let over_time = &s.coverage.over_time;
        let link_bytes = |classes: &[Class], offered: bool| -> u64 {
            s.per_robot
                .iter()
                .filter_map(|r| r.truth.link.as_ref())
                .map(|l| {
                    classes
                        .iter()
                        .map(|&c| {
                            let c = l.shaper.class(c);
                            if offered {
                                c.offered_bytes
                            } else {
                                c.sent_bytes
                            }
                        })
                        .sum::<u64>()
                })
                .sum()
        };
        let map = [Class::Keyframe, Class::Bulk];
        RunRow {
            run: variant.name.clone(),
            labels: variant.labels.clone(),
            seed: variant.seed,
            final_coverage: s.coverage.final_fraction,
            time_to_coverage_s: times_to_coverage(over_time, levels),
            collisions: s.collisions,
            robot_contacts: s.robot_contacts,
            min_inter_robot_distance_m: s.min_inter_robot_distance_m,
            unsafe_plans: s.per_robot.iter().map(|r| r.truth.unsafe_plans).sum(),
            // In robot order, a fixed order.
            distance_m: s.per_robot.iter().map(|r| r.truth.distance_m).sum(),
            map_bytes_offered: link_bytes(&map, true),
            map_bytes_sent: link_bytes(&map, false),
            link_bytes_sent: link_bytes(&Class::ALL, false),
            coverage_over_time: over_time.clone(),
            wall_s: output.timing.wall_s,
            og_change_set_bytes: variant
                .scenario
                .metrics
                .og_change_set_resolutions_m
                .iter()
                .map(|&r| {
                    let bytes: u64 = s
                        .og_change_sets
                        .iter()
                        .filter(|o| o.totals.resolution_m == r)
                        .map(|o| o.totals.bytes)
                        .sum();
                    [r, bytes as f64]
                })
                .collect(),
            // Summed in nanoseconds and converted once: exact in any order.
            unproductive_s: Some(ns_to_s(
                s.per_robot
                    .iter()
                    .map(|r| r.truth.unproductive.total_ns())
                    .sum(),
            )),
            longest_unproductive_s: Some(
                s.per_robot
                    .iter()
                    .map(|r| r.truth.longest_unproductive_s)
                    .fold(0.0, f64::max),
            ),
            longest_unproductive_with_frontiers_s: Some(
                s.per_robot
                    .iter()
                    .map(|r| r.truth.longest_unproductive_with_frontiers_s)
                    .fold(0.0, f64::max),
            ),
            reexploration: Some(s.reexploration),
            map_data: map_data(output),
        }
    }
}

/// Each robot's cumulative keyframe-class bytes offered and received per sample period.
fn map_data(output: &RunOutput) -> Vec<RobotMapData> {
    let mut robots: Vec<RobotMapData> = Vec::new();
    for r in &output.timeseries {
        if robots.len() <= r.robot {
            robots.resize_with(r.robot + 1, RobotMapData::default);
            robots[r.robot].robot = r.robot;
        }
        robots[r.robot].offered_received.push([
            r.time_s,
            r.offered_bytes_keyframe as f64,
            r.received_bytes_keyframe as f64,
        ]);
    }
    robots
}

/// The file in a run's report directory that lets `troupe sweep --resume` reuse the run
/// instead of flying it again: the scenario the run flew and its row.
pub const FINISHED_RUN_FILE: &str = "study_row.json";

/// The scenario as JSON, read back once, so that a scenario compares equal to the same
/// scenario read from a file (float parsing need not round-trip every last bit).
fn scenario_json(scenario: &Scenario) -> serde_json::Result<serde_json::Value> {
    serde_json::from_str(&serde_json::to_string(scenario)?)
}

/// The troupe version that flies runs now, kept in every finished-run record:
/// `--resume` reuses and `--merge` accepts only runs flown by the same version.
pub const TROUPE_VERSION: &str = env!("CARGO_PKG_VERSION");

/// A finished run as [`save_finished_run`] records it.
#[derive(Deserialize)]
struct Record {
    /// The study's name (absent in records written before it was kept).
    #[serde(default)]
    study: Option<String>,
    /// The troupe version that flew the run (absent in records written before it
    /// was kept, all by troupe 0.1.0).
    #[serde(default)]
    troupe: Option<String>,
    /// The scenario the run flew, as [`scenario_json`] writes it.
    scenario: serde_json::Value,
    row: RunRow,
}

impl Record {
    /// Whether the run was flown by this troupe version.
    fn same_version(&self) -> bool {
        self.troupe.as_deref().is_none_or(|v| v == TROUPE_VERSION)
    }
}

/// Records a finished run of study `study` in `run_dir` (its report directory) for
/// `--resume` and `--merge`.
///
/// # Errors
///
/// Any I/O error.
pub fn save_finished_run(
    run_dir: &Path,
    study: &str,
    variant: &Variant,
    row: &RunRow,
) -> std::io::Result<()> {
    let record = serde_json::json!({
        "study": study,
        "troupe": TROUPE_VERSION,
        "scenario": scenario_json(&variant.scenario)?,
        "row": row,
    });
    let partial = run_dir.join(format!(".{FINISHED_RUN_FILE}.partial"));
    std::fs::write(&partial, serde_json::to_vec_pretty(&record)?)?;
    std::fs::rename(&partial, run_dir.join(FINISHED_RUN_FILE))
}

/// The row of a run that an earlier sweep finished in `run_dir`, if it flew exactly
/// this variant's scenario, with the times to `levels` taken from its coverage curve;
/// `None` when there is no record, it cannot be read, or the scenario differs (the
/// study or its base scenario changed since).
#[must_use]
pub fn finished_run(run_dir: &Path, variant: &Variant, levels: &[f64]) -> Option<RunRow> {
    let bytes = std::fs::read(run_dir.join(FINISHED_RUN_FILE)).ok()?;
    let record: Record = serde_json::from_slice(&bytes).ok()?;
    let same = scenario_json(&variant.scenario).ok()? == record.scenario
        && record.same_version()
        && record.row.run == variant.name
        && record.row.seed == variant.seed;
    same.then(|| RunRow {
        time_to_coverage_s: times_to_coverage(&record.row.coverage_over_time, levels),
        ..record.row
    })
}

/// The first time each coverage level was reached (`None`: never).
fn times_to_coverage(over_time: &[[f64; 2]], levels: &[f64]) -> Vec<Option<f64>> {
    levels
        .iter()
        .map(|&l| over_time.iter().find(|[_, c]| *c >= l).map(|[t, _]| *t))
        .collect()
}

fn opt(v: Option<f64>) -> String {
    v.map_or(String::new(), |x| format!("{x}"))
}

/// `results.csv`: one row per run.
#[must_use]
pub fn results_csv(study: &Study, rows: &[RunRow]) -> String {
    let mut header: Vec<String> = vec!["run".into(), "seed".into()];
    header.extend(study.axes.iter().map(|a| a.name.clone()));
    header.push("final_coverage".into());
    header.extend(
        study
            .coverage_levels
            .iter()
            .map(|l| format!("time_to_{}pct_s", (l * 100.0).round())),
    );
    header.extend(
        [
            "collisions",
            "robot_contacts",
            "min_inter_robot_distance_m",
            "unsafe_plans",
            "distance_m",
            "map_bytes_offered",
            "map_bytes_sent",
            "link_bytes_sent",
            "unproductive_s",
            "longest_unproductive_s",
            "longest_unproductive_with_frontiers_s",
            "reexplored_m3",
            "exclusive_m3",
            "shared_m3",
            "redundant_flight_s",
            "wall_s",
        ]
        .map(String::from),
    );
    // One column per resolution at which any run counted the baseline's bytes.
    let mut og_resolutions: Vec<f64> = rows
        .iter()
        .flat_map(|r| r.og_change_set_bytes.iter().map(|[res, _]| *res))
        .collect();
    og_resolutions.sort_by(f64::total_cmp);
    og_resolutions.dedup();
    header.extend(og_resolutions.iter().map(|r| format!("og_bytes_{r}m")));
    let mut out = header.join(",");
    out.push('\n');
    for r in rows {
        let mut cells = vec![r.run.clone(), r.seed.to_string()];
        cells.extend(r.labels.iter().cloned());
        cells.push(r.final_coverage.to_string());
        cells.extend(r.time_to_coverage_s.iter().map(|t| opt(*t)));
        cells.extend([
            r.collisions.to_string(),
            r.robot_contacts.to_string(),
            opt(r.min_inter_robot_distance_m),
            r.unsafe_plans.to_string(),
            r.distance_m.to_string(),
            r.map_bytes_offered.to_string(),
            r.map_bytes_sent.to_string(),
            r.link_bytes_sent.to_string(),
            opt(r.unproductive_s),
            opt(r.longest_unproductive_s),
            opt(r.longest_unproductive_with_frontiers_s),
            opt(r.reexploration.map(|x| x.reexplored_m3)),
            opt(r.reexploration.map(|x| x.exclusive_m3)),
            opt(r.reexploration.map(|x| x.shared_m3)),
            opt(r.reexploration.map(|x| x.redundant_flight_s)),
            format!("{:.3}", r.wall_s),
        ]);
        cells.extend(og_resolutions.iter().map(|res| {
            r.og_change_set_bytes
                .iter()
                .find(|[x, _]| x == res)
                .map_or(String::new(), |[_, bytes]| bytes.to_string())
        }));
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    out
}

/// Mean and 95% confidence half-width (Student t) of a sample. The sums run over the
/// values in ascending order, so the figures do not depend on the order of the runs
/// (e.g. on how a study was split into shards and merged).
#[must_use]
pub fn mean_ci95(values: &[f64]) -> (f64, f64) {
    let n = values.len();
    if n == 0 {
        return (f64::NAN, f64::NAN);
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let values = &sorted[..];
    let mean = values.iter().sum::<f64>() / n as f64;
    if n == 1 {
        return (mean, 0.0);
    }
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    (mean, t_975(n - 1) * (var / n as f64).sqrt())
}

/// The 97.5% quantile of Student's t with `dof` degrees of freedom.
fn t_975(dof: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    TABLE.get(dof.max(1) - 1).copied().unwrap_or(1.96)
}

/// The runs of one combination of levels, grouped (file order).
#[must_use]
pub fn groups(rows: &[RunRow]) -> Vec<(Vec<String>, Vec<&RunRow>)> {
    let mut order: Vec<Vec<String>> = Vec::new();
    let mut by: BTreeMap<Vec<String>, Vec<&RunRow>> = BTreeMap::new();
    for r in rows {
        if !by.contains_key(&r.labels) {
            order.push(r.labels.clone());
        }
        by.entry(r.labels.clone()).or_default().push(r);
    }
    order
        .into_iter()
        .map(|k| {
            let v = by.remove(&k).unwrap_or_default();
            (k, v)
        })
        .collect()
}

/// `aggregate.csv`: per combination of levels, means and 95% intervals over seeds; the
/// time to each coverage level over the runs that reached it, with their number.
#[must_use]
pub fn aggregate_csv(study: &Study, rows: &[RunRow]) -> String {
    let mut header: Vec<String> = study.axes.iter().map(|a| a.name.clone()).collect();
    header.extend(
        [
            "runs",
            "final_coverage_mean",
            "final_coverage_ci95",
            "map_bytes_offered_mean",
            "map_bytes_sent_mean",
            "map_bytes_sent_ci95",
            "collisions_total",
            "robot_contacts_total",
            "unproductive_s_mean",
            "unproductive_s_ci95",
            "longest_unproductive_s_max",
            "longest_unproductive_with_frontiers_s_max",
            "reexplored_m3_mean",
            "reexplored_m3_ci95",
            "exclusive_m3_mean",
            "exclusive_m3_ci95",
            "redundant_flight_s_mean",
            "redundant_flight_s_ci95",
        ]
        .map(String::from),
    );
    for l in &study.coverage_levels {
        let p = (l * 100.0).round();
        header.push(format!("time_to_{p}pct_s_mean"));
        header.push(format!("time_to_{p}pct_s_ci95"));
        header.push(format!("reached_{p}pct_runs"));
    }
    let mut out = header.join(",");
    out.push('\n');
    for (labels, group) in groups(rows) {
        let mut cells = labels.clone();
        let cov: Vec<f64> = group.iter().map(|r| r.final_coverage).collect();
        let bytes: Vec<f64> = group.iter().map(|r| r.map_bytes_sent as f64).collect();
        let offered: Vec<f64> = group.iter().map(|r| r.map_bytes_offered as f64).collect();
        let (cm, cc) = mean_ci95(&cov);
        let (bm, bc) = mean_ci95(&bytes);
        cells.extend([
            group.len().to_string(),
            cm.to_string(),
            cc.to_string(),
            mean_ci95(&offered).0.to_string(),
            bm.to_string(),
            bc.to_string(),
            group.iter().map(|r| r.collisions).sum::<u64>().to_string(),
            group
                .iter()
                .map(|r| r.robot_contacts)
                .sum::<u64>()
                .to_string(),
        ]);
        let unproductive: Vec<f64> = group.iter().filter_map(|r| r.unproductive_s).collect();
        let longest = group
            .iter()
            .filter_map(|r| r.longest_unproductive_s)
            .reduce(f64::max);
        let longest_with_frontiers = group
            .iter()
            .filter_map(|r| r.longest_unproductive_with_frontiers_s)
            .reduce(f64::max);
        cells.extend(mean_and_ci95_cells(&unproductive));
        cells.push(opt(longest));
        cells.push(opt(longest_with_frontiers));
        for figure in [
            |x: TeamReExploration| x.reexplored_m3,
            |x: TeamReExploration| x.exclusive_m3,
            |x: TeamReExploration| x.redundant_flight_s,
        ] {
            let values: Vec<f64> = group
                .iter()
                .filter_map(|r| r.reexploration.map(figure))
                .collect();
            cells.extend(mean_and_ci95_cells(&values));
        }
        for i in 0..study.coverage_levels.len() {
            let reached: Vec<f64> = group
                .iter()
                .filter_map(|r| r.time_to_coverage_s[i])
                .collect();
            cells.extend(mean_and_ci95_cells(&reached));
            cells.push(reached.len().to_string());
        }
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    out
}

/// The mean and 95% half-width of `values` as two cells, both empty when there are
/// no values.
fn mean_and_ci95_cells(values: &[f64]) -> [String; 2] {
    if values.is_empty() {
        return [String::new(), String::new()];
    }
    let (mean, half) = mean_ci95(values);
    [mean.to_string(), half.to_string()]
}

/// Runs every variant, `jobs` at a time; `done` is called after each run with its row
/// (from a worker thread, in completion order). Rows come back in variant order.
///
/// # Errors
///
/// The first run that could not be assembled (checked variants assemble; this is for
/// configurations that only fail when the world is built).
pub fn run_variants(
    variants: &[Variant],
    levels: &[f64],
    jobs: usize,
    mut done: impl FnMut(&Variant, &RunOutput, &RunRow) + Send,
) -> Result<Vec<RunRow>, troupe_robot::AssembleError> {
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Result<RunRow, troupe_robot::AssembleError>>>> =
        Mutex::new(variants.iter().map(|_| None).collect());
    let done = Mutex::new(&mut done);
    std::thread::scope(|scope| {
        for _ in 0..jobs.clamp(1, variants.len().max(1)) {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(variant) = variants.get(i) else {
                        break;
                    };
                    let result = Team::new(&variant.scenario).map(|team| {
                        let output = team.run(|_| {});
                        let row = RunRow::from_output(variant, &output, levels);
                        let mut done = done.lock().unwrap_or_else(|e| e.into_inner());
                        (*done)(variant, &output, &row);
                        row
                    });
                    results.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(result);
                }
            });
        }
    });
    results
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .flatten()
        .collect()
}

/// Writes `results.csv`, `aggregate.csv`, `ratios.csv` (when the study has a
/// `[ratio]`) and the plots — `coverage`, `map_data` (one panel per combination, when
/// the runs recorded map data) and `time_to_coverage` — into `root` and returns the
/// file names.
///
/// # Errors
///
/// Any I/O error.
pub fn write_study(root: &Path, study: &Study, rows: &[RunRow]) -> std::io::Result<Vec<String>> {
    std::fs::create_dir_all(root)?;
    let mut files = vec![
        ("results.csv", results_csv(study, rows)),
        ("aggregate.csv", aggregate_csv(study, rows)),
    ];
    if let Some(spec) = &study.ratio {
        files.push((
            "ratios.csv",
            ratios_csv(study, spec, &ratios(study, spec, rows)),
        ));
    }
    let mut written = Vec::new();
    for (name, text) in files {
        let path = root.join(name);
        let partial = root.join(format!(".{name}.partial"));
        std::fs::write(&partial, text)?;
        std::fs::rename(&partial, &path)?;
        written.push(path.display().to_string());
    }
    write_chart(&coverage_chart(study, rows), root, "coverage")?;
    written.push(root.join("coverage.{svg,png}").display().to_string());
    let panels = map_data_panels(study, rows);
    if !panels.is_empty() {
        // One column per level of the last axis: a row per combination of the others.
        let columns = study.axes.last().map_or(1, |a| a.levels.len());
        write_panels(&panels, columns, root, "map_data")?;
        written.push(root.join("map_data.{svg,png}").display().to_string());
    }
    if !study.coverage_levels.is_empty() {
        write_chart(
            &time_to_coverage_chart(study, rows),
            root,
            "time_to_coverage",
        )?;
        written.push(
            root.join("time_to_coverage.{svg,png}")
                .display()
                .to_string(),
        );
    }
    Ok(written)
}

/// Mean team coverage over time per combination of levels, with 95% bands over seeds
/// (clipped to the 0–100 % a coverage can take).
#[must_use]
pub fn coverage_chart(study: &Study, rows: &[RunRow]) -> Chart {
    let series = groups(rows)
        .into_iter()
        .map(|(labels, group)| {
            let samples = group
                .iter()
                .map(|r| r.coverage_over_time.len())
                .min()
                .unwrap_or(0);
            let mut points = Vec::with_capacity(samples);
            let mut band = Vec::with_capacity(samples);
            for k in 0..samples {
                let t = group[0].coverage_over_time[k][0];
                let values: Vec<f64> = group
                    .iter()
                    .map(|r| 100.0 * r.coverage_over_time[k][1])
                    .collect();
                let (mean, half) = mean_ci95(&values);
                points.push((t, mean));
                // Coverage lies in [0, 100] %: a wide interval over few seeds is cut there.
                band.push((t, (mean - half).max(0.0), (mean + half).min(100.0)));
            }
            Series {
                label: figure::combination_label(study, &labels),
                points,
                band,
                ..Series::default()
            }
        })
        .collect();
    Chart {
        title: format!("{}: team coverage (mean, 95% band over seeds)", study.name),
        x_label: "time (s)".into(),
        y_label: "coverage (%)".into(),
        series,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).expect("write test file");
        p
    }

    /// `text` written as `study.toml` in a fresh directory and loaded: the directory
    /// (to keep while the study is used) and the study.
    fn load_study(text: &str) -> (tempfile::TempDir, Study) {
        let dir = tempfile::tempdir().expect("temp dir");
        let study = Study::load(&write(dir.path(), "study.toml", text)).expect("study");
        (dir, study)
    }

    #[test]
    fn axes_expand_to_every_combination_under_every_seed() {
        let dir = tempfile::tempdir().expect("temp dir");
        write(
            dir.path(),
            "base.toml",
            "duration_s = 5.0\nrobots = 1\n[robot]\nspeed_mps = 0.5\n",
        );
        let path = write(
            dir.path(),
            "study.toml",
            r#"
name = "s"
scenario = "base.toml"
seeds = [1, 2]
[[axes]]
key = "robot.speed_mps"
values = [1.0, 1.5]
[[axes]]
name = "robots"
[[axes.levels]]
label = "one"
[[axes.levels]]
label = "two"
set = { robots = 2, "robot.link.odometry_rate_hz" = 5.0 }
"#,
        );
        let study = Study::load(&path).expect("valid study");
        let variants = study.variants().expect("variants");
        assert_eq!(variants.len(), 8);
        assert_eq!(variants[0].name, "s-1.0-one-s1");
        assert_eq!(variants[7].name, "s-1.5-two-s2");
        assert_eq!(variants[7].scenario.robots, 2);
        assert_eq!(variants[7].scenario.robot.link.odometry_rate_hz, 5.0);
        assert_eq!(variants[7].scenario.robot.speed_mps, 1.5);
        assert_eq!(variants[0].scenario.robots, 1);
        assert_eq!(variants[0].scenario.duration_s, 5.0);
        // Seed by seed: every combination of seed 1 before seed 2.
        assert_eq!(variants[1].name, "s-1.0-two-s1");
        assert_eq!(variants[4].name, "s-1.0-one-s2");
        assert_eq!(variants[4].scenario.seed, 2);
    }

    #[test]
    fn bad_studies_name_the_problem() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cases = [
            ("name = \"s\"\nseeds = []\n", "seeds"),
            ("name = \"s\"\nseeds = [1]\nbogus = 1\n", "bogus"),
            (
                "name = \"s\"\nseeds = [1]\n[[axes]]\nkey = \"robots\"\nvalues = [0]\n",
                "robots",
            ),
            (
                "name = \"s\"\nseeds = [1]\n[[axes]]\nkey = \"robots\"\n",
                "either `key` and `values`",
            ),
            (
                "name = \"s\"\nseeds = [1]\nscenario = \"missing.toml\"\n",
                "missing.toml",
            ),
            (
                "name = \"s\"\nseeds = [1]\n[[axes]]\nkey = \"robots\"\nvalues = [1, 2]\nlabels = [\"a\"]\n",
                "`axes[0].labels` must give one label per value (2), got 1 labels",
            ),
            (
                "name = \"s\"\nseeds = [1]\n[[axes]]\nname = \"n\"\n[[axes.levels]]\nlabel = \"a/b\"\n",
                "`axes[0].levels[0].label` must be non-empty",
            ),
            ("name = \"../x\"\nseeds = [1]\n", "`name` must be non-empty"),
        ];
        for (text, needle) in cases {
            let path = write(dir.path(), "bad.toml", text);
            let error = Study::load(&path).expect_err(text);
            // What the CLI prints: the error and its causes.
            let message = troupe_core::ErrorChain(&error).to_string();
            assert!(
                message.contains(needle),
                "{message:?} should mention {needle}"
            );
        }
    }

    #[test]
    fn a_finished_run_is_reused_only_for_the_same_scenario() {
        let (dir, study) = load_study(
            "name = \"s\"\nseeds = [1]\nduration_s = 5.0\n[[axes]]\nkey = \"robots\"\nvalues = [1, 2]\n",
        );
        let variants = study.variants().expect("variants");
        let variant = &variants[0];
        let row = RunRow {
            run: variant.name.clone(),
            labels: variant.labels.clone(),
            seed: variant.seed,
            final_coverage: 0.5,
            time_to_coverage_s: vec![Some(2.0)],
            collisions: 0,
            robot_contacts: 0,
            min_inter_robot_distance_m: None,
            unsafe_plans: 0,
            distance_m: 3.25,
            map_bytes_offered: 10,
            map_bytes_sent: 9,
            link_bytes_sent: 20,
            coverage_over_time: vec![[1.0, 0.1], [2.0, 0.3], [3.0, 0.5]],
            wall_s: 1.5,
            og_change_set_bytes: vec![[0.1, 1000.0]],
            unproductive_s: Some(12.5),
            longest_unproductive_s: Some(8.0),
            longest_unproductive_with_frontiers_s: Some(6.0),
            reexploration: Some(TeamReExploration {
                reexplored_m3: 3.5,
                exclusive_m3: 40.0,
                shared_m3: 6.25,
                redundant_flight_s: 7.5,
            }),
            map_data: vec![RobotMapData {
                robot: 0,
                offered_received: vec![[1.0, 0.1, 1e6 / 3.0]],
            }],
        };
        let run_dir = dir.path().join(&variant.name);
        assert_eq!(
            finished_run(&run_dir, variant, &[0.3]),
            None,
            "no record yet"
        );
        std::fs::create_dir(&run_dir).expect("run dir");
        save_finished_run(&run_dir, "s", variant, &row).expect("save");

        assert_eq!(finished_run(&run_dir, variant, &[0.3]), Some(row.clone()));
        let other_levels = finished_run(&run_dir, variant, &[0.1, 0.4, 0.9]).expect("reused");
        assert_eq!(
            other_levels.time_to_coverage_s,
            vec![Some(1.0), Some(3.0), None]
        );

        let mut changed = variant.clone();
        changed.scenario.duration_s = 6.0;
        assert_eq!(
            finished_run(&run_dir, &changed, &[0.3]),
            None,
            "scenario changed"
        );
        assert_eq!(
            finished_run(&run_dir, &variants[1], &[0.3]),
            None,
            "another run"
        );

        std::fs::write(run_dir.join(FINISHED_RUN_FILE), b"{\"row\": tru").expect("corrupt");
        assert_eq!(
            finished_run(&run_dir, variant, &[0.3]),
            None,
            "corrupt record"
        );
    }

    /// Issue 42 item 6: a merged or resumed study reads its runs back from
    /// `study_row.json`; every float must come back as the float written, or the merged
    /// tables differ from the whole study's in the last digit (`unproductive_s`
    /// 23.400000000000006 read back as 23.40000000000001).
    #[test]
    fn a_finished_run_reads_back_every_float_exactly() {
        let (dir, study) = load_study("name = \"s\"\nseeds = [1]\nduration_s = 5.0\n");
        let variants = study.variants().expect("variants");
        let variant = &variants[0];
        // Sums of 0.1 and 0.2 and their ratios: floats with 16–17 significant digits,
        // many of which a fast (not correctly rounded) parser gets one ulp wrong.
        let (mut a, mut b) = (0.0, 0.0);
        let coverage_over_time: Vec<[f64; 2]> = (1..=300)
            .map(|_| {
                a += 0.1;
                b += 0.2;
                [a, a / (a + b + 1.0)]
            })
            .collect();
        let row = RunRow {
            run: variant.name.clone(),
            seed: variant.seed,
            final_coverage: 0.1 + 0.2,
            distance_m: 9.399999999999999,
            min_inter_robot_distance_m: Some(1.5999999999999999),
            coverage_over_time,
            unproductive_s: Some(23.400000000000006),
            longest_unproductive_s: Some(1.0 / 3.0),
            longest_unproductive_with_frontiers_s: Some(2.0f64.sqrt()),
            og_change_set_bytes: vec![[0.1, 1e17 / 3.0]],
            ..row_with_coverage(1, 0.0)
        };
        let run_dir = dir.path().join(&variant.name);
        std::fs::create_dir(&run_dir).expect("run dir");
        save_finished_run(&run_dir, "s", variant, &row).expect("save");
        let read = finished_run(&run_dir, variant, &[]).expect("reused");
        let bits = |r: &RunRow| -> Vec<u64> {
            r.coverage_over_time
                .iter()
                .flatten()
                .chain([&r.final_coverage, &r.distance_m])
                .chain(r.unproductive_s.iter())
                .map(|x| x.to_bits())
                .collect()
        };
        assert_eq!(bits(&read), bits(&row));
        assert_eq!(read, row);
    }

    #[test]
    fn coverage_bands_stay_within_0_and_100_percent() {
        let (_dir, study) = load_study("name = \"s\"\nseeds = [1, 2, 3]\nduration_s = 5.0\n");
        // Three seeds far apart: the 95% interval alone would reach below 0 and above 100 %.
        let rows: Vec<RunRow> = [0.02, 0.5, 0.98]
            .iter()
            .zip(1..)
            .map(|(&c, seed)| row_with_coverage(seed, c))
            .collect();
        let chart = coverage_chart(&study, &rows);
        let (t, low, high) = chart.series[0].band[0];
        assert_eq!((t, low, high), (1.0, 0.0, 100.0));
        assert!((chart.series[0].points[0].1 - 50.0).abs() < 1e-9);
    }

    /// A row of run `s-s<seed>` that reached `coverage` at 1 s.
    fn row_with_coverage(seed: u64, coverage: f64) -> RunRow {
        RunRow {
            run: format!("s-s{seed}"),
            labels: Vec::new(),
            seed,
            final_coverage: coverage,
            coverage_over_time: vec![[1.0, coverage]],
            ..RunRow::default()
        }
    }

    const RATIO_STUDY: &str = r#"name = "r"
seeds = [1, 2, 3, 4]
coverage_levels = [0.5]
[[axes]]
name = "map"
key = "robot.map_sharing"
values = ["gmm", "grid"]
labels = ["gmm", "og"]
[[axes]]
name = "rate"
key = "robot.link.shaper.rate_bps"
values = [100000, 250000]
labels = ["slow", "fast"]
[ratio]
axis = "map"
numerator = "gmm"
denominator = "og"
[[ratio.thesis]]
at = { rate = "fast" }
level = 0.5
says = 'below 0.8, "faster"'
"#;

    #[test]
    fn ratios_pair_seeds_count_never_as_last_and_carry_the_claim() {
        let dir = tempfile::tempdir().expect("temp dir");
        let study = Study::load(&write(dir.path(), "study.toml", RATIO_STUDY)).expect("study");
        let spec = study.ratio.clone().expect("a ratio");
        // Times to 50 % per seed, slow rate: GMM 10, 20, 30, never; OG 40, 50, 60, 70.
        // Fast rate: both 5 × seed, and seed 4 has no OG run (unpaired).
        let time = |map: &str, rate: &str, seed: u64| -> Option<Option<f64>> {
            match (map, rate) {
                ("gmm", "slow") => Some((seed < 4).then_some(10.0 * seed as f64)),
                ("og", "slow") => Some(Some(30.0 + 10.0 * seed as f64)),
                ("og", "fast") if seed == 4 => None,
                _ => Some(Some(5.0 * seed as f64)),
            }
        };
        let mut rows = Vec::new();
        for seed in 1..=4 {
            for map in ["gmm", "og"] {
                for rate in ["slow", "fast"] {
                    if let Some(t) = time(map, rate, seed) {
                        rows.push(RunRow {
                            labels: vec![map.into(), rate.into()],
                            time_to_coverage_s: vec![t],
                            ..row_with_coverage(seed, 0.6)
                        });
                    }
                }
            }
        }
        let r = ratios(&study, &spec, &rows);
        assert_eq!(r.len(), 2);
        // Slow: the medians (nearest rank: the upper middle of four) are 30 and 60.
        assert_eq!(r[0].labels, vec!["slow".to_string()]);
        assert_eq!((r[0].pairs, r[0].medians_s), (4, [Some(30.0), Some(60.0)]));
        assert_eq!(r[0].ratio, Some(0.5));
        assert_eq!(r[0].numerator_first, 3);
        let (lo, hi) = r[0].interval.expect("an interval");
        assert!(lo <= 0.5 && (0.5..1.0).contains(&hi), "{lo} {hi}");
        assert_eq!(r[0].thesis, None);
        // Fast: three pairs, equal times; the study file's claim.
        assert_eq!(
            (r[1].pairs, r[1].ratio, r[1].numerator_first),
            (3, Some(1.0), 0)
        );
        assert_eq!(r[1].interval, Some((1.0, 1.0)));
        let csv = ratios_csv(&study, &spec, &r);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(
            lines[0],
            "rate,coverage_level,pairs,gmm_median_s,og_median_s,ratio,ratio_ci95_low,\
             ratio_ci95_high,gmm_first,thesis"
        );
        assert_eq!(
            lines[2],
            r#"fast,0.5,3,10,10,1,1,1,0,"below 0.8, ""faster""""#
        );
    }

    #[test]
    fn a_ratio_must_name_an_axis_its_levels_and_a_coverage_level() {
        let dir = tempfile::tempdir().expect("temp dir");
        for (from, to, key) in [
            (r#"axis = "map""#, r#"axis = "speed""#, "ratio.axis"),
            (
                r#"numerator = "gmm""#,
                r#"numerator = "none""#,
                "ratio.numerator",
            ),
            ("level = 0.5", "level = 0.6", "ratio.thesis[0].level"),
            (
                r#"rate = "fast""#,
                r#"rate = "fastest""#,
                "ratio.thesis[0].at.rate",
            ),
        ] {
            let text = RATIO_STUDY.replace(from, to);
            assert_ne!(text, RATIO_STUDY);
            let e = Study::load(&write(dir.path(), "study.toml", &text)).expect_err(key);
            let StudyError::Invalid { source, .. } = e else {
                panic!("{e:?}")
            };
            assert_eq!(source.key, key);
        }
    }

    #[test]
    fn results_have_one_og_bytes_column_per_resolution_counted() {
        let (_dir, study) = load_study("name = \"s\"\nseeds = [1, 2]\n");
        let levels = study.coverage_levels.len();
        let [mut counted, mut plain] = [1, 2].map(|seed| row_with_coverage(seed, 0.5));
        for row in [&mut counted, &mut plain] {
            row.time_to_coverage_s = vec![None; levels];
        }
        counted.og_change_set_bytes = vec![[0.1, 800.0], [0.05, 6400.0]];
        let csv = results_csv(&study, &[counted, plain]);
        let lines: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
        let n = lines[0].len();
        assert_eq!(lines[0][n - 2..], ["og_bytes_0.05m", "og_bytes_0.1m"]);
        assert_eq!(lines[1][n - 2..], ["6400", "800"]);
        assert_eq!(lines[2][n - 2..], ["", ""], "a run that counted nothing");
        assert!(lines.iter().all(|l| l.len() == n));
    }

    #[test]
    fn results_carry_the_reexploration_figures_and_empty_cells_for_old_records() {
        let (_dir, study) = load_study("name = \"s\"\nseeds = [1, 2]\n");
        let levels = study.coverage_levels.len();
        let [mut measured, mut old] = [1, 2].map(|seed| row_with_coverage(seed, 0.5));
        for row in [&mut measured, &mut old] {
            row.time_to_coverage_s = vec![None; levels];
        }
        measured.reexploration = Some(TeamReExploration {
            reexplored_m3: 12.5,
            exclusive_m3: 300.0,
            shared_m3: 20.25,
            redundant_flight_s: 41.0,
        });
        let csv = results_csv(&study, &[measured, old]);
        let lines: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
        let names = [
            "reexplored_m3",
            "exclusive_m3",
            "shared_m3",
            "redundant_flight_s",
        ];
        let at = names.map(|n| lines[0].iter().position(|h| *h == n).expect(n));
        assert_eq!(at.map(|i| lines[1][i]), ["12.5", "300", "20.25", "41"]);
        assert_eq!(at.map(|i| lines[2][i]), ["", "", "", ""]);
    }

    #[test]
    fn the_shipped_studies_load_and_every_variant_validates() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
        let mut studies = 0;
        for entry in std::fs::read_dir(&dir).expect("sims/studies") {
            let path = entry.expect("entry").path();
            if path.extension().is_some_and(|e| e == "toml") {
                let variants = Study::load(&path)
                    .and_then(|s| s.variants())
                    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                assert!(!variants.is_empty(), "{}", path.display());
                studies += 1;
            }
        }
        assert!(studies >= 6, "{studies} studies");
    }

    #[test]
    fn aggregate_has_intervals_on_times_to_coverage_and_counts_the_runs_reaching_them() {
        let (_dir, study) =
            load_study("name = \"s\"\nseeds = [1, 2, 3]\ncoverage_levels = [0.5, 0.9]\n");
        let rows: Vec<RunRow> = [(Some(10.0), 4.0), (Some(20.0), 40.0), (None, 7.0)]
            .into_iter()
            .zip(1..)
            .map(|((t, longest), seed)| RunRow {
                time_to_coverage_s: vec![t, None],
                unproductive_s: Some(2.0 * longest),
                longest_unproductive_s: Some(longest),
                longest_unproductive_with_frontiers_s: Some(longest / 2.0),
                // The third run comes from a record written before re-exploration was
                // measured: the means are over the other two.
                reexploration: (seed < 3).then_some(TeamReExploration {
                    reexplored_m3: 10.0 * longest,
                    exclusive_m3: 100.0,
                    shared_m3: 1.0,
                    redundant_flight_s: longest,
                }),
                ..row_with_coverage(seed, 0.6)
            })
            .collect();
        let csv = aggregate_csv(&study, &rows);
        let lines: Vec<&str> = csv.lines().collect();
        let column = |name: &str| {
            let i = lines[0]
                .split(',')
                .position(|h| h == name)
                .unwrap_or_else(|| panic!("no column {name} in {}", lines[0]));
            lines[1].split(',').nth(i).expect("cell").to_string()
        };
        assert_eq!(column("time_to_50pct_s_mean"), "15");
        let (_, half) = mean_ci95(&[10.0, 20.0]);
        assert_eq!(column("time_to_50pct_s_ci95"), half.to_string());
        assert_eq!(column("reached_50pct_runs"), "2");
        assert_eq!(column("time_to_90pct_s_mean"), "");
        assert_eq!(column("time_to_90pct_s_ci95"), "");
        assert_eq!(column("reached_90pct_runs"), "0");
        assert_eq!(column("unproductive_s_mean"), "34");
        assert_eq!(column("longest_unproductive_s_max"), "40");
        assert_eq!(column("longest_unproductive_with_frontiers_s_max"), "20");
        assert_eq!(column("reexplored_m3_mean"), "220");
        let (_, half) = mean_ci95(&[40.0, 400.0]);
        assert_eq!(column("reexplored_m3_ci95"), half.to_string());
        assert_eq!(column("exclusive_m3_mean"), "100");
        assert_eq!(column("exclusive_m3_ci95"), "0");
        assert_eq!(column("redundant_flight_s_mean"), "22");
    }

    #[test]
    fn confidence_interval_matches_a_hand_computation() {
        let (m, h) = mean_ci95(&[1.0, 2.0, 3.0]);
        assert_eq!(m, 2.0);
        // s = 1, t(2) = 4.303, h = 4.303 / sqrt(3).
        assert!((h - 4.303 / 3f64.sqrt()).abs() < 1e-12);
        assert_eq!(mean_ci95(&[5.0]), (5.0, 0.0));
    }
}
