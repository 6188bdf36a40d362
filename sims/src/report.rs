//! Writing a run's outputs: `summary.json`, `timing.json`, `timeseries.csv`, the
//! plots, and — when the robots have mappers — each robot's map
//! (`maps/robot<i>.troupe`) and the team's merged map as a point cloud
//! (`merged_map.ply`, with a `source` property naming the robot).
//!
//! Files are written into a temporary directory next to the destination and moved
//! into place at the end, so a run directory is either complete or absent.

use std::fmt::Write as _;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use troupe_algorithms::mapfile::write_ply_with_source;
use troupe_robot::base::merged_points;

use crate::plot::{Chart, Series, write_chart};
use crate::team::{RunOutput, SeriesRow};

/// Column names of `timeseries.csv`, in order.
pub const TIMESERIES_COLUMNS: &[&str] = &[
    "time_s",
    "robot",
    "x_m",
    "y_m",
    "z_m",
    "yaw_rad",
    "speed_mps",
    "distance_m",
    "frames",
    "team_coverage",
    "team_explored_m3",
    "nearest_robot_m",
    "sent_bytes_odometry",
    "sent_bytes_plan",
    "sent_bytes_keyframe",
    "sent_bytes_bulk",
    "received_bytes",
    "received_bytes_keyframe",
    "offered_bytes_keyframe",
    "discovered_m3",
    "unproductive_s",
    "longest_unproductive_s",
    "longest_unproductive_with_frontiers_s",
    "observed_m3",
    "first_observed_m3",
    "reexplored_m3",
    "exclusive_m3",
    "redundant_flight_s",
    "phase",
];

/// The time series as CSV text.
#[must_use]
pub fn timeseries_csv(rows: &[SeriesRow]) -> String {
    let mut out = TIMESERIES_COLUMNS.join(",");
    out.push('\n');
    for r in rows {
        // Writing to a String cannot fail.
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.time_s,
            r.robot,
            r.x_m,
            r.y_m,
            r.z_m,
            r.yaw_rad,
            r.speed_mps,
            r.distance_m,
            r.frames,
            r.team_coverage,
            r.team_explored_m3,
            r.nearest_robot_m.map_or(String::new(), |d| d.to_string()),
            r.sent_bytes[0],
            r.sent_bytes[1],
            r.sent_bytes[2],
            r.sent_bytes[3],
            r.received_bytes,
            r.received_bytes_keyframe,
            r.offered_bytes_keyframe,
            r.discovered_m3,
            r.unproductive_s,
            r.longest_unproductive_s,
            r.longest_unproductive_with_frontiers_s,
            r.observed_m3,
            r.first_observed_m3,
            r.reexplored_m3,
            r.exclusive_m3,
            r.redundant_flight_s,
            r.phase.as_str()
        );
    }
    out
}

/// Writes the run into `root/name/` (replacing an earlier run of that name) and
/// returns the directory.
pub fn write_run(root: &Path, name: &str, output: &RunOutput) -> io::Result<PathBuf> {
    fs::create_dir_all(root)?;
    let dir = root.join(name);
    let staging = root.join(format!(".{name}.partial-{}", std::process::id()));
    if staging.exists() {
        fs::remove_dir_all(&staging)?;
    }
    fs::create_dir(&staging)?;
    fs::write(staging.join("summary.json"), pretty_json(&output.summary)?)?;
    fs::write(staging.join("timing.json"), pretty_json(&output.timing)?)?;
    fs::write(
        staging.join("timeseries.csv"),
        timeseries_csv(&output.timeseries),
    )?;
    for (stem, chart) in run_charts(&output.timeseries) {
        write_chart(&chart, &staging, stem)?;
    }
    write_maps(&staging, output)?;
    if dir.exists() {
        fs::remove_dir_all(&dir)?;
    }
    fs::rename(&staging, &dir)?;
    Ok(dir)
}

/// Points in `merged_map.ply`.
pub const MERGED_MAP_POINTS: usize = 200_000;

