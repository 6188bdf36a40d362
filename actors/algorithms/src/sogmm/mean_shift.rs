//! Number of components `M` from a flat-kernel mean shift of bandwidth σ on the 2D
//! (depth, intensity) pixel data (thesis §6.1.2–6.1.3, Eqs. 6.5–6.7), in two variants
//! ([`MeanShiftKind`]):
//!
//! **Reference** (the default): the non-blurring mean shift of the authors' published
//! implementation (gira3d/self_organizing_gmm), which is scikit-learn's
//! `MeanShift(bandwidth=σ, bin_seeding=True)`. Seeds are the occupied bins of a σ grid
//! (each point rounded to the nearest multiple of σ, ties to even, as `np.round`; the
//! points themselves when every point has its own bin, or when no bin centre has a
//! point within σ, where scikit-learn fails). Each seed moves to the mean of
//! the *input* points within distance σ (`≤ σ`, Eq. 6.6 with the flat kernel of Eq. 6.7,
//! the data held fixed) until it moves by at most `tolerance · σ` or after
//! `max_iterations` moves (default 300); its support is the number of points within σ
//! of its last position. Modes are then visited by decreasing support (ties: by
//! decreasing coordinates) and kept unless a kept mode lies within σ. A uniform grid of
//! cell side σ over the input makes each step visit only the 3×3 cells around the
//! seed, and seeds run in parallel (rayon) with the result independent of the thread
//! count.
//!
//! **Blurring**: the thesis' Gaussian blurring mean shift. Each iteration moves every
//! point to the mean of the current points within distance σ (blurring update). Points
//! that become bit-identical are merged into one weighted point, which leaves the
//! update unchanged (identical points receive identical updates) and shrinks the work
//! as the data collapses onto its modes. Stop when no point moved more than
//! `tolerance · σ` in an iteration or after `max_iterations` (default 100). The
//! surviving points are visited by decreasing weight (ties by coordinates) and a point
//! becomes a new mode unless a mode already kept lies within σ, in which case its
//! weight joins the nearest such mode. It finds fewer modes than the reference (61–84 %
//! of them on the frames of `scripts/sogmm_meanshift_vs_sklearn.py`), i.e. coarser maps.
//!
//! `M` is the number of modes in both variants.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use troupe_core::ConfigError;

/// Which mean shift chooses `M` (`"reference"` or `"blurring"` in TOML and on the
/// command line); see the module doc.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum MeanShiftKind {
    /// Non-blurring mean shift from bin seeds, as the published implementation and
    /// scikit-learn's `MeanShift(bin_seeding=True)`.
    #[default]
    Reference,
    /// The thesis text's blurring mean shift (coarser: fewer modes).
    Blurring,
}

impl MeanShiftKind {
    /// The name used in config files and on the command line.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            MeanShiftKind::Reference => "reference",
            MeanShiftKind::Blurring => "blurring",
        }
    }
}

impl std::fmt::Display for MeanShiftKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for MeanShiftKind {
    type Err = ConfigError;

    /// `"reference"` or `"blurring"`; anything else is a [`ConfigError`] on `mean_shift`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "reference" => Ok(MeanShiftKind::Reference),
            "blurring" => Ok(MeanShiftKind::Blurring),
            other => Err(ConfigError::new(
                "mean_shift",
                "must be \"reference\" or \"blurring\"",
                format!("{other:?}"),
            )),
        }
    }
}

impl TryFrom<String> for MeanShiftKind {
    type Error = ConfigError;

    fn try_from(s: String) -> Result<Self, Self::Error> {
        s.parse()
    }
}

impl From<MeanShiftKind> for String {
    fn from(kind: MeanShiftKind) -> Self {
        kind.name().to_string()
    }
}

/// Settings of [`mean_shift_modes`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeanShiftConfig {
    /// The variant.
    pub kind: MeanShiftKind,
    /// Stop when a displacement (reference: of the seed; blurring: the largest of the
    /// iteration) is at most `tolerance · σ`.
    pub tolerance: f64,
    /// Iteration cap `T`.
    pub max_iterations: usize,
}

impl MeanShiftConfig {
    /// The settings of `kind`: `tolerance = 1e-3` and `max_iterations` 300 for the
    /// reference (the published implementation's), 100 for the blurring variant.
    #[must_use]
    pub fn of(kind: MeanShiftKind) -> Self {
        Self {
            kind,
            tolerance: 1e-3,
            max_iterations: match kind {
                MeanShiftKind::Reference => 300,
                MeanShiftKind::Blurring => 100,
            },
        }
    }
}

impl Default for MeanShiftConfig {
    /// The reference mean shift: `tolerance = 1e-3`, `max_iterations = 300`.
    fn default() -> Self {
        Self::of(MeanShiftKind::Reference)
    }
}

