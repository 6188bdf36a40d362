//! `run.mcap`: the recording of a simulated run (sim time) — what the robots
//! published, through a [`Recorder`] tap, plus each robot's samples of
//! `timeseries.csv` and the team's coverage, with `summary.json` and the scenario
//! attached — and reading one back for `troupe replay` (summary, plots). The channels
//! are listed in [`troupe_record::recorder`] and `docs/recordings.md`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Serialize;
use troupe_actors::runtime::Time;
use troupe_record::{Recorder, schemas};

use crate::report::run_charts;
use crate::scenario::Scenario;
use crate::team::{RunOutput, SeriesRow};

/// File name of a run's recording in its report directory.
pub const RUN_RECORDING: &str = "run.mcap";

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
}

/// Writes what the run produced besides publications: every [`SeriesRow`] on its
/// robot's sample channel and the team coverage at its sample time, and attaches
/// `summary.json` and `scenario.toml`.
pub fn record_outputs(recorder: &mut Recorder, output: &RunOutput, scenario: &Scenario) {
    for row in &output.timeseries {
        let at = Time::from_secs_f64(row.time_s);
        recorder.write(&sample_topic(row.robot), &schemas::SAMPLE, at, row);
        if row.robot == 0 {
            let coverage = CoverageSample {
                time_s: row.time_s,
                fraction: row.team_coverage,
                explored_m3: row.team_explored_m3,
            };
            recorder.write(COVERAGE_TOPIC, &schemas::COVERAGE, at, &coverage);
        }
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
