//! `troupe sweep STUDY`: every run of a study, in parallel, and the study's tables;
//! across machines with `--shard K/N`, collected with `--merge`.

use std::io::Write as _;
use std::path::PathBuf;

use crate::report::write_run;
use crate::study::{
    RunRow, Shard, Study, Variant, finished_run, merge_finished_runs, run_variants,
    save_finished_run, write_study,
};
use anyhow::Context as _;

#[derive(Debug, clap::Args)]
pub(crate) struct SweepArgs {
    /// Study file (TOML), e.g. `sims/studies/link_constraint.toml`.
    study: PathBuf,
    /// Runs at once (default: the number of CPU cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Directory that receives the study directory.
    #[arg(long, default_value = "runs")]
    out: PathBuf,
    /// List the runs (of this shard) and exit without running them.
    #[arg(long)]
    dry_run: bool,
    /// Reuse runs that an earlier sweep into the same directory finished with the
    /// same scenario (their `runs/<run>/study_row.json`); fly only the rest.
    #[arg(long)]
    resume: bool,
    /// Fly only shard K of N (0 <= K < N): the runs whose position in the study's
    /// run list (`--dry-run` order) is K modulo N, whatever `--jobs`. Writes their
    /// reports under `OUT/<study>/runs/` but not the study's tables: collect those
    /// with `--merge` once every shard is done.
    #[arg(long, value_name = "K/N", conflicts_with = "merge")]
    shard: Option<Shard>,
    /// Fly nothing: rebuild `results.csv`, `aggregate.csv` and the plots in
    /// `OUT/<study>/` from the finished runs (`study_row.json`) found under these
    /// directories (e.g. the `OUT/<study>` of every shard). Refuses runs of another
    /// version of the study; lists the runs still missing and then fails.
    #[arg(
        long,
        value_name = "DIR",
        num_args = 1..,
        conflicts_with_all = ["jobs", "dry_run", "resume"]
    )]
    merge: Vec<PathBuf>,
}

pub(crate) fn run(args: SweepArgs) -> anyhow::Result<()> {
    let study = Study::load(&args.study)?;
    let all = study.variants()?;
    if !args.merge.is_empty() {
        return merge(&study, &all, &args.merge, &args.out);
    }
    let variants = match args.shard {
        Some(shard) => shard.select(&all),
        None => all,
    };
    if args.dry_run {
        let mut out = std::io::stdout().lock();
        for v in &variants {
            writeln!(out, "{}", v.name)?;
        }
        return Ok(());
    }
    let jobs = args.jobs.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    let root = args.out.join(&study.name);
    let runs_dir = root.join("runs");
    let total = variants.len();
    let share = args.shard.map_or(String::new(), |s| format!(", shard {s}"));
    eprintln!(
        "{}{share}: {total} runs ({} seeds), {jobs} at a time",
        study.name,
        study.seeds.len()
    );
    let mut rows: Vec<Option<RunRow>> = variants
        .iter()
        .map(|v| {
            args.resume
                .then(|| finished_run(&runs_dir.join(&v.name), v, &study.coverage_levels))
                .flatten()
        })
        .collect();
    let to_fly: Vec<Variant> = variants
        .iter()
        .zip(&rows)
        .filter(|(_, row)| row.is_none())
        .map(|(v, _)| v.clone())
        .collect();
    let reused = total - to_fly.len();
    if args.resume {
        eprintln!(
            "resuming: {reused} of {total} runs reused from {}",
            runs_dir.display()
        );
    }
    let started = std::time::Instant::now();
    let mut finished = reused;
    let mut write_errors = Vec::new();
    let flown = run_variants(
        &to_fly,
        &study.coverage_levels,
        jobs,
        |variant, output, row| {
            finished += 1;
            let saved = write_run(&runs_dir, &variant.name, output)
                .and_then(|dir| save_finished_run(&dir, &study.name, variant, row));
            if let Err(e) = saved {
                write_errors.push(format!("{}: {e}", variant.name));
            }
            eprintln!(
                "[{finished}/{total}] {}: coverage {:.1}%, collisions {}, map bytes offered {} sent {}, {:.0} wall s",
                variant.name,
                100.0 * row.final_coverage,
                row.collisions,
                row.map_bytes_offered,
                row.map_bytes_sent,
                row.wall_s
            );
        },
    )?;
    if let Some(e) = write_errors.first() {
        anyhow::bail!("writing a run report under {}: {e}", runs_dir.display());
    }
    if let Some(shard) = args.shard {
        // Other shards may be writing into the same directory: the study's tables
        // come from `--merge` once all of them are done.
        println!(
            "{} shard {shard}: {total} runs in {:.0} wall s under {}; when every shard is done: troupe sweep {} --merge DIR…",
            study.name,
            started.elapsed().as_secs_f64(),
            runs_dir.display(),
            args.study.display()
        );
        return Ok(());
    }
    let mut flown = flown.into_iter();
    for row in &mut rows {
        if row.is_none() {
            *row = flown.next();
        }
    }
    let rows: Vec<RunRow> = rows.into_iter().flatten().collect();
    let written = write_study(&root, &study, &rows)
        .with_context(|| format!("writing the study outputs under {}", root.display()))?;
    println!(
        "{}: {total} runs in {:.0} wall s; outputs: {}",
        study.name,
        started.elapsed().as_secs_f64(),
        written.join(", ")
    );
    Ok(())
}

