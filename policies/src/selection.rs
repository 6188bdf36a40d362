//! Action selection over scored candidates (thesis §4.1.3, paper Alg. 1).
//!
//! - [`Greedy`]: the single best step (paper Alg. 1);
//! - [`RandomFeasible`]: the baseline, a random safe step;
//! - [`Mcts`]: anytime Monte Carlo tree search with UCT over primitive sequences.

pub mod mcts;

pub use mcts::{Mcts, SearchOutcome, search};

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use troupe_algorithms::planner::round::Candidate;
use troupe_algorithms::planner::selection::ActionSelection;

/// Single-step selection (paper Alg. 1): the candidate with the highest reward
/// I + αV; ties go to the first.
#[derive(Clone, Copy, Debug, Default)]
pub struct Greedy;

impl ActionSelection for Greedy {
    fn select(&mut self, candidates: &[Candidate], _rng: &mut ChaCha8Rng) -> Option<usize> {
        candidates
            .iter()
            .enumerate()
            .fold(None, |best: Option<(usize, f64)>, (i, c)| match best {
                Some((_, r)) if r >= c.reward => best,
                _ => Some((i, c.reward)),
            })
            .map(|(i, _)| i)
    }
}

/// The baseline: a uniformly random candidate among the same safe, feasible ones.
#[derive(Clone, Copy, Debug, Default)]
pub struct RandomFeasible;

impl ActionSelection for RandomFeasible {
    fn select(&mut self, candidates: &[Candidate], rng: &mut ChaCha8Rng) -> Option<usize> {
        (!candidates.is_empty()).then(|| rng.random_range(0..candidates.len()))
    }
}
