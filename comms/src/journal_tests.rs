//! Journal tests: round trip, torn tails, ids across restarts, compaction, and a
//! writer killed with SIGKILL in the middle of its work.

use std::io::{BufRead, BufReader, Write as _};
use std::process::{Command, Stdio};

use super::*;

fn message(id: u32, missing: Vec<u32>, len: usize) -> DurableMessage {
    DurableMessage {
        class: Class::Keyframe,
        lane: None,
        id: MessageId(id),
        bytes: vec![id as u8; len].into(),
        offered_ns: u64::from(id) * 1_000,
        missing,
    }
}

fn state(next_id: u32, stored: Vec<DurableMessage>) -> DurableState {
    DurableState {
        next_id,
        peers: vec![1, 2],
        stored,
    }
}

#[test]
fn what_was_synced_comes_back_after_reopening() {
    let dir = tempfile::tempdir().unwrap();
    let (mut j, recovered) = DiskJournal::open(dir.path(), 1_000, 1 << 20).unwrap();
    assert_eq!(recovered.state.next_id, 1_000);
    assert!(recovered.state.stored.is_empty());
    j.sync(
        &state(
            1_003,
            vec![
                message(1_000, vec![1, 2], 500),
                message(1_001, vec![2], 700),
            ],
        ),
        5,
    )
    .unwrap();
    // Robot 2 acknowledged 1 000; robot 1 acknowledged 1 001 earlier; 1 002 is new.
    j.sync(
        &state(
            1_003,
            vec![message(1_000, vec![1], 500), message(1_002, vec![1, 2], 10)],
        ),
        6,
    )
    .unwrap();
    j.record_received(2, 77, b"envelope").unwrap();
    drop(j);
    let (_, recovered) = DiskJournal::open(dir.path(), 0, 1 << 20).unwrap();
    let got: Vec<(u32, Vec<u32>, usize)> = recovered
        .state
        .stored
        .iter()
        .map(|m| (m.id.0, m.missing.clone(), m.bytes.len()))
        .collect();
    assert_eq!(got, vec![(1_000, vec![1], 500), (1_002, vec![1, 2], 10)]);
    assert_eq!(recovered.state.peers, vec![1, 2]);
    // Ids and sequence numbers continue past everything handed out.
    assert!(recovered.state.next_id >= 1_003);
    assert!(recovered.sequence >= 6);
    assert_eq!(recovered.received.len(), 1);
    assert_eq!(
        (recovered.received[0].source, recovered.received[0].id),
        (2, 77)
    );
    assert_eq!(&*recovered.received[0].bytes, b"envelope");
    assert_eq!(recovered.discarded_bytes, 0);
}

#[test]
fn a_torn_or_corrupt_tail_is_cut_off_and_the_rest_kept() {
    let dir = tempfile::tempdir().unwrap();
    let (mut j, _) = DiskJournal::open(dir.path(), 0, 1 << 20).unwrap();
    j.sync(&state(1, vec![message(0, vec![1], 100)]), 1)
        .unwrap();
    let good = j.file_bytes();
    j.sync(
        &state(2, vec![message(0, vec![1], 100), message(1, vec![1], 100)]),
        2,
    )
    .unwrap();
    let path = j.path().to_path_buf();
    drop(j);
    // A write cut in the middle of the second change.
    let len = std::fs::metadata(&path).unwrap().len();
    let file = OpenOptions::new().write(true).open(&path).unwrap();
    file.set_len(len - 7).unwrap();
    drop(file);
    let (mut j, recovered) = DiskJournal::open(dir.path(), 0, 1 << 20).unwrap();
    assert_eq!(recovered.state.stored.len(), 1);
    assert!(recovered.discarded_bytes > 0);
    assert_eq!(
        std::fs::metadata(&path).unwrap().len(),
        good.max(j.file_bytes())
    );
    // Appending after the cut gives a readable journal again.
    j.sync(
        &state(
            300,
            vec![message(0, vec![1], 100), message(299, vec![2], 50)],
        ),
        9,
    )
    .unwrap();
    drop(j);
    // Flip a byte in the last record: its checksum fails, it is dropped.
    let mut bytes = std::fs::read(&path).unwrap();
    let last = bytes.len() - 3;
    bytes[last] ^= 0xff;
    std::fs::write(&path, &bytes).unwrap();
    let (_, recovered) = DiskJournal::open(dir.path(), 0, 1 << 20).unwrap();
    assert!(recovered.discarded_bytes > 0);
    assert!(recovered.state.stored.iter().any(|m| m.id.0 == 0));
}

#[test]
fn not_a_journal_is_an_error_not_a_fresh_start() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join(FILE_NAME), b"hello world, not a journal").unwrap();
    let e = DiskJournal::open(dir.path(), 0, 1 << 20).unwrap_err();
    assert!(matches!(e, JournalError::NotAJournal { .. }), "{e}");
}

#[test]
fn ids_are_never_reused_across_three_restarts() {
    let dir = tempfile::tempdir().unwrap();
    let mut handed_out = Vec::new();
    let mut next = 0;
    for _ in 0..4 {
        let (mut j, recovered) = DiskJournal::open(dir.path(), 0, 1 << 20).unwrap();
        next = recovered.state.next_id.max(next);
        assert!(handed_out.iter().all(|id| *id < recovered.state.next_id));
        // Hand out 300 ids (more than a block), journaling every 7th change only,
        // as a crash can cut the last changes.
        for k in 0..300 {
            handed_out.push(next);
            next += 1;
            if k % 7 == 0 {
                j.sync(&state(next, Vec::new()), u64::from(next)).unwrap();
            }
        }
    }
}

