//! The frontier memory shared with peers (`[robot.planner.guidance] share_memory`): each
//! planning round a robot sends the cells its own observations changed in its memory, on
//! a shared topic of the link, and folds in what its peers sent where its memory knows
//! nothing — their remembered frontiers beyond its window, and the passable cells that
//! lead there (issue 18's team frontier memory; docs/exploration.md).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use troupe_algorithms::exploration::{CellKey, CellRecord};
use troupe_runtime::Message;

use crate::link::{SharePolicy, SharedTopic};

/// Most cells one message may carry; a longer one is rejected whole.
pub const MAX_SHARED_CELLS: usize = 65_536;

/// Cell coordinates beyond this (in cells, per axis) are rejected.
const MAX_CELL_INDEX: u32 = 100_000_000;

/// Memory cells a robot's own observations changed since its last message.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MemoryCells {
    /// Edge of the sender's memory cells, metres (team configuration: a receiver with
    /// another edge rejects the message).
    pub cell_m: f64,
    /// Each cell's key (`floor(p / cell_m)` per axis, sender's world frame) and record
    /// ([`CellRecord::to_bits`]), with [`GIVEN_UP_BIT`] set on the pockets the sender
    /// gave up since its last message (`share_given_up`).
    pub cells: Vec<(CellKey, u8)>,
}
impl Message for MemoryCells {
    fn payload_bytes(&self) -> usize {
        std::mem::size_of::<Self>() + 13 * self.cells.len()
    }
}

/// The bit above a record's four that marks a pocket the sender gave up.
pub const GIVEN_UP_BIT: u8 = 1 << 4;

/// Where planners share their memory changes: store-and-forward at plan priority, since
/// a lost message is a change the peer never hears of.
pub const MEMORY_CELLS: SharedTopic<MemoryCells> = SharedTopic::new(
    "exploration/memory",
    1,
    SharePolicy::store_and_forward_in_plan_class(),
);

/// A checked [`MemoryCells`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DecodedCells {
    /// The changed cells and their records.
    pub cells: Vec<(CellKey, CellRecord)>,
    /// The pockets the peer gave up (among `cells`).
    pub given_up: Vec<CellKey>,
}

/// Why a peer's memory cells were rejected.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum MemoryCellsError {
    /// Another cell edge than ours.
    #[error("cell edge {peer_m} m, ours {own_m} m")]
    CellSize {
        /// The peer's edge, metres.
        peer_m: f64,
        /// Ours, metres.
        own_m: f64,
    },
    /// More than [`MAX_SHARED_CELLS`] cells.
    #[error("{0} cells, more than {MAX_SHARED_CELLS}")]
    TooMany(usize),
    /// A record with bits beyond the four and [`GIVEN_UP_BIT`], or a key out of range.
    #[error("cell {0} is malformed")]
    Malformed(usize),
}

impl MemoryCells {
    /// The message of `changes` and of the pockets `given_up` (each with its record),
    /// in key order; without pockets, the cells of `changes` alone.
    #[must_use]
    pub fn new(
        cell_m: f64,
        changes: &[(CellKey, CellRecord)],
        given_up: &[(CellKey, CellRecord)],
    ) -> Self {
        let mut cells: BTreeMap<CellKey, u8> =
            changes.iter().map(|(k, r)| (*k, r.to_bits())).collect();
        for (k, r) in given_up {
            *cells.entry(*k).or_insert(r.to_bits()) |= GIVEN_UP_BIT;
        }
        MemoryCells {
            cell_m,
            cells: cells.into_iter().collect(),
        }
    }

