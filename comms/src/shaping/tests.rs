//! Shaping conformance in sim time.

use proptest::prelude::*;

use super::*;

const MS: u64 = 1_000_000;
const S: u64 = 1_000_000_000;

fn config(rate_bps: u64, burst_bytes: u64, mtu_bytes: usize) -> ShaperConfig {
    ShaperConfig {
        rate_bps: Some(rate_bps),
        burst_bytes,
        mtu_bytes,
        ..ShaperConfig::default()
    }
}

/// `c` with keyframes stored and forwarded, at most `capacity_messages` of them.
fn storing_keyframes(mut c: ShaperConfig, capacity_messages: usize) -> ShaperConfig {
    c.keyframe = ClassConfig {
        capacity_messages,
        ..ClassConfig::store_and_forward()
    };
    c
}

/// Transmission time of `bytes` at `rate_bps`, ns (rounded up).
/// Sends everything the shaper has from `now` on (at most 10 s of it); returns the
/// frames and the time it stopped.
fn drain(s: &mut LinkShaper, mut now: u64) -> (Vec<Frame>, u64) {
    let mut frames = Vec::new();
    let end = now + 10 * S;
    while let Some(next) = s.next_send_time(now) {
        if next > end {
            break;
        }
        now = next;
        match s.poll(now) {
            Some(f) => frames.push(f),
            None if s.next_send_time(now) == Some(now) => break,
            None => {}
        }
        if frames.len() > 10_000 {
            break;
        }
    }
    (frames, now)
}

fn tx_ns(bytes: usize, rate_bps: u64) -> u64 {
    (bytes as u64 * 8 * S).div_ceil(rate_bps)
}

/// The id of the message whose last fragment a frame of `kind` carries; `None` for
/// other fragments and for acknowledgements.
fn completed_message(kind: &FrameKind) -> Option<u32> {
    match *kind {
        FrameKind::Data {
            message_id,
            index,
            count,
        } if index + 1 == count => Some(message_id),
        _ => None,
    }
}

/// Drives one shaper: offers at their times, polls whenever it may send, until
/// `until_ns`. Returns each frame with its poll time.
fn drive(
    shaper: &mut LinkShaper,
    offers: &[(u64, Class, usize)],
    until_ns: u64,
    mut on_frame: impl FnMut(u64, Frame),
) {
    let mut next_offer = 0;
    let mut now = 0;
    loop {
        let offer_t = offers.get(next_offer).map(|o| o.0);
        let send_t = shaper.next_send_time(now);
        let Some(t) = [offer_t, send_t].into_iter().flatten().min() else {
            break;
        };
        if t > until_ns {
            break;
        }
        assert!(t >= now, "time went backwards");
        now = t;
        while let Some(&(ot, class, len)) = offers.get(next_offer) {
            if ot > now {
                break;
            }
            let _ = shaper.offer(now, class, vec![class.index() as u8; len]);
            next_offer += 1;
        }
        let mut sent = false;
        while let Some(f) = shaper.poll(now) {
            sent = true;
            on_frame(now, f);
        }
        if !sent && send_t == Some(now) && offer_t != Some(now) {
            panic!("next_send_time promised a frame at {now} that poll did not give");
        }
    }
}

#[test]
fn saturated_250kbps_link_delivers_rate_times_time_plus_burst() {
    let (rate, burst) = (250_000u64, 4_000u64);
    let mut c = config(rate, burst, 1_200);
    c.keyframe.capacity_messages = 16;
    let mut shaper = LinkShaper::new(c).unwrap();
    // 6 kB keyframes at 10 Hz: 480 kbit/s offered, about twice the rate.
    let offers: Vec<_> = (0..600)
        .map(|i| (i * 100 * MS, Class::Keyframe, 6_039))
        .collect();
    let mut delivered = 0u64;
    drive(&mut shaper, &offers, 60 * S, |_, f| {
        delivered += f.bytes.len() as u64
    });
    let bound = rate * 60 / 8 + burst;
    let ratio = delivered as f64 / bound as f64;
    eprintln!("saturated 250 kbit/s for 60 s: {delivered} B of {bound} B ({ratio:.4})");
    assert!((0.95..=1.0).contains(&ratio), "{ratio}");
    assert_eq!(shaper.stats().total_sent_bytes(), delivered);
    assert!(shaper.stats().class(Class::Keyframe).drops.overflow > 0);
}

/// Delays through shaper + a serialising link at the same rate (what a radio
/// does with what the shaper releases). Returns per-class max end-to-end delay
/// (offer → last byte of the message received), ns.
fn priority_run(mtu: usize, burst: u64) -> ([u64; 4], ShaperStats) {
    let rate = 250_000;
    let mut shaper = LinkShaper::new(config(rate, burst, mtu)).unwrap();
    let mut offers = Vec::new();
    for i in 0..600u64 {
        offers.push((i * 100 * MS, Class::Odometry, 90)); // 10 Hz odometry
        offers.push((i * 100 * MS + 37 * MS, Class::Keyframe, 6_039)); // 10 Hz keyframes
        if i % 10 == 3 {
            offers.push((i * 100 * MS + 51 * MS, Class::Plan, 615)); // 1 Hz plans
        }
    }
    offers.sort_by_key(|o| o.0);
    // Message ids are assigned in offer order (every offer is accepted here).
    let offered_at: std::collections::HashMap<u32, u64> = offers
        .iter()
        .enumerate()
        .map(|(id, o)| (id as u32, o.0))
        .collect();
    let mut link_free = 0u64;
    let mut worst = [0u64; 4];
    drive(&mut shaper, &offers, 60 * S, |t, f| {
        let arrival = t.max(link_free) + tx_ns(f.bytes.len(), rate);
        link_free = arrival;
        if let Some(message_id) = completed_message(&f.kind) {
            let d = arrival - offered_at[&message_id];
            let w = &mut worst[f.class.index()];
            *w = (*w).max(d);
        }
    });
    (worst, *shaper.stats())
}

