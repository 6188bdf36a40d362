//! `run.mcap`: the recording of a simulated run (sim time) — what the robots
//! published, through a [`Recorder`] tap, plus the world's surface, each robot's
//! samples of `timeseries.csv` and the team's coverage, with `summary.json` and the
//! scenario attached — and reading one back for `troupe replay` (summary, plots). The
//! channels are listed in [`troupe_record::recorder`] and `docs/recordings.md`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;
use troupe_core::Time;
use troupe_record::{RecordOptions, Recorder, period_of_hz, schemas};

use crate::report::run_charts;
use crate::scenario::{MetricsConfig, Scenario};
use crate::team::{RunOutput, SeriesRow};
use crate::world::World;

/// Channel of robot `i`'s samples (its rows of `timeseries.csv`).
#[must_use]
pub fn sample_topic(robot: usize) -> String {
    format!("/robot{robot}/sample")
}

/// Channel of the team's coverage.
pub const COVERAGE_TOPIC: &str = "/team/coverage";

/// One message on [`COVERAGE_TOPIC`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CoverageSample {
    /// Sim time, seconds.
    pub time_s: f64,
    /// Explored fraction of the free volume.
    pub fraction: f64,
    /// Explored volume, m³.
    pub explored_m3: f64,
    /// Volume the robots observed after a peer had, summed over robots, m³ (thesis
    /// §8.2.7's re-exploration; [`crate::reexploration`]).
    pub reexplored_m3: f64,
    /// Volume only one robot observed, summed over robots, m³.
    pub exclusive_m3: f64,
    /// Time the robots spent moving between frames that observed nothing new to the
    /// team, summed over robots, seconds.
    pub redundant_flight_s: f64,
}

/// What `[metrics]` asks a run's recorder to write of the bulky topics.
#[must_use]
pub fn record_options(metrics: &MetricsConfig) -> RecordOptions {
    RecordOptions {
        grid_period_s: period_of_hz(metrics.record_grid_hz),
        depth_period_s: period_of_hz(metrics.record_depth_hz),
        compression: metrics.record_compression,
        ..RecordOptions::default()
    }
}

/// Finest sampling of the world's distance field for its recorded surface, metres.
pub const WORLD_SURFACE_CELL_M: f64 = 1.0;

/// Most distance samples taken for the recorded surface: a larger world is sampled
/// more coarsely (the surface is decimated to keep `/world` a few MB at most).
pub const WORLD_SURFACE_SAMPLES: usize = 400_000;

/// A triangle mesh: vertices and three vertex indices per triangle.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceMesh {
    /// Vertices, world frame, metres.
    pub vertices: Vec<Point3<f64>>,
    /// Triangles, counter-clockwise seen from free space.
    pub triangles: Vec<[u32; 3]>,
}

