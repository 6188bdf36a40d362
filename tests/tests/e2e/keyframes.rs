//! Keyframe GMMs flow from one robot's mapper over the shaped link to its peers.

use troupe_actors::mapper::MapperConfig;
use troupe_robot::RobotConfig;
use troupe_sims::scenario::Scenario;
use troupe_sims::team::Team;

#[test]
fn keyframes_are_fitted_shared_and_received() {
    let scenario = Scenario {
        name: "keyframes".into(),
        duration_s: 12.0,
        robot: RobotConfig {
            mapper: MapperConfig {
                enabled: true,
                pixel_stride: 4,
                ..MapperConfig::default()
            },
            ..RobotConfig::default()
        },
        ..Scenario::default()
    };
    let s = Team::new(&scenario).expect("assemble").run(|_| {}).summary;
    for (me, peer) in [(0, 1), (1, 0)] {
        let mine = &s.per_robot[me];
        let theirs = &s.per_robot[peer];
        let sent = mine.topics.get("mapper/keyframe").map_or(0, |t| t.messages);
        let received = theirs.topics.get("peer/keyframe").map_or(0, |t| t.messages);
        assert!(sent >= 2, "robot{me} made {sent} keyframes");
        // Every keyframe published before the last moments arrives at the peer.
        assert!(
            received + 1 >= sent && received <= sent,
            "sent {sent}, peer received {received}"
        );
        let link = mine.truth.link.as_ref().expect("link status");
        assert_eq!(link.rejected_messages, 0);
        assert!(
            mine.actors.iter().all(|a| a.errors == 0 && a.panics == 0),
            "{:?}",
            mine.actors
        );
    }
    assert_eq!(s.collisions, 0);
}
