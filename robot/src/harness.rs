//! The robot-process harness: what every troupe process that runs a robot's actors
//! on the wall clock does around them — a simulated robot process (`troupe robot`),
//! a hardware robot (`troupe-robot`, [`crate::hardware`]) and the base station
//! (`troupe base`, [`crate::base`]).
//!
//! A process builds its [`RobotSpec`] (that part is its own), then:
//!
//! 1. [`open_journal`]: the link's journal on disk, its message ids starting from the
//!    clock, so a restarted process resends what was not acknowledged and never reuses
//!    an id (`docs/link-durability.md`);
//! 2. [`Harness::open`]: the team link's zenoh session and the real-time executor for
//!    its one robot under its link id; its own odometry tells the transport where it
//!    is (troupe_comms::scope);
//! 3. taps: [`Harness::add_tap`], [`Harness::latest`] (the last status on a topic),
//!    [`Harness::track_trajectory`];
//! 4. [`Harness::record`]: `out/run.mcap` in wall time (`docs/recordings.md`);
//! 5. [`Harness::run`]: until the duration is over or `stop` resolves
//!    ([`shutdown_signal`]: SIGINT or SIGTERM), then shuts the actors down, closes the
//!    session and finishes the recording ([`Finished`]);
//! 6. [`write_summary`] (`out/summary.json`) and its other outputs.
//!
//! [`block_on`] runs that on a new multi-threaded tokio runtime, [`init_logging`]
//! and [`exit_code`] are the binaries' first and last lines.
//!
//! ```no_run
//! use troupe_actors::link::{LINK_STATUS, LinkActor, LinkConfig};
//! use troupe_runtime::{ActorSpec, RobotSpec};
//! use troupe_comms::scope::SubscriptionConfig;
//! use troupe_comms::zenoh::ZenohConfig;
//! use troupe_robot::harness::{self, Harness, Member};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let out = std::path::PathBuf::from("runs/listener");
//! let link = LinkConfig::default();
//! let journal = harness::open_journal(&link.journal_dir_in(&out), None)?;
//! let spec = RobotSpec::new("listener").with(ActorSpec::new("link", move || {
//!     LinkActor::new(link.clone())?.journaled(journal.clone())
//! }));
//! let zenoh = ZenohConfig::default();
//! let member = Member {
//!     name: "robot5".into(),
//!     id: 5,
//!     seed: 1,
//!     team: 0,
//!     zenoh: &zenoh,
//!     subscription: SubscriptionConfig::default(),
//!     out: out.clone(),
//! };
//! let mut process = Harness::open(member, spec)?;
//! let status = process.latest(LINK_STATUS);
//! let finished = harness::block_on(process.run(Some(10.0), harness::shutdown_signal()))??;
//! println!("{} wall s, last link status {:?}", finished.wall_s, status.take());
//! # Ok(())
//! # }
//! ```

use std::fmt::Write as _;
use std::future::Future;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::Serialize;
use troupe_actors::link::LinkJournal;
use troupe_actors::msgs::ODOMETRY;
use troupe_comms::journal::JournalError;
use troupe_comms::scope::SubscriptionConfig;
use troupe_comms::transport::TransportError;
use troupe_comms::zenoh::{ZenohConfig, ZenohStats, ZenohTransport};
use troupe_core::{ErrorChain, Message, RobotId};
use troupe_record::{
    Clock, RUN_RECORDING, RecordError, RecordOptions, Recorder, RecordingStats, SharedRecorder,
};
use troupe_runtime::{
    Publication, RealtimeExecutor, RobotIdsError, RobotReport, RobotSpec, Tap, Topic,
};

/// The file every process writes its summary into, in its output directory.
pub const SUMMARY_JSON: &str = "summary.json";

