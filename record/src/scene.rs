//! Plain conversions of robot messages into Foxglove scene primitives: keyframe
//! mixtures as ellipsoids and as sampled point clouds, the local grid's occupied and
//! frontier cells as point clouds, trajectories as line strips, a triangle mesh as a
//! triangle list, robot colours.

use nalgebra::{Matrix3, Point3, Rotation3, SymmetricEigen, UnitQuaternion, Vector4};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use troupe_algorithms::grid::{CellState, GridSnapshot};
use troupe_algorithms::keyframe::Keyframe;
use troupe_algorithms::mapfile::sample_surface;
use troupe_algorithms::trajectory::Trajectory;
use troupe_core::Time;

use crate::foxglove::{
    Color, KeyValuePair, LINE_STRIP, LinePrimitive, PointCloud, Pose, SceneEntity, SpherePrimitive,
    Timestamp, TriangleListPrimitive, Vector3,
};

/// Half-axes of a keyframe ellipsoid, in standard deviations of its component.
pub const ELLIPSOID_SIGMAS: f64 = 2.0;

/// Alpha of keyframe ellipsoids.
const ELLIPSOID_ALPHA: f64 = 0.5;

/// Width of plan lines, metres.
pub const PLAN_LINE_M: f64 = 0.05;

/// The colour of robot `index` (a qualitative palette, repeating after eight robots).
#[must_use]
pub fn robot_color(index: u32, alpha: f64) -> Color {
    const PALETTE: [[f64; 3]; 8] = [
        [0.12, 0.47, 0.71],
        [1.00, 0.50, 0.05],
        [0.17, 0.63, 0.17],
        [0.84, 0.15, 0.16],
        [0.58, 0.40, 0.74],
        [0.55, 0.34, 0.29],
        [0.89, 0.47, 0.76],
        [0.09, 0.75, 0.81],
    ];
    let [r, g, b] = PALETTE[index as usize % PALETTE.len()];
    Color { r, g, b, a: alpha }
}

/// The ellipsoid of one mixture component at [`ELLIPSOID_SIGMAS`]: centred on the
/// spatial mean, axes along the eigenvectors of the spatial covariance block (a
/// right-handed frame), diameters `2 · ELLIPSOID_SIGMAS · √λ` (thesis Eq. 6.1: the
/// component's (x, y, z) marginal). `None` for a non-finite or non-positive block.
#[must_use]
pub fn ellipsoid(
    mean: &Vector4<f64>,
    covariance: &nalgebra::Matrix4<f64>,
    color: Color,
) -> Option<SpherePrimitive> {
    let block: Matrix3<f64> = covariance.fixed_view::<3, 3>(0, 0).into_owned();
    let symmetric = (block + block.transpose()) * 0.5;
    if !symmetric.iter().all(|v| v.is_finite()) || !mean.iter().all(|v| v.is_finite()) {
        return None;
    }
    let eigen = SymmetricEigen::new(symmetric);
    if eigen.eigenvalues.iter().any(|l| *l <= 0.0) {
        return None;
    }
    let mut axes = eigen.eigenvectors;
    if axes.determinant() < 0.0 {
        axes.column_mut(2).neg_mut();
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(axes));
    let d = eigen.eigenvalues.map(|l| 2.0 * ELLIPSOID_SIGMAS * l.sqrt());
    Some(SpherePrimitive {
        pose: Pose {
            position: Vector3::from(Point3::from(mean.xyz())),
            orientation: rotation.into(),
        },
        size: Vector3 {
            x: d[0],
            y: d[1],
            z: d[2],
        },
        color,
    })
}

/// A keyframe's mixture as one scene entity of ellipsoids, id `robot<owner>/kf<id>`,
/// coloured by `owner`, with the keyframe's facts as metadata. Components whose
/// ellipsoid cannot be formed are left out and counted in the metadata.
#[must_use]
pub fn keyframe_entity(owner: u32, keyframe: &Keyframe, at: Time) -> SceneEntity {
    let color = robot_color(owner, ELLIPSOID_ALPHA);
    let mut entity = SceneEntity::new(
        Timestamp::of(at),
        "world",
        format!("robot{owner}/kf{}", keyframe.id),
    );
    let gmm = &keyframe.gmm;
    entity.spheres = gmm
        .means()
        .iter()
        .zip(gmm.covariances())
        .filter_map(|(m, c)| ellipsoid(m, c, color))
        .collect();
    entity.metadata = vec![
        KeyValuePair::new("robot", owner),
        KeyValuePair::new("keyframe", keyframe.id),
        KeyValuePair::new("stamp_s", keyframe.stamp.as_secs_f64()),
        KeyValuePair::new("support_points", keyframe.support_size),
        KeyValuePair::new("components", gmm.len()),
        KeyValuePair::new("skipped_components", gmm.len() - entity.spheres.len()),
    ];
    entity
}

/// A trajectory's knots as a line strip.
#[must_use]
pub fn trajectory_line(trajectory: &Trajectory, color: Color) -> LinePrimitive {
    path_line(trajectory.knots().iter().map(|k| k.position_m), color)
}

