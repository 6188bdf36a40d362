//! How a planning round chooses among its scored candidates: the [`ActionSelection`]
//! policy the planner actor asks each round (implementations live in
//! `troupe-policies` and are chosen by name).

use rand_chacha::ChaCha8Rng;

use super::primitives::FlatState;
use super::problem::PlanningProblem;
use super::round::Candidate;

/// Chooses among scored candidates. Implementations live in `troupe-policies`.
pub trait ActionSelection: Send + 'static {
    /// Index of the chosen candidate, or `None` to stop.
    fn select(&mut self, candidates: &[Candidate], rng: &mut ChaCha8Rng) -> Option<usize>;

    /// Index of the chosen candidate among the children of `root` (`candidates`,
    /// computed by `problem`), or `None` to stop. Search policies override this to
    /// expand deeper states through `problem` (thesis §4.1.3); by default it is
    /// [`Self::select`].
    fn select_in(
        &mut self,
        problem: &PlanningProblem<'_>,
        root: &FlatState,
        candidates: &[Candidate],
        rng: &mut ChaCha8Rng,
    ) -> Option<usize> {
        let _ = (problem, root);
        self.select(candidates, rng)
    }
}

impl ActionSelection for Box<dyn ActionSelection> {
    fn select(&mut self, candidates: &[Candidate], rng: &mut ChaCha8Rng) -> Option<usize> {
        (**self).select(candidates, rng)
    }

    fn select_in(
        &mut self,
        problem: &PlanningProblem<'_>,
        root: &FlatState,
        candidates: &[Candidate],
        rng: &mut ChaCha8Rng,
    ) -> Option<usize> {
        (**self).select_in(problem, root, candidates, rng)
    }
}
