//! Runtime tests: the same actors under both executors, latency modelling, queue
//! policies, supervision, determinism and the network boundary.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rand::Rng;
use rayon::prelude::*;

use super::*;

#[derive(Debug, Clone, PartialEq)]
struct Number(u64);
impl Message for Number {}

const NUMBERS: Topic<Number> = Topic::new("numbers");
const DOUBLED: Topic<Number> = Topic::new("doubled");
const TICK: TimerId = TimerId(0);

/// Publishes 1, 2, 3, … on a timer, up to `limit`.
struct Source {
    next: u64,
    limit: u64,
    period: Duration,
}

impl Actor for Source {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(TICK, self.period);
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if matches!(event, Event::Timer(TICK)) && self.next < self.limit {
            self.next += 1;
            ctx.publish(&NUMBERS, Number(self.next));
        }
        Ok(())
    }
}

/// Doubles what it receives; panics on the values in `panic_on`.
struct Doubler {
    panic_on: Vec<u64>,
}

impl Actor for Doubler {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&NUMBERS, QueuePolicy::fifo(1024));
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if let Some(n) = event.message().and_then(|m| m.get(&NUMBERS)) {
            assert!(!self.panic_on.contains(&n.0), "injected panic on {}", n.0);
            ctx.publish(&DOUBLED, Number(n.0 * 2));
        }
        Ok(())
    }
}

/// Records what it receives into a shared vector.
struct Sink {
    seen: Arc<Mutex<Vec<(u64, Time)>>>,
    policy: QueuePolicy,
}

impl Actor for Sink {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&DOUBLED, self.policy);
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if let Some(n) = event.message().and_then(|m| m.get(&DOUBLED)) {
            self.seen.lock().unwrap().push((n.0, ctx.now()));
        }
        Ok(())
    }
}

fn pipeline(seen: &Arc<Mutex<Vec<(u64, Time)>>>, limit: u64, panic_on: Vec<u64>) -> RobotSpec {
    let seen = seen.clone();
    RobotSpec::new("r0")
        .with(ActorSpec::new("source", move || Source {
            next: 0,
            limit,
            period: Duration::from_millis(5),
        }))
        .with(ActorSpec::new("doubler", move || Doubler {
            panic_on: panic_on.clone(),
        }))
        .with(ActorSpec::new("sink", move || Sink {
            seen: seen.clone(),
            policy: QueuePolicy::fifo(1024),
        }))
}

#[test]
fn same_actors_run_under_both_executors() {
    let sim_seen = Arc::new(Mutex::new(Vec::new()));
    let mut sim = SimExecutor::new(vec![pipeline(&sim_seen, 20, vec![])], 1);
    sim.run_until(Time::from_secs_f64(1.0));
    let sim_reports = sim.finish();
    let sim_values: Vec<u64> = sim_seen.lock().unwrap().iter().map(|(v, _)| *v).collect();
    assert_eq!(sim_values, (1..=20).map(|v| v * 2).collect::<Vec<_>>());
    assert_eq!(sim_reports[0].topics["doubled"].messages, 20);

    let rt_seen = Arc::new(Mutex::new(Vec::new()));
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let rt_reports = runtime.block_on(async {
        let handle = RealtimeExecutor::new(vec![pipeline(&rt_seen, 20, vec![])], 1).spawn();
        for _ in 0..400 {
            if rt_seen.lock().unwrap().len() == 20 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        handle.shutdown().await
    });
    let rt_values: Vec<u64> = rt_seen.lock().unwrap().iter().map(|(v, _)| *v).collect();
    assert_eq!(rt_values, sim_values);
    assert_eq!(rt_reports[0].topics["doubled"].messages, 20);
}

#[test]
fn sim_time_is_exact_and_latency_delays_outputs() {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut robot = pipeline(&seen, 3, vec![]);
    robot.actors[1].options.latency = LatencyModel::fixed(0.4);
    let mut sim = SimExecutor::new(vec![robot], 1);
    sim.run_until(Time::from_secs_f64(2.0));
    let seen = seen.lock().unwrap().clone();
    // Published at 5, 10, 15 ms; the doubler takes 0.4 s per call, so the second
    // input waits until the first call is done.
    let times: Vec<u64> = seen.iter().map(|(_, t)| t.as_nanos()).collect();
    assert_eq!(times, vec![405_000_000, 805_000_000, 1_205_000_000]);
}

/// Stores every number it hears; publishes how many on each tick (its "round").
struct Rounds {
    heard: u64,
    bookkeeping: bool,
}

impl Actor for Rounds {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&NUMBERS, QueuePolicy::fifo(1024));
        ctx.set_timer(TICK, Duration::from_millis(100));
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(_) => {
                self.heard += 1;
                if self.bookkeeping {
                    ctx.bookkeeping_only();
                }
            }
            Event::Timer(_) => ctx.publish(&DOUBLED, Number(self.heard)),
        }
        Ok(())
    }
}

