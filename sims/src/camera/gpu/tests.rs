//! GPU against CPU images in every world with a GPU description. They run wherever a
//! Vulkan adapter exists (CI installs Mesa's lavapipe) and skip, saying why, elsewhere.

use std::sync::Arc;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};

use super::*;
use crate::camera::{CameraBackend, CameraRenderer, Choice, GpuUnavailable};
use crate::world::{
    Aabb, BoxRoom, CaveParams, CaveWorld, DoorParams, OpenField, OpenFieldParams, OpeningScene,
    Site, Warehouse, WarehouseParams, WindowParams, World,
};

/// Depth tolerance: 1 cm or 0.5 % of the depth, whichever is larger. Both paths stop
/// within `HIT_EPS_M` (1 mm) of the surface and refine once; the rest is `f32` rounding
/// of positions up to ~100 m (~8 µm) amplified at grazing incidence.
fn depth_tolerance_m(depth_m: f32) -> f32 {
    (0.005 * depth_m).max(0.01)
}

/// Intensity tolerance: the normals come from finite differences over 1 mm, where `f32`
/// rounding of ~50 m coordinates (~4 µm) tilts them by up to ~0.5 %; the texture noise is
/// evaluated at points that differ by the depth error.
const INTENSITY_TOLERANCE: f32 = 0.02;

/// Half the thickness of the slab around a hit within which a texture discontinuity
/// makes the intensity ambiguous, metres.
const TEXTURE_SLAB_M: f64 = 1e-3;

/// Fraction of pixels that must agree (hit/no-hit; depth and intensity among hits):
/// silhouette edges and grazing rays that use up `MAX_TRACE_STEPS` may flip.
const MIN_AGREEMENT: f64 = 0.99;

fn gpu_available() -> bool {
    match GpuContext::shared() {
        Ok(ctx) => {
            eprintln!("GPU camera tests on {}", ctx.adapter_name());
            true
        }
        Err(e) => {
            eprintln!("skipping the GPU camera test: {e}");
            false
        }
    }
}

/// Agreement of a GPU image with the CPU image.
#[derive(Debug, Default)]
struct Agreement {
    pixels: usize,
    same_hit: usize,
    both_hit: usize,
    depth_ok: usize,
    intensity_ok: usize,
    /// Hits where the texture is discontinuous across the surface (a wall lying on a
    /// checker or brick boundary): which side a point within rounding of the surface
    /// falls on is arbitrary on either path, so these are not compared.
    ambiguous: usize,
    max_depth_err_m: f32,
    max_intensity_err: f32,
}

impl Agreement {
    fn add(
        &mut self,
        world: &dyn World,
        pose: &Isometry3<f64>,
        cpu: &DepthFrame,
        gpu: &DepthFrame,
    ) {
        for i in 0..cpu.depth_m.len() {
            let (dc, dg) = (cpu.depth_m[i], gpu.depth_m[i]);
            self.pixels += 1;
            if (dc > 0.0) == (dg > 0.0) {
                self.same_hit += 1;
            }
            if dc > 0.0 && dg > 0.0 {
                self.both_hit += 1;
                let de = (dc - dg).abs();
                let ie = (cpu.intensity[i] - gpu.intensity[i]).abs();
                self.depth_ok += usize::from(de <= depth_tolerance_m(dc));
                self.max_depth_err_m = self.max_depth_err_m.max(de);
                let k = &cpu.intrinsics;
                let (col, row) = ((i % k.width as usize) as u32, (i / k.width as usize) as u32);
                let p = pose * k.back_project(col, row, f64::from(dc));
                let n = world.normal(&p) * TEXTURE_SLAB_M;
                let jump = (world.albedo(&(p + n)) - world.albedo(&(p - n))).abs();
                if jump > f64::from(INTENSITY_TOLERANCE) {
                    self.ambiguous += 1;
                    self.intensity_ok += 1;
                    continue;
                }
                self.intensity_ok += usize::from(ie <= INTENSITY_TOLERANCE);
                self.max_intensity_err = self.max_intensity_err.max(ie);
            }
        }
    }

    fn check(&self, what: &str) {
        let frac = |n: usize, d: usize| n as f64 / d.max(1) as f64;
        eprintln!("{what}: {self:?}");
        assert!(
            frac(self.both_hit, self.pixels) > 0.3,
            "{what}: too few returns to compare: {self:?}"
        );
        assert!(
            frac(self.same_hit, self.pixels) >= MIN_AGREEMENT,
            "{what}: hit/no-hit differs: {self:?}"
        );
        assert!(
            frac(self.both_hit - self.ambiguous, self.pixels) > 0.3,
            "{what}: too few unambiguous intensities to compare: {self:?}"
        );
        assert!(
            frac(self.depth_ok, self.both_hit) >= MIN_AGREEMENT,
            "{what}: depths differ: {self:?}"
        );
        assert!(
            frac(self.intensity_ok, self.both_hit) >= MIN_AGREEMENT,
            "{what}: intensities differ: {self:?}"
        );
    }
}

