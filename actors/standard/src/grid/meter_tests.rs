//! The occupancy-grid meter counts what the grid actor's change sets would send.
#![allow(clippy::unwrap_used)]

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use troupe_algorithms::frame::DepthFrame;
use troupe_algorithms::grid::meter::*;
use troupe_algorithms::grid::{
    LocalGrid, LogOddsParams, ScanScratch, UpdateRule, insert_frame_with,
};
use troupe_algorithms::sogmm::synthetic::room_corner_frame;

use super::changeset::OwnChanges;

/// The room-corner frame seen from `pose` moved by `dx` metres and yawed by `yaw` rad.
fn frame_moved(dx: f64, yaw: f64) -> DepthFrame {
    let mut frame = room_corner_frame();
    let step = Isometry3::from_parts(
        Translation3::new(dx, 0.0, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
    );
    frame.pose = step * frame.pose;
    frame
}

/// The frames of the tests: the same view twice, then moved and turned views.
fn frames() -> Vec<DepthFrame> {
    vec![
        frame_moved(0.0, 0.0),
        frame_moved(0.0, 0.0),
        frame_moved(0.3, 0.1),
        frame_moved(-0.5, -0.2),
        frame_moved(0.0, 0.0),
    ]
}

#[test]
fn counts_the_cells_the_grid_actors_change_sets_carry() {
    for resolution_m in [0.2, 0.1] {
        let params = LogOddsParams::default();
        let stride = 2;
        // A window that holds every ray of every frame: the actor's sets are then
        // complete, and the meter must count exactly their cells.
        let mut grid = LocalGrid::centred(
            &Point3::new(0.0, 0.0, 0.0),
            &Vector3::new(24.0, 24.0, 16.0),
            resolution_m,
            params,
        );
        let (mut own, mut scratch) = (OwnChanges::default(), ScanScratch::default());
        let mut meter = ChangeSetMeter::new(resolution_m, params, stride);
        let mut sent = 0;
        for (k, frame) in frames().iter().enumerate() {
            own.begin(&grid);
            insert_frame_with(&mut grid, frame, stride, UpdateRule::PerScan, &mut scratch);
            own.end(&grid);
            let cells: usize = own.take_sets(&grid).iter().map(|s| s.changes.len()).sum();
            assert!(cells > 0, "frame {k} changes something");
            assert_eq!(meter.observe(frame), cells, "frame {k} at {resolution_m} m");
            sent += cells as u64;
        }
        // Same values cell for cell.
        for (i, v) in grid.values().iter().enumerate() {
            let cell = grid.lattice_cell(grid.cell_at(i));
            assert_eq!(meter.value(cell), *v);
        }
        let totals = meter.totals();
        assert_eq!(totals.frames, 5);
        assert_eq!(totals.sets, 5);
        assert_eq!(totals.changed_cells, sent);
        assert_eq!(totals.bytes, 8 * sent + 24 * 5);
        let observed = grid.values().iter().filter(|v| **v != 0.0).count();
        assert_eq!(totals.mapped_cells, observed as u64);
    }
}

#[test]
fn a_view_seen_again_and_again_stops_costing_bytes() {
    // Log-odds clamp (OctoMap's 0.12 / 0.97): after five hits or misses a cell no
    // longer changes, so the same view sends nothing more.
    let mut meter = ChangeSetMeter::new(0.2, LogOddsParams::default(), 2);
    let frame = room_corner_frame();
    let counts: Vec<usize> = (0..8).map(|_| meter.observe(&frame)).collect();
    assert!(counts[0] > 1000, "{counts:?}");
    assert!(counts.windows(2).all(|w| w[1] <= w[0]), "{counts:?}");
    assert_eq!(counts[6..], [0, 0], "{counts:?}");
    let bytes_after_six = {
        let t = meter.totals();
        (t.bytes, t.sets)
    };
    meter.observe(&frame);
    assert_eq!((meter.totals().bytes, meter.totals().sets), bytes_after_six);
    assert_eq!(meter.totals().frames, 9);
}

#[test]
fn finer_cells_cost_more() {
    let bytes: Vec<u64> = [0.2, 0.1, 0.05]
        .map(|r| {
            let mut meter = ChangeSetMeter::new(r, LogOddsParams::default(), 1);
            meter.observe(&room_corner_frame());
            meter.totals().bytes
        })
        .to_vec();
    assert!(bytes[0] < bytes[1] && bytes[1] < bytes[2], "{bytes:?}");
}

#[test]
fn a_frame_with_a_non_finite_pose_changes_nothing() {
    let mut frame = room_corner_frame();
    frame.pose.translation.vector.x = f64::NAN;
    let mut meter = ChangeSetMeter::new(0.1, LogOddsParams::default(), 1);
    assert_eq!(meter.observe(&frame), 0);
    let totals = meter.totals();
    assert_eq!((totals.frames, totals.sets, totals.bytes), (1, 0, 0));
}
