//! Studies across machines: `troupe sweep STUDY --shard K/N` flies one share of the
//! runs, `troupe sweep STUDY --merge DIR…` collects the finished runs of every share
//! into the study's tables.
//!
//! A shard is fixed by the study alone: run `i` of the study's run list
//! ([`Study::variants`], the `--dry-run` order) belongs to shard `i mod N`, so the
//! shares do not depend on `--jobs`, on the machine, or on which shards already ran.
//! Each finished run leaves its row and the scenario it flew in
//! `runs/<run>/study_row.json` ([`super::FINISHED_RUN_FILE`]); merging reads those,
//! checks that each was flown with the scenario the study gives now and by this
//! troupe version ([`super::TROUPE_VERSION`]), and lists the runs that no directory
//! holds.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use super::{
    FINISHED_RUN_FILE, Record, RunRow, Study, TROUPE_VERSION, Variant, scenario_json,
    times_to_coverage,
};

/// One of `count` shares of a study's runs: the runs at positions `index`,
/// `index + count`, `index + 2·count`, … of [`Study::variants`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    index: usize,
    count: usize,
}

/// A shard that is not `K/N` with `0 <= K < N`.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
#[error("shard `{0}` is not K/N with whole numbers 0 <= K < N (e.g. 0/4)")]
pub struct ShardError(String);

impl Shard {
    /// Shard `index` of `count`.
    pub fn new(index: usize, count: usize) -> Result<Shard, ShardError> {
        if index < count {
            Ok(Shard { index, count })
        } else {
            Err(ShardError(format!("{index}/{count}")))
        }
    }

    /// This shard's position `K` among the shares.
    #[must_use]
    pub fn index(self) -> usize {
        self.index
    }

    /// The number of shares `N`.
    #[must_use]
    pub fn count(self) -> usize {
        self.count
    }

    /// This shard's share of `runs` (in the study's order), in their order.
    #[must_use]
    pub fn select<T: Clone>(self, runs: &[T]) -> Vec<T> {
        runs.iter()
            .skip(self.index)
            .step_by(self.count)
            .cloned()
            .collect()
    }
}

impl FromStr for Shard {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || ShardError(s.to_owned());
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let parse = |x: &str| {
            // `usize::from_str` takes a leading `+`; a shard is plain digits.
            if x.is_empty() || !x.bytes().all(|b| b.is_ascii_digit()) {
                return Err(bad());
            }
            x.parse::<usize>().map_err(|_| bad())
        };
        Shard::new(parse(k)?, parse(n)?).map_err(|_| bad())
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// The finished runs of a study collected from several directories.
#[derive(Clone, Debug, PartialEq)]
pub struct Merged {
    /// Rows of the runs found, in the study's order.
    pub rows: Vec<RunRow>,
    /// Names of the study's runs that no directory holds, in the study's order.
    pub missing: Vec<String>,
    /// `study_row.json` files of other studies that were passed over.
    pub other_studies: usize,
}

/// Why finished runs could not be merged.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// A directory or record could not be read.
    #[error("reading `{path}`")]
    Read {
        /// The directory or file.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// A record is not a `study_row.json` troupe wrote.
    #[error("`{path}` is not a finished-run record")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Cause.
        source: serde_json::Error,
    },
    /// A study's scenario could not be encoded for comparison.
    #[error("encoding the scenario of run `{run}`")]
    Encode {
        /// The run.
        run: String,
        /// Cause.
        source: serde_json::Error,
    },
    /// A run was flown by another version of the study (its scenario, axes or seeds
    /// changed since) or by another troupe version.
    #[error(
        "`{path}`: run `{run}` {why}; refusing to merge runs of different versions of study `{study}`"
    )]
    MixedVersions {
        /// The record.
        path: PathBuf,
        /// The run it holds.
        run: String,
        /// The study.
        study: String,
        /// How it differs.
        why: String,
    },
}