#[test]
fn the_file_is_compacted_and_received_messages_are_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let (mut j, _) = DiskJournal::open(dir.path(), 0, 50_000).unwrap();
    for id in 0..2_000u32 {
        // One message stored, then released at the next change.
        j.sync(&state(id + 1, vec![message(id, vec![1], 2_000)]), 0)
            .unwrap();
        j.record_received(1, id, &[7; 1_000]).unwrap();
    }
    // 2 000 × 3 kB went through; the file holds what is live.
    assert!(j.file_bytes() < 3 << 20, "{} bytes", j.file_bytes());
    drop(j);
    let (_, recovered) = DiskJournal::open(dir.path(), 0, 50_000).unwrap();
    assert_eq!(recovered.state.stored.len(), 1);
    assert_eq!(recovered.state.stored[0].id.0, 1_999);
    assert!(recovered.received.len() <= 50);
    assert_eq!(recovered.received.last().map(|r| r.id), Some(1_999));
}

/// Issue 45, item 2: a member flooding the journal with large valid messages
/// (nine 3.9 MB ones, as the attacker sent) evicts its own messages, not the
/// keyframes another member sent before, in memory and after reopening; each
/// eviction is counted.
#[test]
fn a_flooding_sender_evicts_its_own_messages_not_another_members() {
    let dir = tempfile::tempdir().unwrap();
    let budget = 16 << 20;
    let (mut j, _) = DiskJournal::open(dir.path(), 0, budget).unwrap();
    for id in 0..8u32 {
        j.record_received(0, id, &[id as u8; 60_000]).unwrap();
    }
    let big = vec![9u8; 3_900_000];
    for id in 100..109u32 {
        j.record_received(1, id, &big).unwrap();
    }
    // 8 × 60 kB of robot 0's and 9 × 3.9 MB of the flooder's: 5 of the flooder's go.
    assert_eq!(j.received_evicted(), 5);
    drop(j);
    let (j, recovered) = DiskJournal::open(dir.path(), 0, budget).unwrap();
    let kept = |source: u32| -> Vec<u32> {
        recovered
            .received
            .iter()
            .filter(|m| m.source == source)
            .map(|m| m.id)
            .collect()
    };
    assert_eq!(kept(0), (0..8).collect::<Vec<_>>());
    assert_eq!(kept(1), (105..109).collect::<Vec<_>>());
    assert!(
        j.received_evicted() > 0,
        "reading back replays the evictions"
    );
}

/// The child half of the kill test: writes forever, printing each id after the
/// change that handed it out was synced.
#[test]
fn kill_test_child_writer() {
    let Some(dir) = std::env::var_os("TROUPE_JOURNAL_KILL_TEST_DIR") else {
        return; // only as the child of `a_writer_killed_with_sigkill_loses_nothing_synced`
    };
    let (mut j, recovered) = DiskJournal::open(Path::new(&dir), 0, 1 << 20).unwrap();
    let mut next = recovered.state.next_id;
    let mut stored: Vec<DurableMessage> = recovered.state.stored;
    let mut out = std::io::stdout().lock();
    loop {
        stored.push(message(next, vec![1], 3_000));
        if stored.len() > 20 {
            stored.remove(0);
        }
        next += 1;
        j.sync(&state(next, stored.clone()), u64::from(next))
            .unwrap();
        writeln!(out, "{}", next - 1).unwrap();
        out.flush().unwrap();
    }
}

/// `kill -9` of a process in the middle of journaling, three times: each restart
/// reads back every message of the last change the writer reported synced that
/// it still holds, and hands out no id used before.
#[test]
fn a_writer_killed_with_sigkill_loses_nothing_synced() {
    let dir = tempfile::tempdir().unwrap();
    let exe = std::env::current_exe().unwrap();
    let mut used: Vec<u32> = Vec::new();
    for _ in 0..3 {
        let mut child = Command::new(&exe)
            .args([
                "--exact",
                "journal::tests::kill_test_child_writer",
                "--nocapture",
                "--test-threads=1",
            ])
            .env("TROUPE_JOURNAL_KILL_TEST_DIR", dir.path())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let mut synced = Vec::new();
        while synced.len() < 150 {
            let Some(Ok(line)) = lines.next() else { break };
            if let Ok(id) = line.trim().parse::<u32>() {
                synced.push(id);
            }
        }
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        assert_eq!(synced.len(), 150, "the child wrote");
        let (_, recovered) = DiskJournal::open(dir.path(), 0, 1 << 20).unwrap();
        // The child keeps writing while the pipe holds its lines, so the state read
        // back may be newer than the last line read. It holds the 20 newest
        // messages of a synced state no older than that line, or, when the kill cut
        // a change after its release and before its addition, the 19 both share.
        let last = *synced.last().unwrap();
        let kept: Vec<u32> = recovered.state.stored.iter().map(|m| m.id.0).collect();
        let newest = *kept.last().unwrap();
        assert!(newest >= last, "the last synced change survived");
        let oldest = kept[0];
        assert!(newest - oldest >= 18, "a message both states hold was lost");
        assert_eq!(kept, (oldest..=newest).collect::<Vec<_>>());
        assert!(recovered.state.next_id > newest);
        assert!(
            synced.iter().all(|id| !used.contains(id)),
            "an id was reused"
        );
        used.extend(synced);
    }
}