/// Why a process's harness could not start, run or write.
#[derive(Debug, thiserror::Error)]
pub enum HarnessError {
    /// The link's journal could not be opened.
    #[error("opening the link journal")]
    Journal {
        /// Why (names the file).
        source: JournalError,
    },
    /// The team link's zenoh session did not open.
    #[error("opening the team link's zenoh session")]
    Session(#[source] TransportError),
    /// The executor did not accept the robot's id.
    #[error("starting the executor")]
    RobotId(#[source] RobotIdsError),
    /// The executor could not start receiving from the team link.
    #[error("starting the team link")]
    Transport(#[source] TransportError),
    /// The recording could not be created.
    #[error("creating the recording")]
    Recording(#[source] RecordError),
    /// The tokio runtime could not start.
    #[error("starting the tokio runtime")]
    Runtime(#[source] std::io::Error),
    /// The executor ended without a report of the robot.
    #[error("the executor reported no robot")]
    NoReport,
    /// An output could not be written.
    #[error("writing {}", path.display())]
    Output {
        /// The file or directory.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// Who a process is in its team and how it reaches the others.
#[derive(Clone, Debug)]
pub struct Member<'a> {
    /// Its name in the log (`robot0`, `base`).
    pub name: String,
    /// Its id on the link.
    pub id: u32,
    /// Seeds its actors' generators.
    pub seed: u64,
    /// The team's id (`[robot.link] team`).
    pub team: u32,
    /// Its zenoh session.
    pub zenoh: &'a ZenohConfig,
    /// Whose frames it receives (`[robot.link] subscribe`; the default: everyone's).
    pub subscription: SubscriptionConfig,
    /// Its output directory.
    pub out: PathBuf,
}

/// One robot on the real-time executor with the team link over zenoh, ready to run.
pub struct Harness {
    name: String,
    out: PathBuf,
    executor: RealtimeExecutor,
    transport: Arc<ZenohTransport>,
    recorder: Option<SharedRecorder>,
    trajectory: Option<Shared<Vec<[f64; 4]>>>,
}

/// What a process's robot did, once [`Harness::run`] is over.
#[derive(Debug)]
pub struct Finished {
    /// The executor's report of the robot (topics, actors).
    pub report: RobotReport,
    /// Wall seconds from the start of the actors to the end of the shutdown.
    pub wall_s: f64,
    /// The zenoh session's counters.
    pub zenoh: ZenohStats,
    /// Packets the executor could not hand to the transport.
    pub transport_errors: u64,
    /// The recording, when one was written and finished.
    pub recording: Option<RecordingStats>,
    /// `[unix_time_s, x_m, y_m, z_m]` at every odometry message, with
    /// [`Harness::track_trajectory`] (empty without).
    pub trajectory: Vec<[f64; 4]>,
}

impl Finished {
    /// Messages published on the topic `name`.
    #[must_use]
    pub fn messages(&self, name: &str) -> u64 {
        self.report.topics.get(name).map_or(0, |t| t.messages)
    }

    /// Every actor's health, in the order they were added.
    #[must_use]
    pub fn actors(&self) -> Vec<ActorHealth> {
        self.report
            .actors
            .iter()
            .map(|a| ActorHealth {
                name: a.name.clone(),
                handled: a.stats.handled,
                errors: a.stats.errors,
                panics: a.stats.panics,
            })
            .collect()
    }
}

/// One actor's health, in a process's `summary.json`.
#[derive(Clone, Debug, Serialize)]
pub struct ActorHealth {
    /// Name.
    pub name: String,
    /// Events handled.
    pub handled: u64,
    /// Hooks that returned an error.
    pub errors: u64,
    /// Panics.
    pub panics: u64,
}

type Shared<T> = Arc<Mutex<T>>;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The last message published on a topic ([`Harness::latest`]).
#[derive(Debug)]
pub struct Latest<T>(Shared<Option<T>>);

impl<T> Clone for Latest<T> {
    fn clone(&self) -> Self {
        Latest(self.0.clone())
    }
}

impl<T: Clone> Latest<T> {
    /// The last message so far (`None` before the first).
    #[must_use]
    pub fn get(&self) -> Option<T> {
        lock(&self.0).clone()
    }

    /// Takes the last message out.
    #[must_use]
    pub fn take(&self) -> Option<T> {
        lock(&self.0).take()
    }
}

impl Harness {
    /// Opens `member`'s zenoh session and puts `spec` on a real-time executor under
    /// its link id; nothing runs yet. The robot's own odometry tells the transport
    /// where it is (its keyframes' cell and, under a neighbourhood scope, the cells
    /// it hears: troupe_comms::scope).
    pub fn open(member: Member<'_>, spec: RobotSpec) -> Result<Self, HarnessError> {
        let id = member.id;
        let transport = Arc::new(
            ZenohTransport::open(member.zenoh, member.team, vec![id])
                .map_err(HarnessError::Session)?
                .with_subscription(member.subscription),
        );
        let mut executor = RealtimeExecutor::new(vec![spec], member.seed)
            .with_robot_ids(vec![RobotId(id)])
            .map_err(HarnessError::RobotId)?;
        let position = transport.clone();
        executor.add_tap(move |p: &Publication<'_>| {
            if let Some(o) = p.get(&ODOMETRY) {
                let v = o.pose.translation.vector;
                position.set_position(id, [v.x, v.y, v.z]);
            }
        });
        Ok(Harness {
            name: member.name,
            out: member.out,
            executor,
            transport,
            recorder: None,
            trajectory: None,
        })
    }

    /// Adds an observer of every publication of the robot.
    pub fn add_tap(&mut self, tap: impl Tap + 'static) {
        self.executor.add_tap(tap);
    }

    /// Keeps the last message published on `topic` (a status, a list).
    pub fn latest<T: Message + Clone>(&mut self, topic: Topic<T>) -> Latest<T> {
        let latest = Latest(Arc::default());
        let slot = latest.clone();
        self.executor.add_tap(move |p: &Publication<'_>| {
            if let Some(m) = p.get(&topic) {
                *lock(&slot.0) = Some(m.clone());
            }
        });
        latest
    }

    /// Keeps the robot's position and the Unix time at every odometry message
    /// ([`Finished::trajectory`], [`write_trajectory`]).
    pub fn track_trajectory(&mut self) {
        let samples: Shared<Vec<[f64; 4]>> = Arc::default();
        let tap = samples.clone();
        self.executor.add_tap(move |p: &Publication<'_>| {
            if let Some(o) = p.get(&ODOMETRY) {
                let v = o.pose.translation.vector;
                lock(&tap).push([unix_now_s(), v.x, v.y, v.z]);
            }
        });
        self.trajectory = Some(samples);
    }

    /// Records what the robot publishes into `out/run.mcap` in wall time from now;
    /// `prepare` adds to the recorder first (a world, peer poses).
    pub fn record(
        &mut self,
        options: RecordOptions,
        prepare: impl FnOnce(Recorder) -> Recorder,
    ) -> Result<(), HarnessError> {
        std::fs::create_dir_all(&self.out).map_err(|source| HarnessError::Output {
            path: self.out.clone(),
            source,
        })?;
        let path = self.out.join(RUN_RECORDING);
        let recorder = Recorder::create_with(&path, Clock::wall_from_now(), options)
            .map_err(HarnessError::Recording)?;
        let recorder = SharedRecorder::new(prepare(recorder));
        self.executor.add_tap(recorder.clone());
        self.recorder = Some(recorder);
        Ok(())
    }

    /// The recording, once [`Harness::record`] made one: to write a process's own
    /// channels beside what the robot publishes.
    #[must_use]
    pub fn recorder(&self) -> Option<SharedRecorder> {
        self.recorder.clone()
    }

    /// Starts the actors and the team link, runs until `duration_s` is over (never,
    /// when `None`) or `stop` resolves, then shuts the actors down, closes the
    /// session and finishes the recording. Must be called inside a multi-threaded
    /// tokio runtime.
    pub async fn run(
        self,
        duration_s: Option<f64>,
        stop: impl Future<Output = ()>,
    ) -> Result<Finished, HarnessError> {
        let Harness {
            name,
            executor,
            transport,
            recorder,
            trajectory,
            ..
        } = self;
        let started = Instant::now();
        let handle = executor
            .spawn_with_transport(transport.clone())
            .map_err(HarnessError::Transport)?;
        tracing::info!("{name}: running");
        run_for(duration_s, stop).await;
        let transport_errors = handle.transport_errors();
        let reports = handle.shutdown().await;
        let zenoh = transport.stats();
        if let Err(e) = transport.close() {
            tracing::warn!("{name}: closing zenoh: {e}");
        }
        let report = reports.into_iter().next().ok_or(HarnessError::NoReport)?;
        let recording = finish_recording(recorder.as_ref(), &name);
        Ok(Finished {
            report,
            wall_s: started.elapsed().as_secs_f64(),
            zenoh,
            transport_errors,
            recording,
            trajectory: trajectory
                .map(|t| std::mem::take(&mut *lock(&t)))
                .unwrap_or_default(),
        })
    }
}

/// Opens the link's journal in `dir` (`[robot.link] journal_dir` under the output
/// directory), keeping up to `keep_received_bytes` of received messages for a
/// restart (`None`: the journal's default). A new journal starts its message ids from
/// the clock, somewhere new, so that peers who remember ids of an earlier run (their
/// duplicate filter) do not drop this run's first messages as repeats.
pub fn open_journal(
    dir: &Path,
    keep_received_bytes: Option<usize>,
) -> Result<LinkJournal, HarnessError> {
    let first_id = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u32);
    match keep_received_bytes {
        None => LinkJournal::on_disk(dir, first_id),
        Some(bytes) => LinkJournal::on_disk_keeping(dir, first_id, bytes),
    }
    .map_err(|source| HarnessError::Journal { source })
}

/// Runs `future` to its end on a new multi-threaded tokio runtime.
pub fn block_on<F: Future>(future: F) -> Result<F::Output, HarnessError> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(HarnessError::Runtime)?;
    Ok(runtime.block_on(future))
}

/// Waits for SIGINT or SIGTERM on a small runtime of its own (a process whose
/// work runs on other threads, e.g. a zenoh router).
pub fn wait_for_signal() -> Result<(), HarnessError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(HarnessError::Runtime)?
        .block_on(shutdown_signal());
    Ok(())
}