/// While keyframes saturate the link, odometry and plans keep a bounded delay.
///
/// Bound: the bucket's credit is never negative and a lower class is never
/// chosen while a higher one waits, so a message leaves the shaper within
/// (its own frame bytes + higher-priority frame bytes offered meanwhile) · 8 /
/// rate. The link behind it serialises at the same rate and never holds more
/// than `burst_bytes` of earlier frames (token-bucket output into a server of
/// the same rate), adding at most burst · 8 / rate. With one MTU of burst:
/// odometry ≤ (101 + 1200) B, plans ≤ (626 + 101 + 1200) B at 250 kbit/s, i.e.
/// 41.6 ms and 61.7 ms — against 193 ms for a whole 6 kB keyframe.
#[test]
fn odometry_and_plans_keep_a_bounded_delay_while_keyframes_saturate() {
    let (mtu, rate) = (1_200usize, 250_000);
    let (worst, stats) = priority_run(mtu, mtu as u64);
    let odometry_bound = tx_ns(90 + DATA_HEADER_BYTES + mtu, rate);
    let plan_bound = tx_ns(615 + DATA_HEADER_BYTES + 90 + DATA_HEADER_BYTES + mtu, rate);
    eprintln!(
        "fragmented (MTU {mtu}): worst odometry {:.1} ms (bound {:.1}), plan {:.1} ms (bound {:.1})",
        worst[0] as f64 / 1e6,
        odometry_bound as f64 / 1e6,
        worst[1] as f64 / 1e6,
        plan_bound as f64 / 1e6
    );
    assert!(worst[0] <= odometry_bound, "odometry {}", worst[0]);
    assert!(worst[1] <= plan_bound, "plan {}", worst[1]);
    assert_eq!(stats.class(Class::Odometry).sent_messages, 600);
    assert_eq!(stats.class(Class::Plan).sent_messages, 60);
    assert_eq!(stats.class(Class::Odometry).drops.total(), 0);
    // Keyframes still get the rest of the link.
    assert!(stats.class(Class::Keyframe).sent_messages > 250);

    // Without fragmentation (one frame per keyframe, burst to match) a plan can
    // wait behind a whole keyframe on the link.
    let (worst_whole, _) = priority_run(7_000, 7_000);
    eprintln!(
        "unfragmented: worst odometry {:.1} ms, plan {:.1} ms",
        worst_whole[0] as f64 / 1e6,
        worst_whole[1] as f64 / 1e6
    );
    assert!(worst_whole[1] > tx_ns(6_039, rate));
}

/// A→B keyframes over store-and-forward, B→A acknowledgements, both through
/// shapers; every frame in either direction sent during the partition is lost.
#[test]
fn store_and_forward_loses_nothing_over_a_30s_partition() {
    let (rate, mtu) = (250_000, 1_200);
    let c = storing_keyframes(config(rate, mtu as u64, mtu), 64);
    let mut a = LinkShaper::new(c).unwrap();
    let mut b = LinkShaper::new(c).unwrap();
    a.add_peer(1);
    b.add_peer(0);
    let mut at_b = Reassembler::default();
    let mut at_a = Reassembler::default();
    let partitioned = |t: u64| (10 * S..40 * S).contains(&t);
    let latency = 20 * MS;
    // In flight: (arrival, to_b, bytes).
    let mut flight: Vec<(u64, bool, Vec<u8>)> = Vec::new();
    let mut accepted = Vec::new();
    let mut received = Vec::new();
    let mut now = 0u64;
    let mut next_offer = 0u64;
    while now <= 120 * S {
        let t_offer = (next_offer < 60).then_some(next_offer * S);
        let t_flight = flight.iter().map(|f| f.0).min();
        let candidates = [
            t_offer,
            a.next_send_time(now),
            b.next_send_time(now),
            t_flight,
        ];
        let Some(t) = candidates.into_iter().flatten().min() else {
            break;
        };
        now = t;
        if t_offer == Some(now) {
            let body = (next_offer as u32).to_le_bytes().repeat(1_500); // 6 kB
            accepted.push(a.offer(now, Class::Keyframe, body).unwrap().0);
            next_offer += 1;
        }
        let (due, rest): (Vec<_>, Vec<_>) = flight.drain(..).partition(|f| f.0 <= now);
        flight = rest;
        for (_, to_b, bytes) in due {
            if to_b {
                match at_b.push(now, 0, &bytes).unwrap() {
                    Some(Incoming::Message(m)) => {
                        received.push(m.message_id);
                        assert!(m.ack_requested);
                        b.queue_ack(0, m.message_id);
                    }
                    Some(Incoming::Duplicate {
                        message_id,
                        ack_requested: true,
                        ..
                    }) => b.queue_ack(0, message_id),
                    _ => {}
                }
            } else if let Some(Incoming::Ack { ids, .. }) = at_a.push(now, 1, &bytes).unwrap() {
                for id in ids {
                    a.acknowledge(now, 1, MessageId(id));
                }
            }
        }
        for (shaper, to_b) in [(&mut a, true), (&mut b, false)] {
            while let Some(f) = shaper.poll(now) {
                if !partitioned(now) {
                    flight.push((now + latency, to_b, f.bytes));
                }
            }
        }
    }
    let stats = a.stats().class(Class::Keyframe);
    eprintln!(
        "store-and-forward over a 30 s partition: {} accepted, {} received, {} retransmissions, {} duplicates at the receiver",
        accepted.len(),
        received.len(),
        stats.retransmitted_messages,
        at_b.stats().duplicates
    );
    assert_eq!(accepted.len(), 60);
    assert_eq!(
        received, accepted,
        "every accepted keyframe, once, in order"
    );
    assert_eq!(stats.drops.total(), 0);
    assert_eq!(stats.acknowledged_messages, 60);
    assert_eq!(
        a.queued_messages(Class::Keyframe),
        0,
        "store empty once acknowledged"
    );
    assert!(stats.retransmitted_messages > 0);
}

