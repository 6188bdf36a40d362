use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use troupe_core::Time;

use super::*;
use crate::camera::CameraParams;
use crate::world::{Aabb, BoxRoom, CaveParams, CaveWorld};

fn room() -> BoxRoom {
    BoxRoom::new(Aabb::new(
        Point3::new(-1.0, -2.0, -1.5),
        Point3::new(4.0, 2.0, 1.5),
    ))
}

fn yawed(p: Point3<f64>, yaw: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(p.coords),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
    )
}

#[test]
fn box_room_cells_are_all_free_and_volume_matches() {
    let cov = CoverageGrid::new(&room(), 0.25);
    assert_eq!(cov.grid().dims, [20, 16, 12]);
    assert_eq!(cov.free_cells(), 20 * 16 * 12);
    assert!((cov.free_volume_m3() - 60.0).abs() < 1e-9);
    assert_eq!(cov.coverage(), 0.0);
}

#[test]
fn one_frame_explores_the_air_but_not_the_wall_cell() {
    let room = room();
    let cam = CameraParams::default();
    let mut cov = CoverageGrid::new(&room, 0.25);
    let pose = Isometry3::identity();
    cov.observe(&cam.render(&room, Time::ZERO, &pose, 0), 1);
    assert!(cov.coverage() > 0.0 && cov.coverage() <= 1.0);
    let g = *cov.grid();
    // The centre ray ends on the wall x = 4 (cells start at x = -1).
    let wall_cell = g.cell_of(&Point3::new(3.9, 0.01, 0.01)).expect("in grid");
    let air_cell = g.cell_of(&Point3::new(3.6, 0.01, 0.01)).expect("in grid");
    assert!(!cov.is_explored(wall_cell));
    assert!(cov.is_explored(air_cell));
    // Nothing behind the camera is seen.
    let behind = g.cell_of(&Point3::new(-0.6, 0.01, 0.01)).expect("in grid");
    assert!(!cov.is_explored(behind));
    assert!(
        (cov.explored_volume_m3() - cov.explored_cells() as f64 * 0.25f64.powi(3)).abs() < 1e-9
    );
}

#[test]
fn coverage_grows_monotonically_and_stays_at_most_one() {
    let room = room();
    let cam = CameraParams::default();
    let mut cov = CoverageGrid::new(&room, 0.25);
    let mut last = 0.0;
    for k in 0..16 {
        let pose = yawed(
            Point3::new(1.5, 0.0, 0.0),
            k as f64 * std::f64::consts::TAU / 16.0,
        );
        cov.observe(&cam.render(&room, Time::ZERO, &pose, k), 2);
        let c = cov.coverage();
        assert!(c >= last && c <= 1.0, "frame {k}: {last} -> {c}");
        last = c;
    }
    // A full turn in the middle of the room sees most of it.
    assert!(last > 0.6, "coverage after a full turn {last}");
}

#[test]
fn cave_coverage_is_deterministic_and_monotone_along_the_route() {
    let cave = CaveWorld::generate(&CaveParams::default(), 2);
    let cam = CameraParams::default();
    let route = cave.centreline_route(0, 1);
    let run = || {
        let mut cov = CoverageGrid::new(&cave, 0.5);
        let mut trace = Vec::new();
        for w in route.windows(2).take(12) {
            let yaw = (w[1].y - w[0].y).atan2(w[1].x - w[0].x);
            let pose = yawed(w[0], yaw);
            cov.observe(&cam.render(&cave, Time::ZERO, &pose, 0), 2);
            trace.push(cov.explored_cells());
        }
        (cov, trace)
    };
    let (a, trace) = run();
    let (b, _) = run();
    assert_eq!(a, b);
    assert!(trace[0] > 0);
    assert!(trace.windows(2).all(|w| w[1] >= w[0]));
    assert!(a.coverage() > 0.0 && a.coverage() < 1.0);
    // The free volume is in the range of tunnels of ~2 m radius and ~190 m total length.
    let v = a.free_volume_m3();
    assert!((1000.0..8000.0).contains(&v), "free volume {v}");
}

/// Two rooms side by side, separated by a 1 m thick wall at 0.5 ≤ x ≤ 1.5.
struct TwoRooms;

impl crate::world::World for TwoRooms {
    fn sdf_m(&self, p: &Point3<f64>) -> f64 {
        let left = BoxRoom::new(Aabb::new(
            Point3::new(-4.0, -2.0, -1.5),
            Point3::new(0.5, 2.0, 1.5),
        ));
        let right = BoxRoom::new(Aabb::new(
            Point3::new(1.5, -2.0, -1.5),
            Point3::new(6.0, 2.0, 1.5),
        ));
        left.sdf_m(p).max(right.sdf_m(p))
    }
    fn albedo(&self, _: &Point3<f64>) -> f64 {
        0.5
    }
    fn bounds(&self) -> Aabb {
        Aabb::new(Point3::new(-4.0, -2.0, -1.5), Point3::new(6.0, 2.0, 1.5))
    }
}

#[test]
fn rays_without_a_return_stop_at_the_first_rock_cell() {
    let world = TwoRooms;
    let cam = CameraParams::default();
    let mut cov = CoverageGrid::new(&world, 0.25);
    // Every pixel dropped out: rays run to the 5 m range, which would cross the wall.
    let pose = Isometry3::translation(-2.0, 0.0, 0.0);
    cov.observe(&cam.blank_frame(Time::ZERO, &pose), 1);
    let g = *cov.grid();
    let near = g.cell_of(&Point3::new(0.1, 0.01, 0.01)).expect("in grid");
    assert!(cov.is_explored(near));
    for x in [1.6, 2.0, 2.9] {
        let behind = g.cell_of(&Point3::new(x, 0.01, 0.01)).expect("in grid");
        assert!(cov.is_free(behind) && !cov.is_explored(behind), "x = {x}");
    }
}

#[test]
fn a_frame_whose_buffers_do_not_fit_its_intrinsics_is_ignored() {
    let room = room();
    let cam = CameraParams::default();
    let mut cov = CoverageGrid::new(&room, 0.25);
    let mut frame = cam.render(&room, Time::ZERO, &Isometry3::identity(), 0);
    frame.depth_m.truncate(100);
    cov.observe(&frame, 1);
    frame.depth_m.clear();
    frame.intensity.clear();
    cov.observe(&frame, 1);
    assert_eq!(cov.explored_cells(), 0);
}