/// Collects the finished runs of `study` (whose runs are `variants`) from the
/// `study_row.json` files anywhere under `dirs`. A run found in several places is
/// taken from the first (directories in the given order, files in name order).
/// Records of other studies are passed over and counted; a record of this study
/// that the study as it stands does not give (another scenario, or a run it no
/// longer has) is an error.
pub fn merge_finished_runs(
    study: &Study,
    variants: &[Variant],
    dirs: &[PathBuf],
) -> Result<Merged, MergeError> {
    let expected: HashMap<&str, (usize, serde_json::Value)> = variants
        .iter()
        .enumerate()
        .map(|(i, v)| {
            scenario_json(&v.scenario)
                .map(|json| (v.name.as_str(), (i, json)))
                .map_err(|source| MergeError::Encode {
                    run: v.name.clone(),
                    source,
                })
        })
        .collect::<Result<_, _>>()?;
    let prefix = format!("{}-", study.name);
    let mut rows: Vec<Option<RunRow>> = vec![None; variants.len()];
    let mut other_studies = 0;
    for dir in dirs {
        let mut files = Vec::new();
        find_records(dir, &mut files)?;
        for path in files {
            let bytes = std::fs::read(&path).map_err(|source| MergeError::Read {
                path: path.clone(),
                source,
            })?;
            let record: Record =
                serde_json::from_slice(&bytes).map_err(|source| MergeError::Corrupt {
                    path: path.clone(),
                    source,
                })?;
            let ours = match &record.study {
                Some(name) => *name == study.name,
                // Records from before the study name was kept: by the run name.
                None => record.row.run.starts_with(&prefix),
            };
            if !ours {
                other_studies += 1;
                continue;
            }
            let mixed = |why: String| MergeError::MixedVersions {
                path: path.clone(),
                run: record.row.run.clone(),
                study: study.name.clone(),
                why,
            };
            let Some((i, scenario)) = expected.get(record.row.run.as_str()) else {
                return Err(mixed(
                    "is not a run of the study as it stands (its axes or seeds changed)".into(),
                ));
            };
            if *scenario != record.scenario || record.row.seed != variants[*i].seed {
                return Err(mixed(
                    "flew another scenario than the study gives now (the study or its base scenario changed)".into(),
                ));
            }
            if !record.same_version() {
                return Err(mixed(format!(
                    "was flown by troupe {}, not by this troupe {TROUPE_VERSION}",
                    record.troupe.as_deref().unwrap_or("?")
                )));
            }
            rows[*i].get_or_insert_with(|| RunRow {
                time_to_coverage_s: times_to_coverage(
                    &record.row.coverage_over_time,
                    &study.coverage_levels,
                ),
                ..record.row
            });
        }
    }
    let missing = variants
        .iter()
        .zip(&rows)
        .filter(|(_, row)| row.is_none())
        .map(|(v, _)| v.name.clone())
        .collect();
    Ok(Merged {
        rows: rows.into_iter().flatten().collect(),
        missing,
        other_studies,
    })
}

