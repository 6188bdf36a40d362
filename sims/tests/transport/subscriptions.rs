//! Issue 22: subscription scopes over a real zenoh router (`troupe_comms::scope`,
//! `troupe_comms::zenoh`).
#![allow(clippy::unwrap_used)]

use crate::{common, wait_for};

use std::sync::{Arc, Mutex};
use std::time::Duration;

use troupe_comms::scope::{Scope, SubscriptionConfig};
use troupe_comms::shaping::{LinkShaper, ShaperConfig};
use troupe_comms::transport::{PacketSink, PacketTransport as _, ReceivedPacket};
use troupe_comms::wire::Class;
use troupe_comms::zenoh::{ZenohConfig, ZenohMode, ZenohTransport};
use zenoh::Wait as _;

type Seen = Arc<Mutex<Vec<(u32, Option<u32>, Vec<u8>)>>>;

fn sink(seen: &Seen) -> PacketSink {
    let seen = seen.clone();
    Arc::new(move |p: ReceivedPacket<'_>| {
        seen.lock().unwrap().push((p.from, p.to, p.bytes.to_vec()));
    })
}

/// One frame of `class` from its own shaper.
fn frame_of(class: Class) -> Vec<u8> {
    let mut shaper = LinkShaper::new(ShaperConfig::default()).unwrap();
    shaper.offer(0, class, vec![7; 100]).unwrap();
    shaper.poll(0).unwrap().bytes
}

/// Issue 22: a robot with a neighbourhood scope, a client of a zenoh router, gets
/// the keyframes and odometry of a robot nearby and not those of a robot 200 m
/// away — zenoh never hands them over (nothing is counted as rejected) — while it
/// still gets what the far robot addresses to it; a robot with scope `all` gets
/// everything. When the robot moves next to the far one, its subscriptions follow.
#[test]
fn a_neighbourhood_scope_subscribes_to_nearby_cells_through_a_router() {
    let p = common::free_ports_from(1_200, 1)[0];
    let mut router_config = ZenohConfig {
        listen: vec![format!("tcp/127.0.0.1:{p}")],
        ..ZenohConfig::default()
    }
    .to_zenoh()
    .unwrap();
    router_config.insert_json5("mode", "\"router\"").unwrap();
    let router = zenoh::open(router_config).wait().unwrap();
    let client = ZenohConfig {
        mode: ZenohMode::Client,
        connect: vec![format!("tcp/127.0.0.1:{p}")],
        ..ZenohConfig::default()
    };
    let scope = |scope| SubscriptionConfig {
        scope,
        radius_m: 20.0,
        cell_m: 10.0,
    };
    let open = |robot: u32, s: Scope, at: [f64; 3]| {
        let t = ZenohTransport::open(&client, 1, vec![robot])
            .unwrap()
            .with_subscription(scope(s));
        t.set_position(robot, at);
        let seen: Seen = Arc::default();
        t.start(sink(&seen)).unwrap();
        (t, seen)
    };
    let (me, seen_me) = open(0, Scope::Neighbourhood, [0.0, 0.0, 1.0]);
    let (near, _) = open(1, Scope::Neighbourhood, [12.0, -3.0, 1.0]);
    let (far, _) = open(2, Scope::Neighbourhood, [200.0, 0.0, 1.0]);
    let (all, seen_all) = open(3, Scope::All, [0.0, 0.0, 1.0]);
    assert!(me.stats().subscribed_cells > 0);
    assert_eq!(all.stats().subscribed_cells, 0);
    let (keyframe, odometry) = (frame_of(Class::Keyframe), frame_of(Class::Odometry));
    let heard = |seen: &Seen, from: u32, frame: &[u8]| {
        seen.lock()
            .unwrap()
            .iter()
            .any(|(f, _, b)| *f == from && b == frame)
    };
    wait_for(
        "every frame at the robot with scope all",
        Duration::from_secs(20),
        Duration::from_millis(10),
        || {
            for (t, id) in [(&near, 1), (&far, 2)] {
                t.send(id, None, &keyframe).unwrap();
                t.send(id, None, &odometry).unwrap();
            }
            far.send(2, Some(0), &keyframe).unwrap();
            std::thread::sleep(Duration::from_millis(50));
            heard(&seen_all, 1, &keyframe)
                && heard(&seen_all, 2, &odometry)
                && heard(&seen_me, 1, &keyframe)
                && heard(&seen_me, 1, &odometry)
                && seen_me
                    .lock()
                    .unwrap()
                    .iter()
                    .any(|(from, to, _)| *from == 2 && *to == Some(0))
        },
    );
    let broadcast_from_far = seen_me
        .lock()
        .unwrap()
        .iter()
        .any(|(from, to, _)| *from == 2 && to.is_none());
    assert!(!broadcast_from_far, "a broadcast from 200 m away");
    let s = me.stats();
    assert_eq!(
        s.received_frames,
        seen_me.lock().unwrap().len() as u64,
        "{s:?}"
    );
    assert_eq!(s.rejected_key + s.rejected_class + s.rejected_frame, 0);
    // The robot moves next to the far one: it now hears it, and not the near one.
    me.set_position(0, [195.0, 4.0, 1.0]);
    assert!(me.stats().resubscriptions >= 2);
    seen_me.lock().unwrap().clear();
    wait_for(
        "the far robot's keyframe after the move",
        Duration::from_secs(20),
        Duration::from_millis(10),
        || {
            far.send(2, None, &keyframe).unwrap();
            near.send(1, None, &keyframe).unwrap();
            std::thread::sleep(Duration::from_millis(50));
            heard(&seen_me, 2, &keyframe)
        },
    );
    near.send(1, None, &keyframe).unwrap();
    std::thread::sleep(Duration::from_millis(200));
    assert!(
        !heard(&seen_me, 1, &keyframe),
        "the old neighbour's keyframe"
    );
    for t in [me, near, far, all] {
        t.close().unwrap();
    }
    router.close().wait().unwrap();
}
