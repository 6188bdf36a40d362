//! Golden CDR payloads written by rclpy's `serialize_message` (scripts/ros2/make_golden.py):
//! every field decodes to the value the script set, re-encoding gives the same message,
//! and the conversions turn them into the troupe frames and odometry they stand for.

#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use nalgebra::{Isometry3, Point3, Vector3};
use troupe_core::Time;
use troupe_robot::ros2::cdr::{decode, encode};
use troupe_robot::ros2::convert::{
    DepthInputs, depth_frame_from_image, depth_frame_from_points, odometry_from_ros,
};
use troupe_robot::ros2::msgs::{
    CameraInfo, DiagnosticArray, DiagnosticStatus, Header, Image, KeyValue, Odometry, Path,
    PointCloud2, PointField, RosString, RosTime,
};
use troupe_robot::ros2::{CdrError, RosMessage};

fn golden(name: &str) -> Vec<u8> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/ros2")
        .join(format!("{name}.cdr"));
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

const STAMP: RosTime = RosTime {
    sec: 1_700_000_000,
    nanosec: 123_456_789,
};

fn header(frame: &str) -> Header {
    Header {
        stamp: STAMP,
        frame_id: frame.into(),
    }
}

/// Decodes a golden file, checks it against `expected`, and checks that our encoding
/// decodes to the same message (rclpy's padding bytes are unspecified, so bytes may differ
/// only there: the lengths agree).
fn check<T: RosMessage + PartialEq + std::fmt::Debug>(name: &str, expected: &T) -> T {
    let bytes = golden(name);
    let decoded: T = decode(&bytes).unwrap();
    assert_eq!(&decoded, expected, "{name}");
    let ours = encode(&decoded).unwrap();
    assert_eq!(ours.len(), bytes.len(), "{name}: encoded length");
    assert_eq!(decode::<T>(&ours).unwrap(), decoded, "{name}: round trip");
    decoded
}

fn strings(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| (*s).to_owned()).collect()
}

