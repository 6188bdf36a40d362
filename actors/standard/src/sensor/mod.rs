//! The sensor actor: turns a [`FrameSource`] into [`DepthFrame`]s at a fixed rate.
//!
//! The source is a trait so that the same actor serves a simulated camera, a
//! recorded sequence, or a hardware driver.

use std::sync::Arc;
use std::time::Duration;

use crate::msgs::{DEPTH_FRAME, ODOMETRY};
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_algorithms::frame::{DepthFrame, Odometry};
use troupe_runtime::{Actor, ActorError, ActorResult, Context, Event, QueuePolicy, Time, TimerId};

/// Where frames come from.
pub trait FrameSource: Send + 'static {
    /// Captures one frame at time `now`. Simulated sources render from the latest
    /// body odometry (`None` before the first one arrives); recorded sources may
    /// ignore it. `Ok(None)` means "nothing this time" (end of a sequence, no pose yet).
    fn capture(
        &mut self,
        now: Time,
        odometry: Option<&Odometry>,
    ) -> Result<Option<DepthFrame>, ActorError>;
}

const CAPTURE: TimerId = TimerId(0);

/// Captures a frame every `period` and publishes it on [`DEPTH_FRAME`]; invalid
/// frames are rejected (counted as actor errors) and never published. Frames wider
/// than [`SensorActor::decimating_to`]'s width are decimated first.
pub struct SensorActor<S> {
    source: S,
    period: Duration,
    latest: Option<Arc<Odometry>>,
    max_width_px: u32,
}

impl<S: FrameSource> SensorActor<S> {
    /// A sensor capturing at `rate_hz` (must be > 0).
    #[must_use]
    pub fn new(source: S, rate_hz: f64) -> Self {
        SensorActor {
            source,
            period: Duration::from_secs_f64(1.0 / rate_hz.max(1e-3)),
            latest: None,
            max_width_px: 0,
        }
    }

    /// The same sensor, publishing frames at most `max_width_px` wide: a wider frame
    /// becomes one pixel per block ([`DepthFrame::decimated`]: the block's nearest
    /// return), so the mapper, grid and planner cost what the authors' 160 × 120
    /// frames cost whatever the camera delivers (0: frames as they come).
    #[must_use]
    pub fn decimating_to(mut self, max_width_px: u32) -> Self {
        self.max_width_px = max_width_px;
        self
    }
}

impl<S: FrameSource> Actor for SensorActor<S> {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        ctx.set_timer(CAPTURE, self.period);
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(m) => {
                if let Some(odometry) = m.get_arc(&ODOMETRY) {
                    self.latest = Some(odometry);
                }
                ctx.bookkeeping_only();
            }
            Event::Timer(_) => {
                if let Some(frame) = self.source.capture(ctx.now(), self.latest.as_deref())? {
                    frame
                        .validate()
                        .map_err(|e| ActorError::with_source("rejected a frame", e))?;
                    let factor =
                        PinholeIntrinsics::decimation(frame.intrinsics.width, self.max_width_px);
                    let frame = if factor > 1 {
                        frame.decimated(factor)
                    } else {
                        frame
                    };
                    ctx.publish(&DEPTH_FRAME, frame);
                }
            }
        }
        Ok(())
    }
}
