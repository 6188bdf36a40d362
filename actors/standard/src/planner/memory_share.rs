//! The frontier memory shared with peers (`[robot.planner.guidance] share_memory`): each
//! planning round a robot sends the cells its own observations changed in its memory, on
//! a shared topic of the link, and folds in what its peers sent where its memory knows
//! nothing — their remembered frontiers beyond its window, and the passable cells that
//! lead there (issue 18's team frontier memory; docs/exploration.md).

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
    /// ([`CellRecord::to_bits`]).
    pub cells: Vec<(CellKey, u8)>,
    /// Frontiers the sender gave up since its last message because its camera did not
    /// see into them from nearby (`share_given_up`; empty otherwise).
    pub given_up: Vec<CellKey>,
}
impl Message for MemoryCells {
    fn payload_bytes(&self) -> usize {
        std::mem::size_of::<Self>() + 13 * self.cells.len() + 12 * self.given_up.len()
    }
}

/// Where planners share their memory changes: store-and-forward at plan priority, since
/// a lost message is a change the peer never hears of.
pub const MEMORY_CELLS: SharedTopic<MemoryCells> = SharedTopic::new(
    "exploration/memory",
    1,
    SharePolicy::store_and_forward_in_plan_class(),
);

/// A checked [`MemoryCells`].
#[derive(Clone, Debug, PartialEq)]
pub struct DecodedCells {
    /// The changed cells and their records.
    pub cells: Vec<(CellKey, CellRecord)>,
    /// The frontiers the peer gave up.
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
    /// More than [`MAX_SHARED_CELLS`] cells, given-up ones included.
    #[error("{0} cells, more than {MAX_SHARED_CELLS}")]
    TooMany(usize),
    /// A record with bits beyond the four, or a key out of range (cells counted
    /// first, then given-up frontiers).
    #[error("cell {0} is malformed")]
    Malformed(usize),
}

impl MemoryCells {
    /// The message of `changes` and of the frontiers `given_up`.
    #[must_use]
    pub fn new(cell_m: f64, changes: &[(CellKey, CellRecord)], given_up: Vec<CellKey>) -> Self {
        MemoryCells {
            cell_m,
            cells: changes.iter().map(|(k, r)| (*k, r.to_bits())).collect(),
            given_up,
        }
    }

    /// The cells and the given-up frontiers, checked against a memory of `own_cell_m`
    /// cells: all or nothing.
    pub fn decode(&self, own_cell_m: f64) -> Result<DecodedCells, MemoryCellsError> {
        if !(self.cell_m.is_finite() && (self.cell_m - own_cell_m).abs() <= 1e-9 * own_cell_m) {
            return Err(MemoryCellsError::CellSize {
                peer_m: self.cell_m,
                own_m: own_cell_m,
            });
        }
        let count = self.cells.len() + self.given_up.len();
        if count > MAX_SHARED_CELLS {
            return Err(MemoryCellsError::TooMany(count));
        }
        let in_range = |key: &CellKey| key.iter().all(|v| v.unsigned_abs() <= MAX_CELL_INDEX);
        let cells = self
            .cells
            .iter()
            .enumerate()
            .map(|(i, (key, bits))| match CellRecord::from_bits(*bits) {
                Some(record) if in_range(key) => Ok((*key, record)),
                _ => Err(MemoryCellsError::Malformed(i)),
            })
            .collect::<Result<_, _>>()?;
        if let Some(i) = self.given_up.iter().position(|key| !in_range(key)) {
            return Err(MemoryCellsError::Malformed(self.cells.len() + i));
        }
        Ok(DecodedCells {
            cells,
            given_up: self.given_up.clone(),
        })
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
        let given_up = vec![[4, 4, -1]];
        let message = MemoryCells::new(1.0, &changes, given_up.clone());
        let bytes = postcard::to_allocvec(&message).unwrap();
        let back: MemoryCells = postcard::from_bytes(&bytes).unwrap();
        assert_eq!(
            back.decode(1.0).unwrap(),
            DecodedCells {
                cells: changes,
                given_up
            }
        );
    }

    #[test]
    fn hostile_cells_are_rejected_whole() {
        let good = MemoryCells::new(1.0, &[([0, 0, 0], record(true))], vec![[1, 0, 0]]);
        assert!(matches!(
            good.decode(0.5),
            Err(MemoryCellsError::CellSize { .. })
        ));
        let mut bits = good.clone();
        bits.cells.push(([1, 1, 1], 16));
        assert_eq!(bits.decode(1.0), Err(MemoryCellsError::Malformed(1)));
        let mut far = good.clone();
        far.cells.push(([i32::MAX, 0, 0], 1));
        assert_eq!(far.decode(1.0), Err(MemoryCellsError::Malformed(1)));
        let mut far_given_up = good.clone();
        far_given_up.given_up.push([0, i32::MIN, 0]);
        assert_eq!(
            far_given_up.decode(1.0),
            Err(MemoryCellsError::Malformed(2))
        );
        let nan = MemoryCells {
            cell_m: f64::NAN,
            ..good.clone()
        };
        assert!(nan.decode(1.0).is_err());
        let many = MemoryCells {
            cell_m: 1.0,
            cells: vec![([0, 0, 0], 1); MAX_SHARED_CELLS],
            given_up: vec![[0, 0, 0]],
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
                let good = MemoryCells::new(1.0, &[([3, 0, 0], record(true))], Vec::new());
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