/// Output times (ms) of a round actor (50 ms per call) hearing a number every 5 ms.
fn round_times_ms(bookkeeping: bool) -> Vec<u64> {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let sink_seen = seen.clone();
    let robot = RobotSpec::new("r0")
        .with(ActorSpec::new("source", || Source {
            next: 0,
            limit: 1000,
            period: Duration::from_millis(5),
        }))
        .with(
            ActorSpec::new("rounds", move || Rounds {
                heard: 0,
                bookkeeping,
            })
            .with_latency(LatencyModel::fixed(0.05)),
        )
        .with(ActorSpec::new("sink", move || Sink {
            seen: sink_seen.clone(),
            policy: QueuePolicy::fifo(1024),
        }));
    let mut sim = SimExecutor::new(vec![robot], 1);
    sim.run_until(Time::from_secs_f64(0.5));
    seen.lock()
        .unwrap()
        .iter()
        .map(|(_, t)| t.as_nanos() / 1_000_000)
        .collect()
}

#[test]
fn bookkeeping_calls_are_not_charged_the_modelled_latency() {
    // Storing a number is free: every round's output comes 50 ms after its tick.
    assert_eq!(round_times_ms(true), vec![150, 250, 350, 450]);
    // Charged 50 ms per stored number, the actor falls behind its own timer.
    let charged = round_times_ms(false);
    assert!(charged.len() < 4, "{charged:?}");
    assert!(charged.first().is_none_or(|&t| t > 150), "{charged:?}");
}

#[test]
fn keep_latest_drops_are_counted_while_busy() {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut robot = pipeline(&seen, 10, vec![]);
    robot.actors[1].options.latency = LatencyModel::fixed(1.0);
    robot.actors[2] = {
        let seen = seen.clone();
        ActorSpec::new("sink", move || Sink {
            seen: seen.clone(),
            policy: QueuePolicy::LATEST,
        })
    };
    // The doubler subscribes FIFO; make the sink the slow one instead.
    robot.actors[1].options.latency = LatencyModel::fixed(0.0);
    robot.actors[2].options.latency = LatencyModel::fixed(1.0);
    let mut sim = SimExecutor::new(vec![robot], 1);
    sim.run_until(Time::from_secs_f64(5.0));
    let reports = sim.finish();
    let values: Vec<u64> = seen.lock().unwrap().iter().map(|(v, _)| *v).collect();
    // First value handled at 10 ms; while busy for 1 s the other nine arrive and only
    // the newest is kept.
    assert_eq!(values, vec![2, 20]);
    assert_eq!(reports[0].actors[2].dropped_by_topic["doubled"], 8);
}

#[test]
fn panicking_handler_is_restarted_and_counted() {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut sim = SimExecutor::new(vec![pipeline(&seen, 10, vec![3, 7])], 1);
    sim.run_until(Time::from_secs_f64(1.0));
    let reports = sim.finish();
    let doubler = &reports[0].actors[1].stats;
    assert_eq!(doubler.panics, 2);
    assert_eq!(doubler.restarts, 2);
    assert!(!doubler.stopped);
    let values: Vec<u64> = seen.lock().unwrap().iter().map(|(v, _)| *v).collect();
    assert_eq!(values, vec![2, 4, 8, 10, 12, 16, 18, 20]);
}