/// Output of [`mean_shift_modes`].
#[derive(Clone, Debug, PartialEq)]
pub struct MeanShiftModes {
    /// Modes `(depth, intensity)`, by decreasing support.
    pub modes: Vec<[f64; 2]>,
    /// Support of each mode: reference, the input points within σ of it; blurring, the
    /// input points absorbed by it.
    pub support: Vec<usize>,
    /// Iterations run (reference: the most any seed ran).
    pub iterations: usize,
    /// Whether the displacement rule stopped the loop (false: iteration cap; reference:
    /// for every seed).
    pub converged: bool,
}

impl MeanShiftModes {
    /// Number of modes, the `M` of the SOGMM fit (§6.1.3).
    #[must_use]
    pub fn len(&self) -> usize {
        self.modes.len()
    }

    /// True when there were no input points.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.modes.is_empty()
    }

    fn empty() -> Self {
        MeanShiftModes {
            modes: vec![],
            support: vec![],
            iterations: 0,
            converged: true,
        }
    }
}

/// Sorted-cell index over 2D points (cell side `h`), with the occupied first cell
/// coordinates and the run of slots of each (no table over the whole range, so far-apart
/// or huge finite values cost nothing).
struct CellIndex2 {
    /// Cell key of each slot of `order`, sorted.
    keys: Vec<(i64, i64)>,
    /// Point indices sorted by cell key (stable: by index inside a cell).
    order: Vec<u32>,
    /// Distinct first key coordinates, increasing.
    columns: Vec<i64>,
    /// `col_start[c] .. col_start[c + 1]`: the slots whose first key is `columns[c]`.
    col_start: Vec<u32>,
}

impl CellIndex2 {
    fn new(points: &[[f64; 2]], inv_h: f64) -> Self {
        // `as` saturates: huge or infinite coordinates land in the extreme cells.
        let key = |p: &[f64; 2]| ((p[0] * inv_h).floor() as i64, (p[1] * inv_h).floor() as i64);
        let mut order: Vec<u32> = (0..points.len() as u32).collect();
        order.sort_by_key(|&i| key(&points[i as usize]));
        let keys: Vec<(i64, i64)> = order.iter().map(|&i| key(&points[i as usize])).collect();
        let mut columns = Vec::new();
        let mut col_start = Vec::new();
        for (slot, k) in keys.iter().enumerate() {
            if columns.last() != Some(&k.0) {
                columns.push(k.0);
                col_start.push(slot as u32);
            }
        }
        col_start.push(keys.len() as u32);
        Self {
            keys,
            order,
            columns,
            col_start,
        }
    }

    /// Slots of the cells `(kx, ky − 1 ..= ky + 1)`.
    fn column(&self, kx: i64, ky: i64) -> std::ops::Range<usize> {
        let Ok(c) = self.columns.binary_search(&kx) else {
            return 0..0;
        };
        let (a, b) = (self.col_start[c] as usize, self.col_start[c + 1] as usize);
        let run = &self.keys[a..b];
        let lo = run.partition_point(|k| k.1 < ky.saturating_sub(1));
        let hi = run.partition_point(|k| k.1 <= ky.saturating_add(1));
        a + lo..a + hi
    }

    /// Slots of the 3×3 cells around `(kx, ky)`, column by column.
    fn around(&self, kx: i64, ky: i64) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
        [kx.checked_sub(1), Some(kx), kx.checked_add(1)]
            .into_iter()
            .flatten()
            .map(move |x| self.column(x, ky))
    }
}

/// Merge bit-identical points, adding their weights; output sorted by coordinates.
fn compact(points: Vec<[f64; 2]>, weights: Vec<f64>) -> (Vec<[f64; 2]>, Vec<f64>) {
    let mut idx: Vec<usize> = (0..points.len()).collect();
    idx.sort_by(|&a, &b| {
        points[a][0]
            .total_cmp(&points[b][0])
            .then(points[a][1].total_cmp(&points[b][1]))
    });
    let mut out_p: Vec<[f64; 2]> = Vec::with_capacity(points.len());
    let mut out_w: Vec<f64> = Vec::with_capacity(points.len());
    for i in idx {
        match out_p.last() {
            Some(last)
                if last[0].to_bits() == points[i][0].to_bits()
                    && last[1].to_bits() == points[i][1].to_bits() =>
            {
                if let Some(w) = out_w.last_mut() {
                    *w += weights[i];
                }
            }
            _ => {
                out_p.push(points[i]);
                out_w.push(weights[i]);
            }
        }
    }
    (out_p, out_w)
}

