//! The study's figures beyond mean coverage, as thesis Fig. 8.9 draws them (§8.2.7):
//! cumulative map data sent and received per robot, median and interquartile band over
//! seeds, one panel per combination of levels ((a)–(f)); the median time to each
//! coverage level with a bootstrap interval ((g)); and, when the study names a
//! [`RatioSpec`], the ratio of two levels' median times to each coverage level with a
//! paired bootstrap interval over seeds, beside what the thesis says of it.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use rand::{Rng as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use toml::Table;

use super::{RunRow, Study, groups};
use crate::plot::{Chart, Series};

/// Resamples behind every bootstrap interval.
pub const BOOTSTRAP_RESAMPLES: usize = 2000;
/// Seed of the bootstrap's resampling: the same rows give the same intervals.
const BOOTSTRAP_SEED: u64 = 0x8_2_7;

/// Map data of one robot over a run, cumulative, of the keyframe class (GMM keyframes
/// or occupancy-grid change sets): what it offered to the link — the thesis' "sent",
/// which its token bucket then passed or dropped — and what reached it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RobotMapData {
    /// Robot index.
    pub robot: usize,
    /// `[time_s, offered_bytes, received_bytes]` per sample period.
    pub offered_received: Vec<[f64; 3]>,
}

/// A ratio the study reports: of the median times to each coverage level at
/// `numerator` over those at `denominator`, two levels of `axis`, for every combination
/// of the other axes (`[ratio]` in the study file).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RatioSpec {
    /// The axis whose two levels are compared.
    pub axis: String,
    /// The level whose times are divided…
    pub numerator: String,
    /// …by this level's.
    pub denominator: String,
    /// What the source says of the ratio, per combination and coverage level.
    #[serde(default)]
    pub thesis: Vec<Claim>,
}

/// What a source says of one ratio (`[[ratio.thesis]]`).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Claim {
    /// Levels of other axes the claim is about (`{ rate = "0.25Mbps" }`); axes not
    /// named: any level.
    #[serde(default)]
    pub at: Table,
    /// The coverage level, a fraction of `coverage_levels`.
    pub level: f64,
    /// The claim, as a short phrase with its section.
    pub says: String,
}

/// The `q` quantile of sorted `values` (nearest rank); `None` when empty.
fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    let last = sorted.len().checked_sub(1)?;
    Some(sorted[((q * last as f64).round() as usize).min(last)])
}

/// The median of times where a run that never reached the level counts as never
/// (`None` then sorts last): `None` when at least half the runs never reached it.
fn median_time(times: &[Option<f64>]) -> Option<f64> {
    let mut t: Vec<f64> = times.iter().map(|t| t.unwrap_or(f64::INFINITY)).collect();
    t.sort_by(f64::total_cmp);
    quantile(&t, 0.5).filter(|m| m.is_finite())
}

/// The 2.5 % and 97.5 % quantiles of `statistic` over `BOOTSTRAP_RESAMPLES` resamples
/// of `n` indices with replacement; resamples where the statistic is undefined are
/// left out (the interval is then over the rest; `None` when all are).
fn bootstrap(n: usize, statistic: impl Fn(&[usize]) -> Option<f64>) -> Option<(f64, f64)> {
    if n == 0 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(BOOTSTRAP_SEED);
    let mut idx = vec![0; n];
    let mut values: Vec<f64> = (0..BOOTSTRAP_RESAMPLES)
        .filter_map(|_| {
            idx.iter_mut().for_each(|i| *i = rng.random_range(0..n));
            statistic(&idx)
        })
        .collect();
    values.sort_by(f64::total_cmp);
    Some((quantile(&values, 0.025)?, quantile(&values, 0.975)?))
}

/// A combination's name in charts: its labels, or the study's name without axes.
pub(super) fn combination_label(study: &Study, labels: &[String]) -> String {
    if labels.is_empty() {
        study.name.clone()
    } else {
        labels.join(" / ")
    }
}

/// Panels (a)–(f) of Fig. 8.9: per combination of levels, each robot's cumulative map
/// data sent (offered to the link) and received, MB, median over seeds with the
/// interquartile band. Empty when no run recorded map data (records written before it
/// was kept).
#[must_use]
pub fn map_data_panels(study: &Study, rows: &[RunRow]) -> Vec<Chart> {
    if rows.iter().all(|r| r.map_data.is_empty()) {
        return Vec::new();
    }
    groups(rows)
        .into_iter()
        .map(|(labels, group)| {
            let robots = group.iter().map(|r| r.map_data.len()).min().unwrap_or(0);
            let mut series = Vec::new();
            for robot in 0..robots {
                for (column, what) in [(1, "sent"), (2, "received")] {
                    series.push(Series {
                        // A robot's two lines share a colour; what it received is dashed.
                        dashed: column == 2,
                        colour: Some(robot),
                        ..median_band(
                            format!("robot {robot} {what}"),
                            &group
                                .iter()
                                .map(|r| &r.map_data[robot].offered_received)
                                .collect::<Vec<_>>(),
                            column,
                        )
                    });
                }
            }
            Chart {
                title: combination_label(study, &labels),
                x_label: "time (s)".into(),
                y_label: "map data (MB)".into(),
                series,
            }
        })
        .collect()
}