/// What [`three_robots`] saw: per receiver (1 and 2), the message ids it
/// completed (first time only) with the time.
struct TeamRun {
    accepted: Vec<u32>,
    received: [Vec<(u32, u64)>; 2],
    /// Most messages robot 0 stored at any time during the run.
    max_stored: usize,
    sender: LinkShaper,
}

/// Robot 0 sends 60 store-and-forward keyframes (one per second) to robots 1 and
/// 2, which acknowledge; every frame between 0 and `cut` (both ways) sent while
/// `partitioned(t)` is lost. Frames honour their addressee (`Frame::to`).
fn three_robots(cut: u32, partitioned: impl Fn(u64) -> bool) -> TeamRun {
    let (rate, mtu) = (250_000, 1_200);
    let c = storing_keyframes(config(rate, mtu as u64, mtu), 64);
    let mut shapers: Vec<LinkShaper> = (0..3).map(|_| LinkShaper::new(c).unwrap()).collect();
    for (me, s) in shapers.iter_mut().enumerate() {
        for peer in 0..3u32 {
            if peer != me as u32 {
                s.add_peer(peer);
            }
        }
    }
    let mut receivers: Vec<Reassembler> = (0..3).map(|_| Reassembler::default()).collect();
    let latency = 20 * MS;
    // In flight: (arrival, from, to, bytes).
    let mut flight: Vec<(u64, u32, u32, Vec<u8>)> = Vec::new();
    let mut run = TeamRun {
        accepted: Vec::new(),
        received: [Vec::new(), Vec::new()],
        max_stored: 0,
        sender: LinkShaper::new(c).unwrap(),
    };
    let mut now = 0u64;
    let mut next_offer = 0u64;
    while now <= 150 * S {
        let t_offer = (next_offer < 60).then_some(next_offer * S);
        let t_flight = flight.iter().map(|f| f.0).min();
        let mut candidates = vec![t_offer, t_flight];
        candidates.extend(shapers.iter_mut().map(|s| s.next_send_time(now)));
        let Some(t) = candidates.into_iter().flatten().min() else {
            break;
        };
        now = t;
        if t_offer == Some(now) {
            let body = (next_offer as u32).to_le_bytes().repeat(1_500); // 6 kB
            run.accepted
                .push(shapers[0].offer(now, Class::Keyframe, body).unwrap().0);
            next_offer += 1;
        }
        let (due, rest): (Vec<_>, Vec<_>) = flight.drain(..).partition(|f| f.0 <= now);
        flight = rest;
        for (_, from, to, bytes) in due {
            match receivers[to as usize].push(now, from, &bytes).unwrap() {
                Some(Incoming::Message(m)) => {
                    assert_eq!(from, 0);
                    run.received[to as usize - 1].push((m.message_id, now));
                    shapers[to as usize].queue_ack(from, m.message_id);
                }
                Some(Incoming::Duplicate {
                    message_id,
                    ack_requested: true,
                    ..
                }) => shapers[to as usize].queue_ack(from, message_id),
                Some(Incoming::Ack { ids, .. }) => {
                    for id in ids {
                        shapers[to as usize].acknowledge(now, from, MessageId(id));
                    }
                }
                _ => {}
            }
        }
        for (from, shaper) in shapers.iter_mut().enumerate() {
            let from = from as u32;
            while let Some(f) = shaper.poll(now) {
                for to in 0..3u32 {
                    let addressed = f.to.map_or(to != from, |p| p == to);
                    let cut_off = (from, to) == (0, cut) || (from, to) == (cut, 0);
                    if addressed && !(cut_off && partitioned(now)) {
                        flight.push((now + latency, from, to, f.bytes.clone()));
                    }
                }
            }
        }
        run.max_stored = run
            .max_stored
            .max(shapers[0].queued_messages(Class::Keyframe));
    }
    run.sender = shapers.swap_remove(0);
    run
}

/// Issue 3: partition one pair only (0–1 from 10 to 40 s; 0–2 stays up). Nothing
/// accepted is lost for robot 1, which receives every stored keyframe once and in
/// order after healing; robot 2 is not held back meanwhile; and the store keeps
/// each message until both peers have it.
#[test]
fn store_and_forward_is_per_peer_when_one_pair_is_partitioned() {
    let run = three_robots(1, |t| (10 * S..40 * S).contains(&t));
    assert_eq!(run.accepted.len(), 60);
    for (peer, got) in run.received.iter().enumerate() {
        let ids: Vec<u32> = got.iter().map(|(id, _)| *id).collect();
        assert_eq!(
            ids,
            run.accepted,
            "robot {}: every keyframe, once, in order",
            peer + 1
        );
    }
    // Robot 2 got each keyframe within a second of its offer, partition or not.
    for (i, (_, at)) in run.received[1].iter().enumerate() {
        assert!(
            *at < i as u64 * S + S,
            "keyframe {i} reached robot 2 at {at} ns"
        );
    }
    // Robot 1 got nothing offered during the partition before it healed.
    let late = run.received[0]
        .iter()
        .filter(|(id, at)| (10..40).contains(id) && *at >= 40 * S);
    assert_eq!(late.count(), 30);
    // Robot 2's acknowledgements alone released nothing: about 30 messages
    // waited for robot 1.
    assert!(run.max_stored >= 29, "{} stored at most", run.max_stored);
    let stats = run.sender.stats().class(Class::Keyframe);
    assert_eq!(stats.drops.total(), 0);
    assert_eq!(stats.acknowledged_messages, 60);
    assert_eq!(run.sender.queued_messages(Class::Keyframe), 0);
}

