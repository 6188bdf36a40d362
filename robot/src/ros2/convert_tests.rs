use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::sogmm::Gmm4;
use troupe_algorithms::trajectory::{Knot, Trajectory};
use troupe_core::Time;

use super::*;
use crate::ros2::cdr::{decode, encode};
use crate::ros2::msgs::{Odometry as RosOdometry, Point as RosPoint, Quaternion as RosQuaternion};

fn info(width: u32, height: u32) -> CameraInfo {
    CameraInfo {
        height,
        width,
        k: [2.0, 0.0, 1.0, 0.0, 2.0, 1.0, 0.0, 0.0, 1.0],
        ..Default::default()
    }
}

fn image(encoding: &str, width: u32, height: u32, pixel_bytes: u32, data: Vec<u8>) -> Image {
    Image {
        height,
        width,
        encoding: encoding.into(),
        step: width * pixel_bytes,
        data,
        ..Default::default()
    }
}

fn all() -> (Vec<String>, Vec<String>) {
    (
        vec!["16UC1".into(), "32FC1".into()],
        vec!["mono8".into(), "mono16".into()],
    )
}

fn convert(
    depth: &Image,
    info: &CameraInfo,
    intensity: Option<&Image>,
) -> Result<DepthFrame, ConvertError> {
    let (d, i) = all();
    depth_frame_from_image(
        &DepthInputs {
            depth,
            info,
            intensity,
            depth_encodings: &d,
            intensity_encodings: &i,
            max_depth_m: 5.0,
        },
        Isometry3::identity(),
        Time::ZERO,
    )
}

#[test]
fn intensity_images_scale_to_unit_range_and_follow_returns() {
    let depth = image(
        "16UC1",
        2,
        1,
        2,
        [0u16, 1000].iter().flat_map(|v| v.to_le_bytes()).collect(),
    );
    let mono8 = image("mono8", 2, 1, 1, vec![255, 51]);
    let frame = convert(&depth, &info(2, 1), Some(&mono8)).unwrap();
    assert_eq!(frame.intensity, [0.0, 0.2]);
    let mono16 = image(
        "mono16",
        2,
        1,
        2,
        [7u16, 65535].iter().flat_map(|v| v.to_le_bytes()).collect(),
    );
    let frame = convert(&depth, &info(2, 1), Some(&mono16)).unwrap();
    assert_eq!(frame.intensity, [0.0, 1.0]);
}

#[test]
fn big_endian_and_padded_rows_are_read_correctly() {
    // 1×2 image, 4-byte rows padded to 6 bytes, big-endian millimetres.
    let mut depth = image("16UC1", 1, 2, 2, vec![0x03, 0xe8, 0xaa, 0xbb, 0x07, 0xd0]);
    depth.step = 4;
    depth.is_bigendian = 1;
    let frame = convert(&depth, &info(1, 2), None).unwrap();
    assert_eq!(frame.depth_m, [1.0, 2.0]);
}