/// The median over runs of column `column` of their samples, MB, with the
/// interquartile band, over the samples every run has.
fn median_band(label: String, runs: &[&Vec<[f64; 3]>], column: usize) -> Series {
    let samples = runs.iter().map(|r| r.len()).min().unwrap_or(0);
    let mut points = Vec::with_capacity(samples);
    let mut band = Vec::with_capacity(samples);
    for k in 0..samples {
        let t = runs[0][k][0];
        let mut values: Vec<f64> = runs.iter().map(|r| r[k][column] / 1e6).collect();
        values.sort_by(f64::total_cmp);
        if let (Some(lo), Some(mid), Some(hi)) = (
            quantile(&values, 0.25),
            quantile(&values, 0.5),
            quantile(&values, 0.75),
        ) {
            points.push((t, mid));
            band.push((t, lo, hi));
        }
    }
    Series {
        label,
        points,
        band,
        ..Series::default()
    }
}

/// Panel (g) of Fig. 8.9: per combination, the median time to each coverage level
/// (runs that never reach it count as never; no point where half never did) with its
/// 95 % bootstrap interval over seeds, the upper end drawn at the run's duration where
/// it is "never".
#[must_use]
pub fn time_to_coverage_chart(study: &Study, rows: &[RunRow]) -> Chart {
    let duration_s = rows
        .iter()
        .filter_map(|r| r.coverage_over_time.last().map(|[t, _]| *t))
        .fold(0.0, f64::max);
    let series = groups(rows)
        .into_iter()
        .map(|(labels, group)| {
            let mut points = Vec::new();
            let mut band = Vec::new();
            for (i, level) in study.coverage_levels.iter().enumerate() {
                let times: Vec<Option<f64>> =
                    group.iter().map(|r| r.time_to_coverage_s[i]).collect();
                let x = 100.0 * level;
                if let Some(m) = median_time(&times) {
                    points.push((x, m));
                }
                let interval = bootstrap(times.len(), |idx| {
                    let t: Vec<Option<f64>> = idx.iter().map(|&j| times[j]).collect();
                    Some(median_time(&t).unwrap_or(duration_s))
                });
                if let Some((lo, hi)) = interval {
                    band.push((x, lo, hi));
                }
            }
            Series {
                label: combination_label(study, &labels),
                points,
                band,
                ..Series::default()
            }
        })
        .collect();
    Chart {
        title: format!(
            "{}: median time to coverage (95% bootstrap band)",
            study.name
        ),
        x_label: "coverage (%)".into(),
        y_label: "time (s)".into(),
        series,
    }
}

/// One ratio of [`ratios`].
#[derive(Clone, Debug, PartialEq)]
pub struct Ratio {
    /// The labels of the other axes, in axis order.
    pub labels: Vec<String>,
    /// The coverage level, a fraction.
    pub level: f64,
    /// Seeds flown at both levels.
    pub pairs: usize,
    /// Median time of the numerator's and the denominator's runs, seconds (`None`:
    /// half of them or more never reached the level).
    pub medians_s: [Option<f64>; 2],
    /// The ratio of the medians.
    pub ratio: Option<f64>,
    /// Its 95 % bootstrap interval, resampling seeds in pairs.
    pub interval: Option<(f64, f64)>,
    /// Seeds where the numerator reached the level first (a tie counts for neither).
    pub numerator_first: usize,
    /// What the source says, if the study file gives it.
    pub thesis: Option<String>,
}