#[test]
fn removing_a_peer_gives_its_messages_up_and_counts_them() {
    let mut c = config(100_000, 1_200, 1_200);
    c.keyframe = ClassConfig::store_and_forward();
    let mut s = LinkShaper::new(c).unwrap();
    // Offered before any peer is known: kept for the first peers.
    s.offer(0, Class::Keyframe, vec![1; 100]).unwrap();
    assert!(s.add_peer(1));
    assert!(s.add_peer(2));
    assert!(!s.add_peer(2));
    s.offer(0, Class::Keyframe, vec![2; 100]).unwrap();
    // Not sent yet: an acknowledgement cannot be real.
    assert_eq!(s.acknowledge(0, 1, MessageId(0)), AckOutcome::NotSent);
    drain(&mut s, 0);
    assert!(s.acknowledge(0, 1, MessageId(0)).recorded());
    assert!(s.acknowledge(0, 1, MessageId(1)).recorded());
    assert_eq!(s.queued_messages(Class::Keyframe), 2, "robot 2 misses both");
    assert!(s.acknowledge(0, 2, MessageId(0)).recorded());
    assert_eq!(s.queued_messages(Class::Keyframe), 1);
    assert_eq!(s.remove_peer(2), 1);
    assert_eq!(s.queued_messages(Class::Keyframe), 0);
    let st = s.stats().class(Class::Keyframe);
    assert_eq!(st.drops.peer_removed, 1);
    assert_eq!(st.acknowledged_messages, 1);
    assert_eq!(s.peers(), vec![1]);
}

#[test]
fn a_full_store_refuses_and_keeps_what_it_accepted() {
    let c = storing_keyframes(config(100_000, 1_200, 1_200), 3);
    let mut s = LinkShaper::new(c).unwrap();
    s.add_peer(1);
    for i in 0..3 {
        s.offer(0, Class::Keyframe, vec![i; 100]).unwrap();
    }
    assert_eq!(
        s.offer(0, Class::Keyframe, vec![9; 100]),
        Err(Refused::StoreFull)
    );
    // Sending does not free the store; acknowledging does.
    let mut t = 0;
    while let Some(next) = s.next_send_time(t) {
        t = next;
        if s.poll(t).is_none() || t > 10 * S {
            break;
        }
    }
    assert_eq!(s.queued_messages(Class::Keyframe), 3);
    assert_eq!(
        s.offer(t, Class::Keyframe, vec![9; 100]),
        Err(Refused::StoreFull)
    );
    assert!(s.acknowledge(t, 1, MessageId(0)).recorded());
    assert!(!s.acknowledge(t, 1, MessageId(0)).recorded());
    assert!(s.offer(t, Class::Keyframe, vec![9; 100]).is_ok());
    let st = s.stats().class(Class::Keyframe);
    assert_eq!(st.drops.store_full, 2);
    assert_eq!(st.acknowledged_messages, 1);
}

#[test]
fn keep_latest_supersedes_and_drop_oldest_overflows() {
    let mut c = config(8_000, 1_200, 1_200); // 1 kB/s: nothing drains quickly
    c.bulk = ClassConfig {
        capacity_messages: 2,
        ..ClassConfig::default()
    };
    let mut s = LinkShaper::new(c).unwrap();
    // Odometry: a partly sent message is finished; waiting ones are replaced.
    s.offer(0, Class::Odometry, vec![1; 2_000]).unwrap();
    let first = s.poll(0).unwrap(); // fragment 0 of 2
    assert!(matches!(
        first.kind,
        FrameKind::Data {
            index: 0,
            count: 2,
            ..
        }
    ));
    s.offer(0, Class::Odometry, vec![2; 50]).unwrap();
    s.offer(0, Class::Odometry, vec![3; 50]).unwrap();
    assert_eq!(s.queued_messages(Class::Odometry), 2);
    assert_eq!(s.stats().class(Class::Odometry).drops.superseded, 1);
    // Bulk: a bounded FIFO that drops its oldest.
    for i in 0..5 {
        s.offer(0, Class::Bulk, vec![i; 10]).unwrap();
    }
    assert_eq!(s.queued_messages(Class::Bulk), 2);
    assert_eq!(s.stats().class(Class::Bulk).drops.overflow, 3);
    // Too large for the class capacity.
    c.plan.capacity_bytes = 100;
    let mut s = LinkShaper::new(c).unwrap();
    assert!(matches!(
        s.offer(0, Class::Plan, vec![0; 101]),
        Err(Refused::TooLarge { .. })
    ));
    assert_eq!(s.stats().class(Class::Plan).drops.too_large, 1);
}

#[test]
fn unlimited_links_send_at_once_and_count_bytes() {
    let mut s = LinkShaper::new(ShaperConfig::default()).unwrap();
    s.offer(5, Class::Keyframe, vec![0; 10_000]).unwrap();
    assert_eq!(s.next_send_time(5), Some(5));
    let mut n = 0;
    while s.poll(5).is_some() {
        n += 1;
    }
    assert_eq!(n, 10_000usize.div_ceil(1_200 - DATA_HEADER_BYTES));
    assert_eq!(s.next_send_time(5), None);
    let st = s.stats().class(Class::Keyframe);
    assert_eq!(st.sent_bytes, 10_000 + n as u64 * DATA_HEADER_BYTES as u64);
    assert_eq!(st.completion_delay.max_ns, 0);
}

#[test]
fn age_of_information_is_a_time_average() {
    let mut a = AgeOfInformation::default();
    // Updates generated every second, delivered 0.2 s later: age saws between
    // 0.2 and 1.2 s, mean 0.7 s.
    for i in 0..100u64 {
        a.record(i * S + 200 * MS, i * S);
    }
    let mean = a.mean_s(99 * S + 200 * MS).unwrap();
    assert!((mean - 0.7).abs() < 1e-9, "{mean}");
    assert!((a.peak_ns as f64 * 1e-9 - 1.2).abs() < 1e-9);
    // A stale update does not make the information younger.
    a.record(100 * S, 5 * S);
    assert_eq!(a.newest_generated_ns, Some(99 * S));
}