#[test]
fn each_inconsistency_is_one_clear_error() {
    let good = image("16UC1", 2, 2, 2, vec![0; 8]);
    let cases: Vec<(Image, CameraInfo, Option<Image>, &str)> = vec![
        (
            image("bgr8", 2, 2, 3, vec![0; 12]),
            info(2, 2),
            None,
            "encoding",
        ),
        (good.clone(), info(3, 2), None, "size_mismatch"),
        (
            Image {
                step: 3,
                ..good.clone()
            },
            info(2, 2),
            None,
            "layout",
        ),
        (
            Image {
                data: vec![0; 7],
                ..good.clone()
            },
            info(2, 2),
            None,
            "layout",
        ),
        (
            Image {
                is_bigendian: 2,
                ..good.clone()
            },
            info(2, 2),
            None,
            "endianness",
        ),
        (image("16UC1", 0, 0, 2, vec![]), info(0, 0), None, "empty"),
        (
            good.clone(),
            CameraInfo {
                k: [f64::NAN; 9],
                ..info(2, 2)
            },
            None,
            "intrinsics",
        ),
        (
            good.clone(),
            info(2, 2),
            Some(image("mono8", 1, 2, 1, vec![0; 2])),
            "size_mismatch",
        ),
        (
            good.clone(),
            info(2, 2),
            Some(image("rgb8", 2, 2, 3, vec![0; 12])),
            "encoding",
        ),
    ];
    for (depth, info, intensity, reason) in cases {
        let err = convert(&depth, &info, intensity.as_ref()).unwrap_err();
        assert_eq!(err.reason(), reason, "{err}");
        assert!(!err.to_string().contains('\n'));
    }
    // An encoding the configuration does not accept is refused even if supported.
    let float = image("32FC1", 2, 2, 4, vec![0; 16]);
    let err = depth_frame_from_image(
        &DepthInputs {
            depth: &float,
            info: &info(2, 2),
            intensity: None,
            depth_encodings: &["16UC1".to_owned()],
            intensity_encodings: &[],
            max_depth_m: 5.0,
        },
        Isometry3::identity(),
        Time::ZERO,
    )
    .unwrap_err();
    assert_eq!(
        err.to_string(),
        "depth image encoding `32FC1` is not accepted (accepted: 16UC1)"
    );
}

#[test]
fn optical_axes_map_to_camera_body_axes() {
    let r = optical_to_camera();
    // Optical z (forward) is body +x, optical x (right) is body −y, optical y (down) −z.
    assert!((r * Vector3::z() - Vector3::x()).norm() < 1e-12);
    assert!((r * Vector3::x() + Vector3::y()).norm() < 1e-12);
    assert!((r * Vector3::y() + Vector3::z()).norm() < 1e-12);
}

#[test]
fn camera_pose_composes_body_pose_and_extrinsics() {
    // Body at (1, 2, 0) yawed 90° (facing world +y); the optical frame 0.1 m ahead of
    // the body, pitched down 90° (the camera looks along body −z, straight down).
    let body = Isometry3::from_parts(
        Translation3::new(1.0, 2.0, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
    );
    let down = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
    let optical_in_body =
        Isometry3::from_parts(Translation3::new(0.1, 0.0, 0.0), down * optical_to_camera());
    let camera = camera_pose(&body, &optical_in_body);
    assert!((camera * Point3::origin() - Point3::new(1.0, 2.1, 0.0)).norm() < 1e-12);
    // The camera's viewing axis (body +x of the camera frame) points down in the world.
    assert!((camera.rotation * Vector3::x() + Vector3::z()).norm() < 1e-12);
    // A point 2 m in front of the optical frame (optical z) lies 2 m below.
    let optical = body * optical_in_body;
    assert!((optical * Point3::new(0.0, 0.0, 2.0) - Point3::new(1.0, 2.1, -2.0)).norm() < 1e-12);
}

#[test]
fn odometry_rejects_non_finite_and_zero_quaternions() {
    let mut odometry = RosOdometry::default();
    assert!(odometry_from_ros(&odometry, Time::ZERO).is_ok());
    odometry.pose.pose.orientation = RosQuaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 0.0,
    };
    assert_eq!(
        odometry_from_ros(&odometry, Time::ZERO),
        Err(ConvertError::Pose)
    );
    odometry.pose.pose.orientation = RosQuaternion::default();
    odometry.pose.pose.position = RosPoint {
        x: f64::NAN,
        y: 0.0,
        z: 0.0,
    };
    assert_eq!(
        odometry_from_ros(&odometry, Time::ZERO),
        Err(ConvertError::Pose)
    );
}

#[test]
fn stamps_map_by_age_both_ways() {
    let map = StampMap {
        troupe_now: Time::from_secs_f64(10.0),
        unix_now_ns: 1_700_000_000_000_000_000,
    };
    let stamp = RosTime {
        sec: 1_699_999_999,
        nanosec: 750_000_000,
    };
    assert_eq!(map.to_troupe(stamp), Time::from_secs_f64(9.75));
    assert_eq!(map.to_ros(Time::from_secs_f64(9.75)), stamp);
    // From the future: now. Before the run: time zero.
    assert_eq!(
        map.to_troupe(RosTime {
            sec: 1_800_000_000,
            nanosec: 0
        }),
        map.troupe_now
    );
    assert_eq!(map.to_troupe(RosTime { sec: 0, nanosec: 0 }), Time::ZERO);
}

