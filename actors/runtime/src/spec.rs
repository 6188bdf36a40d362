//! How actors and robots are described before a run.

use std::sync::Arc;
use std::time::Duration;
use troupe_core::ConfigError;

use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::actor::Actor;

/// The compute latency the sim-time executor charges for each handler call.
///
/// A handler called at time `t` publishes its outputs at `t + latency`, and the
/// actor handles nothing else before then; meanwhile its queues fill and apply their
/// policies. This is how mapping latency (0.4 s in thesis Table 4.1) or a planning
/// budget shows up in a simulated run. Calls that only store what arrived
/// ([`Context::bookkeeping_only`](crate::Context::bookkeeping_only)) are not charged.
/// The real-time executor ignores it (latency is whatever the handler really takes).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum LatencyModel {
    /// Every call takes the same time.
    Fixed {
        /// Seconds per handler call (≥ 0).
        seconds: f64,
    },
    /// Each call takes a time drawn uniformly from `[min_s, max_s]` (deterministic:
    /// drawn from the actor's seeded generator).
    Uniform {
        /// Shortest call, seconds (≥ 0).
        min_s: f64,
        /// Longest call, seconds (≥ `min_s`).
        max_s: f64,
    },
}

impl Default for LatencyModel {
    fn default() -> Self {
        LatencyModel::Fixed { seconds: 0.0 }
    }
}

impl LatencyModel {
    /// A fixed latency in seconds.
    #[must_use]
    pub const fn fixed(seconds: f64) -> Self {
        LatencyModel::Fixed { seconds }
    }

    /// Checks the numbers; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        match *self {
            LatencyModel::Fixed { seconds } => ConfigError::non_negative("seconds", seconds),
            LatencyModel::Uniform { min_s, max_s } => {
                ConfigError::non_negative("min_s", min_s)?;
                ConfigError::non_negative("max_s", max_s)?;
                if max_s < min_s {
                    return Err(ConfigError::new(
                        "max_s",
                        format!("must be ≥ min_s ({min_s})"),
                        max_s,
                    ));
                }
                Ok(())
            }
        }
    }

    pub(crate) fn sample(&self, rng: &mut impl Rng) -> Duration {
        let seconds = match *self {
            LatencyModel::Fixed { seconds } => seconds,
            LatencyModel::Uniform { min_s, max_s } if max_s > min_s => {
                rng.random_range(min_s..=max_s)
            }
            LatencyModel::Uniform { min_s, .. } => min_s,
        };
        Duration::try_from_secs_f64(seconds.max(0.0)).unwrap_or(Duration::ZERO)
    }
}

/// What the runtime does when an actor's handler panics.
///
/// The actor is rebuilt from its factory (its queues are kept) unless it already
/// restarted `max_restarts` times within the last `window_s` seconds; then it is
/// stopped for the rest of the run and the robot keeps going without it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RestartPolicy {
    /// Restarts allowed within the window (0: stop at the first panic).
    pub max_restarts: u32,
    /// Length of the window in seconds of run time.
    pub window_s: f64,
}

impl Default for RestartPolicy {
    fn default() -> Self {
        RestartPolicy {
            max_restarts: 3,
            window_s: 60.0,
        }
    }
}

/// Per-actor runtime options.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ActorOptions {
    /// Modelled compute latency of one handler call (sim-time executor).
    pub latency: LatencyModel,
    /// Panic handling.
    pub restart: RestartPolicy,
    /// Heavy compute: under the real-time executor, run handlers where they may block
    /// a thread without stalling the async workers.
    pub blocking: bool,
}

/// Builds actor instances (called at start and on every restart).
pub type ActorFactory = Box<dyn FnMut() -> Box<dyn Actor> + Send>;

/// An actor to be run: a name, a factory (called at start and on every restart) and
/// options.
pub struct ActorSpec {
    pub(crate) name: Arc<str>,
    pub(crate) factory: ActorFactory,
    pub(crate) options: ActorOptions,
}

impl ActorSpec {
    /// An actor built by `factory`.
    pub fn new<A, F>(name: impl Into<String>, mut factory: F) -> Self
    where
        A: Actor,
        F: FnMut() -> A + Send + 'static,
    {
        ActorSpec {
            name: Arc::from(name.into()),
            factory: Box::new(move || Box::new(factory()) as Box<dyn Actor>),
            options: ActorOptions::default(),
        }
    }

    /// Sets all options.
    #[must_use]
    pub fn with_options(mut self, options: ActorOptions) -> Self {
        self.options = options;
        self
    }

    /// Sets the modelled compute latency.
    #[must_use]
    pub fn with_latency(mut self, latency: LatencyModel) -> Self {
        self.options.latency = latency;
        self
    }

    /// Sets the restart policy.
    #[must_use]
    pub fn with_restart(mut self, restart: RestartPolicy) -> Self {
        self.options.restart = restart;
        self
    }

    /// Marks the actor as doing heavy compute (see [`ActorOptions::blocking`]).
    #[must_use]
    pub fn blocking(mut self) -> Self {
        self.options.blocking = true;
        self
    }

    /// The actor's name.
    #[must_use]
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Wraps every instance the factory builds (for instrumentation or fault
    /// injection) without knowing the actor's type.
    #[must_use]
    pub fn wrap<F>(mut self, mut wrapper: F) -> Self
    where
        F: FnMut(Box<dyn Actor>) -> Box<dyn Actor> + Send + 'static,
    {
        let mut inner = self.factory;
        self.factory = Box::new(move || wrapper(inner()));
        self
    }

    /// Replaces the factory with one built from it — for wrappers that must build
    /// fresh instances themselves (a simulated crash and reboot loses all state).
    #[must_use]
    pub fn map_factory(mut self, f: impl FnOnce(ActorFactory) -> ActorFactory) -> Self {
        self.factory = f(self.factory);
        self
    }
}

/// One robot: a name and its actors. Both executors take a team of these.
pub struct RobotSpec {
    pub(crate) name: Arc<str>,
    pub(crate) actors: Vec<ActorSpec>,
}

impl RobotSpec {
    /// A robot with no actors yet.
    #[must_use]
    pub fn new(name: impl Into<String>) -> Self {
        RobotSpec {
            name: Arc::from(name.into()),
            actors: Vec::new(),
        }
    }

    /// Adds an actor.
    pub fn add(&mut self, actor: ActorSpec) -> &mut Self {
        self.actors.push(actor);
        self
    }

    /// Adds an actor (builder style).
    #[must_use]
    pub fn with(mut self, actor: ActorSpec) -> Self {
        self.actors.push(actor);
        self
    }

    /// The robot's name.
    #[must_use]
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Takes the actors out (to rebuild the robot with some of them changed).
    #[must_use]
    pub fn into_actors(self) -> Vec<ActorSpec> {
        self.actors
    }

    /// Names of the actors added so far.
    pub fn actor_names(&self) -> impl Iterator<Item = &str> {
        self.actors.iter().map(|a| a.name())
    }
}