/// Resolves after `duration_s` seconds (never, when `None`) or when `stop` resolves,
/// whichever comes first: how long a robot or base process runs.
pub async fn run_for(duration_s: Option<f64>, stop: impl Future<Output = ()>) {
    match duration_s {
        Some(d) => {
            tokio::select! {
                () = tokio::time::sleep(Duration::from_secs_f64(d)) => {}
                () = stop => {}
            }
        }
        None => stop.await,
    }
}

/// Resolves on SIGINT (Ctrl-C) or SIGTERM.
pub async fn shutdown_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        if let Ok(mut term) = signal(SignalKind::terminate()) {
            tokio::select! {
                _ = tokio::signal::ctrl_c() => {}
                _ = term.recv() => {}
            }
            return;
        }
    }
    let _ = tokio::signal::ctrl_c().await;
}

/// Finishes a process's `run.mcap` (`None`: recording was off); a failed recording
/// is logged as a warning naming `who` and gives `None`, since the run itself succeeded.
fn finish_recording(recorder: Option<&SharedRecorder>, who: &str) -> Option<RecordingStats> {
    match recorder?.finish()? {
        Ok(stats) => Some(stats),
        Err(e) => {
            tracing::warn!("{who}: recording: {}", ErrorChain(&e));
            None
        }
    }
}

