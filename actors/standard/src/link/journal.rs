//! The link's non-volatile storage ([`LinkJournal`]): in memory for simulated teams,
//! on disk ([`troupe_comms::journal`]) for robot processes.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError};

use troupe_comms::journal::{DiskJournal, JournalError, ReceivedMessage};
use troupe_comms::shaping::{ClassConfig, DurableState};
use troupe_comms::wire::Class;

use super::shared::ShareRequest;

/// Most bytes of received store-and-forward messages an on-disk journal keeps
/// for the team map of a restarted robot (oldest dropped first).
pub const MAX_RECEIVED_BYTES: usize = 32 * 1024 * 1024;

/// The link's non-volatile storage: what it must not forget when it restarts (an
/// actor restart after a panic, or a reboot of the whole robot). It holds the
/// shaper's [`DurableState`] — the next message id and every store-and-forward
/// message not yet acknowledged by all its recipients — and the envelope sequence.
/// A [`LinkActor::journaled`](super::LinkActor::journaled) link writes it after every event it handles and
/// resumes from it when built again, so nothing accepted into a store-and-forward
/// class is lost and peers never see a reused message id (they would drop the
/// message as a duplicate). The robot assembly gives each robot one, outside the
/// actors' factories; clones share the storage.
#[derive(Clone, Debug, Default)]
pub struct LinkJournal(Arc<Mutex<JournalEntry>>);

#[derive(Debug, Default)]
pub(super) struct JournalEntry {
    pub shaper: Option<DurableState>,
    pub sequence: u64,
    /// The shared topics' lanes in the order they were added.
    pub lanes: Vec<JournaledLane>,
    /// The file, for a journal on disk.
    pub disk: Option<DiskJournal>,
    /// Where the lanes are kept beside a journal on disk ([`LANES_FILE`]).
    pub lanes_path: Option<PathBuf>,
    /// Messages received before a restart, not yet handed to a link.
    pub received: Vec<ReceivedMessage>,
}

/// The file beside `link.journal` that keeps the shared topics' lanes (name, class,
/// queue settings, in the order they were added; postcard), rewritten atomically
/// when a lane is added: stored messages of a lane go back to it after a restart,
/// so they keep their store-and-forward lane rather than falling back to their
/// class's own queue.
pub const LANES_FILE: &str = "link.lanes";

/// What [`LANES_FILE`] holds per lane.
type DiskLane = (String, Class, ClassConfig);

/// The lanes kept in `path` (none when there is no file yet).
fn read_lanes(path: &Path) -> Result<Vec<JournaledLane>, JournalError> {
    let io = |source| JournalError::Io {
        path: path.to_owned(),
        source,
    };
    let bytes = match std::fs::read(path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(io(e)),
    };
    let lanes: Vec<DiskLane> = postcard::from_bytes(&bytes).map_err(|e| {
        io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not a list of link lanes: {e}"),
        ))
    })?;
    Ok(lanes
        .into_iter()
        .map(|(name, class, config)| JournaledLane {
            name,
            class,
            config,
            request: None,
        })
        .collect())
}

impl JournalEntry {
    /// On disk: writes the lanes to [`LANES_FILE`] (a new file, fsync'd, renamed
    /// over the old one, so a crash leaves the old list or the new one).
    pub(super) fn sync_lanes(&self) -> Result<(), JournalError> {
        let Some(path) = &self.lanes_path else {
            return Ok(());
        };
        let lanes: Vec<DiskLane> = self
            .lanes
            .iter()
            .map(|l| (l.name.clone(), l.class, l.config))
            .collect();
        let bytes = postcard::to_allocvec(&lanes).map_err(JournalError::Encode)?;
        let temporary = path.with_extension("lanes.new");
        let write = || -> std::io::Result<()> {
            let mut file = std::fs::File::create(&temporary)?;
            file.write_all(&bytes)?;
            file.sync_all()?;
            std::fs::rename(&temporary, path)?;
            if let Some(dir) = path.parent() {
                std::fs::File::open(dir)?.sync_all()?;
            }
            Ok(())
        };
        write().map_err(|source| JournalError::Io {
            path: path.clone(),
            source,
        })
    }
}

/// A shared topic's lane as the journal keeps it: a new link adds the lanes again
/// in the same order (so stored messages return to them) and keeps sharing the
/// topics without the actors asking again.
#[derive(Clone, Debug)]
pub(super) struct JournaledLane {
    pub name: String,
    pub class: Class,
    pub config: ClassConfig,
    pub request: Option<ShareRequest>,
}

impl LinkJournal {
    /// An empty journal whose first message id is `first_id`. A robot process that
    /// keeps no journal across its own restarts starts each run at a different id
    /// (e.g. from the clock) so that peers who remember the previous run's ids do
    /// not take new messages for repeats.
    #[must_use]
    pub fn starting_at(first_id: u32) -> Self {
        LinkJournal(Arc::new(Mutex::new(JournalEntry {
            shaper: Some(DurableState {
                next_id: first_id,
                ..DurableState::default()
            }),
            ..JournalEntry::default()
        })))
    }