/// Every `study_row.json` under `dir` (not following symbolic links), sorted.
fn find_records(dir: &Path, found: &mut Vec<PathBuf>) -> Result<(), MergeError> {
    let read = |source| MergeError::Read {
        path: dir.to_owned(),
        source,
    };
    let mut entries = std::fs::read_dir(dir)
        .map_err(read)?
        .collect::<Result<Vec<_>, _>>()
        .map_err(read)?;
    entries.sort_by_key(std::fs::DirEntry::file_name);
    for entry in entries {
        let kind = entry.file_type().map_err(read)?;
        if kind.is_dir() {
            find_records(&entry.path(), found)?;
        } else if kind.is_file() && entry.file_name() == FINISHED_RUN_FILE {
            found.push(entry.path());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::save_finished_run;
    use super::*;

    #[test]
    fn shards_parse_and_split_the_runs_whatever_their_number() {
        assert_eq!("1/3".parse(), Shard::new(1, 3));
        assert_eq!("0/1".parse::<Shard>().map(Shard::count), Ok(1));
        for bad in [
            "3/3", "0/0", "1", "a/3", "1/b", "-1/3", "+1/3", "1/3/5", "", " 1/3",
        ] {
            let error = bad.parse::<Shard>().expect_err(bad);
            assert!(error.to_string().contains("0 <= K < N"), "{error}");
        }
        let runs: Vec<usize> = (0..10).collect();
        let shares: Vec<Vec<usize>> = (0..3)
            .map(|k| Shard::new(k, 3).expect("shard").select(&runs))
            .collect();
        assert_eq!(shares, [vec![0, 3, 6, 9], vec![1, 4, 7], vec![2, 5, 8]]);
        assert_eq!(Shard::new(4, 12).expect("shard").select(&runs), [4]);
        assert!(Shard::new(11, 12).expect("shard").select(&runs).is_empty());
        assert_eq!(Shard::new(2, 7).expect("shard").to_string(), "2/7");
    }

    fn study(dir: &Path, duration_s: f64, seeds: &str) -> (Study, Vec<Variant>) {
        let path = dir.join("study.toml");
        std::fs::write(
            &path,
            format!(
                "name = \"m\"\nseeds = {seeds}\nduration_s = {duration_s:?}\ncoverage_levels = [0.5]\n[[axes]]\nkey = \"robots\"\nvalues = [1, 2]\n"
            ),
        )
        .expect("study file");
        let study = Study::load(&path).expect("study");
        let variants = study.variants().expect("variants");
        (study, variants)
    }

    /// Records `variant` as finished under `dir/runs/<run>/`, reaching 50 % at `t`.
    fn finish(dir: &Path, study: &str, variant: &Variant, t: f64) {
        let run_dir = dir.join("runs").join(&variant.name);
        std::fs::create_dir_all(&run_dir).expect("run dir");
        let row = RunRow {
            run: variant.name.clone(),
            labels: variant.labels.clone(),
            seed: variant.seed,
            final_coverage: 0.6,
            distance_m: 1.0,
            coverage_over_time: vec![[t, 0.6]],
            wall_s: 0.1,
            ..RunRow::default()
        };
        save_finished_run(&run_dir, study, variant, &row).expect("record");
    }

    #[test]
    fn merging_collects_rows_in_study_order_and_lists_the_missing() {
        let dir = tempfile::tempdir().expect("temp dir");
        let (study, variants) = study(dir.path(), 5.0, "[1, 2]");
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        // Runs 0 and 3 on one machine, run 2 on the other (twice: the first wins),
        // run 1 nowhere; a run of another study beside them.
        finish(&a, "m", &variants[3], 4.0);
        finish(&a, "m", &variants[0], 1.0);
        finish(&b, "m", &variants[2], 3.0);
        let c = dir.path().join("c");
        finish(&c, "m", &variants[2], 9.0);
        finish(&b, "other", &variants[1], 2.0);
        let merged = merge_finished_runs(&study, &variants, &[a, b, c]).expect("merged");
        let names: Vec<&str> = merged.rows.iter().map(|r| r.run.as_str()).collect();
        assert_eq!(
            names,
            [&variants[0].name, &variants[2].name, &variants[3].name]
        );
        assert_eq!(merged.missing, [variants[1].name.clone()]);
        assert_eq!(merged.other_studies, 1);
        // Times to coverage come from the study's levels.
        assert_eq!(merged.rows[0].time_to_coverage_s, [Some(1.0)]);
        assert_eq!(
            merged.rows[1].time_to_coverage_s,
            [Some(3.0)],
            "the first directory's record of a run wins"
        );

        let missing_dir = merge_finished_runs(&study, &variants, &[dir.path().join("nope")]);
        assert!(matches!(missing_dir, Err(MergeError::Read { .. })));
    }

    #[test]
    fn merging_refuses_runs_of_another_version_of_the_study() {
        let dir = tempfile::tempdir().expect("temp dir");
        let (_, old) = study(dir.path(), 5.0, "[1, 2, 3]");
        finish(dir.path(), "m", &old[0], 1.0);
        // The duration changed: same run names, other scenarios.
        let (study_now, variants) = study(dir.path(), 6.0, "[1, 2, 3]");
        let error = merge_finished_runs(&study_now, &variants, &[dir.path().to_owned()])
            .expect_err("mixed versions");
        let message = error.to_string();
        assert!(
            matches!(error, MergeError::MixedVersions { .. })
                && message.contains(&old[0].name)
                && message.contains("another scenario")
                && !message.contains('\n'),
            "{message}"
        );
        // A seed was dropped: the record names a run the study no longer has.
        let (study_now, variants) = study(dir.path(), 5.0, "[2, 3]");
        let message = merge_finished_runs(&study_now, &variants, &[dir.path().to_owned()])
            .expect_err("dropped seed")
            .to_string();
        assert!(message.contains("not a run of the study"), "{message}");
        // The same run flown by another troupe version: not merged, not resumed.
        let (study_now, variants) = study(dir.path(), 5.0, "[1, 2, 3]");
        let record = dir
            .path()
            .join("runs")
            .join(&old[0].name)
            .join(FINISHED_RUN_FILE);
        merge_finished_runs(&study_now, &variants, &[dir.path().to_owned()])
            .expect("the same study and troupe merge");
        let mut json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&record).expect("record")).expect("json");
        json["troupe"] = "0.0.1-elsewhere".into();
        std::fs::write(&record, serde_json::to_vec(&json).expect("json")).expect("record");
        let message = merge_finished_runs(&study_now, &variants, &[dir.path().to_owned()])
            .expect_err("another troupe")
            .to_string();
        assert!(
            message.contains("flown by troupe 0.0.1-elsewhere")
                && message.contains(&format!("this troupe {TROUPE_VERSION}")),
            "{message}"
        );
        let run_dir = record.parent().expect("run dir");
        assert_eq!(
            super::super::finished_run(run_dir, &variants[0], &[0.5]),
            None
        );
        // A record that is not JSON is an error, not a missing run.
        std::fs::write(
            dir.path()
                .join("runs")
                .join(&old[0].name)
                .join(FINISHED_RUN_FILE),
            b"\xff{",
        )
        .expect("corrupt");
        let error = merge_finished_runs(&study_now, &variants, &[dir.path().to_owned()])
            .expect_err("corrupt");
        assert!(matches!(error, MergeError::Corrupt { .. }), "{error}");
    }
}