#[test]
fn reassembler_bounds_memory_times_out_and_drops_duplicates() {
    let r_config = ReassemblyConfig {
        max_bytes: 10_000,
        max_messages: 4,
        timeout_s: 1.0,
        dedup_window: 8,
    };
    let mut r = Reassembler::new(r_config).unwrap();
    let mut s = LinkShaper::new(ShaperConfig::default()).unwrap();
    // Six 3-fragment messages; deliver only the first fragment of each.
    for i in 0..6u8 {
        s.offer(0, Class::Bulk, vec![i; 3_000]).unwrap();
    }
    let frames: Vec<Frame> = std::iter::from_fn(|| s.poll(0)).collect();
    assert_eq!(frames.len(), 18);
    for f in frames.iter().step_by(3) {
        assert_eq!(r.push(0, 7, &f.bytes).unwrap(), None);
    }
    assert_eq!(r.partial_messages(), 4);
    assert_eq!(r.stats().evicted, 2);
    assert!(r.held_bytes() <= 10_000);
    // Time out the rest.
    r.expire(2 * S);
    assert_eq!(r.partial_messages(), 0);
    assert_eq!(r.held_bytes(), 0);
    assert_eq!(r.stats().incomplete_timed_out, 4);
    // Complete one message, out of order, then see its fragments again.
    let msg: Vec<&Frame> = frames[3..6].iter().collect();
    assert_eq!(r.push(3 * S, 7, &msg[2].bytes).unwrap(), None);
    assert_eq!(r.push(3 * S, 7, &msg[0].bytes).unwrap(), None);
    let Some(Incoming::Message(m)) = r.push(3 * S, 7, &msg[1].bytes).unwrap() else {
        panic!("expected a message");
    };
    assert_eq!(
        (m.message_id, m.bytes.len(), m.class),
        (1, 3_000, Class::Bulk)
    );
    assert_eq!(r.push(3 * S, 7, &msg[0].bytes).unwrap(), None);
    assert!(matches!(
        r.push(3 * S, 7, &msg[2].bytes).unwrap(),
        Some(Incoming::Duplicate {
            message_id: 1,
            ack_requested: false,
            ..
        })
    ));
    assert_eq!(r.stats().duplicates, 2);
    // The same id from another source is another message.
    assert_eq!(r.push(3 * S, 8, &msg[0].bytes).unwrap(), None);
}

#[test]
fn reassembler_rejects_malformed_frames() {
    let mut r = Reassembler::default();
    assert_eq!(r.push(0, 0, &[]), Err(FrameError::Truncated(0)));
    assert_eq!(r.push(0, 0, &[9]), Err(FrameError::UnknownKind(9)));
    assert_eq!(r.push(0, 0, &[0, 1, 0]), Err(FrameError::Truncated(3)));
    let mut bad_class = frame::data_frame(
        &DataHeader {
            class: Class::Bulk,
            ack_requested: false,
            message_id: 1,
            index: 0,
            count: 2,
        },
        b"abc",
    );
    bad_class[1] = 4;
    assert_eq!(r.push(0, 0, &bad_class), Err(FrameError::UnknownClass(4)));
    let mut bad_index = bad_class.clone();
    bad_index[1] = 0;
    bad_index[7] = 2;
    assert!(matches!(
        r.push(0, 0, &bad_index),
        Err(FrameError::BadFragment { .. })
    ));
    assert_eq!(
        r.push(0, 0, &[1, 2, 0, 1, 2, 3, 4]),
        Err(FrameError::BadAck)
    );
    // Fragment counts that disagree.
    let f = |count| {
        frame::data_frame(
            &DataHeader {
                class: Class::Bulk,
                ack_requested: false,
                message_id: 5,
                index: 0,
                count,
            },
            b"x",
        )
    };
    assert_eq!(r.push(0, 0, &f(3)).unwrap(), None);
    assert_eq!(r.push(0, 0, &f(4)), Err(FrameError::Inconsistent(5)));
    assert_eq!(r.stats().malformed_frames, 7);
}

#[test]
fn config_reads_from_toml_and_names_bad_keys() {
    let c: ShaperConfig = toml::from_str(
        "rate_bps = 100_000\nburst_bytes = 2000\nmtu_bytes = 1000\n[plan]\npolicy = \"keep_latest\"\n",
    )
    .unwrap();
    c.validate().unwrap();
    assert_eq!(c.plan.policy, QueuePolicy::KeepLatest);
    assert_eq!(
        c.odometry,
        ClassConfig::keep_latest(),
        "untouched tables keep their default"
    );
    // A class table changes the keys it names; the rest keep that class's default.
    let partial: ShaperConfig =
        toml::from_str("[odometry]\ncapacity_messages = 3\n[keyframe]\nwindow_messages = 2\n")
            .unwrap();
    assert_eq!(partial.odometry.policy, QueuePolicy::KeepLatest);
    assert_eq!(partial.odometry.capacity_messages, 3);
    assert_eq!(partial.keyframe.policy, QueuePolicy::DropOldest);
    assert!(toml::from_str::<ShaperConfig>("[plan]\npolcy = \"drop_oldest\"\n").is_err());
    assert!(toml::from_str::<ShaperConfig>("rate_bsp = 1").is_err());
    let err = |c: ShaperConfig| c.validate().unwrap_err().key;
    assert_eq!(
        err(ShaperConfig {
            rate_bps: Some(0),
            ..c
        }),
        "rate_bps"
    );
    assert_eq!(err(ShaperConfig { mtu_bytes: 10, ..c }), "mtu_bytes");
    assert_eq!(
        err(ShaperConfig {
            burst_bytes: 999,
            ..c
        }),
        "burst_bytes"
    );
    let mut bad = c;
    bad.keyframe.retransmit_timeout_s = f64::NAN;
    assert_eq!(err(bad), "keyframe.retransmit_timeout_s");
    let e = ShaperConfig { mtu_bytes: 10, ..c }.validate().unwrap_err();
    assert_eq!(
        e.to_string(),
        "`mtu_bytes` must be between 64 and 65507, got 10"
    );
    assert_eq!(
        ReassemblyConfig {
            timeout_s: -1.0,
            ..ReassemblyConfig::default()
        }
        .validate()
        .unwrap_err()
        .key,
        "timeout_s"
    );
}