#[test]
fn repeated_panics_stop_the_actor_and_the_robot_keeps_running() {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut robot = pipeline(&seen, 10, (1..=10).collect());
    robot.actors[1].options.restart = RestartPolicy {
        max_restarts: 2,
        window_s: 60.0,
    };
    let mut sim = SimExecutor::new(vec![robot], 1);
    sim.run_until(Time::from_secs_f64(1.0));
    let reports = sim.finish();
    let doubler = &reports[0].actors[1].stats;
    assert_eq!(doubler.panics, 3);
    assert_eq!(doubler.restarts, 2);
    assert!(doubler.stopped);
    assert_eq!(doubler.dropped_while_stopped, 7);
    // The source kept running to the end.
    assert_eq!(reports[0].topics["numbers"].messages, 10);
    assert_eq!(reports[0].actors[0].stats.handled, 200);
}

/// Uses rayon inside the handler and a random draw: results must not depend on
/// thread timing.
struct ParallelWork {
    out: Arc<Mutex<Vec<u64>>>,
}

impl Actor for ParallelWork {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(TICK, Duration::from_millis(10));
        Ok(())
    }
    fn handle(&mut self, _event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let salt: u64 = ctx.rng().random();
        let values: Vec<f64> = (0..10_000u64)
            .into_par_iter()
            .map(|i| ((i ^ salt) as f64).sqrt().sin())
            .collect();
        let sum: f64 = values.iter().sum();
        self.out.lock().unwrap().push(sum.to_bits());
        Ok(())
    }
}

/// Each robot's results, in order (robots run side by side: each has its own list).
fn parallel_run(seed: u64) -> Vec<Vec<u64>> {
    let outs: Vec<_> = (0..2).map(|_| Arc::new(Mutex::new(Vec::new()))).collect();
    let robots = outs
        .iter()
        .enumerate()
        .map(|(i, out)| {
            let o = out.clone();
            RobotSpec::new(format!("r{i}")).with(
                ActorSpec::new("work", move || ParallelWork { out: o.clone() }).with_latency(
                    LatencyModel::Uniform {
                        min_s: 0.001,
                        max_s: 0.02,
                    },
                ),
            )
        })
        .collect();
    let mut sim = SimExecutor::new(robots, seed);
    sim.run_until(Time::from_secs_f64(0.5));
    drop(sim.finish());
    outs.iter().map(|o| o.lock().unwrap().clone()).collect()
}

#[test]
fn same_seed_same_results_with_rayon_inside() {
    let a = parallel_run(11);
    let b = parallel_run(11);
    assert!(a.iter().all(|r| !r.is_empty()));
    assert_eq!(a, b);
    assert_ne!(a, parallel_run(12));
}

struct Chatter;
impl Actor for Chatter {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&LINK_RX, QueuePolicy::fifo(16));
        ctx.set_timer(TICK, Duration::from_millis(100));
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Timer(_) => ctx.publish(
                &LINK_TX,
                LinkTx {
                    to: Destination::Broadcast,
                    bytes: Arc::from(vec![ctx.robot().0 as u8; 10]),
                },
            ),
            Event::Message(m) => {
                let rx = m
                    .get(&LINK_RX)
                    .ok_or_else(|| ActorError::msg("unexpected topic"))?;
                assert_ne!(rx.from, ctx.robot());
                assert_eq!(rx.bytes[0] as u32, rx.from.0);
                assert_eq!(ctx.now() - m.published_at(), Duration::ZERO);
            }
        }
        Ok(())
    }
}

#[test]
fn network_carries_packets_between_robots_with_latency() {
    let robots = (0..3)
        .map(|i| RobotSpec::new(format!("r{i}")).with(ActorSpec::new("chat", || Chatter)))
        .collect();
    let mut sim = SimExecutor::new(robots, 3).with_network(IdealNetwork {
        latency: Duration::from_millis(30),
    });
    let arrivals = Arc::new(Mutex::new(Vec::new()));
    let a = arrivals.clone();
    sim.add_tap(move |p: &Publication<'_>| {
        if let Some(rx) = p.get(&LINK_RX) {
            a.lock().unwrap().push((p.time, rx.from, p.robot));
        }
    });
    sim.run_until(Time::from_secs_f64(0.15));
    let reports = sim.finish();
    let arrivals = arrivals.lock().unwrap().clone();
    // One broadcast per robot at 0.1 s, two receivers each, 30 ms later.
    assert_eq!(arrivals.len(), 6);
    assert!(arrivals.iter().all(|(t, _, _)| t.as_nanos() == 130_000_000));
    for r in &reports {
        assert_eq!(r.topics["link/tx"].messages, 1);
        assert_eq!(r.topics["link/rx"].messages, 2);
        assert_eq!(r.topics["link/rx"].bytes, 20);
        assert_eq!(r.actors[0].stats.errors, 0);
    }
}

