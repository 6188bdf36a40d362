//! The artifact reporter in a simulated team: reports cross the link and land in
//! the peer's list; the summary scores the team's list against the placed artifacts.

use troupe_actors::artifacts::ARTIFACT_REPORTS;
use troupe_sims::scenario::Scenario;

use crate::run;

#[test]
fn artifact_reports_cross_the_link_and_every_list_is_the_union() {
    let mut scenario = Scenario {
        name: "artifacts".into(),
        // Seed 1's first artifact is reported at about 48 s and the second at 57 s.
        duration_s: 75.0,
        ..Scenario::default()
    };
    scenario.world.artifacts.count = 8;
    scenario.robot.artifacts.enabled = true;
    scenario.camera.render_stride = 1; // the detector reads every pixel
    let output = run(&scenario);
    let s = &output.summary;
    let score = s.artifact_score.as_ref().expect("artifacts were placed");
    assert_eq!(score.placed, 8);
    assert!(score.found >= 1, "{score:?}");
    assert!(score.false_reports <= score.found, "{score:?}");
    // Every report crossed the link: each robot received what the other sent, and
    // each robot's list (per_robot) scores like the team's union.
    let shared: Vec<_> = s
        .per_robot
        .iter()
        .map(|r| r.truth.link.as_ref().unwrap().shared[ARTIFACT_REPORTS.name()].clone())
        .collect();
    assert_eq!(shared[0].sent.sent_messages, shared[1].received);
    assert_eq!(shared[1].sent.sent_messages, shared[0].received);
    assert!(shared[0].sent.sent_messages + shared[1].sent.sent_messages >= 1);
    let team = [score.found, score.false_reports];
    for (robot, own) in score.per_robot.iter().enumerate() {
        assert_eq!(*own, team, "robot {robot}'s list is the team's");
    }
    for a in &s.artifacts {
        assert!(a.first_seen_s > 0.0 && a.first_seen_s <= scenario.duration_s);
        assert!(!a.correct || a.error_m <= 1.0, "{a:?}");
    }
}
