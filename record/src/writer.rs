//! The MCAP file of a recording: one channel per topic name, created on first use with
//! its schema, JSON messages, and attachments for the run's own files.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::records::MessageHeader;
use serde::{Deserialize, Serialize};

use crate::schemas::Schema;

/// MCAP profile of a recording (none of the well-known ROS profiles applies).
pub const PROFILE: &str = "troupe";

/// Target size of an MCAP chunk before it is closed, bytes.
const CHUNK_BYTES: u64 = 1 << 20;

/// How a recording's chunks are compressed (the `record_compression` key of a
/// scenario's `[metrics]` and of robot and base files). Readers decompress by the
/// name each chunk carries, so a file's compression needs no setting to read it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Compression {
    /// Zstandard at its default level: the default run's file is about a quarter
    /// of its uncompressed size (`docs/recordings.md`).
    #[default]
    Zstd,
    /// LZ4 frames: faster to write, about half the uncompressed size.
    Lz4,
    /// Uncompressed chunks.
    None,
}

impl Compression {
    fn mcap(self) -> Option<mcap::Compression> {
        match self {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        }
    }
}

/// Why a recording could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file could not be created.
    #[error("cannot create recording `{path}`")]
    Create {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The MCAP writer failed (an I/O error underneath, or too many channels).
    #[error("writing recording `{path}`")]
    Write {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: mcap::McapError,
    },
    /// A message could not be encoded as JSON.
    #[error("encoding a message for `{topic}`")]
    Encode {
        /// The channel.
        topic: String,
        /// The cause.
        source: serde_json::Error,
    },
}

/// An open recording. Call [`Recording::finish`] to write its summary and index; a
/// recording dropped without it is truncated (readers can still scan its messages).
pub struct Recording {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    channels: BTreeMap<String, u16>,
    schemas: BTreeMap<&'static str, u16>,
    sequence: u32,
    buffer: Vec<u8>,
}

impl Recording {
    /// Creates (or replaces) the MCAP file at `path`, its chunks compressed as
    /// `compression` says.
    pub fn create(path: &Path, compression: Compression) -> Result<Self, RecordError> {
        let file = File::create(path).map_err(|source| RecordError::Create {
            path: path.to_path_buf(),
            source,
        })?;
        let writer = mcap::WriteOptions::new()
            .profile(PROFILE)
            .library(concat!("troupe-record ", env!("CARGO_PKG_VERSION")))
            .compression(compression.mcap())
            // Chunks are compressed on the writing thread: no worker threads
            // competing with the run for the cores.
            .compression_threads(0)
            .chunk_size(Some(CHUNK_BYTES))
            .create(BufWriter::new(file))
            .map_err(|source| RecordError::Write {
                path: path.to_path_buf(),
                source,
            })?;
        Ok(Recording {
            path: path.to_path_buf(),
            writer,
            channels: BTreeMap::new(),
            schemas: BTreeMap::new(),
            sequence: 0,
            buffer: Vec::new(),
        })
    }

    /// Where the recording goes.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn write_error(&self, source: mcap::McapError) -> RecordError {
        RecordError::Write {
            path: self.path.clone(),
            source,
        }
    }

    fn channel(&mut self, topic: &str, schema: &Schema) -> Result<u16, RecordError> {
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let schema_id = match self.schemas.get(schema.name) {
            Some(&id) => id,
            None => {
                let id = self
                    .writer
                    .add_schema(schema.name, "jsonschema", &schema.data())
                    .map_err(|e| self.write_error(e))?;
                self.schemas.insert(schema.name, id);
                id
            }
        };
        let id = self
            .writer
            .add_channel(schema_id, topic, "json", &BTreeMap::new())
            .map_err(|e| self.write_error(e))?;
        self.channels.insert(topic.to_string(), id);
        Ok(id)
    }

    /// Writes `message` as JSON on `topic` (created with `schema` on first use) at
    /// `log_time_ns` (the recording's clock: sim time for simulated runs, Unix time for
    /// processes).
    pub fn write<T: Serialize>(
        &mut self,
        topic: &str,
        schema: &Schema,
        log_time_ns: u64,
        message: &T,
    ) -> Result<(), RecordError> {
        let channel_id = self.channel(topic, schema)?;
        self.buffer.clear();
        serde_json::to_writer(&mut self.buffer, message).map_err(|source| RecordError::Encode {
            topic: topic.to_string(),
            source,
        })?;
        let header = MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.sequence = self.sequence.wrapping_add(1);
        self.writer
            .write_to_known_channel(&header, &self.buffer)
            .map_err(|e| self.write_error(e))
    }

    /// Attaches a file of the run (`summary.json`, the scenario) under `name`.
    pub fn attach(
        &mut self,
        name: &str,
        media_type: &str,
        log_time_ns: u64,
        data: &[u8],
    ) -> Result<(), RecordError> {
        let attachment = mcap::Attachment {
            log_time: log_time_ns,
            create_time: log_time_ns,
            name: name.to_string(),
            media_type: media_type.to_string(),
            data: std::borrow::Cow::Borrowed(data),
        };
        self.writer
            .attach(&attachment)
            .map_err(|e| self.write_error(e))
    }

    /// Writes the summary section and index, and closes the file.
    pub fn finish(mut self) -> Result<PathBuf, RecordError> {
        self.writer.finish().map_err(|e| self.write_error(e))?;
        Ok(self.path)
    }
}
