//! Anytime Monte Carlo tree search with UCT over sequences of motion primitives
//! (thesis §4.1.3, after Corah et al.): each iteration descends the tree by UCT,
//! expands one untried action of the node it stops at — building its primitive,
//! checking acceleration and jerk limits and the safety of the primitive and its
//! stopping primitive (the kinodynamic checks at expansion) — scores it, and
//! backs up the return accumulated along the branch. There is no random playout: a
//! playout step costs as much as an expansion (one CSQMI view), so the budget goes to
//! growing the tree instead. When the budget runs out, the first action of the best
//! branch found is returned. Under the wall clock the budget is wall time (or an
//! iteration cap, whichever comes first); under simulated time it is a fixed number
//! of iterations ([`SearchParams::sim_iterations`]) and the wall clock is never read,
//! so a simulated flight does not change with the machine's load.

use std::time::{Duration, Instant};

use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use troupe_algorithms::planner::primitives::FlatState;
use troupe_algorithms::planner::problem::{PlanningProblem, SearchParams};
use troupe_algorithms::planner::round::Candidate;
use troupe_algorithms::planner::selection::ActionSelection;

/// What a search found.
#[derive(Clone, Debug, PartialEq)]
pub struct SearchOutcome {
    /// Index of the chosen root candidate (`None` when there is none).
    pub choice: Option<usize>,
    /// Discounted return Σ γ^k r_k of the best branch found (the branch the choice
    /// starts); `None` without candidates.
    pub best_return: Option<f64>,
    /// Actions of the best branch, as indices into the library.
    pub best_branch: Vec<usize>,
    /// Iterations run.
    pub iterations: usize,
    /// Nodes in the tree (the root included).
    pub nodes: usize,
}

struct Node {
    /// The primitive reaching this node (absent at the root).
    candidate: Option<Candidate>,
    parent: Option<usize>,
    depth: usize,
    children: Vec<usize>,
    /// Library actions not tried yet from this node, in a random order.
    untried: Vec<usize>,
    /// Where children start: computed at the first expansion (`Some(None)`: the
    /// primitive's tail is unsafe, so the branch ends here).
    state: Option<Option<FlatState>>,
    visits: u32,
    /// Sum of the returns backed up through this node, counted from its own edge.
    total: f64,
    /// Best return from this node's edge down.
    best: f64,
}

impl Node {
    fn new(candidate: Option<Candidate>, parent: Option<usize>, depth: usize) -> Self {
        Node {
            candidate,
            parent,
            depth,
            children: Vec::new(),
            untried: Vec::new(),
            state: None,
            visits: 0,
            total: 0.0,
            best: f64::NEG_INFINITY,
        }
    }

    fn reward(&self) -> f64 {
        self.candidate.as_ref().map_or(0.0, |c| c.reward)
    }
}

/// Runs one anytime search from `root` whose children are `candidates` (already
/// computed by the round). Under simulated time
/// ([`PlanningProblem::time_source`]) it runs [`SearchParams::sim_iterations`]
/// iterations and is deterministic for a given `rng` state; under the wall clock it
/// stops at [`SearchParams::budget_s`] or [`SearchParams::max_iterations`], whichever
/// comes first (deterministic whenever the cap ends it).
#[must_use]
pub fn search(
    problem: &PlanningProblem<'_>,
    root: &FlatState,
    candidates: &[Candidate],
    params: &SearchParams,
    rng: &mut ChaCha8Rng,
) -> SearchOutcome {
    if candidates.is_empty() {
        return SearchOutcome {
            choice: None,
            best_return: None,
            best_branch: Vec::new(),
            iterations: 0,
            nodes: 1,
        };
    }
    // Under simulated time no wall clock: a fixed number of iterations.
    let (cap, deadline) = if problem.time_source().is_simulated() {
        (Some(params.sim_iterations), None)
    } else {
        let budget = Duration::try_from_secs_f64(params.budget_s.max(0.0)).unwrap_or(Duration::MAX);
        (params.max_iterations, Some((Instant::now(), budget)))
    };
    let max_depth = params.max_depth.max(1);
    let gamma = params.discount.clamp(0.0, 1.0);
    // UCT's exploration term is scaled to the rewards at hand.
    let scale = candidates
        .iter()
        .map(|c| c.reward.abs())
        .fold(0.0, f64::max)
        .max(1e-9);
    let c_uct = params.exploration.max(0.0) * scale;

    let mut tree = vec![Node::new(None, None, 0)];
    tree[0].state = Some(Some(*root));
    for c in candidates {
        let id = tree.len();
        let mut node = Node::new(Some(c.clone()), Some(0), 1);
        node.visits = 1;
        node.total = c.reward;
        node.best = c.reward;
        tree.push(node);
        tree[0].children.push(id);
    }
    tree[0].visits = candidates.len() as u32;

    let mut iterations = 0;
    loop {
        if cap.is_some_and(|cap| iterations >= cap)
            || deadline.is_some_and(|(started, budget)| started.elapsed() >= budget)
        {
            break;
        }
        iterations += 1;
        let selected = select(&tree, c_uct, max_depth);
        let leaf = expand(&mut tree, selected, problem, rng, max_depth);
        backpropagate(&mut tree, leaf, gamma);
    }

    // The first action of the best branch (ties go to the earlier candidate).
    let mut choice = 0;
    for (i, &child) in tree[0].children.iter().enumerate() {
        if tree[child].best > tree[tree[0].children[choice]].best {
            choice = i;
        }
    }
    let first = tree[0].children[choice];
    let best_return = tree[first].best;
    let best_branch = best_branch(&tree, first, gamma);
    SearchOutcome {
        choice: Some(choice),
        best_return: Some(best_return),
        best_branch,
        iterations,
        nodes: tree.len(),
    }
}