fn u16_bytes(values: &[u16]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn camera_info() -> CameraInfo {
    CameraInfo {
        header: header("camera_depth_optical_frame"),
        height: 3,
        width: 4,
        distortion_model: "plumb_bob".into(),
        d: vec![0.1, -0.2, 0.001, 0.002, 0.0],
        k: [2.0, 0.0, 2.0, 0.0, 2.5, 1.5, 0.0, 0.0, 1.0],
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [2.0, 0.0, 2.0, 0.0, 0.0, 2.5, 1.5, 0.0, 0.0, 0.0, 1.0, 0.0],
        binning_x: 1,
        binning_y: 2,
        roi: Default::default(),
    }
}

#[test]
fn depth_16uc1_image_decodes_and_converts_to_metres() {
    let mm = [
        0, 1000, 1500, 2000, 2500, 3000, 65535, 1, 250, 500, 750, 4999,
    ];
    let image = check(
        "depth_16uc1",
        &Image {
            header: header("camera_depth_optical_frame"),
            height: 3,
            width: 4,
            encoding: "16UC1".into(),
            is_bigendian: 0,
            step: 8,
            data: u16_bytes(&mm),
        },
    );
    let info = check("camera_info", &camera_info());
    let frame = depth_frame_from_image(
        &DepthInputs {
            depth: &image,
            info: &info,
            intensity: None,
            depth_encodings: &strings(&["16UC1"]),
            intensity_encodings: &strings(&["mono8"]),
            max_depth_m: 5.0,
        },
        Isometry3::identity(),
        Time::from_nanos(7),
    )
    .unwrap();
    // 65.535 m is beyond range: no return.
    let expected = [
        0.0, 1.0, 1.5, 2.0, 2.5, 3.0, 0.0, 0.001, 0.25, 0.5, 0.75, 4.999,
    ];
    for (got, want) in frame.depth_m.iter().zip(expected) {
        assert!((f64::from(*got) - want).abs() < 1e-6, "{got} vs {want}");
    }
    let hits: Vec<f32> = expected
        .iter()
        .map(|d| if *d > 0.0 { 1.0 } else { 0.0 })
        .collect();
    assert_eq!(frame.intensity, hits);
    // Troupe's pixel centres are at +0.5: cx 2 → 2.5, cy 1.5 → 2.
    let k = frame.intrinsics;
    assert_eq!(
        (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
        (4, 3, 2.0, 2.5, 2.5, 2.0)
    );
    assert_eq!(frame.stamp, Time::from_nanos(7));
}

#[test]
fn depth_32fc1_image_decodes_and_nan_is_no_return() {
    let m: [f32; 12] = [
        0.0,
        1.0,
        1.5,
        2.0,
        2.5,
        3.0,
        f32::NAN,
        0.001,
        0.25,
        0.5,
        0.75,
        4.999,
    ];
    let image: Image = decode(&golden("depth_32fc1")).unwrap();
    assert_eq!(
        (
            image.header.clone(),
            image.height,
            image.width,
            image.encoding.as_str(),
            image.is_bigendian,
            image.step
        ),
        (header("camera_depth_optical_frame"), 3, 4, "32FC1", 0, 16)
    );
    let values: Vec<f32> = image
        .data
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    for (got, want) in values.iter().zip(m) {
        assert!(got.to_bits() == want.to_bits(), "{got} vs {want}");
    }
    let frame = depth_frame_from_image(
        &DepthInputs {
            depth: &image,
            info: &camera_info(),
            intensity: None,
            depth_encodings: &strings(&["32FC1"]),
            intensity_encodings: &strings(&["mono8"]),
            max_depth_m: 5.0,
        },
        Isometry3::identity(),
        Time::ZERO,
    )
    .unwrap();
    assert_eq!(frame.depth_m[6], 0.0);
    assert_eq!(frame.depth_m[11], 4.999);
}

#[test]
fn point_cloud_decodes_and_projects_into_the_intrinsics() {
    let field = |name: &str, offset| PointField {
        name: name.into(),
        offset,
        datatype: PointField::FLOAT32,
        count: 1,
    };
    let points = [
        [0.5f32, 0.0, 0.0, 2.0],
        [0.25, 1.0, -0.5, 4.0],
        [1.0, -1.0, 0.75, 3.0],
    ];
    let mut data = Vec::new();
    for p in points {
        for v in p {
            data.extend_from_slice(&v.to_le_bytes());
        }
        data.extend_from_slice(&[0xee; 4]);
    }
    let cloud = check(
        "points",
        &PointCloud2 {
            header: header("camera_depth_optical_frame"),
            height: 1,
            width: 3,
            fields: vec![
                field("intensity", 0),
                field("x", 4),
                field("y", 8),
                field("z", 12),
            ],
            is_bigendian: false,
            point_step: 20,
            row_step: 60,
            data,
            is_dense: true,
        },
    );
    let intrinsics = troupe_algorithms::camera::PinholeIntrinsics {
        width: 4,
        height: 3,
        fx: 2.0,
        fy: 2.0,
        cx: 2.0,
        cy: 1.5,
        max_depth_m: 5.0,
    };
    let frame =
        depth_frame_from_points(&cloud, intrinsics, Isometry3::identity(), Time::ZERO).unwrap();
    // (0,0,2) → u = 2, v = 1.5 → pixel (2, 1); (1,-0.5,4) → u 2.5, v 1.25 → (2, 1) but
    // farther, so hidden; (-1, 0.75, 3) → u 1.33, v 2 → (1, 2).
    let mut expected = vec![0.0f32; 12];
    expected[4 + 2] = 2.0;
    expected[2 * 4 + 1] = 3.0;
    assert_eq!(frame.depth_m, expected);
    assert_eq!(frame.intensity[6], 0.5);
    assert_eq!(frame.intensity[9], 1.0);
}

#[test]
fn odometry_decodes_with_both_covariances_and_converts() {
    let odometry: Odometry = decode(&golden("odometry")).unwrap();
    assert_eq!(odometry.header, header("odom"));
    assert_eq!(odometry.child_frame_id, "base_link");
    let p = odometry.pose.pose;
    assert_eq!((p.position.x, p.position.y, p.position.z), (1.0, -2.0, 3.5));
    let q = p.orientation;
    let h = std::f64::consts::FRAC_1_SQRT_2;
    assert_eq!((q.x, q.y, q.z, q.w), (0.0, 0.0, h, h));
    for i in 0..36 {
        assert_eq!(odometry.pose.covariance.0[i], i as f64);
        assert_eq!(odometry.twist.covariance.0[i], -(i as f64));
    }
    let t = odometry.twist.twist;
    assert_eq!((t.linear.x, t.linear.y, t.linear.z), (0.5, 0.0, -0.1));
    assert_eq!((t.angular.x, t.angular.y, t.angular.z), (0.0, 0.0, 0.2));
    check("odometry", &odometry);

    // Yaw 90°: body forward is world +y, so 0.5 m/s forward is +y in the world.
    let troupe = odometry_from_ros(&odometry, Time::from_nanos(5)).unwrap();
    assert!((troupe.pose * Point3::origin() - Point3::new(1.0, -2.0, 3.5)).norm() < 1e-12);
    assert!((troupe.velocity_mps - Vector3::new(0.0, 0.5, -0.1)).norm() < 1e-12);
}

#[test]
fn path_and_status_decode() {
    let path: Path = decode(&golden("path")).unwrap();
    assert_eq!(path.header, header("odom"));
    assert_eq!(path.poses.len(), 2);
    for (i, pose) in path.poses.iter().enumerate() {
        assert_eq!(pose.header, header("odom"));
        let i = i as f64;
        let p = pose.pose.position;
        assert_eq!((p.x, p.y, p.z), (i, 2.0 * i, 1.0));
        assert_eq!(pose.pose.orientation.w, 1.0);
    }
    check("path", &path);
    check(
        "status",
        &RosString {
            data: r#"{"robot":"r0","state":"exploring"}"#.into(),
        },
    );
}

/// The vehicle's state as rclpy writes a `diagnostic_msgs/DiagnosticArray`, and ours the
/// same: issue 40's status message in a standard type.
#[test]
fn diagnostics_decode_and_ours_have_the_same_layout() {
    let expected = DiagnosticArray {
        header: header(""),
        status: vec![DiagnosticStatus {
            level: 1,
            name: "troupe/robot0/vehicle".into(),
            message: "holding: sensor timeout".into(),
            hardware_id: "MAVLink system 1 component 1".into(),
            values: vec![
                KeyValue {
                    key: "armed".into(),
                    value: "true".into(),
                },
                KeyValue {
                    key: "mode".into(),
                    value: "OFFBOARD".into(),
                },
            ],
        }],
    };
    check("diagnostics", &expected);
    fails_when_cut::<DiagnosticArray>("diagnostics");
}

/// Every proper prefix of a golden payload is an error for its type, never a panic.
fn fails_when_cut<T: RosMessage + std::fmt::Debug>(name: &str) {
    let bytes = golden(name);
    for cut in 0..bytes.len() {
        assert!(
            decode::<T>(&bytes[..cut]).is_err(),
            "{name} cut to {cut} bytes decoded"
        );
    }
}

#[test]
fn truncated_golden_payloads_are_errors() {
    fails_when_cut::<Image>("depth_16uc1");
    fails_when_cut::<Image>("depth_32fc1");
    fails_when_cut::<CameraInfo>("camera_info");
    fails_when_cut::<PointCloud2>("points");
    fails_when_cut::<Odometry>("odometry");
    fails_when_cut::<Path>("path");
    fails_when_cut::<RosString>("status");
    assert!(matches!(
        decode::<Image>(&[0, 1, 0]),
        Err(CdrError::NoHeader(3))
    ));
    assert!(matches!(
        decode::<Image>(&[0, 2, 0, 0]),
        Err(CdrError::Encapsulation(2))
    ));
    let mut long = golden("status");
    long.extend_from_slice(&[0; 8]);
    assert!(matches!(
        decode::<RosString>(&long),
        Err(CdrError::TrailingBytes { extra: 8, .. })
    ));
}