/// Writes `maps/robot<i>.troupe` for every robot that published keyframes and
/// `merged_map.ply` (points of all robots' maps, tagged by robot); nothing when no
/// robot did.
fn write_maps(dir: &Path, output: &RunOutput) -> io::Result<()> {
    if output.maps.iter().all(|m| m.keyframes.is_empty()) {
        return Ok(());
    }
    let maps_dir = dir.join("maps");
    fs::create_dir(&maps_dir)?;
    for (i, map) in output.maps.iter().enumerate() {
        if !map.keyframes.is_empty() {
            map.save(&maps_dir.join(format!("robot{i}.troupe")))
                .map_err(io::Error::other)?;
        }
    }
    let (points, source) = merged_points(&output.maps, MERGED_MAP_POINTS, output.summary.seed)
        .map_err(io::Error::other)?;
    let file = io::BufWriter::new(fs::File::create(dir.join("merged_map.ply"))?);
    write_ply_with_source(file, &points, Some(&source))
}

/// Pretty JSON with a trailing newline.
fn pretty_json<T: serde::Serialize>(value: &T) -> io::Result<String> {
    let mut s = serde_json::to_string_pretty(value).map_err(io::Error::other)?;
    s.push('\n');
    Ok(s)
}

/// The plots of a run, by file stem: coverage, link bytes per class and robot, speeds,
/// unproductive time, distance to the nearest robot, and the trajectories seen from above.
#[must_use]
pub fn run_charts(rows: &[SeriesRow]) -> Vec<(&'static str, Chart)> {
    let robots = rows.iter().map(|r| r.robot + 1).max().unwrap_or(0);
    let per_robot = |label: &dyn Fn(usize) -> String,
                     f: &dyn Fn(&SeriesRow) -> Option<(f64, f64)>| {
        (0..robots)
            .map(|i| Series {
                label: label(i),
                points: rows.iter().filter(|r| r.robot == i).filter_map(f).collect(),
                ..Series::default()
            })
            .collect::<Vec<_>>()
    };
    let robot_name = |i: usize| format!("robot{i}");
    let coverage = Chart {
        title: "Team coverage of the free volume".into(),
        x_label: "time (s)".into(),
        y_label: "coverage (%)".into(),
        series: vec![Series {
            label: "team".into(),
            points: rows
                .iter()
                .filter(|r| r.robot == 0)
                .map(|r| (r.time_s, 100.0 * r.team_coverage))
                .collect(),
            ..Series::default()
        }],
    };
    let classes = ["odometry", "plans", "keyframes", "bulk"];
    let mut bytes = Vec::new();
    for i in 0..robots {
        for (c, class) in classes.iter().enumerate() {
            let points: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.robot == i)
                .map(|r| (r.time_s, r.sent_bytes[c] as f64 / 1e3))
                .collect();
            if points.iter().any(|p| p.1 > 0.0) {
                bytes.push(Series {
                    label: format!("robot{i} sent {class}"),
                    points,
                    ..Series::default()
                });
            }
        }
        bytes.push(Series {
            label: format!("robot{i} received"),
            points: rows
                .iter()
                .filter(|r| r.robot == i)
                .map(|r| (r.time_s, r.received_bytes as f64 / 1e3))
                .collect(),
            ..Series::default()
        });
    }
    vec![
        ("coverage", coverage),
        (
            "link_bytes",
            Chart {
                title: "Link bytes, cumulative".into(),
                x_label: "time (s)".into(),
                y_label: "kB".into(),
                series: bytes,
            },
        ),
        (
            "speed",
            Chart {
                title: "Speed".into(),
                x_label: "time (s)".into(),
                y_label: "speed (m/s)".into(),
                series: per_robot(&robot_name, &|r| Some((r.time_s, r.speed_mps))),
            },
        ),
        (
            "unproductive",
            Chart {
                title: "Time moving without seeing new volume, cumulative".into(),
                x_label: "time (s)".into(),
                y_label: "unproductive time (s)".into(),
                series: per_robot(&robot_name, &|r| Some((r.time_s, r.unproductive_s))),
            },
        ),
        (
            "nearest_robot",
            Chart {
                title: "Distance to the nearest robot".into(),
                x_label: "time (s)".into(),
                y_label: "distance (m)".into(),
                series: per_robot(&robot_name, &|r| Some((r.time_s, r.nearest_robot_m?))),
            },
        ),
        (
            "trajectories",
            Chart {
                title: "Trajectories (top view)".into(),
                x_label: "x (m)".into(),
                y_label: "y (m)".into(),
                series: per_robot(&robot_name, &|r| Some((r.x_m, r.y_m))),
            },
        ),
    ]
}
