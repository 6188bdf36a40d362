//! Custom actors that talk to other robots: the artifact reporter.
//!
//! The cave gets a few artifacts (small retroreflective spheres, placed by the world
//! seed); every robot runs `troupe_actors::artifacts::ArtifactActor`, which finds them
//! in its depth + intensity frames, localises them in the world frame and shares one
//! report per artifact on the shared topic `artifacts/report` — a `SharedTopic`
//! whose messages the link carries store-and-forward at plan priority, ahead of the
//! keyframes. Each robot keeps the team's deduplicated list; the run's
//! `summary.json` scores it against the placed artifacts.
//!
//! The same run from a scenario file: `[world.artifacts] count = 8`,
//! `[robot.artifacts] enabled = true` and `[camera] render_stride = 1` (see
//! docs/user-messages.md).
//!
//! Run: `cargo run --release -p troupe-tests --example artifact_reporter [seed] [seconds]`

use troupe_actors::artifacts::ARTIFACT_REPORTS;
use troupe_sims::scenario::Scenario;
use troupe_sims::team::Team;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let seed: u64 = args.next().map_or(Ok(1), |s| s.parse())?;
    let duration_s: f64 = args.next().map_or(Ok(120.0), |s| s.parse())?;
    let mut scenario = Scenario {
        name: "artifact_reporter".into(),
        seed,
        duration_s,
        ..Scenario::default()
    };
    scenario.world.artifacts.count = 8;
    scenario.robot.artifacts.enabled = true;
    // The detector reads every pixel (the default camera renders every second one).
    scenario.camera.render_stride = 1;
    let output = Team::new(&scenario)?.run(|_| {});
    let summary = &output.summary;
    for robot in &summary.per_robot {
        let Some(shared) = robot
            .truth
            .link
            .as_ref()
            .and_then(|l| l.shared.get(ARTIFACT_REPORTS.name()))
        else {
            continue;
        };
        println!(
            "{}: sent {} reports, received {} from peers",
            robot.name, shared.sent.sent_messages, shared.received
        );
    }
    for a in &summary.artifacts {
        println!(
            "artifact at ({:.1}, {:.1}, {:.1}) first reported by robot {} at {:.1} s: {}",
            a.position_m[0],
            a.position_m[1],
            a.position_m[2],
            a.first_reporter,
            a.first_seen_s,
            if a.correct { "correct" } else { "false" }
        );
    }
    if let Some(score) = &summary.artifact_score {
        println!(
            "found {} of {} placed, {} false reports",
            score.found, score.placed, score.false_reports
        );
    }
    Ok(())
}