/// Selection: descends from the root by UCT while the node is fully expanded, and
/// returns the node to expand.
fn select(tree: &[Node], c_uct: f64, max_depth: usize) -> usize {
    let mut id = 0;
    loop {
        let node = &tree[id];
        let expandable = node.state.is_none() || !node.untried.is_empty();
        if node.depth >= max_depth || expandable || node.children.is_empty() {
            return id;
        }
        let ln_n = f64::from(node.visits.max(1)).ln();
        let mut best_child = node.children[0];
        let mut best_score = f64::NEG_INFINITY;
        for &child in &node.children {
            let ch = &tree[child];
            let n = f64::from(ch.visits.max(1));
            let score = ch.total / n + c_uct * (2.0 * ln_n / n).sqrt();
            if score > best_score {
                best_score = score;
                best_child = child;
            }
        }
        id = best_child;
    }
}

/// Expansion: adds one new feasible, safe child of `id`, if it has any left, and
/// returns it (else `id`).
fn expand(
    tree: &mut Vec<Node>,
    id: usize,
    problem: &PlanningProblem<'_>,
    rng: &mut ChaCha8Rng,
    max_depth: usize,
) -> usize {
    if tree[id].depth >= max_depth {
        return id;
    }
    if tree[id].state.is_none() {
        let next = tree[id]
            .candidate
            .as_ref()
            .and_then(|c| problem.continuation(c));
        let mut untried: Vec<usize> = if next.is_some() {
            (0..problem.actions().len()).collect()
        } else {
            Vec::new()
        };
        untried.shuffle(rng);
        tree[id].untried = untried;
        tree[id].state = Some(next);
    }
    if let Some(Some(from)) = tree[id].state {
        while let Some(action) = tree[id].untried.pop() {
            if let Some(child) = problem.child(&from, action) {
                let child_id = tree.len();
                let depth = tree[id].depth + 1;
                tree.push(Node::new(Some(child), Some(id), depth));
                tree[id].children.push(child_id);
                return child_id;
            }
        }
    }
    id
}

/// Backpropagation of the return accumulated along the branch ending at `id`,
/// discounted by `gamma`.
fn backpropagate(tree: &mut [Node], id: usize, gamma: f64) {
    let mut value = 0.0;
    let mut cursor = Some(id);
    while let Some(n) = cursor {
        let node = &mut tree[n];
        if node.parent.is_some() {
            value = node.reward() + gamma * value;
            node.best = node.best.max(value);
        }
        node.visits += 1;
        node.total += value;
        cursor = node.parent;
    }
}

/// The action indices of the best branch from `first` downwards.
fn best_branch(tree: &[Node], first: usize, gamma: f64) -> Vec<usize> {
    let mut branch = Vec::new();
    let mut id = first;
    loop {
        if let Some(c) = &tree[id].candidate {
            branch.push(c.action_index);
        }
        let Some(&next) = tree[id].children.iter().max_by(|&&a, &&b| {
            tree[a]
                .best
                .partial_cmp(&tree[b].best)
                .unwrap_or(std::cmp::Ordering::Equal)
        }) else {
            return branch;
        };
        // Only follow a child that lies on the best branch.
        let r = tree[id].reward();
        if (r + gamma * tree[next].best - tree[id].best).abs() > 1e-9 * tree[id].best.abs().max(1.0)
        {
            return branch;
        }
        id = next;
    }
}

