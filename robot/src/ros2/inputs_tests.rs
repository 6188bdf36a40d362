use troupe_core::Time;

use super::*;
use crate::ros2::cdr::encode;
use crate::ros2::msgs::{Header, Image, Odometry as RosOdometry, RosTime};

fn config(format: &str, intensity: bool) -> Ros2Config {
    let intensity = if intensity { "intensity = \"/ir\"" } else { "" };
    toml::from_str(&format!(
        r#"
        format = "{format}"
        odometry_tolerance_s = 0.02
        [topics]
        depth = "/depth"
        camera_info = "/info"
        odometry = "/odom"
        {intensity}
        "#
    ))
    .unwrap()
}

fn stamp(ms: i64) -> RosTime {
    RosTime::from_nanos(1_700_000_000_000_000_000 + ms * 1_000_000)
}

/// A 2 × 1 image stamped `ms` in the optical frame.
fn image(ms: i64, encoding: &str, step: u32, data: Vec<u8>) -> Vec<u8> {
    encode(&Image {
        header: Header {
            stamp: stamp(ms),
            frame_id: "optical".into(),
        },
        height: 1,
        width: 2,
        encoding: encoding.into(),
        step,
        data,
        ..Default::default()
    })
    .unwrap()
}

fn depth(ms: i64) -> Vec<u8> {
    image(ms, "16UC1", 4, vec![0xe8, 0x03, 0xd0, 0x07])
}

fn intensity(ms: i64) -> Vec<u8> {
    image(ms, "mono8", 2, vec![0, 255])
}

fn info() -> Vec<u8> {
    encode(&CameraInfo {
        height: 1,
        width: 2,
        k: [1.0, 0.0, 1.0, 0.0, 1.0, 0.5, 0.0, 0.0, 1.0],
        ..Default::default()
    })
    .unwrap()
}

fn odometry(ms: i64, x: f64) -> Vec<u8> {
    let mut o = RosOdometry {
        header: Header {
            stamp: stamp(ms),
            frame_id: "odom".into(),
        },
        ..Default::default()
    };
    o.pose.pose.position.x = x;
    encode(&o).unwrap()
}

const ATTACHMENT: [u8; 33] = {
    let mut a = [0u8; 33];
    a[16] = 16;
    a
};

fn shared(format: &str, intensity: bool) -> Shared {
    Shared::new(&config(format, intensity)).unwrap()
}

#[test]
fn frame_pairs_with_the_nearest_odometry_and_is_returned_once() {
    let s = shared("bridge", false);
    assert!(s.capture(Time::ZERO).is_none());
    s.ingest(Input::CameraInfo, &info(), None);
    s.ingest(Input::Odometry, &odometry(0, 1.0), None);
    s.ingest(Input::Odometry, &odometry(10, 2.0), None);
    s.ingest(Input::Odometry, &odometry(30, 3.0), None);
    s.ingest(Input::Depth, &depth(12), None);
    let frame = s.capture(Time::from_secs_f64(100.0)).unwrap();
    // Odometry at 10 ms (x = 2) is nearest; the default extrinsics add no offset.
    assert!((frame.pose.translation.vector.x - 2.0).abs() < 1e-12);
    assert_eq!(frame.depth_m, [1.0, 2.0]);
    // Stamped by its age: long ago relative to wall clock, so at the start of the run.
    assert!(frame.stamp < Time::from_secs_f64(100.0));
    assert!(
        s.capture(Time::from_secs_f64(100.0)).is_none(),
        "returned twice"
    );
    assert_eq!(s.lock().stats.frames, 1);
}

