//! The sensor actor: turns a [`FrameSource`] into [`DepthFrame`]s at a fixed rate.
//!
//! The source is a trait so that the same actor serves a simulated camera, a
//! recorded sequence, or a hardware driver.

use std::sync::Arc;
use std::time::Duration;

use crate::msgs::{DEPTH_FRAME, DepthFrame, ODOMETRY, Odometry};
use crate::runtime::{Actor, ActorError, ActorResult, Context, Event, QueuePolicy, Time, TimerId};

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

/// Checks that a frame is usable: sizes agree with the intrinsics, depths are finite
/// and non-negative, the pose is finite. Frames with no valid pixel are allowed
/// (everything beyond range is information too).
pub fn validate_frame(frame: &DepthFrame) -> Result<(), ActorError> {
    let pixels = frame.intrinsics.width as usize * frame.intrinsics.height as usize;
    if pixels == 0 {
        return Err(ActorError::msg("frame has zero pixels"));
    }
    if frame.depth_m.len() != pixels || frame.intensity.len() != pixels {
        return Err(ActorError::msg(format!(
            "frame buffers have {} depth and {} intensity values for {}×{} pixels",
            frame.depth_m.len(),
            frame.intensity.len(),
            frame.intrinsics.width,
            frame.intrinsics.height
        )));
    }
    if let Some(i) = frame
        .depth_m
        .iter()
        .position(|d| !d.is_finite() || *d < 0.0)
    {
        return Err(ActorError::msg(format!(
            "depth pixel {i} is {}",
            frame.depth_m[i]
        )));
    }
    let pose_ok = frame.pose.translation.vector.iter().all(|v| v.is_finite())
        && frame.pose.rotation.coords.iter().all(|v| v.is_finite());
    if !pose_ok {
        return Err(ActorError::msg("frame pose is not finite"));
    }
    Ok(())
}

const CAPTURE: TimerId = TimerId(0);

/// Captures a frame every `period` and publishes it on [`DEPTH_FRAME`]; invalid
/// frames are rejected (counted as actor errors) and never published.
pub struct SensorActor<S> {
    source: S,
    period: Duration,
    latest: Option<Arc<Odometry>>,
}

impl<S: FrameSource> SensorActor<S> {
    /// A sensor capturing at `rate_hz` (must be > 0).
    #[must_use]
    pub fn new(source: S, rate_hz: f64) -> Self {
        SensorActor {
            source,
            period: Duration::from_secs_f64(1.0 / rate_hz.max(1e-3)),
            latest: None,
        }
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
            }
            Event::Timer(_) => {
                if let Some(frame) = self.source.capture(ctx.now(), self.latest.as_deref())? {
                    validate_frame(&frame)?;
                    ctx.publish(&DEPTH_FRAME, frame);
                }
            }
        }
        Ok(())
    }
}