#[test]
fn plan_becomes_a_path_of_its_knots() {
    let knot = |t: f64, x: f64, yaw: f64| Knot {
        time: Time::from_secs_f64(t),
        position_m: Point3::new(x, 1.0, 2.0),
        yaw_rad: yaw,
    };
    let plan = Plan::new(
        Time::from_secs_f64(1.0),
        Trajectory::new(vec![
            knot(1.0, 0.0, 0.0),
            knot(2.0, 1.5, std::f64::consts::FRAC_PI_2),
        ])
        .unwrap(),
    );
    let map = StampMap {
        troupe_now: Time::from_secs_f64(1.0),
        unix_now_ns: 5_000_000_000,
    };
    let path = path_from_plan(&plan, "odom", &map);
    assert_eq!(path.header.frame_id, "odom");
    assert_eq!(path.header.stamp, RosTime { sec: 5, nanosec: 0 });
    assert_eq!(path.poses.len(), 2);
    assert_eq!(path.poses[1].header.stamp, RosTime { sec: 6, nanosec: 0 });
    let p = path.poses[1].pose;
    assert_eq!((p.position.x, p.position.y, p.position.z), (1.5, 1.0, 2.0));
    let h = std::f64::consts::FRAC_1_SQRT_2;
    assert!((p.orientation.z - h).abs() < 1e-12 && (p.orientation.w - h).abs() < 1e-12);
    assert_eq!(decode::<Path>(&encode(&path).unwrap()).unwrap(), path);
}

#[test]
fn gmm_cloud_samples_the_spatial_marginal_with_intensity() {
    let cov = nalgebra::Matrix4::from_diagonal(&nalgebra::Vector4::new(0.01, 0.01, 0.01, 0.001));
    let gmm = Gmm4::new(
        vec![0.5, 0.5],
        vec![
            nalgebra::Vector4::new(1.0, 0.0, 0.0, 0.2),
            nalgebra::Vector4::new(-1.0, 0.0, 3.0, 0.8),
        ],
        vec![cov, cov],
    )
    .unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let cloud = cloud_from_gmm(&gmm, 400, Header::default(), &mut rng);
    assert_eq!(
        (cloud.width, cloud.height, cloud.point_step, cloud.row_step),
        (400, 1, 16, 6400)
    );
    assert_eq!(cloud.data.len(), 6400);
    let decoded: PointCloud2 = decode(&encode(&cloud).unwrap()).unwrap();
    let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    let mut near = [0usize; 2];
    for p in decoded.data.chunks_exact(16) {
        let (x, z, g) = (f(&p[0..4]), f(&p[8..12]), f(&p[12..16]));
        // Each point lies by one of the two components and carries its intensity.
        let m = usize::from(x < 0.0);
        near[m] += 1;
        let (mx, mz, mg) = if m == 0 {
            (1.0, 0.0, 0.2)
        } else {
            (-1.0, 3.0, 0.8)
        };
        assert!((x - mx).abs() < 0.6 && (z - mz).abs() < 0.6, "{x} {z}");
        assert!((g - mg).abs() < 1e-3, "{g}");
    }
    assert!(near[0] > 150 && near[1] > 150, "{near:?}");
}