#[test]
fn a_frame_waits_for_odometry_then_is_skipped_when_none_is_close() {
    let s = shared("bridge", false);
    s.ingest(Input::CameraInfo, &info(), None);
    s.ingest(Input::Odometry, &odometry(0, 1.0), None);
    s.ingest(Input::Depth, &depth(100), None);
    // Odometry has not reached the frame's stamp yet: wait.
    assert!(s.capture(Time::ZERO).is_none());
    assert!(s.lock().depth.is_some());
    s.ingest(Input::Odometry, &odometry(110, 1.0), None);
    s.ingest(Input::Odometry, &odometry(200, 1.0), None);
    // 10 ms away: within 20 ms.
    assert!(s.capture(Time::ZERO).is_some());
    s.ingest(Input::Depth, &depth(150), None);
    assert!(s.capture(Time::ZERO).is_none());
    assert_eq!(s.lock().stats.rejected["frame/no_odometry"], 1);
    assert!(s.lock().depth.is_none());
}

#[test]
fn bad_payloads_attachments_and_frames_are_counted_by_reason() {
    let s = shared("rmw_zenoh", true);
    s.ingest(Input::Depth, &[0, 1, 0, 0, 9], Some(&ATTACHMENT));
    s.ingest(Input::Odometry, &odometry(0, 0.0), None);
    s.ingest(Input::Odometry, &odometry(5, 0.0), Some(&[1, 2, 3]));
    s.ingest(Input::CameraInfo, &info(), Some(&ATTACHMENT));
    s.ingest(Input::Depth, &depth(0), Some(&ATTACHMENT));
    // An intensity topic is configured but nothing came yet: the frame waits.
    assert!(s.capture(Time::ZERO).is_none());
    assert!(s.lock().depth.is_some());
    // An intensity image newer than the frame but too far from it: skipped.
    s.ingest(Input::Intensity, &intensity(30), Some(&ATTACHMENT));
    assert!(s.capture(Time::ZERO).is_none());
    assert!(s.lock().depth.is_none());
    let stats = s.lock().stats.clone();
    assert_eq!(stats.rejected["depth/malformed"], 1);
    assert_eq!(stats.rejected["odometry/no_attachment"], 1);
    assert_eq!(stats.rejected["odometry/attachment"], 1);
    assert_eq!(stats.rejected["frame/no_intensity"], 1);
    assert_eq!(stats.received["depth"], 2);
    // A malformed image is not stored, so the good one superseded nothing.
    assert_eq!(stats.superseded, 0);
    // A calibration of another size: the frame is rejected with that reason.
    let s = shared("bridge", false);
    s.ingest(
        Input::CameraInfo,
        &encode(&CameraInfo {
            width: 3,
            height: 1,
            ..Default::default()
        })
        .unwrap(),
        None,
    );
    s.ingest(Input::Odometry, &odometry(0, 0.0), None);
    s.ingest(Input::Depth, &depth(0), None);
    assert!(s.capture(Time::ZERO).is_none());
    assert_eq!(s.lock().stats.rejected["frame/size_mismatch"], 1);
}

#[test]
fn a_frame_waits_for_its_intensity_image_and_uses_the_nearest() {
    let s = shared("bridge", true);
    s.ingest(Input::CameraInfo, &info(), None);
    s.ingest(Input::Odometry, &odometry(0, 0.0), None);
    s.ingest(Input::Odometry, &odometry(40, 0.0), None);
    s.ingest(Input::Intensity, &intensity(0), None);
    s.ingest(Input::Depth, &depth(20), None);
    s.ingest(Input::Depth, &depth(21), None);
    assert!(
        s.capture(Time::ZERO).is_none(),
        "the intensity of 21 ms may still come"
    );
    s.ingest(Input::Intensity, &intensity(22), None);
    let frame = s.capture(Time::ZERO).unwrap();
    assert_eq!(frame.intensity, [0.0, 1.0]);
    let stats = s.lock().stats.clone();
    assert_eq!(stats.superseded, 1);
    assert!(stats.rejected.is_empty(), "{stats:?}");
}

#[test]
fn odometry_history_is_bounded() {
    let s = shared("bridge", false);
    for i in 0..500 {
        s.ingest(Input::Odometry, &odometry(i, 0.0), None);
    }
    assert_eq!(s.lock().odometry.len(), 200);
}