/// `M` and the modes of the 2D `(depth, intensity)` points for bandwidth `sigma`, by the
/// variant `config.kind` (see the module doc for both). Non-finite points are ignored.
/// Deterministic, and independent of the rayon thread count.
///
/// # Panics
/// Never; a non-positive or non-finite `sigma` yields one mode per distinct point.
#[must_use]
pub fn mean_shift_modes(data: &[[f64; 2]], sigma: f64, config: &MeanShiftConfig) -> MeanShiftModes {
    let finite: Vec<[f64; 2]> = data
        .iter()
        .copied()
        .filter(|p| p[0].is_finite() && p[1].is_finite())
        .collect();
    if finite.is_empty() {
        return MeanShiftModes::empty();
    }
    if !sigma.is_finite() || sigma <= 0.0 {
        let n = finite.len();
        let (modes, w) = compact(finite, vec![1.0; n]);
        return MeanShiftModes {
            modes,
            support: w.iter().map(|v| *v as usize).collect(),
            iterations: 0,
            converged: true,
        };
    }
    match config.kind {
        MeanShiftKind::Reference => reference_modes(&finite, sigma, config),
        MeanShiftKind::Blurring => blurring_modes(finite, sigma, config),
    }
}

/// Seeds of the reference variant: the occupied bins of the σ grid (nearest multiple,
/// ties to even), in order of first occurrence, scaled back by σ; the points themselves
/// when there are as many bins as points.
fn bin_seeds(points: &[[f64; 2]], sigma: f64) -> Vec<[f64; 2]> {
    let mut seen = std::collections::HashSet::with_capacity(points.len());
    let mut bins: Vec<[f64; 2]> = Vec::new();
    for p in points {
        let b = [
            (p[0] / sigma).round_ties_even(),
            (p[1] / sigma).round_ties_even(),
        ];
        if seen.insert((b[0].to_bits(), b[1].to_bits())) {
            bins.push(b);
        }
    }
    if bins.len() == points.len() {
        return points.to_vec();
    }
    bins.iter().map(|b| [b[0] * sigma, b[1] * sigma]).collect()
}

/// One seed of the reference variant: `(mode, support, moves, converged)`.
fn shift_seed(
    seed: [f64; 2],
    pts: &[[f64; 2]],
    index: &CellIndex2,
    sigma: f64,
    config: &MeanShiftConfig,
) -> ([f64; 2], usize, usize, bool) {
    let inv_h = 1.0 / sigma;
    let s2 = sigma * sigma;
    let stop = config.tolerance * sigma;
    let mut mean = seed;
    let mut moves = 0;
    loop {
        let (kx, ky) = (
            (mean[0] * inv_h).floor() as i64,
            (mean[1] * inv_h).floor() as i64,
        );
        let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
        for run in index.around(kx, ky) {
            for q in &pts[run] {
                let (ex, ey) = (q[0] - mean[0], q[1] - mean[1]);
                if ex * ex + ey * ey <= s2 {
                    sx += q[0];
                    sy += q[1];
                    n += 1;
                }
            }
        }
        if n == 0 {
            return (mean, 0, moves, true);
        }
        let old = mean;
        mean = [sx / n as f64, sy / n as f64];
        let shift = ((mean[0] - old[0]).powi(2) + (mean[1] - old[1]).powi(2)).sqrt();
        if shift <= stop {
            return (mean, n, moves, true);
        }
        if moves == config.max_iterations {
            return (mean, n, moves, false);
        }
        moves += 1;
    }
}

fn reference_modes(points: &[[f64; 2]], sigma: f64, config: &MeanShiftConfig) -> MeanShiftModes {
    let index = CellIndex2::new(points, 1.0 / sigma);
    // The points in slot order, so that a cell's run is contiguous in memory.
    let sorted: Vec<[f64; 2]> = index.order.iter().map(|&i| points[i as usize]).collect();
    let shift_all = |seeds: &[[f64; 2]]| -> Vec<([f64; 2], usize, usize, bool)> {
        seeds
            .par_iter()
            .map(|&s| shift_seed(s, &sorted, &index, sigma, config))
            .collect()
    };
    let mut shifted = shift_all(&bin_seeds(points, sigma));
    if shifted.iter().all(|r| r.1 == 0) {
        // No bin seed has a point within σ (σ below the rounding of the bin centres):
        // seed from the points themselves, each its own neighbour.
        shifted = shift_all(points);
    }
    let iterations = shifted.iter().map(|r| r.2).max().unwrap_or(0);
    let converged = shifted.iter().all(|r| r.3);
    let mut candidates: Vec<([f64; 2], usize)> = shifted
        .into_iter()
        .filter(|r| r.1 > 0)
        .map(|r| (r.0, r.1))
        .collect();
    candidates.sort_by(|a, b| {
        b.1.cmp(&a.1)
            .then(b.0[0].total_cmp(&a.0[0]))
            .then(b.0[1].total_cmp(&a.0[1]))
    });
    let points_in_order: Vec<[f64; 2]> = candidates.iter().map(|c| c.0).collect();
    let mut modes = Vec::new();
    let mut support = Vec::new();
    for (c, joined) in candidates.iter().zip(greedy_merge(&points_in_order, sigma)) {
        if joined.is_none() {
            modes.push(c.0);
            support.push(c.1);
        }
    }
    MeanShiftModes {
        modes,
        support,
        iterations,
        converged,
    }
}