/// Anytime MCTS selection (thesis §4.1.3) with the round's [`SearchParams`]
/// (`RoundConfig::search`).
#[derive(Clone, Debug, Default)]
pub struct Mcts {
    last: Option<SearchOutcome>,
}

impl Mcts {
    /// The outcome of the last search (for reports and tests).
    #[must_use]
    pub fn last_outcome(&self) -> Option<&SearchOutcome> {
        self.last.as_ref()
    }
}

impl ActionSelection for Mcts {
    /// Without the problem there is no tree to grow: the best single step.
    fn select(&mut self, candidates: &[Candidate], rng: &mut ChaCha8Rng) -> Option<usize> {
        super::Greedy.select(candidates, rng)
    }

    fn select_in(
        &mut self,
        problem: &PlanningProblem<'_>,
        root: &FlatState,
        candidates: &[Candidate],
        rng: &mut ChaCha8Rng,
    ) -> Option<usize> {
        let params = problem.config().search;
        let outcome = search(problem, root, candidates, &params, rng);
        let choice = outcome.choice;
        tracing::debug!(
            iterations = outcome.iterations,
            nodes = outcome.nodes,
            best_return = outcome.best_return,
            branch = ?outcome.best_branch,
            "mcts"
        );
        self.last = Some(outcome);
        choice
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use troupe_algorithms::grid::GridSnapshot;
    use troupe_algorithms::planner::scenes::{self, SceneRound};
    use troupe_core::TimeSource;

    use super::*;

    fn scene() -> GridSnapshot {
        scenes::room_with_doorway(3.5, 1.5, 0.5)
    }

    fn root() -> FlatState {
        FlatState::at_rest(nalgebra::Vector3::zeros(), 0.0)
    }

    /// Replays a branch of library actions from the root: every step must be a
    /// feasible, safe child, and every step but the last must continue safely.
    fn replay(problem: &PlanningProblem<'_>, branch: &[usize], gamma: f64) -> f64 {
        let mut state = root();
        let mut value = 0.0;
        let mut weight = 1.0;
        for (k, &action) in branch.iter().enumerate() {
            let child = problem
                .child(&state, action)
                .unwrap_or_else(|| panic!("step {k}: action {action} is not a safe child"));
            let limits = problem.config().limits;
            let (a, j) = child.primitive.peak_accel_jerk(500);
            assert!(a <= limits.max_accel_mps2 * 1.01 && j <= limits.max_jerk_mps3 * 1.01);
            value += weight * child.reward;
            weight *= gamma;
            if k + 1 < branch.len() {
                state = problem
                    .continuation(&child)
                    .unwrap_or_else(|| panic!("step {k}: the branch cannot continue"));
            }
        }
        value
    }

    #[test]
    fn returns_a_valid_plan_at_budgets_from_10_ms_to_1_s() {
        let round = SceneRound::new(scene());
        let problem = round.problem();
        let candidates = problem.children(&root());
        assert!(candidates.len() > 5, "{} candidates", candidates.len());
        for budget_s in [0.01, 0.03, 0.1, 0.3, 1.0] {
            let params = SearchParams {
                budget_s,
                max_iterations: None,
                ..SearchParams::default()
            };
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            let outcome = search(&problem, &root(), &candidates, &params, &mut rng);
            let choice = outcome.choice.expect("a plan");
            let chosen = &candidates[choice];
            assert_eq!(outcome.best_branch.first(), Some(&chosen.action_index));
            assert!(
                round
                    .config
                    .safe_with_stop(&chosen.primitive, &round.snapshot)
                    .is_some()
            );
            let replayed = replay(&problem, &outcome.best_branch, params.discount);
            let best = outcome.best_return.expect("a return");
            assert!(
                (replayed - best).abs() <= 1e-9 * best.abs().max(1.0),
                "budget {budget_s}: replayed {replayed} vs reported {best}"
            );
            assert!(best >= chosen.reward - 1e-12);
        }
    }

    #[test]
    fn more_iterations_never_give_a_worse_best_return() {
        let round = SceneRound::new(scene());
        let problem = round.problem();
        let candidates = problem.children(&root());
        let greedy = candidates.iter().map(|c| c.reward).fold(f64::MIN, f64::max);
        let mut previous = f64::NEG_INFINITY;
        let mut outcomes = Vec::new();
        for cap in [0, 1, 4, 16, 64, 256] {
            let params = SearchParams {
                budget_s: 600.0,
                max_iterations: Some(cap),
                ..SearchParams::default()
            };
            let mut rng = ChaCha8Rng::seed_from_u64(3);
            let outcome = search(&problem, &root(), &candidates, &params, &mut rng);
            let best = outcome.best_return.expect("a return");
            assert_eq!(outcome.iterations, cap);
            assert!(best >= previous, "cap {cap}: {best} < {previous}");
            assert!(best >= greedy - 1e-12);
            previous = best;
            outcomes.push(outcome);
        }
        // Without iterations the search is the single best step; with them it looks
        // deeper and finds longer branches worth more.
        assert_eq!(outcomes[0].best_branch.len(), 1);
        assert!((outcomes[0].best_return.unwrap_or(0.0) - greedy).abs() < 1e-12);
        let last = outcomes.last().expect("outcomes");
        assert!(last.best_branch.len() > 1 && last.best_return > outcomes[0].best_return);
        // Same seed, same cap: the same search.
        let params = SearchParams {
            budget_s: 600.0,
            max_iterations: Some(64),
            ..SearchParams::default()
        };
        let again = search(
            &problem,
            &root(),
            &candidates,
            &params,
            &mut ChaCha8Rng::seed_from_u64(3),
        );
        assert_eq!(&again, &outcomes[4]);
    }

    #[test]
    fn under_simulated_time_a_search_runs_its_iterations_whatever_the_wall_clock() {
        let round = SceneRound::new(scene());
        let wall = round.problem();
        let simulated = round.problem().under(TimeSource::Simulated);
        let candidates = wall.children(&root());
        // No wall-clock budget at all: under the wall clock nothing is searched;
        // under simulated time the budget is not read and the iterations run.
        let params = SearchParams {
            budget_s: 0.0,
            max_iterations: None,
            sim_iterations: 64,
            ..SearchParams::default()
        };
        let seeded = || ChaCha8Rng::seed_from_u64(5);
        let outcome = search(&simulated, &root(), &candidates, &params, &mut seeded());
        assert_eq!(outcome.iterations, 64);
        assert_eq!(
            search(&wall, &root(), &candidates, &params, &mut seeded()).iterations,
            0
        );
        // The same search as the wall clock's capped at 64 with time to spare, and the
        // same again.
        let capped = SearchParams {
            budget_s: 600.0,
            max_iterations: Some(64),
            sim_iterations: 0,
            ..SearchParams::default()
        };
        assert_eq!(
            search(&wall, &root(), &candidates, &capped, &mut seeded()),
            outcome
        );
        assert_eq!(
            search(&simulated, &root(), &candidates, &params, &mut seeded()),
            outcome
        );
    }

    #[test]
    fn a_complete_tree_finds_the_exhaustive_optimum() {
        let round = SceneRound::new(scene());
        let problem = round.problem();
        let candidates = problem.children(&root());
        let gamma = 0.8;
        // Slow reference: every depth-2 branch.
        let mut optimum = f64::NEG_INFINITY;
        let mut tree_size = 1 + candidates.len();
        for c in &candidates {
            let mut value = c.reward;
            if let Some(next) = problem.continuation(c) {
                let children = problem.children(&next);
                tree_size += children.len();
                for d in &children {
                    value = value.max(c.reward + gamma * d.reward);
                }
            }
            optimum = optimum.max(value);
        }
        let params = SearchParams {
            budget_s: 600.0,
            max_iterations: Some(20 * tree_size),
            sim_iterations: 0,
            max_depth: 2,
            discount: gamma,
            // Broad exploration, so that the capped search completes the tree.
            exploration: 20.0,
        };
        let outcome = search(
            &problem,
            &root(),
            &candidates,
            &params,
            &mut ChaCha8Rng::seed_from_u64(11),
        );
        assert_eq!(outcome.nodes, tree_size, "the tree is complete");
        let best = outcome.best_return.expect("a return");
        assert!((best - optimum).abs() < 1e-9, "{best} vs {optimum}");
    }

    #[test]
    fn nothing_feasible_means_stop() {
        let round = SceneRound::new(scene());
        let problem = round.problem();
        let mut mcts = Mcts::default();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        assert_eq!(mcts.select_in(&problem, &root(), &[], &mut rng), None);
        // Deep inside unknown space nothing is safe.
        let lost = FlatState::at_rest(nalgebra::Vector3::new(8.0, 8.0, 0.0), 0.0);
        assert!(problem.children(&lost).is_empty());
    }
}
