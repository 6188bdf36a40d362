#![allow(clippy::unwrap_used)]

use nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};

use super::*;
use crate::camera::CameraParams;
use crate::world::{Aabb, BoxRoom};

fn room() -> BoxRoom {
    BoxRoom::new(Aabb::new(
        Point3::new(-1.0, -2.0, -1.5),
        Point3::new(4.0, 2.0, 1.5),
    ))
}

fn camera() -> CameraParams {
    CameraParams {
        width: 32,
        height: 24,
        ..CameraParams::default()
    }
}

fn path() -> Vec<(f64, Isometry3<f64>)> {
    (0..4)
        .map(|i| {
            (
                10.0 + 0.1 * f64::from(i),
                Isometry3::from_parts(
                    Translation3::new(0.2 * f64::from(i), 0.1, 0.0),
                    UnitQuaternion::from_euler_angles(0.05, -0.1, 0.3 * f64::from(i)),
                ),
            )
        })
        .collect()
}

#[test]
fn a_recorded_sequence_reads_back_within_quantisation() {
    let dir = tempfile::tempdir().unwrap();
    let seq_dir = dir.path().join("seq");
    let cam = camera();
    let world = room();
    record_camera(&seq_dir, &world, &cam, &path(), 1).unwrap();
    let seq = Sequence::open(&seq_dir).unwrap();
    assert_eq!((seq.len(), seq.skipped()), (4, 0));
    for (i, (t, pose)) in path().iter().enumerate() {
        let frame = seq.frame(i).unwrap();
        assert!((frame.stamp.as_secs_f64() - t).abs() < 1e-6);
        assert!((frame.pose.translation.vector - pose.translation.vector).norm() < 1e-8);
        assert!(frame.pose.rotation.angle_to(&pose.rotation) < 1e-8);
        assert_eq!(frame.intrinsics, cam.intrinsics());
        let truth = cam.render(
            &world,
            frame.stamp,
            pose,
            1 ^ (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15),
        );
        for (a, b) in frame.depth_m.iter().zip(&truth.depth_m) {
            assert!((a - b).abs() <= 0.0005 + 1e-6, "depth {a} vs {b}");
        }
        for ((a, b), d) in frame
            .intensity
            .iter()
            .zip(&truth.intensity)
            .zip(&frame.depth_m)
        {
            if *d > 0.0 {
                assert!((a - b).abs() <= 0.5 / 255.0 + 1e-6, "intensity {a} vs {b}");
            }
        }
        frame.validate().unwrap();
    }
    // As a frame source: the frames in order, restamped, then nothing.
    let mut source = SequenceSource::new(seq);
    for k in 0..4 {
        let now = Time::from_secs_f64(f64::from(k));
        let f = source.capture(now, None).unwrap().unwrap();
        assert_eq!(f.stamp, now);
    }
    assert!(source.capture(Time::ZERO, None).unwrap().is_none());
}

#[test]
fn tum_optical_poses_and_body_poses_see_the_same_point() {
    let optical = Isometry3::from_parts(
        Translation3::new(1.0, -2.0, 0.5),
        UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1),
    );
    let k = PinholeIntrinsics {
        width: 64,
        height: 48,
        fx: 50.0,
        fy: 52.0,
        cx: 31.0,
        cy: 25.0,
        max_depth_m: 5.0,
    };
    let (col, row, z) = (10u32, 40u32, 2.5);
    // TUM: X = (u − cx) z / fx, Y = (v − cy) z / fy, Z = z in the optical frame.
    let (u, v) = (f64::from(col) + 0.5, f64::from(row) + 0.5);
    let p_optical = optical * Point3::new((u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z);
    let p_body = body_pose(&optical) * k.back_project(col, row, z);
    assert!((p_optical - p_body).norm() < 1e-12);
    let back = optical_pose(&body_pose(&optical));
    assert!((back.translation.vector - optical.translation.vector).norm() < 1e-12);
    assert!(back.rotation.angle_to(&optical.rotation) < 1e-12);
    // The body looks along +x: the optical axis.
    let axis = body_pose(&optical).rotation * Vector3::x();
    assert!((axis - optical.rotation * Vector3::z()).norm() < 1e-12);
}

/// A sequence recorded to `dir`, for editing.
fn recorded(dir: &Path) -> PathBuf {
    record_camera(&dir.join("seq"), &room(), &camera(), &path(), 0).unwrap()
}

