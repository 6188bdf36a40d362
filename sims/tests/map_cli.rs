//! `troupe map` on a tiny sequence recorded from the simulated camera.

#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use rand::SeedableRng;
use troupe_algorithms::mapfile::GmmMap;
use troupe_algorithms::model::MapModel;
use troupe_sims::camera::CameraParams;
use troupe_sims::sequence::record_camera;
use troupe_sims::world::{Aabb, BoxRoom, World};

fn troupe(args: &[&str], dir: &Path) -> std::process::Output {
    troupe_testkit::run_quiet(env!("CARGO_BIN_EXE_troupe"), args, dir)
}

fn room() -> BoxRoom {
    BoxRoom::new(Aabb::new(
        Point3::new(-2.0, -2.0, -1.0),
        Point3::new(3.0, 2.5, 1.5),
    ))
}

/// Eight 64×48 frames turning on the spot in a box room, 0.1 s apart.
fn record(dir: &Path) -> PathBuf {
    let room = room();
    let camera = CameraParams {
        width: 64,
        height: 48,
        ..CameraParams::default()
    };
    let path: Vec<(f64, Isometry3<f64>)> = (0..8)
        .map(|i| {
            let i = f64::from(i);
            (
                0.1 * i,
                Isometry3::from_parts(
                    Translation3::new(0.0, 0.0, 0.2),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, 0.8 * i),
                ),
            )
        })
        .collect();
    record_camera(&dir.join("seq"), &room, &camera, &path, 0).unwrap()
}

fn stats_of(out: &std::process::Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(stdout.lines().count(), 1, "one JSON line: {stdout}");
    serde_json::from_str(stdout.trim()).unwrap()
}

#[test]
fn map_writes_a_loadable_map_a_ply_and_a_json_line() {
    let dir = tempfile::tempdir().unwrap();
    record(dir.path());
    for (model, expect) in [("windowed", MapModel::Windowed), ("sogmm", MapModel::Sogmm)] {
        let out_dir = format!("out-{model}");
        let out = troupe(
            &[
                "map",
                "seq",
                "--model",
                model,
                "--bandwidth",
                "0.03",
                "--ply-points",
                "1000",
                "--out",
                &out_dir,
            ],
            dir.path(),
        );
        let stats = stats_of(&out);
        let map = GmmMap::load(&dir.path().join(&out_dir).join("map.troupe")).unwrap();
        assert_eq!(map.model, expect);
        assert_eq!(stats["model"], model);
        assert_eq!(stats["frames"], 8);
        // Turning 0.8 rad per frame with a 90° view: most frames are new views.
        let keyframes = stats["keyframes"].as_u64().unwrap() as usize;
        assert!(
            keyframes >= 4 && keyframes == map.keyframes.len(),
            "{stats}"
        );
        assert_eq!(stats["components"], map.occupied_components());
        let bytes = std::fs::metadata(dir.path().join(&out_dir).join("map.troupe"))
            .unwrap()
            .len();
        assert_eq!(stats["bytes"], bytes);
        assert!(stats["fit_s_per_frame"].as_f64().unwrap() > 0.0);
        if expect == MapModel::Windowed {
            assert!(
                stats["free_components"].as_u64().unwrap() == 0,
                "room is closed within 5 m"
            );
        }
        // The map lies on the walls: points sampled from it are within a few cm of
        // them on average (a wrong pose convention would put them metres away).
        let merged = map.merged_occupied().unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let samples = merged.marginal_spatial().sample(5000, &mut rng);
        let room = room();
        let mean_m = samples
            .iter()
            .map(|p| room.sdf_m(&Point3::from(*p)).abs())
            .sum::<f64>()
            / samples.len() as f64;
        assert!(
            mean_m < 0.02,
            "{model}: mean distance to the walls {mean_m} m"
        );
        let ply = std::fs::read(dir.path().join(&out_dir).join("map.ply")).unwrap();
        assert!(ply.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
        let header_end = ply.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        assert_eq!(ply.len() - header_end, 1000 * 19);
    }
}

#[test]
fn frame_stride_reads_fewer_frames() {
    let dir = tempfile::tempdir().unwrap();
    record(dir.path());
    let out = troupe(
        &[
            "map",
            "seq",
            "--model",
            "windowed",
            "--stride",
            "3",
            "--ply-points",
            "10",
            "--out",
            "o",
        ],
        dir.path(),
    );
    assert_eq!(stats_of(&out)["frames"], 3);
}

#[test]
fn missing_or_bad_inputs_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let fails = |args: &[&str], needle: &str| {
        let out = troupe(args, dir.path());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(needle), "`{needle}` not in: {stderr}");
        assert!(!dir.path().join("o").exists(), "something was written");
    };
    fails(&["map", "nope", "--out", "o"], "nope");
    let seq = record(dir.path());
    std::fs::remove_file(seq.join("groundtruth.txt")).unwrap();
    fails(&["map", "seq", "--out", "o"], "groundtruth.txt");
    fails(
        &["map", "seq", "--model", "octomap", "--out", "o"],
        "octomap",
    );
    fails(&["map", "seq", "--bandwidth=0", "--out", "o"], "bandwidth");
    fails(
        &["map", "seq", "--mean-shift", "gaussian", "--out", "o"],
        "mean_shift",
    );
}

#[test]
fn mean_shift_option_picks_the_variant() {
    let dir = tempfile::tempdir().unwrap();
    record(dir.path());
    let components = |kind: &str| {
        let out = troupe(
            &[
                "map",
                "seq",
                "--mean-shift",
                kind,
                "--ply-points",
                "10",
                "--out",
                kind,
            ],
            dir.path(),
        );
        stats_of(&out)["components"].as_u64().unwrap()
    };
    // The reference (non-blurring, bin seeds) mean shift finds more modes than the
    // blurring one on the same keyframes, and it is the default.
    let (reference, blurring) = (components("reference"), components("blurring"));
    assert!(reference > blurring, "{reference} vs {blurring}");
    let default = stats_of(&troupe(
        &["map", "seq", "--ply-points", "10", "--out", "default"],
        dir.path(),
    ));
    assert_eq!(default["components"], reference);
}

#[test]
fn help_lists_the_map_options() {
    let dir = tempfile::tempdir().unwrap();
    let out = troupe(&["map", "--help"], dir.path());
    let help = String::from_utf8_lossy(&out.stdout);
    for option in [
        "--model",
        "--bandwidth",
        "--mean-shift",
        "--stride",
        "--out",
        "SEQUENCE_DIR",
    ] {
        assert!(help.contains(option), "{option} missing from: {help}");
    }
}
