//! k-means++ seeding, steps 1a–1c of Arthur & Vassilvitskii as used by the thesis'
//! KInit (§6.1, Fig. 6.1): (1a) the first centre is a point drawn uniformly; (1b) each
//! next centre is a point drawn with probability `D(x)² / Σ D²`, `D(x)` the Euclidean
//! distance to the nearest centre chosen so far; (1c) repeat (1b) until `M` centres.
//! The nearest centre of every point, tracked along the way, is the hard partition the
//! EM starts from. No Lloyd iterations follow (the thesis stops after step 1c).

use nalgebra::Vector4;
use rand::Rng;

/// Result of [`kmeans_plusplus`].
#[derive(Clone, Debug, PartialEq)]
pub struct Seeding {
    /// Indices of the chosen centres in the input, in the order chosen.
    pub centres: Vec<usize>,
    /// For every point, the index (into `centres`) of its nearest centre.
    pub assignment: Vec<u32>,
}

#[inline(always)]
fn dist2(a: &Vector4<f64>, b: &Vector4<f64>) -> f64 {
    let d = a - b;
    d.dot(&d)
}

/// Steps 1a–1c on 4D points for `m` centres (see the module doc), deterministic for a
/// given `rng` state. Returns fewer than `m` centres only when the points have fewer
/// than `m` distinct values (every `D(x)` is then 0). Empty input or `m == 0` gives an
/// empty seeding.
///
/// Points are kept in clusters by nearest centre, with each cluster's largest `D` and its
/// `Σ D²`. A new centre `c` cannot be nearer than `D(x)` to any point of cluster `j` if
/// `|c − c_j| ≥ 2 max_{x∈j} D(x)` (triangle inequality), so such clusters are skipped;
/// step 1b draws a cluster by its `Σ D²`, then a point inside it by `D²`, which is the
/// same distribution as drawing over all points.
pub fn kmeans_plusplus<R: Rng + ?Sized>(points: &[Vector4<f64>], m: usize, rng: &mut R) -> Seeding {
    let n = points.len();
    if n == 0 || m == 0 {
        return Seeding {
            centres: vec![],
            assignment: vec![0; n],
        };
    }
    // (1a)
    let first = rng.random_range(0..n);
    let mut centres = vec![first];
    let c0 = points[first];
    let mut d2: Vec<f64> = points.iter().map(|p| dist2(p, &c0)).collect();
    let mut assignment = vec![0u32; n];
    let mut members: Vec<Vec<u32>> = vec![(0..n as u32).collect()];
    let summarise = |list: &[u32], d2: &[f64]| {
        list.iter().fold((0.0f64, 0.0f64), |(r, s), &i| {
            (r.max(d2[i as usize]), s + d2[i as usize])
        })
    };
    let (r0, s0) = summarise(&members[0], &d2);
    let mut radius2 = vec![r0];
    let mut sum = vec![s0];
    // (1b)–(1c)
    while centres.len() < m {
        let total: f64 = sum.iter().sum();
        if total.is_nan() || total <= 0.0 {
            break;
        }
        let Some(pick) = draw(&members, &sum, &d2, rng.random::<f64>() * total) else {
            break;
        };
        let k = centres.len() as u32;
        let c = points[pick];
        let mut moved: Vec<u32> = Vec::new();
        for j in 0..members.len() {
            if dist2(&c, &points[centres[j]]) >= 4.0 * radius2[j] {
                continue;
            }
            let before = moved.len();
            members[j].retain(|&i| {
                let e = dist2(&points[i as usize], &c);
                if e < d2[i as usize] {
                    d2[i as usize] = e;
                    assignment[i as usize] = k;
                    moved.push(i);
                    false
                } else {
                    true
                }
            });
            if moved.len() != before {
                (radius2[j], sum[j]) = summarise(&members[j], &d2);
            }
        }
        centres.push(pick);
        let (r, s) = summarise(&moved, &d2);
        members.push(moved);
        radius2.push(r);
        sum.push(s);
    }
    Seeding {
        centres,
        assignment,
    }
}

/// The point where the running sum of `D²` (clusters in order, members in order) first
/// exceeds `target`; rounding at the end falls back to the last point with `D > 0`.
fn draw(members: &[Vec<u32>], sum: &[f64], d2: &[f64], target: f64) -> Option<usize> {
    let mut acc = 0.0;
    let mut last_positive = None;
    for (list, s) in members.iter().zip(sum) {
        if acc + s <= target {
            acc += s;
            if *s > 0.0 {
                last_positive = list
                    .iter()
                    .rev()
                    .find(|&&i| d2[i as usize] > 0.0)
                    .map(|&i| i as usize);
            }
            continue;
        }
        for &i in list {
            let d = d2[i as usize];
            acc += d;
            if d > 0.0 {
                last_positive = Some(i as usize);
                if acc > target {
                    return last_positive;
                }
            }
        }
    }
    last_positive
}
