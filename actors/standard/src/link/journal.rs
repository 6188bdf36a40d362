//! The link's non-volatile storage ([`LinkJournal`]): in memory for simulated teams,
//! on disk ([`troupe_comms::journal`]) for robot processes.

use std::path::Path;
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
    /// Messages received before a restart, not yet handed to a link.
    pub received: Vec<ReceivedMessage>,
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
    /// holds — stored messages, recipients, the next message id, messages received
    /// — and writes every change through, fsync'd, so that `kill -9` and a restart
    /// lose nothing accepted or acknowledged and reuse no id. A new file's ids
    /// start at `first_id`.
    pub fn on_disk(dir: &Path, first_id: u32) -> Result<Self, JournalError> {
        Self::on_disk_keeping(dir, first_id, MAX_RECEIVED_BYTES)
    }

    /// Like [`on_disk`](Self::on_disk), keeping up to `max_received_bytes` of
    /// received messages (oldest dropped first) instead of [`MAX_RECEIVED_BYTES`]:
    /// a base station keeps the team's whole map this way.
    pub fn on_disk_keeping(
        dir: &Path,
        first_id: u32,
        max_received_bytes: usize,
    ) -> Result<Self, JournalError> {
        let (disk, recovered) = DiskJournal::open(dir, first_id, max_received_bytes)?;
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
            lanes: Vec::new(),
            disk: Some(disk),
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

    /// Store-and-forward messages kept (accepted, not acknowledged by every recipient).
    #[must_use]
    pub fn stored_messages(&self) -> usize {
        self.entry().shaper.as_ref().map_or(0, |s| s.stored.len())
    }
}