    /// A journal kept on disk in `dir` (`dir/link.journal`, see
    /// [`troupe_comms::journal`]), for a robot process: it resumes what the file
    /// holds — stored messages, recipients, the next message id, messages received,
    /// and the shared topics' lanes ([`LANES_FILE`]) — and writes every change
    /// through, fsync'd, so that `kill -9` and a restart lose nothing accepted or
    /// acknowledged and reuse no id. A new file's ids start at `first_id`.
    pub fn on_disk(dir: &Path, first_id: u32) -> Result<Self, JournalError> {
        Self::on_disk_keeping(dir, first_id, MAX_RECEIVED_BYTES)
    }

    /// Like [`on_disk`](Self::on_disk), keeping up to `max_received_bytes` of
    /// received messages (past it, the largest sender's oldest first) instead of [`MAX_RECEIVED_BYTES`]:
    /// a base station keeps the team's whole map this way.
    pub fn on_disk_keeping(
        dir: &Path,
        first_id: u32,
        max_received_bytes: usize,
    ) -> Result<Self, JournalError> {
        let (disk, recovered) = DiskJournal::open(dir, first_id, max_received_bytes)?;
        let lanes_path = dir.join(LANES_FILE);
        let lanes = read_lanes(&lanes_path)?;
        if recovered.discarded_bytes > 0 {
            tracing::warn!(
                journal = %disk.path().display(),
                bytes = recovered.discarded_bytes,
                "cut off a torn journal tail (a write interrupted by a crash)"
            );
        }
        if !recovered.state.stored.is_empty() || !recovered.received.is_empty() {
            tracing::info!(
                journal = %disk.path().display(),
                stored = recovered.state.stored.len(),
                received = recovered.received.len(),
                next_id = recovered.state.next_id,
                "link journal reopened"
            );
        }
        Ok(LinkJournal(Arc::new(Mutex::new(JournalEntry {
            shaper: Some(recovered.state),
            sequence: recovered.sequence,
            lanes,
            disk: Some(disk),
            lanes_path: Some(lanes_path),
            received: recovered.received,
        }))))
    }

    pub(super) fn entry(&self) -> std::sync::MutexGuard<'_, JournalEntry> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Journals a store-and-forward message received from `source` before it is
    /// acknowledged (on disk: written and fsync'd; in memory: nothing to do, the
    /// robot's map outlives a link restart).
    pub(super) fn record_received(
        &self,
        source: u32,
        id: u32,
        bytes: &[u8],
    ) -> Result<(), JournalError> {
        match &mut self.entry().disk {
            Some(disk) => disk.record_received(source, id, bytes),
            None => Ok(()),
        }
    }

    /// The messages received before the process restarted, once.
    pub(super) fn take_received(&self) -> Vec<ReceivedMessage> {
        std::mem::take(&mut self.entry().received)
    }

    /// Received messages the journal on disk dropped for room (the sender holding the
    /// most bytes loses its oldest first); 0 in memory.
    #[must_use]
    pub fn received_evicted(&self) -> u64 {
        self.entry()
            .disk
            .as_ref()
            .map_or(0, DiskJournal::received_evicted)
    }

    /// Store-and-forward messages kept (accepted, not acknowledged by every recipient).
    #[must_use]
    pub fn stored_messages(&self) -> usize {
        self.entry().shaper.as_ref().map_or(0, |s| s.stored.len())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// The lanes survive a process restart (they used to be kept in memory only, so
    /// a restarted robot's stored shared-topic messages fell back to their class's
    /// own queue and lost store-and-forward).
    #[test]
    fn lanes_on_disk_come_back_after_a_restart() {
        let dir = tempfile::tempdir().unwrap();
        let journal = LinkJournal::on_disk(dir.path(), 7).unwrap();
        assert!(journal.entry().lanes.is_empty());
        {
            let mut entry = journal.entry();
            for (name, class) in [
                ("artifacts/report", Class::Plan),
                ("base/command", Class::Odometry),
            ] {
                entry.lanes.push(JournaledLane {
                    name: name.to_owned(),
                    class,
                    config: ClassConfig::store_and_forward(),
                    request: None,
                });
            }
            entry.sync_lanes().unwrap();
        }
        drop(journal);
        let again = LinkJournal::on_disk(dir.path(), 9).unwrap();
        let entry = again.entry();
        let lanes: Vec<(&str, Class)> = entry
            .lanes
            .iter()
            .map(|l| (l.name.as_str(), l.class))
            .collect();
        assert_eq!(
            lanes,
            [
                ("artifacts/report", Class::Plan),
                ("base/command", Class::Odometry)
            ]
        );
        assert_eq!(entry.lanes[0].config, ClassConfig::store_and_forward());
        drop(entry);
        std::fs::write(dir.path().join(LANES_FILE), b"\xff\xff\xff").unwrap();
        let e = LinkJournal::on_disk(dir.path(), 9).err().unwrap();
        assert!(e.to_string().contains(LANES_FILE), "{e}");
    }
}