#[derive(Debug)]
struct Other;
impl Message for Other {}

struct WrongType;
impl Actor for WrongType {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.publish(&Topic::<Other>::new("numbers"), Other);
        Ok(())
    }
    fn handle(&mut self, _: &Event, _: &mut Context<'_>) -> ActorResult {
        Ok(())
    }
}

#[test]
fn publishing_the_wrong_type_is_rejected_and_counted() {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let robot = pipeline(&seen, 1, vec![]).with(ActorSpec::new("wrong", || WrongType));
    let mut sim = SimExecutor::new(vec![robot], 1);
    sim.run_until(Time::from_secs_f64(0.1));
    let reports = sim.finish();
    assert_eq!(reports[0].topics["numbers"].type_mismatches, 1);
    assert_eq!(reports[0].topics["numbers"].messages, 1);
    assert_eq!(reports[0].actors[1].stats.errors, 0);
}

#[test]
fn timer_ticks_coalesce_while_busy() {
    struct Slow;
    impl Actor for Slow {
        fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
            ctx.set_timer(TICK, Duration::from_millis(100));
            Ok(())
        }
        fn handle(&mut self, _: &Event, _: &mut Context<'_>) -> ActorResult {
            Ok(())
        }
    }
    let robot = RobotSpec::new("r")
        .with(ActorSpec::new("slow", || Slow).with_latency(LatencyModel::fixed(0.35)));
    let mut sim = SimExecutor::new(vec![robot], 1);
    sim.run_until(Time::from_secs_f64(1.0));
    let reports = sim.finish();
    let stats = &reports[0].actors[0].stats;
    // Handled at 0.1, 0.45 (tick from 0.2; 0.3 and 0.4 coalesced) and 0.8 (tick from
    // 0.5; 0.6, 0.7 and 0.8 — which fires just before the activation — coalesced);
    // then 0.9 waits and 1.0 coalesces.
    assert_eq!(stats.handled, 3);
    assert_eq!(stats.timer_overruns, 6);
}

#[tokio::test(start_paused = true)]
async fn realtime_timers_follow_the_tokio_clock() {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let handle = RealtimeExecutor::new(vec![pipeline(&seen, 1000, vec![])], 1).spawn();
    tokio::time::sleep(Duration::from_millis(101)).await;
    let reports = handle.shutdown().await;
    let n = reports[0].topics["numbers"].messages;
    assert_eq!(n, 20, "5 ms timer over 101 ms of paused-clock time");
}

#[test]
fn realtime_panics_are_contained() {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let reports = runtime.block_on(async {
        let handle = RealtimeExecutor::new(vec![pipeline(&seen, 10, vec![5])], 1).spawn();
        for _ in 0..400 {
            if seen.lock().unwrap().len() == 9 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        handle.shutdown().await
    });
    assert_eq!(reports[0].actors[1].stats.panics, 1);
    assert_eq!(reports[0].actors[1].stats.restarts, 1);
    assert_eq!(seen.lock().unwrap().len(), 9);
}

const READY: Topic<Number> = Topic::new("ready");
const LATE: Topic<Number> = Topic::new("late");

/// Subscribes to [`LATE`] from a timer handler (after the robot started), then
/// says so on [`READY`].
struct LateSubscriber {
    seen: Arc<Mutex<Vec<(u64, Time)>>>,
}

impl Actor for LateSubscriber {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(TICK, Duration::from_millis(20));
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Timer(TICK) => {
                ctx.cancel_timer(TICK);
                ctx.subscribe(&LATE, QueuePolicy::fifo(1024));
                ctx.publish(&READY, Number(0));
            }
            _ => {
                if let Some(n) = event.message().and_then(|m| m.get(&LATE)) {
                    self.seen.lock().unwrap().push((n.0, ctx.now()));
                }
            }
        }
        Ok(())
    }
}