/// Writes `summary` as pretty JSON (and a final newline) into `dir/summary.json`,
/// creating `dir`.
pub fn write_summary(dir: &Path, summary: &impl Serialize) -> Result<(), HarnessError> {
    let output = |path: &Path| {
        let path = path.to_path_buf();
        move |source| HarnessError::Output { path, source }
    };
    std::fs::create_dir_all(dir).map_err(output(dir))?;
    let path = dir.join(SUMMARY_JSON);
    let mut json = serde_json::to_string_pretty(summary).map_err(|e| output(&path)(e.into()))?;
    json.push('\n');
    std::fs::write(&path, json).map_err(output(&path))
}

/// Writes `trajectory.csv` (`unix_time_s,x_m,y_m,z_m`, [`Finished::trajectory`])
/// into `dir`.
pub fn write_trajectory(dir: &Path, trajectory: &[[f64; 4]]) -> Result<(), HarnessError> {
    let mut csv = String::from("unix_time_s,x_m,y_m,z_m\n");
    for [t, x, y, z] in trajectory {
        let _ = writeln!(csv, "{t:.6},{x},{y},{z}");
    }
    let path = dir.join("trajectory.csv");
    std::fs::write(&path, csv).map_err(|source| HarnessError::Output { path, source })
}

/// Reads a `trajectory.csv` written by [`write_trajectory`].
pub fn read_trajectory(path: &Path) -> std::io::Result<Vec<[f64; 4]>> {
    let text = std::fs::read_to_string(path)?;
    text.lines()
        .skip(1)
        .map(|line| {
            let v: Vec<f64> = line
                .split(',')
                .map(str::parse)
                .collect::<Result<_, _>>()
                .map_err(std::io::Error::other)?;
            match v.as_slice() {
                [t, x, y, z] => Ok([*t, *x, *y, *z]),
                _ => Err(std::io::Error::other(format!("bad line `{line}`"))),
            }
        })
        .collect()
}

