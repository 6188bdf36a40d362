//! Statistics of each effect, and determinism.

use super::*;

const MS: u64 = 1_000_000;
const S: u64 = 1_000_000_000;

fn net(model: LinkModel, seed: u64) -> SimNet {
    SimNet::new(
        SimNetConfig {
            default: model,
            ..SimNetConfig::default()
        },
        seed,
    )
    .unwrap()
}

/// Sends `n` frames 0 → 1, one every 10 ms; returns each routing.
fn send(net: &mut SimNet, n: u64, bytes: usize) -> Vec<Routing> {
    let positions = [[0.0; 3], [1.0, 0.0, 0.0]];
    (0..n)
        .map(|i| net.route(i * 10 * MS, 0, 1, bytes, &positions))
        .collect()
}

/// A binomial proportion within 5 standard deviations of `p`.
fn close_to(count: u64, n: u64, p: f64) -> bool {
    let sd = (p * (1.0 - p) / n as f64).sqrt();
    ((count as f64 / n as f64) - p).abs() <= 5.0 * sd + 1e-12
}

#[test]
fn same_seed_same_deliveries_other_seed_other_deliveries() {
    let model = LinkModel {
        jitter_s: 0.01,
        loss_probability: 0.1,
        bursty_loss: Some(GilbertElliott::default()),
        reorder_probability: 0.05,
        duplicate_probability: 0.05,
        rate_bps: Some(1_000_000),
        ..LinkModel::default()
    };
    let run = |seed| {
        let mut n = net(model, seed);
        // Interleave two pairs; a pair's fate must not depend on the other's traffic.
        let mut out = Vec::new();
        for i in 0..2_000u64 {
            out.push(n.route(i * MS, 0, 1, 500, &[]));
            if i % 3 == 0 {
                n.route(i * MS, 1, 0, 500, &[]);
            }
        }
        (out, n.stats())
    };
    assert_eq!(run(7), run(7));
    assert_ne!(run(7).0, run(8).0);
    // Pair 0 → 1 alone gives the same routing as with the other pair's traffic.
    let mut alone = net(model, 7);
    let only: Vec<Routing> = (0..2_000u64)
        .map(|i| alone.route(i * MS, 0, 1, 500, &[]))
        .collect();
    assert_eq!(only, run(7).0);
}

#[test]
fn latency_and_jitter() {
    let mut n = net(
        LinkModel {
            latency_s: 0.02,
            jitter_s: 0.01,
            ..LinkModel::default()
        },
        1,
    );
    let r = send(&mut n, 10_000, 100);
    let delays: Vec<f64> = r
        .iter()
        .enumerate()
        .map(|(i, r)| (r.deliveries[0].arrival_ns - i as u64 * 10 * MS) as f64 * 1e-9)
        .collect();
    let mean = delays.iter().sum::<f64>() / delays.len() as f64;
    // Uniform jitter in [0, 10 ms]: mean 25 ms, sd of the mean 0.029 ms.
    assert!((mean - 0.025).abs() < 2e-4, "{mean}");
    assert!(delays.iter().all(|d| (0.02..=0.030_000_001).contains(d)));
    // Jitter alone never reorders.
    assert!(
        r.windows(2)
            .all(|w| w[0].deliveries[0].arrival_ns <= w[1].deliveries[0].arrival_ns)
    );
}

#[test]
fn independent_loss_rate() {
    let mut n = net(
        LinkModel {
            loss_probability: 0.1,
            ..LinkModel::default()
        },
        2,
    );
    let r = send(&mut n, 20_000, 100);
    let lost = r
        .iter()
        .filter(|r| r.dropped == Some(NetDrop::RandomLoss))
        .count() as u64;
    assert!(close_to(lost, 20_000, 0.1), "{lost}");
    assert_eq!(n.stats().random_loss, lost);
    assert_eq!(n.stats().delivered, 20_000 - lost);
}