fn blurring_modes(finite: Vec<[f64; 2]>, sigma: f64, config: &MeanShiftConfig) -> MeanShiftModes {
    let n_finite = finite.len();
    let (mut pts, mut w) = compact(finite, vec![1.0; n_finite]);
    let inv_h = 1.0 / sigma;
    let s2 = sigma * sigma;
    let mut iterations = 0;
    let mut converged = false;
    while iterations < config.max_iterations {
        iterations += 1;
        let index = CellIndex2::new(&pts, inv_h);
        let mut next = vec![[0.0; 2]; pts.len()];
        let mut max_shift2: f64 = 0.0;
        for (slot, &i) in index.order.iter().enumerate() {
            let p = pts[i as usize];
            let (kx, ky) = index.keys[slot];
            let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
            for run in index.around(kx, ky) {
                for s in run {
                    let j = index.order[s] as usize;
                    let q = pts[j];
                    let (ex, ey) = (q[0] - p[0], q[1] - p[1]);
                    if ex * ex + ey * ey <= s2 {
                        sx += w[j] * q[0];
                        sy += w[j] * q[1];
                        sw += w[j];
                    }
                }
            }
            // sw ≥ w[i] > 0: the point is its own neighbour.
            let np = [sx / sw, sy / sw];
            let (ex, ey) = (np[0] - p[0], np[1] - p[1]);
            max_shift2 = max_shift2.max(ex * ex + ey * ey);
            next[i as usize] = np;
        }
        (pts, w) = compact(next, w);
        if max_shift2.sqrt() <= config.tolerance * sigma {
            converged = true;
            break;
        }
    }
    let mut idx: Vec<usize> = (0..pts.len()).collect();
    idx.sort_by(|&a, &b| {
        w[b].total_cmp(&w[a])
            .then(pts[a][0].total_cmp(&pts[b][0]))
            .then(pts[a][1].total_cmp(&pts[b][1]))
    });
    let ordered: Vec<[f64; 2]> = idx.iter().map(|&i| pts[i]).collect();
    let mut modes: Vec<[f64; 2]> = Vec::new();
    let mut support: Vec<f64> = Vec::new();
    for (&i, joined) in idx.iter().zip(greedy_merge(&ordered, sigma)) {
        match joined {
            Some(m) => support[m] += w[i],
            None => {
                modes.push(pts[i]);
                support.push(w[i]);
            }
        }
    }
    MeanShiftModes {
        modes,
        support: support.iter().map(|s| s.round() as usize).collect(),
        iterations,
        converged,
    }
}

/// Greedy merging of candidate modes visited in the given order: each one becomes a new
/// mode (`None`) unless a mode kept before it lies within σ, then `Some` of the nearest
/// such mode's index among the kept ones (lowest index on ties).
fn greedy_merge(candidates: &[[f64; 2]], sigma: f64) -> Vec<Option<usize>> {
    let inv_h = 1.0 / sigma;
    let key = |p: &[f64; 2]| ((p[0] * inv_h).floor() as i64, (p[1] * inv_h).floor() as i64);
    let mut cells: std::collections::HashMap<(i64, i64), Vec<usize>> =
        std::collections::HashMap::new();
    let mut kept: Vec<[f64; 2]> = Vec::new();
    let s2 = sigma * sigma;
    candidates
        .iter()
        .map(|p| {
            let (kx, ky) = key(p);
            let mut best: Option<(f64, usize)> = None;
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for &m in cells
                        .get(&(kx.saturating_add(dx), ky.saturating_add(dy)))
                        .into_iter()
                        .flatten()
                    {
                        let q = kept[m];
                        let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                        if d2 <= s2 && best.is_none_or(|(bd, bm)| d2 < bd || (d2 == bd && m < bm)) {
                            best = Some((d2, m));
                        }
                    }
                }
            }
            if best.is_none() {
                cells.entry((kx, ky)).or_default().push(kept.len());
                kept.push(*p);
            }
            best.map(|(_, m)| m)
        })
        .collect()
}