#[test]
fn point_clouds_without_xyz_or_with_short_data_are_rejected() {
    let field = |name: &str, offset| PointField {
        name: name.into(),
        offset,
        datatype: PointField::FLOAT32,
        count: 1,
    };
    let k = PinholeIntrinsics {
        width: 2,
        height: 2,
        fx: 1.0,
        fy: 1.0,
        cx: 1.0,
        cy: 1.0,
        max_depth_m: 5.0,
    };
    let mut cloud = PointCloud2 {
        height: 1,
        width: 2,
        fields: vec![field("x", 0), field("y", 4)],
        point_step: 12,
        row_step: 24,
        data: vec![0; 24],
        ..Default::default()
    };
    let err = depth_frame_from_points(&cloud, k, Isometry3::identity(), Time::ZERO).unwrap_err();
    assert_eq!(err, ConvertError::PointField("z", 12));
    cloud.fields.push(field("z", 10)); // runs past the 12-byte point
    assert!(depth_frame_from_points(&cloud, k, Isometry3::identity(), Time::ZERO).is_err());
    cloud.fields[2].offset = 8;
    cloud.data.truncate(23);
    assert_eq!(
        depth_frame_from_points(&cloud, k, Isometry3::identity(), Time::ZERO)
            .unwrap_err()
            .reason(),
        "point_layout"
    );
}

mod hostile {
    use proptest::prelude::*;

    use crate::ros2::cdr::decode;
    use crate::ros2::msgs::{CameraInfo, Image, Odometry, Path, PointCloud2, RosString};

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        /// Arbitrary bytes (a valid header, then anything) decode to a message or an
        /// error, never a panic or a huge allocation.
        #[test]
        fn random_payloads_never_panic(body in proptest::collection::vec(any::<u8>(), 0..256), big in any::<bool>()) {
            let mut bytes = vec![0, u8::from(!big), 0, 0];
            bytes.extend_from_slice(&body);
            let _ = decode::<Image>(&bytes);
            let _ = decode::<CameraInfo>(&bytes);
            let _ = decode::<PointCloud2>(&bytes);
            let _ = decode::<Odometry>(&bytes);
            let _ = decode::<Path>(&bytes);
            let _ = decode::<RosString>(&bytes);
        }

        /// Point clouds with arbitrary layouts and data project or fail cleanly.
        #[test]
        fn random_clouds_project_or_fail_cleanly(
            width in 0u32..6, height in 0u32..3, point_step in 0u32..24, row_step in 0u32..100,
            offsets in proptest::collection::vec(0u32..24, 4), big in any::<bool>(),
            data in proptest::collection::vec(any::<u8>(), 0..300),
        ) {
            let names = ["x", "y", "z", "intensity"];
            let cloud = super::PointCloud2 {
                height, width, point_step, row_step, is_bigendian: big, data,
                fields: names.iter().zip(&offsets).map(|(n, o)| super::PointField {
                    name: (*n).into(), offset: *o, datatype: super::PointField::FLOAT32, count: 1,
                }).collect(),
                ..Default::default()
            };
            let k = super::PinholeIntrinsics {
                width: 4, height: 3, fx: 2.0, fy: 2.0, cx: 2.0, cy: 1.5, max_depth_m: 5.0,
            };
            let frame = super::depth_frame_from_points(
                &cloud, k, super::Isometry3::identity(), super::Time::ZERO,
            );
            if let Ok(frame) = frame {
                prop_assert_eq!(frame.depth_m.len(), 12);
                prop_assert!(frame.depth_m.iter().all(|d| d.is_finite() && *d >= 0.0 && *d <= 5.0));
                prop_assert!(frame.intensity.iter().all(|g| (0.0..=1.0).contains(g)));
            }
        }

        /// Images with arbitrary sizes, steps and data convert or fail cleanly.
        #[test]
        fn random_images_convert_or_fail_cleanly(
            width in 0u32..8, height in 0u32..8, step in 0u32..40, len in 0usize..200,
            big in 0u8..3, float in any::<bool>(), info_w in 0u32..8, info_h in 0u32..8,
        ) {
            let depth = super::Image {
                height, width, step, is_bigendian: big,
                encoding: if float { "32FC1" } else { "16UC1" }.into(),
                data: (0..len).map(|i| i as u8).collect(),
                ..Default::default()
            };
            if let Ok(frame) = super::convert(&depth, &super::info(info_w, info_h), None) {
                prop_assert_eq!(frame.depth_m.len(), (width * height) as usize);
                prop_assert!(frame.depth_m.iter().all(|d| d.is_finite() && *d >= 0.0 && *d <= 5.0));
            }
        }
    }
}