fn looking(from: Point3<f64>, to: Point3<f64>, pitch: f64, roll: f64) -> Isometry3<f64> {
    let yaw = (to.y - from.y).atan2(to.x - from.x);
    Isometry3::from_parts(
        Translation3::from(from.coords),
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    )
}

/// Poses along robot 0's route: level, pitched down and rolled, turned sideways.
fn route_poses(site: &dyn Site) -> Vec<Isometry3<f64>> {
    let route = site.route(0, 1);
    let mut poses = Vec::new();
    for w in route.windows(2).take(4) {
        poses.push(looking(w[0], w[1], 0.0, 0.0));
        poses.push(looking(w[0], w[1], 0.35, 0.2));
        let side = w[0] + (w[1] - w[0]).cross(&nalgebra::Vector3::z());
        poses.push(looking(w[0], side, -0.2, 0.0));
    }
    poses
}

/// Renders `poses` on both paths with `params` and checks the agreement.
fn compare(what: &str, world: Arc<dyn World>, poses: &[Isometry3<f64>], params: &CameraParams) {
    let scene = world.gpu_scene().expect("world has a GPU description");
    let mut gpu = GpuCamera::new(params, &scene).expect("GPU camera");
    let mut agreement = Agreement::default();
    for (k, pose) in poses.iter().enumerate() {
        let seed = 11 + k as u64;
        let cpu = params.render(world.as_ref(), Time::ZERO, pose, seed);
        let img = gpu.render(Time::ZERO, pose, seed).expect("GPU frame");
        agreement.add(world.as_ref(), pose, &cpu, &img);
    }
    agreement.check(what);
}

#[test]
fn the_shader_parses_and_validates_without_an_adapter() {
    let module = naga::front::wgsl::parse_str(&shader_source())
        .unwrap_or_else(|e| panic!("{}", e.emit_to_string(&shader_source())));
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .expect("the shader validates");
    assert!(module.entry_points.iter().any(|e| e.name == "main"));
}

fn small_camera() -> CameraParams {
    CameraParams {
        width: 80,
        height: 60,
        ..CameraParams::default()
    }
}

#[test]
fn gpu_matches_cpu_in_a_box_room() {
    if !gpu_available() {
        return;
    }
    // Walls off the 0.5 m checker lines, so the texture is defined on them.
    let room = BoxRoom::new(Aabb::new(
        Point3::new(-1.1, -2.05, -1.45),
        Point3::new(4.2, 2.15, 1.35),
    ));
    let poses: Vec<_> = (0..6)
        .map(|k| {
            let k = f64::from(k);
            Isometry3::from_parts(
                Translation3::new(0.3 * k, 0.2 - 0.1 * k, 0.1 * k - 0.3),
                UnitQuaternion::from_euler_angles(0.1 * k, -0.15 * k, 1.1 * k),
            )
        })
        .collect();
    compare("box room", Arc::new(room), &poses, &small_camera());
}

#[test]
fn gpu_matches_cpu_in_caves() {
    if !gpu_available() {
        return;
    }
    for seed in [0, 7] {
        let cave = Arc::new(CaveWorld::generate(&CaveParams::default(), seed));
        let poses = route_poses(cave.as_ref());
        compare(&format!("cave seed {seed}"), cave, &poses, &small_camera());
    }
}

#[test]
fn gpu_matches_cpu_in_the_box_worlds() {
    if !gpu_available() {
        return;
    }
    let cam = CameraParams {
        range_m: 12.0,
        ..small_camera()
    };
    let sites: Vec<(&str, Arc<dyn Site>)> = vec![
        (
            "warehouse",
            Arc::new(Warehouse::generate(&WarehouseParams::default(), 3)),
        ),
        (
            "open field",
            Arc::new(OpenField::generate(&OpenFieldParams::default(), 3)),
        ),
        (
            "window",
            Arc::new(OpeningScene::window(&WindowParams::default(), 3)),
        ),
        (
            "door",
            Arc::new(OpeningScene::door(&DoorParams::default(), 3)),
        ),
    ];
    for (what, site) in sites {
        let poses = route_poses(site.as_ref());
        compare(what, site, &poses, &cam);
    }
}

#[test]
fn noise_and_dropouts_are_those_of_the_cpu_path() {
    if !gpu_available() {
        return;
    }
    let cave = Arc::new(CaveWorld::generate(&CaveParams::default(), 0));
    let params = CameraParams {
        depth_noise_std_m: 0.02,
        dropout_prob: 0.3,
        ..small_camera()
    };
    let poses = route_poses(cave.as_ref());
    compare("noisy cave", cave.clone(), &poses[..3], &params);
    // The dropout mask is the CPU's exactly wherever both paths hit.
    let mut gpu = GpuCamera::new(&params, &cave.gpu_scene().expect("scene")).expect("GPU");
    let clean = CameraParams {
        dropout_prob: 0.0,
        depth_noise_std_m: 0.0,
        ..params.clone()
    };
    let mut dropped = 0;
    for pose in &poses[..3] {
        let geometry = clean.render(cave.as_ref(), Time::ZERO, pose, 0);
        let cpu = params.render(cave.as_ref(), Time::ZERO, pose, 5);
        let img = gpu.render(Time::ZERO, pose, 5).expect("frame");
        for i in 0..img.depth_m.len() {
            if geometry.depth_m[i] > 0.0 && img.depth_m[i] == 0.0 {
                dropped += 1;
            }
        }
        let mismatched_drops = (0..img.depth_m.len())
            .filter(|&i| {
                geometry.depth_m[i] > 0.0 && (cpu.depth_m[i] > 0.0) != (img.depth_m[i] > 0.0)
            })
            .count();
        assert!(
            mismatched_drops <= img.depth_m.len() / 100,
            "{mismatched_drops} dropouts differ"
        );
    }
    assert!(dropped > 1000, "only {dropped} dropouts: noise not applied");
}