proptest! {
    #[test]
    fn reassembler_never_panics_on_random_frames(
        frames in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..40), 0..40),
    ) {
        let mut r = Reassembler::new(ReassemblyConfig { max_bytes: 200, max_messages: 3, ..ReassemblyConfig::default() }).unwrap();
        for (i, f) in frames.iter().enumerate() {
            let _ = r.push(i as u64 * MS, (i % 2) as u32, f);
            prop_assert!(r.held_bytes() <= 200);
            prop_assert!(r.partial_messages() <= 3);
        }
    }

    /// Whatever the sizes and MTU, fragments reassemble to the original bytes,
    /// and no frame exceeds the MTU.
    #[test]
    fn fragments_reassemble_exactly(
        mtu in 64usize..2_000,
        sizes in proptest::collection::vec(0usize..5_000, 1..6),
    ) {
        let mut s = LinkShaper::new(ShaperConfig { mtu_bytes: mtu, ..ShaperConfig::default() }).unwrap();
        let mut r = Reassembler::default();
        let messages: Vec<Vec<u8>> = sizes.iter().enumerate().map(|(i, n)| (0..*n).map(|j| (i * 31 + j) as u8).collect()).collect();
        for m in &messages {
            s.offer(0, Class::Bulk, m.clone()).unwrap();
        }
        let mut out = Vec::new();
        while let Some(f) = s.poll(0) {
            prop_assert!(f.bytes.len() <= mtu);
            if let Some(Incoming::Message(m)) = r.push(0, 0, &f.bytes).unwrap() {
                out.push(m.bytes);
            }
        }
        prop_assert_eq!(out, messages);
    }
}

/// Runs `sender` against two peers with their own reassemblers until nothing is
/// left to send (or 60 s), acknowledging what they complete. Returns the ids each
/// peer completed and the ids it saw again as duplicates.
fn deliver_to_two_peers(
    sender: &mut LinkShaper,
    receivers: &mut [Reassembler; 2],
    mut now: u64,
) -> [(Vec<u32>, Vec<u32>); 2] {
    let mut out: [(Vec<u32>, Vec<u32>); 2] = Default::default();
    let end = now + 60 * S;
    while let Some(t) = sender.next_send_time(now) {
        if t > end {
            break;
        }
        now = t;
        while let Some(frame) = sender.poll(now) {
            for (peer, receiver) in [1u32, 2].into_iter().zip(receivers.iter_mut()) {
                if frame.to.is_some_and(|to| to != peer) {
                    continue;
                }
                let got = &mut out[peer as usize - 1];
                match receiver.push(now, 0, &frame.bytes).unwrap() {
                    Some(Incoming::Message(m)) => {
                        got.0.push(m.message_id);
                        sender.acknowledge(now, peer, MessageId(m.message_id));
                    }
                    Some(Incoming::Duplicate { message_id, .. }) => {
                        got.1.push(message_id);
                        sender.acknowledge(now, peer, MessageId(message_id));
                    }
                    _ => {}
                }
            }
        }
    }
    out
}

/// A link that restarts from its durable state loses nothing it accepted: every
/// stored message reaches each recipient that had not acknowledged it, under its
/// old id (a peer that had it already sees a duplicate, not a new message), and new
/// messages continue the id sequence instead of colliding with ids peers remember.
#[test]
fn a_restored_shaper_delivers_what_was_stored_and_continues_the_ids() {
    let mut c = config(100_000, 1_200, 1_200);
    c.keyframe = ClassConfig::store_and_forward();
    let mut before = LinkShaper::new(c).unwrap();
    before.add_peer(1);
    before.add_peer(2);
    let mut receivers = [Reassembler::default(), Reassembler::default()];
    let generation = before.store_generation();
    before.offer(0, Class::Odometry, vec![1; 40]).unwrap();
    assert_eq!(
        before.store_generation(),
        generation,
        "odometry is not stored"
    );
    for i in 0..4 {
        before.offer(0, Class::Keyframe, vec![i; 3_000]).unwrap();
    }
    assert_ne!(before.store_generation(), generation);
    drain(&mut before, 0);
    // Both robots acknowledge the first keyframe; robot 1 also receives the second
    // but its acknowledgement is lost; then the link restarts.
    before.acknowledge(0, 1, MessageId(1));
    before.acknowledge(0, 2, MessageId(1));
    let state = before.durable_state();
    assert_eq!(state.next_id, 5);
    assert_eq!(state.peers, vec![1, 2]);
    let missing: Vec<(u32, Vec<u32>)> = state
        .stored
        .iter()
        .map(|m| (m.id.0, m.missing.clone()))
        .collect();
    assert_eq!(
        missing,
        vec![(2, vec![1, 2]), (3, vec![1, 2]), (4, vec![1, 2])],
        "message 1 left the store; each keeps who still misses it"
    );
    // Robot 1 did complete messages 0–2 earlier: its reassembler remembers them.
    let mut earlier = LinkShaper::new(c).unwrap();
    earlier.add_peer(1);
    for i in 0..3 {
        earlier.offer(0, Class::Keyframe, vec![i; 3_000]).unwrap();
    }
    let mut warm = [Reassembler::default(), Reassembler::default()];
    let got = deliver_to_two_peers(&mut earlier, &mut warm, 0);
    assert_eq!(got[0].0, vec![0, 1, 2]);
    receivers[0] = warm[0].clone();

    let mut after = LinkShaper::restore(c, &state).unwrap();
    assert_eq!(after.next_id(), MessageId(5));
    assert_eq!(after.queued_messages(Class::Keyframe), 3);
    let id = after.offer(S, Class::Keyframe, vec![9; 3_000]).unwrap();
    assert_eq!(id, MessageId(5), "ids go on");
    let got = deliver_to_two_peers(&mut after, &mut receivers, S);
    assert_eq!(
        got[0].0,
        vec![3, 4, 5],
        "robot 1: what it missed, and the new one"
    );
    assert_eq!(
        got[0].1,
        vec![2],
        "robot 1 had message 2: a duplicate, acknowledged"
    );
    assert_eq!(
        got[1].0,
        vec![2, 3, 4, 5],
        "robot 2: what it missed, and the new one"
    );
    assert_eq!(
        after.queued_messages(Class::Keyframe),
        0,
        "all acknowledged"
    );
    assert_eq!(after.stats().class(Class::Keyframe).drops.total(), 0);
}