/// Publishes 0 on [`LATE`] at start (nobody listens yet), and 1..=20 once a
/// subscriber is ready.
struct LatePublisher;

impl Actor for LatePublisher {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&READY, QueuePolicy::fifo(4));
        ctx.publish(&LATE, Number(0));
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if event.message().and_then(|m| m.get(&READY)).is_some() {
            for n in 1..=20 {
                ctx.publish(&LATE, Number(n));
            }
        }
        Ok(())
    }
}

fn late_subscription_robot(seen: &Arc<Mutex<Vec<(u64, Time)>>>) -> RobotSpec {
    let seen = seen.clone();
    RobotSpec::new("r0")
        .with(ActorSpec::new("publisher", || LatePublisher))
        .with(ActorSpec::new("late", move || LateSubscriber {
            seen: seen.clone(),
        }))
}

/// A subscription made in a handler (not in `start`) gets every later message,
/// under both executors alike; what was published before it is not replayed.
#[test]
fn late_subscriptions_receive_every_later_message_under_both_executors() {
    let expected: Vec<u64> = (1..=20).collect();

    let sim_seen = Arc::new(Mutex::new(Vec::new()));
    let mut sim = SimExecutor::new(vec![late_subscription_robot(&sim_seen)], 1);
    sim.run_until(Time::from_secs_f64(1.0));
    let sim_reports = sim.finish();
    let sim_values: Vec<u64> = sim_seen.lock().unwrap().iter().map(|(v, _)| *v).collect();
    assert_eq!(sim_values, expected);
    assert_eq!(sim_reports[0].topics["late"].messages, 21);

    let rt_seen = Arc::new(Mutex::new(Vec::new()));
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let rt_reports = runtime.block_on(async {
        let handle = RealtimeExecutor::new(vec![late_subscription_robot(&rt_seen)], 1).spawn();
        for _ in 0..400 {
            if rt_seen.lock().unwrap().len() == 20 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        // A little longer: nothing more (and nothing twice) may arrive.
        tokio::time::sleep(Duration::from_millis(20)).await;
        handle.shutdown().await
    });
    let rt_values: Vec<u64> = rt_seen.lock().unwrap().iter().map(|(v, _)| *v).collect();
    assert_eq!(rt_values, expected);
    assert_eq!(rt_reports[0].topics["late"].messages, 21);
}

/// `hash` with `bytes` folded in (FNV-1a's step).
fn fold(hash: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(hash, |h, b| {
        (h ^ u64::from(*b)).wrapping_mul(0x100_0000_01b3)
    })
}

/// Gossips a running hash of everything it heard, at random moments.
struct Gossip {
    heard: u64,
}

impl Actor for Gossip {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&LINK_RX, QueuePolicy::fifo(64));
        ctx.set_timer(TICK, Duration::from_millis(7));
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Timer(_) => {
                let salt: u64 = ctx.rng().random();
                let mut bytes = self.heard.to_le_bytes().to_vec();
                bytes.extend_from_slice(&salt.to_le_bytes());
                ctx.publish(
                    &LINK_TX,
                    LinkTx {
                        to: Destination::Broadcast,
                        bytes: Arc::from(bytes),
                    },
                );
            }
            Event::Message(m) => {
                if let Some(rx) = m.get(&LINK_RX) {
                    self.heard = fold(self.heard, &rx.bytes);
                }
            }
        }
        Ok(())
    }
}

/// A [`Gossip`] actor whose calls take 1 to 20 ms.
fn gossip() -> ActorSpec {
    ActorSpec::new("gossip", || Gossip { heard: 0 }).with_latency(LatencyModel::Uniform {
        min_s: 0.001,
        max_s: 0.02,
    })
}

/// Every publication the taps saw, as (time, robot, topic, bytes).
type Seen = Vec<(Time, RobotId, String, Vec<u8>)>;