    /// The cells and the given-up pockets, checked against a memory of `own_cell_m`
    /// cells: all or nothing.
    pub fn decode(&self, own_cell_m: f64) -> Result<DecodedCells, MemoryCellsError> {
        if !(self.cell_m.is_finite() && (self.cell_m - own_cell_m).abs() <= 1e-9 * own_cell_m) {
            return Err(MemoryCellsError::CellSize {
                peer_m: self.cell_m,
                own_m: own_cell_m,
            });
        }
        if self.cells.len() > MAX_SHARED_CELLS {
            return Err(MemoryCellsError::TooMany(self.cells.len()));
        }
        let mut decoded = DecodedCells::default();
        for (i, (key, bits)) in self.cells.iter().enumerate() {
            let in_range = key.iter().all(|v| v.unsigned_abs() <= MAX_CELL_INDEX);
            let Some(record) = CellRecord::from_bits(bits & !GIVEN_UP_BIT).filter(|_| in_range)
            else {
                return Err(MemoryCellsError::Malformed(i));
            };
            decoded.cells.push((*key, record));
            if bits & GIVEN_UP_BIT != 0 {
                decoded.given_up.push(*key);
            }
        }
        Ok(decoded)
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use rand_chacha::ChaCha8Rng;
    use troupe_runtime::{
        Actor, ActorResult, ActorSpec, Context, Event, RobotId, RobotSpec, SimExecutor, Time,
        TimerId,
    };

    use super::*;
    use crate::link::Peer;
    use crate::planner::{PlannerActor, PlannerConfig};
    use troupe_algorithms::planner::round::Candidate;
    use troupe_algorithms::planner::selection::ActionSelection;

    fn record(frontier: bool) -> CellRecord {
        CellRecord {
            seen: true,
            passable: !frontier,
            frontier,
            settled: false,
        }
    }

    #[test]
    fn cells_round_trip_through_postcard() {
        let changes = vec![([1, -2, 3], record(true)), ([-7, 0, 1], record(false))];
        let message = MemoryCells::new(1.0, &changes, &[]);
        let bytes = postcard::to_allocvec(&message).unwrap();
        let back: MemoryCells = postcard::from_bytes(&bytes).unwrap();
        let mut sorted = changes.clone();
        sorted.sort_unstable_by_key(|(k, _)| *k);
        assert_eq!(
            back.decode(1.0).unwrap(),
            DecodedCells {
                cells: sorted.clone(),
                given_up: Vec::new()
            }
        );
        // Pockets given up ride on their cells, changed or not: no byte more without.
        let pocket = ([4, 4, -1], record(true));
        let with = MemoryCells::new(1.0, &changes, &[pocket, changes[1]]);
        let decoded = with.decode(1.0).unwrap();
        assert_eq!(decoded.given_up, vec![[-7, 0, 1], [4, 4, -1]]);
        assert_eq!(decoded.cells.len(), 3);
        assert!(decoded.cells.contains(&pocket));
    }

    #[test]
    fn hostile_cells_are_rejected_whole() {
        let good = MemoryCells::new(1.0, &[([0, 0, 0], record(true))], &[]);
        assert!(matches!(
            good.decode(0.5),
            Err(MemoryCellsError::CellSize { .. })
        ));
        let mut bits = good.clone();
        bits.cells.push(([1, 1, 1], 32));
        assert_eq!(bits.decode(1.0), Err(MemoryCellsError::Malformed(1)));
        let mut far = good.clone();
        far.cells.push(([i32::MAX, 0, 0], 1));
        assert_eq!(far.decode(1.0), Err(MemoryCellsError::Malformed(1)));
        let mut far_given_up = good.clone();
        far_given_up
            .cells
            .push(([0, i32::MIN, 0], GIVEN_UP_BIT | 5));
        assert_eq!(
            far_given_up.decode(1.0),
            Err(MemoryCellsError::Malformed(1))
        );
        let nan = MemoryCells {
            cell_m: f64::NAN,
            ..good.clone()
        };
        assert!(nan.decode(1.0).is_err());
        let many = MemoryCells {
            cell_m: 1.0,
            cells: vec![([0, 0, 0], 1); MAX_SHARED_CELLS + 1],
        };
        assert_eq!(
            many.decode(1.0),
            Err(MemoryCellsError::TooMany(MAX_SHARED_CELLS + 1))
        );
    }

    /// Hands the planner one well-formed and one hostile message, as the link would.
    struct Peers;

    impl Actor for Peers {
        fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
            ctx.set_timer(TimerId(1), Duration::from_millis(100));
            Ok(())
        }
        fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
            if matches!(event, Event::Timer(_)) {
                ctx.cancel_timer(TimerId(1));
                let good = MemoryCells::new(1.0, &[([3, 0, 0], record(true))], &[]);
                let mut hostile = good.clone();
                hostile.cells.push(([0, 0, 0], 0xff));
                for message in [good, hostile] {
                    ctx.publish(
                        &MEMORY_CELLS.peer_topic(),
                        Peer {
                            robot: RobotId(1),
                            sent_at: ctx.now(),
                            received_at: ctx.now(),
                            message,
                        },
                    );
                }
            }
            Ok(())
        }
    }

    struct First;

    impl ActionSelection for First {
        fn select(&mut self, candidates: &[Candidate], _: &mut ChaCha8Rng) -> Option<usize> {
            (!candidates.is_empty()).then_some(0)
        }
    }

    #[test]
    fn a_planner_counts_a_hostile_peer_memory_message_as_an_error_and_keeps_running() {
        let mut config = PlannerConfig::default();
        config.guidance.share_memory = true;
        let camera = troupe_algorithms::sogmm::synthetic::intrinsics(48, 36);
        let robot = RobotSpec::new("r0")
            .with(ActorSpec::new("peers", || Peers))
            .with(ActorSpec::new("planner", move || {
                PlannerActor::new(config, camera, First)
            }));
        let mut sim = SimExecutor::new(vec![robot], 1);
        sim.run_until(Time::from_secs_f64(2.0));
        let report = sim.finish();
        let planner = report[0]
            .actors
            .iter()
            .find(|a| a.name == "planner")
            .unwrap();
        assert_eq!((planner.stats.errors, planner.stats.panics), (1, 0));
        assert!(!planner.stats.stopped);
    }
}