#[test]
fn restoring_keeps_stored_messages_beyond_a_smaller_capacity() {
    let mut c = config(100_000, 1_200, 1_200);
    c.keyframe = ClassConfig::store_and_forward();
    let mut s = LinkShaper::new(c).unwrap();
    s.add_peer(1);
    for i in 0..5 {
        s.offer(0, Class::Keyframe, vec![i; 100]).unwrap();
    }
    c.keyframe.capacity_messages = 2;
    let mut restored = LinkShaper::restore(c, &s.durable_state()).unwrap();
    assert_eq!(restored.queued_messages(Class::Keyframe), 5);
    assert_eq!(
        restored.offer(0, Class::Keyframe, vec![9; 100]),
        Err(Refused::StoreFull)
    );
    // A class that is no longer store-and-forward sends them once from its queue.
    c.keyframe = ClassConfig::default();
    let queued = LinkShaper::restore(c, &s.durable_state()).unwrap();
    assert_eq!(queued.queued_messages(Class::Keyframe), 5);
}

/// Extra lanes: a store-and-forward lane at plan priority next to the keep-latest
/// plan class, under a saturated 100 kbit/s keyframe class.
#[test]
fn an_extra_lane_keeps_its_own_policy_priority_counters_and_addressee() {
    let mut shaper = LinkShaper::new(config(100_000, 1_300, 1_200)).unwrap();
    shaper.add_peer(1);
    shaper.add_peer(2);
    let lane = shaper
        .add_lane(Class::Plan, ClassConfig::store_and_forward())
        .unwrap();
    assert!(shaper.lane_stats(LaneId(1)).is_none());
    // Keyframes flood the link; 5 reports and 5 plans arrive at once.
    for _ in 0..20 {
        shaper.offer(0, Class::Keyframe, vec![2; 5_000]).unwrap();
    }
    for i in 0..5u8 {
        shaper.offer(0, Class::Plan, vec![1; 100]).unwrap();
        let to = (i == 4).then_some(2);
        shaper.offer_to_lane(0, lane, to, vec![10 + i; 60]).unwrap();
    }
    // Keep-latest plans supersede each other; the lane's stored reports do not.
    assert_eq!(shaper.stats().class(Class::Plan).drops.superseded, 4);
    assert_eq!(shaper.lane_queued_messages(lane), 5);
    let mut frames = Vec::new();
    let mut now = 0;
    while frames.len() < 8 {
        now = shaper.next_send_time(now).unwrap();
        while let Some(f) = shaper.poll(now) {
            frames.push(f);
        }
    }
    // The plan goes first (its class's own queue), then the five reports,
    // before any keyframe fragment.
    assert_eq!(frames[0].class, Class::Plan);
    for (i, f) in frames[1..6].iter().enumerate() {
        assert_eq!(f.class, Class::Plan);
        assert_eq!(f.bytes.last(), Some(&(10 + i as u8)));
        assert_eq!(f.to, if i == 4 { Some(2) } else { None });
    }
    assert_eq!(frames[6].class, Class::Keyframe);
    let stats = shaper.lane_stats(lane).unwrap();
    assert_eq!((stats.offered_messages, stats.sent_messages), (5, 5));
    assert_eq!(shaper.stats().class(Class::Plan).sent_messages, 1);
    // The link's total counts the lane's frames too.
    let lane_bytes: u64 = frames[1..6].iter().map(|f| f.bytes.len() as u64).sum();
    assert_eq!(shaper.stats().lane_sent_bytes, lane_bytes);
    assert_eq!(stats.sent_bytes, lane_bytes);
    assert_eq!(
        shaper.stats().total_sent_bytes(),
        frames.iter().map(|f| f.bytes.len() as u64).sum::<u64>()
    );
    // The last five reports wait for acks: the addressed one from robot 2 only.
    let state = shaper.durable_state();
    assert_eq!(state.stored.len(), 5);
    assert!(state.stored.iter().all(|m| m.lane == Some(lane)));
    assert_eq!(state.stored[4].missing, vec![2]);
    for id in state.stored.iter().map(|m| m.id) {
        shaper.acknowledge(now, 2, id);
    }
    assert_eq!(shaper.lane_queued_messages(lane), 4);
    assert_eq!(shaper.lane_stats(lane).unwrap().acknowledged_messages, 1);
    // A restarted shaper with the lane added again takes its messages back.
    let mut again = LinkShaper::new(config(100_000, 1_300, 1_200)).unwrap();
    assert_eq!(
        again
            .add_lane(Class::Plan, ClassConfig::store_and_forward())
            .unwrap(),
        lane
    );
    again.resume(&shaper.durable_state());
    assert_eq!(again.lane_queued_messages(lane), 4);
    assert_eq!(again.queued_messages(Class::Plan), 0);
    // Without it, they join the plan class's own queue.
    let fallback = LinkShaper::restore(config(100_000, 1_300, 1_200), &shaper.durable_state());
    assert_eq!(fallback.unwrap().queued_messages(Class::Plan), 4);
    // Bad lane settings are a ConfigError; unknown lanes refuse offers.
    let bad = ClassConfig {
        window_messages: 0,
        ..ClassConfig::store_and_forward()
    };
    assert_eq!(
        shaper.add_lane(Class::Bulk, bad).unwrap_err().key,
        "lane.window_messages"
    );
    assert!(shaper.offer_to_lane(0, LaneId(9), None, vec![1]).is_err());
}