/// Points joined in order as a line strip of the plans' thickness.
#[must_use]
pub fn path_line(points: impl IntoIterator<Item = Point3<f64>>, color: Color) -> LinePrimitive {
    LinePrimitive {
        kind: LINE_STRIP,
        pose: Pose::default(),
        thickness: PLAN_LINE_M,
        scale_invariant: false,
        points: points.into_iter().map(Vector3::from).collect(),
        color,
        colors: Vec::new(),
        indices: Vec::new(),
    }
}

/// Points drawn from a keyframe's mixture (thesis §6.1.5, Eq. 6.11: a component by
/// weight, a position from its spatial marginal, the intensity that component
/// predicts there), `n` of them at most its support size, as a cloud whose
/// `intensity` field is the predicted intensity in [0, 1]. The draw is seeded by the
/// owner and keyframe id, so a recording is the same from run to run and the robots'
/// own random streams are untouched.
#[must_use]
pub fn keyframe_cloud(owner: u32, keyframe: &Keyframe, n: usize, stamp: Timestamp) -> PointCloud {
    let n = n.min(keyframe.support_size as usize);
    let seed = (u64::from(owner) << 32) | u64::from(keyframe.id);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let points = if keyframe.gmm.is_empty() || n == 0 {
        Vec::new()
    } else {
        sample_surface(&keyframe.gmm, n, &mut rng)
    };
    PointCloud::xyzi(
        stamp,
        "world",
        points
            .iter()
            .filter(|s| s.position.iter().all(|v| v.is_finite()))
            .map(|s| (Point3::from(s.position), s.intensity)),
    )
}

/// The occupied cells of a grid snapshot (cell centres), with the cell's occupancy
/// probability as `intensity`.
#[must_use]
pub fn occupied_cloud(snapshot: &GridSnapshot, stamp: Timestamp) -> PointCloud {
    let grid = &snapshot.grid;
    let geometry = grid.geometry();
    PointCloud::xyzi(
        stamp,
        "world",
        grid.values()
            .iter()
            .enumerate()
            .filter(|(_, v)| grid.classify(**v) == CellState::Occupied)
            .map(|(k, _)| {
                let c = grid.cell_at(k);
                (geometry.cell_centre(c), grid.probability(c))
            }),
    )
}

/// The frontier cells of a grid snapshot (distance to the nearest frontier zero), with
/// the cell's height above the grid's floor as `intensity`.
#[must_use]
pub fn frontier_cloud(snapshot: &GridSnapshot, stamp: Timestamp) -> PointCloud {
    let grid = &snapshot.grid;
    let geometry = grid.geometry();
    PointCloud::xyzi(
        stamp,
        "world",
        snapshot.frontiers.indices().map(|k| {
            let p = geometry.cell_centre(grid.cell_at(k));
            (p, p.z - geometry.origin.z)
        }),
    )
}

/// A triangle mesh (`vertices`, three indices per triangle) as one entity `id` in
/// `world`, shown for the whole recording.
#[must_use]
pub fn mesh_entity(
    id: &str,
    vertices: &[Point3<f64>],
    triangles: &[[u32; 3]],
    color: Color,
    stamp: Timestamp,
) -> SceneEntity {
    let mut entity = SceneEntity::new(stamp, "world", id.into());
    entity.triangles.push(TriangleListPrimitive {
        pose: Pose::default(),
        points: vertices.iter().map(|p| Vector3::from(*p)).collect(),
        color,
        colors: Vec::new(),
        indices: triangles.iter().flatten().copied().collect(),
    });
    entity.metadata = vec![
        KeyValuePair::new("vertices", vertices.len()),
        KeyValuePair::new("triangles", triangles.len()),
    ];
    entity
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix4, Vector3 as V3};

    #[test]
    fn ellipsoid_reproduces_the_spatial_covariance() {
        let r = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1);
        let rm = r.to_rotation_matrix().into_inner();
        let sigma = rm * Matrix3::from_diagonal(&V3::new(0.04, 0.01, 0.0025)) * rm.transpose();
        let mut cov = Matrix4::identity();
        cov.fixed_view_mut::<3, 3>(0, 0).copy_from(&sigma);
        let mean = Vector4::new(1.0, -2.0, 0.5, 0.3);
        let e = ellipsoid(&mean, &cov, robot_color(0, 1.0)).expect("positive definite");
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            e.pose.orientation.w,
            e.pose.orientation.x,
            e.pose.orientation.y,
            e.pose.orientation.z,
        ));
        let axes = q.to_rotation_matrix().into_inner();
        let radii = V3::new(e.size.x, e.size.y, e.size.z) / (2.0 * ELLIPSOID_SIGMAS);
        let back = axes * Matrix3::from_diagonal(&radii.map(|s| s * s)) * axes.transpose();
        assert!((back - sigma).amax() < 1e-12, "{back} vs {sigma}");
        assert_eq!(
            (e.pose.position.x, e.pose.position.y, e.pose.position.z),
            (1.0, -2.0, 0.5)
        );
    }

    #[test]
    fn broken_covariances_give_no_ellipsoid() {
        let mean = Vector4::zeros();
        let color = robot_color(1, 1.0);
        assert!(ellipsoid(&mean, &Matrix4::zeros(), color).is_none());
        let mut nan = Matrix4::identity();
        nan[(1, 1)] = f64::NAN;
        assert!(ellipsoid(&mean, &nan, color).is_none());
        assert!(ellipsoid(&Vector4::repeat(f64::INFINITY), &Matrix4::identity(), color).is_none());
    }
}