#[test]
fn association_by_nearest_timestamp_and_by_file() {
    let dir = tempfile::tempdir().unwrap();
    let seq = recorded(dir.path());
    // Intensity 5 ms later than depth still pairs; a pose 30 ms away does not.
    let rgb = std::fs::read_to_string(seq.join("rgb.txt")).unwrap();
    let shifted: String = rgb
        .lines()
        .map(|l| match l.split_once(' ') {
            Some((t, p)) if !l.starts_with('#') => {
                format!("{:.6} {p}\n", t.parse::<f64>().unwrap() + 0.005)
            }
            _ => format!("{l}\n"),
        })
        .collect();
    std::fs::write(seq.join("rgb.txt"), shifted).unwrap();
    let gt = std::fs::read_to_string(seq.join("groundtruth.txt")).unwrap();
    let moved: String = gt
        .lines()
        .map(|l| {
            if l.starts_with("10.300000") {
                l.replacen("10.300000", "10.330000", 1) + "\n"
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    std::fs::write(seq.join("groundtruth.txt"), moved).unwrap();
    let s = Sequence::open(&seq).unwrap();
    assert_eq!((s.len(), s.skipped()), (3, 1));
    assert!(s.entries()[0].image.ends_with("rgb/10.000000.png"));

    // An associations file takes precedence: only the pairs it lists.
    std::fs::write(
        seq.join("associations.txt"),
        "# t_rgb rgb t_depth depth\n10.100000 rgb/10.000000.png 10.100000 depth/10.100000.png\n",
    )
    .unwrap();
    let s = Sequence::open(&seq).unwrap();
    assert_eq!(s.len(), 1);
    assert!(s.entries()[0].image.ends_with("rgb/10.000000.png"));
    assert!(s.entries()[0].depth.ends_with("depth/10.100000.png"));
}

fn open_err(seq: &Path) -> String {
    troupe_core::ErrorChain(&Sequence::open(seq).unwrap_err()).to_string()
}

#[test]
fn bad_sequences_are_errors_that_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let seq = recorded(dir.path());

    let missing = dir.path().join("nothing");
    assert!(open_err(&missing).contains("nothing"));

    std::fs::rename(seq.join("camera.toml"), seq.join("camera.bak")).unwrap();
    assert!(open_err(&seq).contains("camera.toml"));
    let cam = std::fs::read_to_string(seq.join("camera.bak")).unwrap();
    std::fs::write(
        seq.join("camera.toml"),
        cam.replace("depth_scale = 1000.0", "depth_scale = -1.0"),
    )
    .unwrap();
    let e = open_err(&seq);
    assert!(
        e.contains("camera.toml") && e.contains("depth_scale"),
        "{e}"
    );
    std::fs::write(seq.join("camera.toml"), format!("{cam}lens = 3\n")).unwrap();
    let e = open_err(&seq);
    assert!(e.contains("camera.toml") && e.contains("lens"), "{e}");
    std::fs::write(seq.join("camera.toml"), &cam).unwrap();

    let gt = std::fs::read_to_string(seq.join("groundtruth.txt")).unwrap();
    std::fs::write(
        seq.join("groundtruth.txt"),
        format!("{gt}11.0 1 2 3 0 0 x 1\n"),
    )
    .unwrap();
    let e = open_err(&seq);
    assert!(e.contains("groundtruth.txt:6") && e.contains("qz"), "{e}");
    std::fs::write(seq.join("groundtruth.txt"), &gt).unwrap();

    // A truncated depth PNG and a wrong-sized one: errors when the frame is read.
    let first = seq.join("depth/10.000000.png");
    let bytes = std::fs::read(&first).unwrap();
    std::fs::write(&first, &bytes[..bytes.len() / 2]).unwrap();
    let s = Sequence::open(&seq).unwrap();
    let e = s.frame(0).unwrap_err().to_string();
    assert!(e.contains("10.000000.png"), "{e}");
    std::fs::write(&first, &bytes).unwrap();
    let second = seq.join("depth/10.100000.png");
    png_io::write_depth(
        &second,
        &Plane {
            width: 3,
            height: 2,
            data: vec![1; 6],
        },
    )
    .unwrap();
    let e = s.frame(1).unwrap_err().to_string();
    assert!(e.contains("10.100000.png") && e.contains("3×2"), "{e}");
    // An 8-bit image where depth is expected.
    png_io::write_intensity(
        &second,
        &Plane {
            width: 32,
            height: 24,
            data: vec![0.5; 32 * 24],
        },
    )
    .unwrap();
    let e = s.frame(1).unwrap_err().to_string();
    assert!(e.contains("16-bit"), "{e}");
    assert!(s.frame(0).is_ok());
}

#[test]
fn colour_images_become_luma() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.png");
    let file = std::fs::File::create(&path).unwrap();
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), 2, 1);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header().unwrap();
    w.write_image_data(&[255, 0, 0, 0, 0, 255]).unwrap();
    w.finish().unwrap();
    let plane = png_io::read_intensity(&path).unwrap();
    assert!((plane.data[0] - 0.299).abs() < 1e-6);
    assert!((plane.data[1] - 0.114).abs() < 1e-6);
}
