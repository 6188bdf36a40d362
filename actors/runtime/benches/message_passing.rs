//! Message passing through a chain of six actors.
//!
//! - `sim_chain`: the sim-time executor moving bursts of messages through
//!   source → 4 relays → sink (five hops per message); throughput in hops/s.
//! - `realtime_ring`: the real-time executor on a 2-worker tokio runtime passing one
//!   message around a ring of six actors (six hops per lap); reports the median and
//!   95th percentile per-hop latency measured on every lap.
//!
//! Run: `cargo bench -p troupe-runtime --bench message_passing`

#![allow(missing_docs)]

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use troupe_runtime::*;

struct Stamp(Instant);
impl Message for Stamp {}

fn hop_topic(i: usize) -> Topic<Stamp> {
    Topic::named(format!("hop{i}"))
}

/// Publishes `burst` messages on every tick.
struct Source {
    burst: usize,
}
impl Actor for Source {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(TimerId(0), Duration::from_millis(10));
        Ok(())
    }
    fn handle(&mut self, _: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let out = hop_topic(0);
        let now = Instant::now();
        for _ in 0..self.burst {
            ctx.publish(&out, Stamp(now));
        }
        Ok(())
    }
}

/// Forwards the shared message from one topic to the next (no copy).
struct Relay {
    input: Topic<Stamp>,
    output: Topic<Stamp>,
}
impl Actor for Relay {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&self.input, QueuePolicy::fifo(4096));
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if let Some(m) = event.message().and_then(|m| m.get_arc(&self.input)) {
            ctx.publish_arc(&self.output, m);
        }
        Ok(())
    }
}

fn relay(i: usize) -> ActorSpec {
    ActorSpec::new(format!("relay{i}"), move || Relay {
        input: hop_topic(i),
        output: hop_topic(i + 1),
    })
}

fn sim_chain(c: &mut Criterion) {
    const BURST: usize = 1000;
    const TICKS: u64 = 20;
    // source → relay0..relay4; relay4 publishes hop5 which nobody reads: 5 hops with
    // a subscriber, plus the final publication.
    let hops = (BURST as u64) * TICKS * 5;
    let mut group = c.benchmark_group("sim_chain");
    group.throughput(Throughput::Elements(hops));
    group.bench_function("six_actors_5_hops", |b| {
        b.iter(|| {
            let mut robot = RobotSpec::new("bench");
            robot.add(ActorSpec::new("source", || Source { burst: BURST }));
            for i in 0..5 {
                robot.add(relay(i));
            }
            let mut sim = SimExecutor::new(vec![robot], 1);
            sim.run_until(Time::from_nanos(TICKS * 10_000_000));
            sim.finish()
        });
    });
    group.finish();
}

/// Starts a lap on the first tick and every time the message comes back around.
struct RingHead {
    samples: Arc<Mutex<Vec<Duration>>>,
    laps: usize,
}
impl Actor for RingHead {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&hop_topic(5), QueuePolicy::fifo(16));
        ctx.set_timer(TimerId(0), Duration::from_millis(1));
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Timer(_) => {
                ctx.cancel_timer(TimerId(0));
            }
            Event::Message(m) => {
                if let Some(stamp) = m.get(&hop_topic(5)) {
                    let mut samples = self
                        .samples
                        .lock()
                        .map_err(|_| ActorError::msg("poisoned"))?;
                    samples.push(stamp.0.elapsed() / 6);
                    if samples.len() >= self.laps {
                        return Ok(());
                    }
                }
            }
        }
        ctx.publish(&hop_topic(0), Stamp(Instant::now()));
        Ok(())
    }
}

fn realtime_ring(c: &mut Criterion) {
    const LAPS: usize = 20_000;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("tokio runtime");
    let mut group = c.benchmark_group("realtime_ring");
    group.sample_size(10);
    let mut all = Vec::new();
    group.bench_function("six_actors_per_hop", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                let samples = Arc::new(Mutex::new(Vec::with_capacity(LAPS)));
                let s = samples.clone();
                let mut robot = RobotSpec::new("bench");
                robot.add(ActorSpec::new("head", move || RingHead {
                    samples: s.clone(),
                    laps: LAPS,
                }));
                for i in 0..5 {
                    robot.add(relay(i));
                }
                runtime.block_on(async {
                    let handle = RealtimeExecutor::new(vec![robot], 1).spawn();
                    while samples.lock().map(|s| s.len()).unwrap_or(LAPS) < LAPS {
                        tokio::time::sleep(Duration::from_millis(2)).await;
                    }
                    handle.shutdown().await
                });
                let samples = samples.lock().map(|s| s.clone()).unwrap_or_default();
                total += samples.iter().sum::<Duration>() / samples.len().max(1) as u32;
                all.extend(samples);
            }
            total
        });
    });
    group.finish();
    all.sort();
    if !all.is_empty() {
        let q = |p: f64| all[((all.len() - 1) as f64 * p) as usize];
        println!(
            "realtime_ring per-hop latency over {} hops-samples: median {:?}, p95 {:?}, p99 {:?}",
            all.len(),
            q(0.5),
            q(0.95),
            q(0.99)
        );
    }
}

criterion_group!(benches, sim_chain, realtime_ring);
criterion_main!(benches);