#[test]
fn auto_falls_back_to_the_cpu_for_a_mesh_world_and_gpu_refuses_it() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/mesh_pillars.toml");
    let scenario = crate::scenario::Scenario::load(&path).expect("scenario");
    let site = scenario.world.build().expect("mesh loads");
    let start = site.start_position(0, 1);
    let world: Arc<dyn World> = site;
    assert!(world.gpu_scene().is_none());
    let auto = CameraParams {
        backend: CameraBackend::Auto,
        ..small_camera()
    };
    let mut renderer = CameraRenderer::new(world.clone(), auto.clone()).expect("auto");
    match renderer.choice() {
        Choice::Cpu(reason) => assert!(reason.contains("no GPU description"), "{reason}"),
        Choice::Gpu(name) => panic!("auto chose the GPU ({name}) for a mesh world"),
    }
    let pose = Isometry3::translation(start.x, start.y, start.z);
    let img = renderer.render(Time::ZERO, &pose, 3).expect("CPU frame");
    assert_eq!(img, auto.render(world.as_ref(), Time::ZERO, &pose, 3));
    let forced = CameraParams {
        backend: CameraBackend::Gpu,
        ..small_camera()
    };
    let err = CameraRenderer::new(world, forced)
        .err()
        .expect("gpu must refuse a mesh world");
    assert!(matches!(err, GpuUnavailable::NoGpuScene), "{err}");
}

#[test]
fn auto_picks_a_hardware_gpu_gpu_takes_any_and_cpu_stays_on_the_cpu() {
    let room: Arc<dyn World> = Arc::new(BoxRoom::new(Aabb::new(
        Point3::new(-1.0, -2.0, -1.5),
        Point3::new(4.0, 2.0, 1.5),
    )));
    let cpu = CameraParams {
        backend: CameraBackend::Cpu,
        ..small_camera()
    };
    let renderer = CameraRenderer::new(room.clone(), cpu).expect("cpu");
    assert!(matches!(renderer.choice(), Choice::Cpu(_)));
    let auto = CameraRenderer::new(room.clone(), small_camera()).expect("auto");
    let hardware = GpuContext::shared().is_ok_and(|ctx| !ctx.is_software());
    match auto.choice() {
        Choice::Gpu(_) => assert!(hardware, "auto chose a software adapter"),
        Choice::Cpu(reason) => assert!(!hardware, "auto passed over a GPU: {reason}"),
    }
    // Forced, any adapter will do; on a software one it renders what the CPU renders.
    let forced = CameraParams {
        backend: CameraBackend::Gpu,
        ..small_camera()
    };
    match (
        GpuContext::shared(),
        CameraRenderer::new(room.clone(), forced.clone()),
    ) {
        (Ok(_), Ok(mut gpu)) => {
            assert!(matches!(gpu.choice(), Choice::Gpu(_)));
            let pose = Isometry3::translation(1.0, 0.3, 0.2);
            let img = gpu.render(Time::ZERO, &pose, 1).expect("frame");
            assert_eq!(
                img.valid_pixels(),
                forced
                    .render(room.as_ref(), Time::ZERO, &pose, 1)
                    .valid_pixels()
            );
            // Rendering every second pixel, it reports the pixels the CPU reports.
            let strided = CameraParams {
                render_stride: 2,
                ..forced.clone()
            };
            let mut gpu = CameraRenderer::new(room.clone(), strided.clone()).expect("gpu");
            let img = gpu.render(Time::ZERO, &pose, 1).expect("frame");
            let width = img.intrinsics.width as usize;
            for (i, d) in img.depth_m.iter().enumerate() {
                if !strided.renders(i % width, i / width) {
                    assert_eq!(*d, 0.0, "pixel {i}");
                }
            }
            assert_eq!(
                img.valid_pixels(),
                strided
                    .render(room.as_ref(), Time::ZERO, &pose, 1)
                    .valid_pixels()
            );
        }
        (Err(_), Err(reason)) => assert!(
            matches!(reason, GpuUnavailable::Gpu(GpuError::NoAdapter(_))),
            "{reason}"
        ),
        (ctx, renderer) => panic!("{ctx:?} but {:?}", renderer.map(|r| r.choice().clone())),
    }
}
