//! Number of components from Gaussian blurring mean shift with a flat kernel on the 2D
//! (depth, intensity) pixel data (thesis §6.1.2–6.1.3, Eqs. 6.5–6.7).
//!
//! Each iteration moves every point to the mean of the current points within distance σ
//! (blurring update, Eq. 6.6, with the flat kernel of Eq. 6.7). A uniform grid of cell
//! side σ makes each point visit only the 3×3 cells around it. Points that become
//! bit-identical are merged into one weighted point, which leaves the blurring update
//! unchanged (identical points receive identical updates) and shrinks the work as the
//! data collapses onto its modes.
//!
//! Convergence rule: stop when no point moved more than `tolerance · σ` in an iteration
//! or after `max_iterations`. Mode merging: the surviving points are visited by
//! decreasing weight (ties by coordinates) and a point becomes a new mode unless a mode
//! already kept lies within σ, in which case its weight joins that mode. `M` is the
//! number of modes.

/// Settings of [`mean_shift_modes`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeanShiftConfig {
    /// Stop when the largest displacement of an iteration is at most `tolerance · σ`.
    pub tolerance: f64,
    /// Iteration cap `T`.
    pub max_iterations: usize,
}

impl Default for MeanShiftConfig {
    /// `tolerance = 1e-3`, `max_iterations = 100`.
    fn default() -> Self {
        Self {
            tolerance: 1e-3,
            max_iterations: 100,
        }
    }
}

/// Output of [`mean_shift_modes`].
#[derive(Clone, Debug, PartialEq)]
pub struct MeanShiftModes {
    /// Modes `(depth, intensity)`, by decreasing support.
    pub modes: Vec<[f64; 2]>,
    /// Number of input points absorbed by each mode.
    pub support: Vec<usize>,
    /// Blurring iterations run.
    pub iterations: usize,
    /// Whether the displacement rule stopped the loop (false: iteration cap).
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
}

/// Sorted-cell index over 2D points (cell side `h`), with a direct table from the first
/// cell coordinate to its run of slots.
struct CellIndex2 {
    /// Cell key of each slot of `order`, sorted.
    keys: Vec<(i64, i64)>,
    /// Point indices sorted by cell key (stable: by index inside a cell).
    order: Vec<u32>,
    /// Smallest first key coordinate.
    kx0: i64,
    /// `col_start[kx − kx0] .. col_start[kx − kx0 + 1]`: the slots with that first key.
    col_start: Vec<u32>,
}

impl CellIndex2 {
    fn new(points: &[[f64; 2]], inv_h: f64) -> Self {
        let key = |p: &[f64; 2]| ((p[0] * inv_h).floor() as i64, (p[1] * inv_h).floor() as i64);
        let mut order: Vec<u32> = (0..points.len() as u32).collect();
        order.sort_by_key(|&i| key(&points[i as usize]));
        let keys: Vec<(i64, i64)> = order.iter().map(|&i| key(&points[i as usize])).collect();
        let kx0 = keys.first().map_or(0, |k| k.0);
        let kx1 = keys.last().map_or(0, |k| k.0);
        let span = usize::try_from(kx1 - kx0).unwrap_or(0) + 1;
        let mut col_start = vec![0u32; span + 1];
        for k in &keys {
            col_start[(k.0 - kx0) as usize + 1] += 1;
        }
        for c in 0..span {
            col_start[c + 1] += col_start[c];
        }
        Self {
            keys,
            order,
            kx0,
            col_start,
        }
    }

    /// Slots of the cells `(kx, ky − 1 ..= ky + 1)`.
    fn column(&self, kx: i64, ky: i64) -> std::ops::Range<usize> {
        let c = kx - self.kx0;
        if c < 0 || c as usize + 1 >= self.col_start.len() {
            return 0..0;
        }
        let (a, b) = (
            self.col_start[c as usize] as usize,
            self.col_start[c as usize + 1] as usize,
        );
        let run = &self.keys[a..b];
        let lo = run.partition_point(|k| k.1 < ky - 1);
        let hi = run.partition_point(|k| k.1 <= ky + 1);
        a + lo..a + hi
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

/// Gaussian blurring mean shift with the flat kernel of bandwidth `sigma` (Eqs. 6.6–6.7)
/// on `(depth, intensity)` points, followed by mode merging; see the module doc for the
/// convergence and merging rules. Non-finite points are ignored. Deterministic.
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
    let n_finite = finite.len();
    let (mut pts, mut w) = compact(finite, vec![1.0; n_finite]);
    if pts.is_empty() {
        return MeanShiftModes {
            modes: vec![],
            support: vec![],
            iterations: 0,
            converged: true,
        };
    }
    if !sigma.is_finite() || sigma <= 0.0 {
        let support = w.iter().map(|v| *v as usize).collect();
        return MeanShiftModes {
            modes: pts,
            support,
            iterations: 0,
            converged: true,
        };
    }
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
            for dx in -1..=1 {
                for s in index.column(kx + dx, ky) {
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
    merge_modes(&pts, &w, sigma, iterations, converged)
}

fn merge_modes(
    pts: &[[f64; 2]],
    w: &[f64],
    sigma: f64,
    iterations: usize,
    converged: bool,
) -> MeanShiftModes {
    let mut idx: Vec<usize> = (0..pts.len()).collect();
    idx.sort_by(|&a, &b| {
        w[b].total_cmp(&w[a])
            .then(pts[a][0].total_cmp(&pts[b][0]))
            .then(pts[a][1].total_cmp(&pts[b][1]))
    });
    let inv_h = 1.0 / sigma;
    let key = |p: &[f64; 2]| ((p[0] * inv_h).floor() as i64, (p[1] * inv_h).floor() as i64);
    let mut cells: std::collections::HashMap<(i64, i64), Vec<usize>> =
        std::collections::HashMap::new();
    let mut modes: Vec<[f64; 2]> = Vec::new();
    let mut support: Vec<f64> = Vec::new();
    let s2 = sigma * sigma;
    for i in idx {
        let p = pts[i];
        let (kx, ky) = key(&p);
        // Nearest kept mode within σ (lowest index on ties: deterministic).
        let mut best: Option<(f64, usize)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                if let Some(list) = cells.get(&(kx + dx, ky + dy)) {
                    for &m in list {
                        let q = modes[m];
                        let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                        if d2 <= s2 && best.is_none_or(|(bd, bm)| d2 < bd || (d2 == bd && m < bm)) {
                            best = Some((d2, m));
                        }
                    }
                }
            }
        }
        match best {
            Some((_, m)) => support[m] += w[i],
            None => {
                cells.entry((kx, ky)).or_default().push(modes.len());
                modes.push(p);
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
