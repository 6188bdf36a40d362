//! Writing a run's outputs: `summary.json`, `timing.json`, `timeseries.csv`.
//!
//! Files are written into a temporary directory next to the destination and moved
//! into place at the end, so a run directory is either complete or absent.

use std::fmt::Write as _;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};

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
            "{},{},{},{},{},{},{},{},{},{},{}",
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
            r.team_explored_m3
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
    if dir.exists() {
        fs::remove_dir_all(&dir)?;
    }
    fs::rename(&staging, &dir)?;
    Ok(dir)
}

/// Pretty JSON with a trailing newline.
fn pretty_json<T: serde::Serialize>(value: &T) -> io::Result<String> {
    let mut s = serde_json::to_string_pretty(value).map_err(io::Error::other)?;
    s.push('\n');
    Ok(s)
}