#[test]
fn gilbert_elliott_losses_come_in_bursts() {
    let ge = GilbertElliott {
        p_good_to_bad: 0.02,
        p_bad_to_good: 0.25,
        loss_good: 0.0,
        loss_bad: 1.0,
    };
    let mut n = net(
        LinkModel {
            bursty_loss: Some(ge),
            ..LinkModel::default()
        },
        3,
    );
    let total = 100_000u64;
    let r = send(&mut n, total, 100);
    let lost: Vec<bool> = r.iter().map(|r| r.dropped.is_some()).collect();
    let n_lost = lost.iter().filter(|l| **l).count() as u64;
    let expected = ge.stationary_loss(); // 0.02 / 0.27 = 7.4 %
    // Losses are correlated, so the binomial sd understates; allow 15 % relative.
    let rate = n_lost as f64 / total as f64;
    assert!((rate / expected - 1.0).abs() < 0.15, "{rate} vs {expected}");
    // Mean burst length 1 / p_bad_to_good = 4 packets (independent loss: ~1.08).
    let bursts = lost.windows(2).filter(|w| !w[0] && w[1]).count() as f64;
    let mean_burst = n_lost as f64 / bursts;
    assert!((mean_burst - 4.0).abs() < 0.4, "{mean_burst}");
    assert_eq!(n.stats().burst_loss, n_lost);
}

#[test]
fn reordering_and_duplication_rates() {
    let mut n = net(
        LinkModel {
            reorder_probability: 0.05,
            reorder_delay_s: 0.05,
            duplicate_probability: 0.03,
            ..LinkModel::default()
        },
        4,
    );
    let total = 20_000;
    let r = send(&mut n, total, 100);
    let dups = r.iter().filter(|r| r.deliveries.len() == 2).count() as u64;
    assert!(close_to(dups, total, 0.03), "{dups}");
    assert!(
        r.iter()
            .flat_map(|r| &r.deliveries)
            .filter(|d| d.duplicate)
            .count() as u64
            == dups
    );
    // Held back by 50 ms at a 10 ms spacing: overtaken by the next 4 frames.
    let mut arrivals: Vec<(u64, usize)> = r
        .iter()
        .enumerate()
        .map(|(i, r)| (r.deliveries[0].arrival_ns, i))
        .collect();
    arrivals.sort();
    let overtaken = arrivals.windows(2).filter(|w| w[0].1 > w[1].1).count() as u64;
    let reordered = n.stats().reordered;
    assert!(close_to(reordered, total, 0.05), "{reordered}");
    assert!(overtaken > 0 && overtaken <= reordered);
}

#[test]
fn radius_and_rate_falling_with_distance() {
    let model = LinkModel {
        latency_s: 0.0,
        rate_bps: Some(1_000_000),
        radius_m: Some(100.0),
        full_rate_radius_m: 20.0,
        edge_rate_fraction: 0.1,
        ..LinkModel::default()
    };
    let mut n = net(model, 5);
    let at = |x: f64| [[0.0; 3], [x, 0.0, 0.0]];
    // 10 kB = 80 kbit: 80 ms at full rate.
    let t = |n: &mut SimNet, now: u64, x: f64| {
        n.route(now, 0, 1, 10_000, &at(x))
            .deliveries
            .first()
            .map(|d| d.arrival_ns - now)
    };
    assert_eq!(t(&mut n, 0, 10.0), Some(80 * MS));
    // Halfway between 20 and 100 m: 55 % of the rate.
    let mid = t(&mut n, S, 60.0).unwrap() as f64 * 1e-9;
    assert!((mid - 0.08 / 0.55).abs() < 1e-6, "{mid}");
    // At the radius: 10 % of the rate; beyond: nothing.
    let edge = t(&mut n, 2 * S, 100.0).unwrap() as f64 * 1e-9;
    assert!((edge - 0.8).abs() < 1e-6, "{edge}");
    assert_eq!(t(&mut n, 3 * S, 100.1), None);
    assert_eq!(n.stats().out_of_range, 1);
    // Back-to-back frames queue behind each other.
    let a = n.route(10 * S, 0, 1, 10_000, &at(0.0)).deliveries[0].arrival_ns;
    let b = n.route(10 * S, 0, 1, 10_000, &at(0.0)).deliveries[0].arrival_ns;
    assert_eq!((a, b), (10 * S + 80 * MS, 10 * S + 160 * MS));
}