/// The ratio of [`RatioSpec`] per combination of the other axes and coverage level,
/// over the seeds flown at both levels.
#[must_use]
pub fn ratios(study: &Study, spec: &RatioSpec, rows: &[RunRow]) -> Vec<Ratio> {
    let Some(axis) = study.axes.iter().position(|a| a.name == spec.axis) else {
        return Vec::new();
    };
    let others = |labels: &[String]| -> Vec<String> {
        let mut l = labels.to_vec();
        l.remove(axis);
        l
    };
    // Per combination of the other axes: seed → [numerator's, denominator's] row.
    type BySeed<'a> = BTreeMap<u64, [Option<&'a RunRow>; 2]>;
    let mut pairs: Vec<(Vec<String>, BySeed)> = Vec::new();
    for r in rows {
        let side = if r.labels[axis] == spec.numerator {
            0
        } else if r.labels[axis] == spec.denominator {
            1
        } else {
            continue;
        };
        let key = others(&r.labels);
        let at = match pairs.iter().position(|(k, _)| *k == key) {
            Some(at) => at,
            None => {
                pairs.push((key, BTreeMap::new()));
                pairs.len() - 1
            }
        };
        pairs[at].1.entry(r.seed).or_default()[side] = Some(r);
    }
    let mut out = Vec::new();
    for (labels, by_seed) in pairs {
        let both: Vec<[&RunRow; 2]> = by_seed
            .values()
            .filter_map(|[a, b]| Some([(*a)?, (*b)?]))
            .collect();
        for (i, &level) in study.coverage_levels.iter().enumerate() {
            let times: Vec<[Option<f64>; 2]> = both
                .iter()
                .map(|p| p.map(|r| r.time_to_coverage_s[i]))
                .collect();
            let ratio_of = |[num, den]: [Option<f64>; 2]| Some(num? / den?);
            let medians_s =
                [0, 1].map(|s| median_time(&times.iter().map(|t| t[s]).collect::<Vec<_>>()));
            out.push(Ratio {
                labels: labels.clone(),
                level,
                pairs: both.len(),
                medians_s,
                ratio: ratio_of(medians_s),
                interval: bootstrap(times.len(), |idx| {
                    ratio_of([0, 1].map(|s| {
                        median_time(&idx.iter().map(|&j| times[j][s]).collect::<Vec<_>>())
                    }))
                }),
                numerator_first: times
                    .iter()
                    .filter(|[a, b]| match (a, b) {
                        (Some(a), Some(b)) => a < b,
                        (Some(_), None) => true,
                        _ => false,
                    })
                    .count(),
                thesis: claim(study, spec, axis, &labels, level),
            });
        }
    }
    out
}

/// The claim of the study file about this combination and level, if any.
fn claim(
    study: &Study,
    spec: &RatioSpec,
    axis: usize,
    labels: &[String],
    level: f64,
) -> Option<String> {
    let names: Vec<&str> = study
        .axes
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != axis)
        .map(|(_, a)| a.name.as_str())
        .collect();
    spec.thesis
        .iter()
        .find(|c| {
            (c.level - level).abs() < 1e-9
                && c.at.iter().all(|(k, v)| {
                    names
                        .iter()
                        .position(|n| n == k)
                        .is_some_and(|i| v.as_str() == Some(labels[i].as_str()))
                })
        })
        .map(|c| c.says.clone())
}

/// `ratios.csv`: one row per combination of the other axes and coverage level.
#[must_use]
pub fn ratios_csv(study: &Study, spec: &RatioSpec, ratios: &[Ratio]) -> String {
    let mut header: Vec<String> = study
        .axes
        .iter()
        .filter(|a| a.name != spec.axis)
        .map(|a| a.name.clone())
        .collect();
    header.extend([
        "coverage_level".to_string(),
        "pairs".into(),
        format!("{}_median_s", spec.numerator),
        format!("{}_median_s", spec.denominator),
        "ratio".into(),
        "ratio_ci95_low".into(),
        "ratio_ci95_high".into(),
        format!("{}_first", spec.numerator),
        "thesis".into(),
    ]);
    let mut out = header.join(",");
    out.push('\n');
    let opt = |v: Option<f64>| v.map_or(String::new(), |x| format!("{x}"));
    for r in ratios {
        let mut cells = r.labels.clone();
        cells.extend([
            r.level.to_string(),
            r.pairs.to_string(),
            opt(r.medians_s[0]),
            opt(r.medians_s[1]),
            opt(r.ratio),
            opt(r.interval.map(|i| i.0)),
            opt(r.interval.map(|i| i.1)),
            r.numerator_first.to_string(),
            // A claim is a phrase: quoted, its quotes doubled (RFC 4180).
            r.thesis
                .as_ref()
                .map_or(String::new(), |t| format!("\"{}\"", t.replace('"', "\"\""))),
        ]);
        let _ = writeln!(out, "{}", cells.join(","));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_counts_never_as_last() {
        assert_eq!(median_time(&[Some(3.0), None, Some(1.0)]), Some(3.0));
        assert_eq!(median_time(&[Some(3.0), None, None]), None);
        assert_eq!(median_time(&[]), None);
    }

    #[test]
    fn the_bootstrap_is_deterministic_and_brackets_a_constant() {
        let a = bootstrap(10, |idx| Some(idx.iter().sum::<usize>() as f64));
        assert_eq!(
            a,
            bootstrap(10, |idx| Some(idx.iter().sum::<usize>() as f64))
        );
        let (lo, hi) = a.expect("an interval");
        // The sum of ten uniform draws from 0..10 has mean 45 and sd ≈ 9.1.
        assert!(
            lo < 45.0 && hi > 45.0 && lo > 20.0 && hi < 70.0,
            "{lo} {hi}"
        );
        assert_eq!(bootstrap(5, |_| Some(2.0)), Some((2.0, 2.0)));
        assert_eq!(bootstrap(5, |_| None), None);
    }
}