/// `troupe sweep STUDY --merge DIR…`: the study's tables from finished runs.
fn merge(
    study: &Study,
    variants: &[Variant],
    dirs: &[PathBuf],
    out: &std::path::Path,
) -> anyhow::Result<()> {
    let merged = merge_finished_runs(study, variants, dirs)?;
    let total = variants.len();
    let found = merged.rows.len();
    let places: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
    if found == 0 {
        anyhow::bail!(
            "no finished run of study `{}` under {}",
            study.name,
            places.join(", ")
        );
    }
    if merged.other_studies > 0 {
        eprintln!("passed over {} runs of other studies", merged.other_studies);
    }
    let root = out.join(&study.name);
    let written = write_study(&root, study, &merged.rows)
        .with_context(|| format!("writing the study outputs under {}", root.display()))?;
    println!(
        "{}: {found} of {total} runs merged from {}; outputs: {}",
        study.name,
        places.join(", "),
        written.join(", ")
    );
    if !merged.missing.is_empty() {
        for run in &merged.missing {
            eprintln!("missing: {run}");
        }
        anyhow::bail!(
            "{} of {total} runs missing (listed above): the outputs hold only the {found} found; fly the rest (e.g. their shards with --resume) and merge again",
            merged.missing.len()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Command, parse};

    fn sweep_args(args: &[&str]) -> SweepArgs {
        match parse(args).expect("parses").command {
            Command::Sweep(a) => a,
            other => panic!("not a sweep: {other:?}"),
        }
    }

    #[test]
    fn shard_and_merge_flags_parse() {
        let a = sweep_args(&["sweep", "s.toml", "--shard", "2/5", "--jobs", "3"]);
        assert_eq!(a.shard, Some(Shard::new(2, 5).expect("shard")));
        assert!(a.merge.is_empty());
        let a = sweep_args(&["sweep", "s.toml", "--merge", "a", "b/c", "--out", "o"]);
        assert_eq!(a.merge, [PathBuf::from("a"), PathBuf::from("b/c")]);
        assert_eq!(a.shard, None);
        assert_eq!(a.out, PathBuf::from("o"));
        for bad in [
            &["sweep", "s.toml", "--shard", "5/5"][..],
            &["sweep", "s.toml", "--shard", "1"],
            &["sweep", "s.toml", "--shard", "-1/3"],
            &["sweep", "s.toml", "--merge"],
            &["sweep", "s.toml", "--merge", "a", "--shard", "0/2"],
            &["sweep", "s.toml", "--merge", "a", "--resume"],
            &["sweep", "s.toml", "--merge", "a", "--jobs", "2"],
        ] {
            assert!(parse(bad).is_err(), "{bad:?} parsed");
        }
        let error = parse(&["sweep", "s.toml", "--shard", "3/2"])
            .expect_err("3/2")
            .to_string();
        assert!(error.contains("0 <= K < N"), "{error}");
    }
}