/// The zero level set of the world's signed distance (the rock surface) as a triangle
/// mesh, by surface nets: the distance is sampled on a lattice over the world's
/// bounds every `cell_m` (at least [`WORLD_SURFACE_CELL_M`], coarser when the bounds
/// would take more than [`WORLD_SURFACE_SAMPLES`] samples); each lattice cube whose
/// corners change sign gets one vertex, the mean of its edges' linearly interpolated
/// crossings, and each lattice edge that changes sign joins the four cubes around it
/// with two triangles. Non-finite distances count as rock.
#[must_use]
pub fn world_surface(world: &dyn World) -> SurfaceMesh {
    let bounds = world.bounds();
    let extent = bounds.max - bounds.min;
    if !extent.iter().all(|v| v.is_finite() && *v > 0.0) {
        return SurfaceMesh::default();
    }
    let volume = extent.x * extent.y * extent.z;
    let cell_m = WORLD_SURFACE_CELL_M.max((volume / WORLD_SURFACE_SAMPLES as f64).cbrt());
    // One cell of margin all round, so the surface closes at the bounds.
    let origin = bounds.min - Vector3::repeat(cell_m);
    let n = extent.map(|e| (e / cell_m).ceil() as usize + 3);
    let (nx, ny, nz) = (n.x, n.y, n.z);
    let at =
        |i: usize, j: usize, k: usize| origin + Vector3::new(i as f64, j as f64, k as f64) * cell_m;
    let index = |i: usize, j: usize, k: usize| (k * ny + j) * nx + i;
    let sdf: Vec<f64> = (0..nx * ny * nz)
        .into_par_iter()
        .map(|l| {
            let (i, j, k) = (l % nx, (l / nx) % ny, l / (nx * ny));
            let d = world.sdf_m(&at(i, j, k));
            if d.is_finite() { d } else { -cell_m }
        })
        .collect();
    let free = |i: usize, j: usize, k: usize| sdf[index(i, j, k)] > 0.0;

    // One vertex per cube (named by its lowest corner) that the surface crosses.
    const CORNERS: [[usize; 3]; 8] = [
        [0, 0, 0],
        [1, 0, 0],
        [0, 1, 0],
        [1, 1, 0],
        [0, 0, 1],
        [1, 0, 1],
        [0, 1, 1],
        [1, 1, 1],
    ];
    let mut mesh = SurfaceMesh::default();
    let mut vertex_of = vec![u32::MAX; nx * ny * nz];
    for k in 0..nz - 1 {
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let mut sum = Vector3::zeros();
                let mut crossings = 0.0;
                for (a, ca) in CORNERS.iter().enumerate() {
                    for cb in &CORNERS[a + 1..] {
                        let differs = (0..3).filter(|&d| ca[d] != cb[d]).count() == 1;
                        let pa = (i + ca[0], j + ca[1], k + ca[2]);
                        let pb = (i + cb[0], j + cb[1], k + cb[2]);
                        let (da, db) = (sdf[index(pa.0, pa.1, pa.2)], sdf[index(pb.0, pb.1, pb.2)]);
                        if differs && (da > 0.0) != (db > 0.0) {
                            let t = da / (da - db);
                            let xa = at(pa.0, pa.1, pa.2).coords;
                            let xb = at(pb.0, pb.1, pb.2).coords;
                            sum += xa + (xb - xa) * t;
                            crossings += 1.0;
                        }
                    }
                }
                if crossings > 0.0 {
                    vertex_of[index(i, j, k)] = mesh.vertices.len() as u32;
                    mesh.vertices.push(Point3::from(sum / crossings));
                }
            }
        }
    }
    // Two triangles per sign-changing lattice edge, joining the four cubes around it.
    for k in 1..nz - 1 {
        for j in 1..ny - 1 {
            for i in 1..nx - 1 {
                let here = free(i, j, k);
                // Edges along x, y, z from (i, j, k); the cubes around each, counter-
                // clockwise seen from the edge's far end (a quad facing +axis, turned
                // round when the free side is the near one).
                let edges = [
                    (
                        free(i + 1, j, k),
                        [(i, j - 1, k - 1), (i, j, k - 1), (i, j, k), (i, j - 1, k)],
                    ),
                    (
                        free(i, j + 1, k),
                        [(i - 1, j, k - 1), (i - 1, j, k), (i, j, k), (i, j, k - 1)],
                    ),
                    (
                        free(i, j, k + 1),
                        [(i - 1, j - 1, k), (i, j - 1, k), (i, j, k), (i - 1, j, k)],
                    ),
                ];
                for (next, cubes) in edges {
                    if here == next {
                        continue;
                    }
                    let v = cubes.map(|(a, b, c)| vertex_of[index(a, b, c)]);
                    if v.contains(&u32::MAX) {
                        continue;
                    }
                    let (q0, q1, q2, q3) = if !here {
                        (v[0], v[1], v[2], v[3])
                    } else {
                        (v[0], v[3], v[2], v[1])
                    };
                    mesh.triangles.push([q0, q1, q2]);
                    mesh.triangles.push([q0, q2, q3]);
                }
            }
        }
    }
    mesh
}

/// Writes the world's surface ([`world_surface`]) on the recording's `/world`
/// channel; returns its triangle count.
pub fn record_world(recorder: &mut Recorder, world: &dyn World) -> usize {
    let mesh = world_surface(world);
    recorder.write_world(&mesh.vertices, &mesh.triangles);
    mesh.triangles.len()
}