/// Issue 23: a peer that never acknowledges holds at most its own bound and cannot
/// make the store refuse keyframes for the others; suspended, it stops holding back
/// broadcast frames; heard again, it gets what it missed.
#[test]
fn a_silent_peer_cannot_block_the_others_and_catches_up_when_heard_again() {
    let c = storing_keyframes(config(1_000_000, 4_000, 1_200), 5);
    let mut s = LinkShaper::new(c).unwrap();
    s.add_peer(1);
    s.add_peer(9); // never acknowledges
    let mut now = 0;
    for k in 0..20u8 {
        assert!(
            s.offer(now, Class::Keyframe, vec![k; 300]).is_ok(),
            "keyframe {k}"
        );
        let (frames, t) = drain(&mut s, now);
        now = t + 100 * MS;
        // Robot 1 acknowledges everything it was sent.
        for f in &frames {
            if let Some(message_id) = completed_message(&f.kind)
                && f.to.is_none_or(|to| to == 1)
            {
                s.acknowledge(now, 1, MessageId(message_id));
            }
        }
        let (pending, _) = s.pending_for(Class::Keyframe, 9);
        assert!(pending <= 5, "robot 9 holds {pending}");
        assert_eq!(s.pending_for(Class::Keyframe, 1).0, 0);
    }
    let st = *s.stats().class(Class::Keyframe);
    assert_eq!(st.drops.store_full, 0);
    assert_eq!(
        st.drops.peer_full, 15,
        "15 keyframes skipped for robot 9 only"
    );
    // Robot 9 times out: it is only probed with its oldest message, one at a time,
    // every `retransmit_timeout_max_s` (8 s); its 5 stay.
    assert!(s.suspend_peer(9));
    assert_eq!(s.suspended_peers(), vec![9]);
    let (frames, t) = drain(&mut s, now);
    let probes: Vec<u32> = frames
        .iter()
        .filter_map(|f| match f.kind {
            FrameKind::Data { message_id, .. } if f.to != Some(1) => Some(message_id),
            _ => None,
        })
        .collect();
    assert!(!probes.is_empty() && probes.len() <= 2, "{probes:?}");
    assert!(probes.iter().all(|id| *id == probes[0]), "{probes:?}");
    now = t;
    assert_eq!(s.pending_for(Class::Keyframe, 9).0, 5);
    // A new keyframe goes out to robot 1, addressed (robot 9 must not hear it
    // before its backlog), and is skipped for robot 9 (full).
    s.offer(now, Class::Keyframe, vec![99; 300]).unwrap();
    let (frames, t) = drain(&mut s, now);
    now = t;
    assert!(
        frames
            .iter()
            .any(|f| f.to == Some(1) && f.class == Class::Keyframe)
    );
    assert_eq!(s.stats().class(Class::Keyframe).drops.peer_full, 16);
    // Heard again: it rejoins and gets its five, oldest first.
    assert!(s.add_peer(9));
    assert!(s.suspended_peers().is_empty());
    let (frames, _) = drain(&mut s, now);
    let to_nine: Vec<u32> = frames
        .iter()
        .filter_map(|f| match f.kind {
            FrameKind::Data { message_id, .. } if f.to == Some(9) => Some(message_id),
            _ => None,
        })
        .collect();
    assert_eq!(&to_nine[..5], &[0, 1, 2, 3, 4]);
}

/// Issue 23 effect (b): an acknowledgement of a stored message that was never sent
/// to that peer (bytes that guessed the id) releases nothing.
#[test]
fn an_ack_for_a_message_not_yet_sent_releases_nothing() {
    let mut c = config(1_000, 1_200, 1_200); // slow: the second waits
    c.keyframe = ClassConfig::store_and_forward();
    let mut s = LinkShaper::new(c).unwrap();
    s.add_peer(1);
    s.offer(0, Class::Keyframe, vec![1; 1_000]).unwrap();
    s.offer(0, Class::Keyframe, vec![2; 1_000]).unwrap();
    assert!(s.poll(0).is_some());
    assert_eq!(s.acknowledge(0, 1, MessageId(1)), AckOutcome::NotSent);
    assert_eq!(s.acknowledge(0, 1, MessageId(7)), AckOutcome::Unknown);
    assert_eq!(s.acknowledge(0, 1, MessageId(0)), AckOutcome::Recorded);
    assert_eq!(s.acknowledge(0, 1, MessageId(0)), AckOutcome::Unknown);
    assert_eq!(s.queued_messages(Class::Keyframe), 1);
}

/// A frame announcing 65 535 fragments costs its fragment table: a flood of such
/// frames stays within `max_bytes`, evicting (and counting) the oldest.
#[test]
fn announced_fragment_tables_count_against_the_reassembly_budget() {
    let mut r = Reassembler::new(ReassemblyConfig {
        max_bytes: 4 << 20,
        ..ReassemblyConfig::default()
    })
    .unwrap();
    for id in 0..200u32 {
        let header = frame::DataHeader {
            class: Class::Keyframe,
            ack_requested: false,
            message_id: id,
            index: 0,
            count: u16::MAX,
        };
        let bytes = frame::data_frame(&header, &[0; 10]);
        assert_eq!(r.push(0, 1, &bytes).unwrap(), None);
        assert!(r.held_bytes() <= 4 << 20, "{}", r.held_bytes());
    }
    assert!(r.stats().evicted > 150, "{:?}", r.stats());
    assert!(r.partial_messages() < 5);
}