/// A tap that records every publication into `seen`, with the bytes of link frames
/// and digests.
fn recorder(seen: Arc<Mutex<Seen>>) -> impl Tap {
    move |p: &Publication<'_>| {
        let bytes = p
            .get(&DIGEST)
            .map(|d| d.0.to_le_bytes().to_vec())
            .or_else(|| p.get(&LINK_TX).map(|tx| tx.bytes.to_vec()))
            .or_else(|| p.get(&LINK_RX).map(|rx| rx.bytes.to_vec()))
            .unwrap_or_default();
        seen.lock()
            .unwrap()
            .push((p.time, p.robot, p.topic.to_string(), bytes));
    }
}

/// Every publication of a gossiping team, as its taps saw them, run on `threads`.
fn gossip_run(threads: usize) -> Seen {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let s = seen.clone();
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(|| {
            let robots = (0..4)
                .map(|i| RobotSpec::new(format!("r{i}")).with(gossip()))
                .collect();
            let mut sim = SimExecutor::new(robots, 5).with_network(IdealNetwork {
                latency: Duration::from_millis(5),
            });
            sim.add_tap(recorder(s));
            sim.run_until(Time::from_secs_f64(0.5));
            drop(sim.finish());
        });
    seen.lock().unwrap().clone()
}

#[test]
fn a_team_runs_the_same_on_one_thread_and_on_several() {
    let one = gossip_run(1);
    // Busy handlers coalesce ticks: each robot gossips some 15 times and hears the
    // other three.
    assert!(one.len() > 150, "{} publications", one.len());
    assert!(one.iter().any(|(_, _, topic, _)| topic == "link/rx"));
    assert!(
        one.windows(2).all(|w| (w[0].0, w[0].1) <= (w[1].0, w[1].1)),
        "the taps see publications in (time, robot) order"
    );
    assert_eq!(one, gossip_run(4));
    assert_eq!(one, gossip_run(2));
}

const DIGEST: Topic<Number> = Topic::new("digest");

/// Digests what its robot hears, with a modelled latency, publishing every other
/// digest; its calls overlap the robot's later events when `overlap` is set.
struct Digest {
    heard: u64,
    calls: u64,
    overlap: bool,
}

impl Actor for Digest {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&LINK_RX, QueuePolicy::LATEST);
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if let Some(rx) = event.message().and_then(|m| m.get(&LINK_RX)) {
            self.heard = fold(self.heard, &rx.bytes);
            self.calls += 1;
            if self.calls.is_multiple_of(2) {
                let salt: u64 = ctx.rng().random();
                ctx.publish(&DIGEST, Number(self.heard ^ salt));
            }
        }
        Ok(())
    }
    fn overlaps(&self, _: &Event) -> bool {
        self.overlap
    }
}

/// A gossiping team whose digests overlap or not: every publication the taps saw,
/// the events processed and each actor's handled count.
fn digest_run(overlap: bool) -> (Seen, u64, Vec<u64>) {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let s = seen.clone();
    let robots = (0..3)
        .map(|i| {
            RobotSpec::new(format!("r{i}")).with(gossip()).with(
                ActorSpec::new("digest", move || Digest {
                    heard: 0,
                    calls: 0,
                    overlap,
                })
                .with_latency(LatencyModel::fixed(0.03)),
            )
        })
        .collect();
    let mut sim = SimExecutor::new(robots, 9).with_network(IdealNetwork {
        latency: Duration::from_millis(5),
    });
    sim.add_tap(recorder(s));
    // Steps shorter than a digest's latency and not a multiple of it: calls are in
    // flight when a step ends.
    for step in 1..=7 {
        sim.run_until(Time::from_secs_f64(0.07 * f64::from(step)));
    }
    let events = sim.events_processed();
    let handled = sim
        .finish()
        .iter()
        .flat_map(|r| r.actors.iter().map(|a| a.stats.handled))
        .collect();
    let seen = seen.lock().unwrap().clone();
    (seen, events, handled)
}

#[test]
fn calls_that_overlap_the_robots_events_give_the_same_run() {
    let (in_place, events, handled) = digest_run(false);
    let digests = in_place.iter().filter(|p| p.2 == "digest").count();
    assert!(digests > 20, "{digests} digests");
    let (overlapped, overlapped_events, overlapped_handled) = digest_run(true);
    assert_eq!(in_place, overlapped);
    assert_eq!(events, overlapped_events);
    assert_eq!(handled, overlapped_handled);
}