/// Writes what the run produced besides publications: every [`SeriesRow`] on its
/// robot's sample channel and the team coverage at its sample time (the robots'
/// re-exploration figures summed in robot order), and attaches `summary.json` and
/// `scenario.toml`.
pub fn record_outputs(recorder: &mut Recorder, output: &RunOutput, scenario: &Scenario) {
    for rows in output.timeseries.chunk_by(|a, b| a.time_s == b.time_s) {
        let at = Time::from_secs_f64(rows[0].time_s);
        for row in rows {
            recorder.write(&sample_topic(row.robot), &schemas::SAMPLE, at, row);
        }
        let sum = |f: fn(&SeriesRow) -> f64| rows.iter().map(f).sum::<f64>();
        let coverage = CoverageSample {
            time_s: rows[0].time_s,
            fraction: rows[0].team_coverage,
            explored_m3: rows[0].team_explored_m3,
            reexplored_m3: sum(|r| r.reexplored_m3),
            exclusive_m3: sum(|r| r.exclusive_m3),
            redundant_flight_s: sum(|r| r.redundant_flight_s),
        };
        recorder.write(COVERAGE_TOPIC, &schemas::COVERAGE, at, &coverage);
    }
    let end = Time::from_secs_f64(scenario.duration_s);
    match serde_json::to_vec_pretty(&output.summary) {
        Ok(json) => recorder.attach("summary.json", "application/json", end, &json),
        Err(e) => tracing::warn!("summary.json not attached: {e}"),
    }
    match toml::to_string(scenario) {
        Ok(text) => recorder.attach(
            "scenario.toml",
            "application/toml",
            Time::ZERO,
            text.as_bytes(),
        ),
        Err(e) => tracing::warn!("scenario.toml not attached: {e}"),
    }
}

/// Why a recording could not be read back.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The file could not be read.
    #[error("cannot read recording `{path}`")]
    Read {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Not an MCAP file, or a damaged one.
    #[error("`{path}` is not a readable MCAP recording")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: mcap::McapError,
    },
    /// A sample message is not a `troupe.Sample`.
    #[error("`{path}`: a message on `{topic}` is not a sample")]
    Sample {
        /// The file.
        path: PathBuf,
        /// The channel.
        topic: String,
        /// The cause.
        source: serde_json::Error,
    },
    /// The plots could not be written.
    #[error("writing the plots into `{dir}`")]
    Plot {
        /// The directory.
        dir: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// One channel of a recording.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ChannelSummary {
    /// Schema name (empty without a schema).
    pub schema: String,
    /// Messages.
    pub messages: u64,
}

/// What a recording holds (`troupe replay`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RecordingSummary {
    /// Channels by topic.
    pub channels: BTreeMap<String, ChannelSummary>,
    /// Messages in all.
    pub messages: u64,
    /// First and last message time, seconds on the recording's clock (sim time for
    /// runs, Unix time for processes); `None` without messages.
    pub span_s: Option<[f64; 2]>,
    /// Names of the attached files.
    pub attachments: Vec<String>,
}

impl RecordingSummary {
    /// Seconds between the first and the last message.
    #[must_use]
    pub fn duration_s(&self) -> f64 {
        self.span_s.map_or(0.0, |[a, b]| b - a)
    }
}

/// A recording's bytes, read whole.
pub struct RecordingFile {
    path: PathBuf,
    bytes: Vec<u8>,
}

