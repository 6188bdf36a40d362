//! `troupe replay RECORDING`: a recording's channels and span, and its plots again.

use std::io::Write as _;
use std::path::PathBuf;

use crate::recording::RecordingFile;

#[derive(Debug, clap::Args)]
pub(crate) struct ReplayArgs {
    /// The MCAP recording, e.g. `runs/default/run.mcap`.
    recording: PathBuf,
    /// Draw the run's plots (coverage, link bytes, speed, nearest robot,
    /// trajectories) from the recording's samples into this directory.
    #[arg(long, value_name = "DIR")]
    plots: Option<PathBuf>,
    /// Print the summary as one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

pub(crate) fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let file = RecordingFile::open(&args.recording)?;
    let summary = file.summary()?;
    // A closed pipe (`| head`) ends the listing with an error, not a panic.
    let mut out = std::io::stdout().lock();
    if args.json {
        writeln!(out, "{}", serde_json::to_string(&summary)?)?;
    } else {
        let [start, end] = summary.span_s.unwrap_or_default();
        writeln!(
            out,
            "{}: {} messages on {} channels, {:.3} s ({start:.3} to {end:.3} s){}",
            args.recording.display(),
            summary.messages,
            summary.channels.len(),
            summary.duration_s(),
            if summary.attachments.is_empty() {
                String::new()
            } else {
                format!("; attached: {}", summary.attachments.join(", "))
            }
        )?;
        let width = summary.channels.keys().map(String::len).max().unwrap_or(0);
        for (topic, channel) in &summary.channels {
            println!(
                "  {topic:<width$}  {:>8}  {}",
                channel.messages, channel.schema
            );
        }
    }
    if let Some(dir) = &args.plots {
        let stems = file.render_plots(dir)?;
        anyhow::ensure!(
            !stems.is_empty(),
            "{} has no samples to plot (only `troupe run` records them)",
            args.recording.display()
        );
        eprintln!("plots: {} in {}", stems.join(", "), dir.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Command, parse};

    #[test]
    fn replay_flags_parse() {
        match parse(&["replay", "run.mcap", "--plots", "p", "--json"])
            .expect("replay")
            .command
        {
            Command::Replay(a) => {
                assert_eq!(a.recording, PathBuf::from("run.mcap"));
                assert_eq!(a.plots, Some(PathBuf::from("p")));
                assert!(a.json);
            }
            other => panic!("{other:?}"),
        }
        assert!(parse(&["replay"]).is_err(), "the recording is required");
    }
}