/// Seconds since the Unix epoch, now (0 before it).
#[must_use]
pub fn unix_now_s() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// The log filter of the `troupe` binary without `RUST_LOG`: warnings, less zenoh's
/// notice that gossip is off (troupe turns it off: peers are named, not discovered)
/// and its notice at every TLS connection that the server's name is not checked
/// (certificates name robots, not hosts: the access control checks the name).
pub const DEFAULT_LOG_FILTER: &str =
    "warn,zenoh::net::routing::hat=error,zenoh_link_tls::utils=error";

/// The log filter of `troupe-robot` without `RUST_LOG`: [`DEFAULT_LOG_FILTER`] and
/// the hardware driver's and the link's rare info lines (waiting for the autopilot,
/// control handed over, a restarted peer, an absent base station; docs/hardware.md).
pub const HARDWARE_LOG_FILTER: &str = "warn,zenoh::net::routing::hat=error,zenoh_link_tls::utils=error,troupe_robot=info,\
     troupe_actors::link=info";

/// Logs to stderr, filtered by `RUST_LOG` (default [`DEFAULT_LOG_FILTER`]): a
/// binary's first line.
pub fn init_logging() {
    init_logging_with(DEFAULT_LOG_FILTER);
}

/// Logs to stderr, filtered by `RUST_LOG` (default `default_filter`); zenoh's
/// line per refused connection becomes one line per kind every 10 s
/// ([`troupe_comms::zenoh::refusals`]).
pub fn init_logging_with(default_filter: &str) {
    use tracing_subscriber::layer::{Layer, SubscriberExt};
    use tracing_subscriber::util::SubscriberInitExt;
    use troupe_comms::zenoh::refusals;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default_filter));
    let log = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_filter(tracing_subscriber::filter::FilterExt::and(
            filter,
            refusals::hide_refusals(),
        ));
    tracing_subscriber::registry()
        .with(log)
        .with(refusals::refusal_layer())
        .init();
}

/// A binary's exit code: success, or the error with its causes on one line of
/// standard error (`<prefix>: what: why: …`) and failure. An error caused by a closed
/// pipe (`troupe sweep --dry-run | head`) is success, silently: the reader has all it
/// wanted.
pub fn exit_code(prefix: &str, result: Result<(), &(dyn std::error::Error + 'static)>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if closed_pipe(e) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{prefix}: {}", ErrorChain(e));
            ExitCode::FAILURE
        }
    }
}

/// Whether `e` or one of its causes is an I/O error of a closed pipe.
fn closed_pipe(e: &(dyn std::error::Error + 'static)) -> bool {
    std::iter::successors(Some(e), |e| e.source()).any(|e| {
        e.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_closed_pipe_is_success_and_other_errors_fail() {
        let pipe = std::io::Error::from(std::io::ErrorKind::BrokenPipe);
        assert_eq!(exit_code("t", Err(&pipe)), ExitCode::SUCCESS);
        #[derive(Debug, thiserror::Error)]
        #[error("writing the list")]
        struct Writing(#[source] std::io::Error);
        assert_eq!(exit_code("t", Err(&Writing(pipe))), ExitCode::SUCCESS);
        let other = std::io::Error::from(std::io::ErrorKind::NotFound);
        assert_eq!(exit_code("t", Err(&other)), ExitCode::FAILURE);
    }

    #[test]
    fn a_trajectory_reads_back_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let samples = [[1.5, 0.0, -1.25, 2.0], [2.0, 0.5, 3.0, 1e-3]];
        write_trajectory(dir.path(), &samples).unwrap();
        let read = read_trajectory(&dir.path().join("trajectory.csv")).unwrap();
        assert_eq!(read, samples);
    }

    #[test]
    fn a_summary_is_pretty_json_with_a_final_newline() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("nested/out");
        write_summary(&out, &serde_json::json!({ "robot": 1 })).unwrap();
        let text = std::fs::read_to_string(out.join(SUMMARY_JSON)).unwrap();
        assert_eq!(text, "{\n  \"robot\": 1\n}\n");
    }

    #[tokio::test]
    async fn a_run_lasts_its_duration_or_until_stopped() {
        let started = Instant::now();
        run_for(Some(0.05), std::future::pending()).await;
        assert!(started.elapsed() >= Duration::from_millis(50));
        run_for(None, async {}).await;
        run_for(Some(3600.0), async {}).await;
    }
}