impl RecordingFile {
    /// Reads the file at `path`.
    pub fn open(path: &Path) -> Result<Self, ReplayError> {
        let bytes = std::fs::read(path).map_err(|source| ReplayError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Ok(RecordingFile {
            path: path.to_path_buf(),
            bytes,
        })
    }

    fn mcap_error(&self, source: mcap::McapError) -> ReplayError {
        ReplayError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    fn messages(&self) -> Result<mcap::MessageStream<'_>, ReplayError> {
        mcap::MessageStream::new(&self.bytes).map_err(|e| self.mcap_error(e))
    }

    /// Counts every channel's messages by reading them all (a truncated recording,
    /// whose summary section is missing, is summarised up to its damage, which is
    /// then reported as an error).
    pub fn summary(&self) -> Result<RecordingSummary, ReplayError> {
        let mut channels: BTreeMap<String, ChannelSummary> = BTreeMap::new();
        let mut span: Option<[u64; 2]> = None;
        let mut messages = 0;
        for message in self.messages()? {
            let message = message.map_err(|e| self.mcap_error(e))?;
            let channel = &message.channel;
            channels
                .entry(channel.topic.clone())
                .or_insert_with(|| ChannelSummary {
                    schema: channel
                        .schema
                        .as_ref()
                        .map(|s| s.name.clone())
                        .unwrap_or_default(),
                    messages: 0,
                })
                .messages += 1;
            messages += 1;
            let t = message.log_time;
            span = Some(span.map_or([t, t], |[a, b]| [a.min(t), b.max(t)]));
        }
        let attachments = mcap::Summary::read(&self.bytes)
            .map_err(|e| self.mcap_error(e))?
            .map(|s| {
                s.attachment_indexes
                    .iter()
                    .map(|a| a.name.clone())
                    .collect()
            })
            .unwrap_or_default();
        Ok(RecordingSummary {
            channels,
            messages,
            span_s: span.map(|s| s.map(|t| t as f64 * 1e-9)),
            attachments,
        })
    }

    /// The rows of `timeseries.csv` recorded on the sample channels, in time order.
    pub fn samples(&self) -> Result<Vec<SeriesRow>, ReplayError> {
        let mut rows = Vec::new();
        for message in self.messages()? {
            let message = message.map_err(|e| self.mcap_error(e))?;
            let topic = &message.channel.topic;
            if topic.starts_with("/robot") && topic.ends_with("/sample") {
                let row: SeriesRow = serde_json::from_slice(&message.data).map_err(|source| {
                    ReplayError::Sample {
                        path: self.path.clone(),
                        topic: topic.clone(),
                        source,
                    }
                })?;
                rows.push(row);
            }
        }
        rows.sort_by(|a, b| a.time_s.total_cmp(&b.time_s).then(a.robot.cmp(&b.robot)));
        Ok(rows)
    }

    /// Renders the run's plots (as `troupe run` draws them) from the recording alone
    /// into `dir`; returns the file stems written (none without samples).
    pub fn render_plots(&self, dir: &Path) -> Result<Vec<&'static str>, ReplayError> {
        let rows = self.samples()?;
        if rows.is_empty() {
            return Ok(Vec::new());
        }
        let plot_error = |source| ReplayError::Plot {
            dir: dir.to_path_buf(),
            source,
        };
        std::fs::create_dir_all(dir).map_err(plot_error)?;
        let mut stems = Vec::new();
        for (stem, chart) in run_charts(&rows) {
            crate::plot::write_chart(&chart, dir, stem).map_err(plot_error)?;
            stems.push(stem);
        }
        Ok(stems)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::{Aabb, BoxRoom};

    #[test]
    fn the_surface_of_a_room_lies_on_its_walls_and_faces_into_it() {
        let room = BoxRoom::new(Aabb::new(
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(20.3, 15.6, 6.2),
        ));
        let mesh = world_surface(&room);
        assert!(mesh.triangles.len() > 100, "{}", mesh.triangles.len());
        // On a flat wall the interpolated crossings are exact; at edges and corners
        // the vertex is their mean, inside its 1 m cube.
        let on_walls = mesh
            .vertices
            .iter()
            .filter(|v| room.sdf_m(v).abs() < 1e-9)
            .count();
        assert!(
            on_walls * 10 >= mesh.vertices.len() * 7,
            "{on_walls} of {}",
            mesh.vertices.len()
        );
        for v in &mesh.vertices {
            assert!(
                room.sdf_m(v).abs() < WORLD_SURFACE_CELL_M,
                "vertex {v} off the walls"
            );
        }
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|k| mesh.vertices[k as usize]);
            let normal = (b - a).cross(&(c - a));
            let centroid = Point3::from((a.coords + b.coords + c.coords) / 3.0);
            let step = normal.normalize() * 0.1;
            assert!(
                room.sdf_m(&(centroid + step)) > room.sdf_m(&(centroid - step)),
                "triangle {t:?} faces the rock"
            );
        }
        let sides = [20.3 * 15.6, 20.3 * 6.2, 15.6 * 6.2];
        let area: f64 = mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|k| mesh.vertices[k as usize]);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum();
        let walls = 2.0 * sides.iter().sum::<f64>();
        assert!((area / walls - 1.0).abs() < 0.15, "area {area} vs {walls}");
    }

    #[test]
    fn a_world_without_extent_has_no_surface() {
        let flat = BoxRoom::new(Aabb::new(Point3::origin(), Point3::new(1.0, 1.0, 0.0)));
        assert_eq!(world_surface(&flat), SurfaceMesh::default());
    }

    #[test]
    fn metrics_keys_set_the_recorded_rates() {
        let mut metrics = MetricsConfig::default();
        let options = record_options(&metrics);
        assert_eq!(options.grid_period_s, Some(1.0));
        assert_eq!(options.depth_period_s, None);
        assert_eq!(options.compression, troupe_record::Compression::Zstd);
        metrics.record_grid_hz = 0.0;
        metrics.record_depth_hz = 2.0;
        metrics.record_compression = troupe_record::Compression::None;
        let options = record_options(&metrics);
        assert_eq!(options.grid_period_s, None);
        assert_eq!(options.depth_period_s, Some(0.5));
        assert_eq!(options.compression, troupe_record::Compression::None);
    }
}