#[test]
fn scheduled_partitions_cut_pairs_and_groups() {
    let config = SimNetConfig {
        partitions: vec![
            Partition {
                start_s: 10.0,
                end_s: 20.0,
                groups: vec![vec![0, 1], vec![2]],
                cut: vec![],
            },
            Partition {
                start_s: 30.0,
                end_s: 40.0,
                groups: vec![],
                cut: vec![[0, 2]],
            },
        ],
        ..SimNetConfig::default()
    };
    let mut n = SimNet::new(config, 0).unwrap();
    let ok =
        |n: &mut SimNet, t: u64, a: u32, b: u32| n.route(t * S, a, b, 10, &[]).dropped.is_none();
    assert!(ok(&mut n, 5, 0, 2));
    assert!(ok(&mut n, 15, 0, 1));
    assert!(!ok(&mut n, 15, 0, 2));
    assert!(!ok(&mut n, 15, 2, 1));
    assert!(!ok(&mut n, 15, 3, 0), "robots in no group are cut off");
    assert!(ok(&mut n, 20, 0, 2), "the end is exclusive");
    assert!(!ok(&mut n, 35, 2, 0));
    assert!(ok(&mut n, 35, 1, 2), "only the cut pair");
    assert_eq!(n.stats().partitioned, 4);
}

#[test]
fn pair_overrides_and_config_validation() {
    let c: SimNetConfig = toml::from_str(
        "[default]\nlatency_s = 0.01\n[[pairs]]\nfrom = 0\nto = 1\nlink = { latency_s = 0.5 }\n",
    )
    .unwrap();
    let mut n = SimNet::new(c.clone(), 0).unwrap();
    assert_eq!(n.route(0, 0, 1, 1, &[]).deliveries[0].arrival_ns, 500 * MS);
    assert_eq!(n.route(0, 1, 0, 1, &[]).deliveries[0].arrival_ns, 10 * MS);
    assert!(toml::from_str::<SimNetConfig>("[default]\nlatency_ms = 1").is_err());
    let key = |c: SimNetConfig| c.validate().unwrap_err().key;
    let mut bad = c.clone();
    bad.default.loss_probability = 1.5;
    assert_eq!(key(bad), "default.loss_probability");
    let mut bad = c.clone();
    bad.pairs[0].link.bursty_loss = Some(GilbertElliott {
        loss_bad: f64::NAN,
        ..GilbertElliott::default()
    });
    assert_eq!(key(bad), "pairs[0].link.bursty_loss.loss_bad");
    let mut bad = c.clone();
    bad.partitions.push(Partition {
        start_s: 5.0,
        end_s: 1.0,
        ..Partition::default()
    });
    assert_eq!(key(bad), "partitions[0].end_s");
    let mut bad = c;
    bad.default.radius_m = Some(-1.0);
    assert_eq!(key(bad), "default.radius_m");
}

#[test]
fn no_frame_arrives_sooner_than_the_least_latency() {
    // The sim-time executor runs robots side by side for this long between exchanges.
    let config: SimNetConfig = toml::from_str(
        "[default]\nlatency_s = 0.02\njitter_s = 0.01\nreorder_probability = 0.2\n\
         duplicate_probability = 0.2\nrate_bps = 2000000\n\
         [[pairs]]\nfrom = 1\nto = 0\nlink = { latency_s = 0.005, jitter_s = 0.003 }\n",
    )
    .unwrap();
    let mut n = SimNet::new(config, 3).unwrap();
    assert_eq!(n.min_latency_ns(), 5 * MS);
    let mut earliest = u64::MAX;
    for i in 0..5_000u64 {
        let (from, to) = if i % 2 == 0 { (0, 1) } else { (1, 0) };
        let sent = i * 3 * MS;
        for d in n.route(sent, from, to, 1_200, &[]).deliveries {
            earliest = earliest.min(d.arrival_ns - sent);
        }
    }
    assert!(earliest >= n.min_latency_ns(), "{earliest} ns");
    assert!(earliest < 6 * MS, "the bound is tight: {earliest} ns");
}
