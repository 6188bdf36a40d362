//! Flattening a [`GpuScene`] and a camera pose into the shader's buffers (layouts in
//! `trace.wgsl`): 32-bit words, little-endian, uniforms as rows of four.

use nalgebra::Isometry3;

use crate::camera::CameraParams;
use crate::world::noise::PERIOD;
use crate::world::{GpuAlbedo, GpuGeometry, GpuNoise, GpuPrimitive, GpuScene};

/// Noise slots of the shader: wall roughness, texture grain, strata.
const NOISE_SLOTS: usize = 3;

/// The scene's buffers, as 32-bit words.
pub(super) struct PackedScene {
    /// The `Scene` uniform (7 rows of 4).
    pub uniform: Vec<u32>,
    /// Cave cell starts and items, then the permutation tables of the noise slots.
    pub words: Vec<u32>,
    /// Cave primitives or solid boxes, as `vec4<f32>` bit patterns.
    pub items: Vec<u32>,
    /// Lattice values of the noise slots, as `f32` bit patterns.
    pub lattice_values: Vec<u32>,
}

fn row_f32(v: [f64; 4]) -> [u32; 4] {
    v.map(|x| (x as f32).to_bits())
}

fn len_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// Packs `scene`; every buffer is non-empty (the API forbids empty bindings).
pub(super) fn pack_scene(scene: &GpuScene) -> PackedScene {
    let mut words = Vec::new();
    let mut items: Vec<[u32; 4]> = Vec::new();
    let mut noise: [Option<&GpuNoise>; NOISE_SLOTS] = [None; NOISE_SLOTS];
    let mut rows = [[0u32; 4]; 7];
    match &scene.geometry {
        GpuGeometry::Boxes { interior, solids } => {
            for s in solids {
                items.push(row_f32([s.min.x, s.min.y, s.min.z, 0.0]));
                items.push(row_f32([s.max.x, s.max.y, s.max.z, 0.0]));
            }
            rows[0] = [0, 0, len_u32(solids.len()), 0];
            rows[4] = row_f32([interior.min.x, interior.min.y, interior.min.z, 0.0]);
            rows[5] = row_f32([interior.max.x, interior.max.y, interior.max.z, 0.0]);
        }
        GpuGeometry::Cave(cave) => {
            words.extend_from_slice(&cave.cell_start);
            let items_offset = len_u32(words.len());
            words.extend_from_slice(&cave.cell_items);
            for p in &cave.primitives {
                match *p {
                    GpuPrimitive::Capsule {
                        a,
                        ab,
                        inv_len2,
                        radius_m,
                    } => {
                        items.push(row_f32([0.0, radius_m, inv_len2, 0.0]));
                        items.push(row_f32([a.x, a.y, a.z, 0.0]));
                        items.push(row_f32([ab.x, ab.y, ab.z, 0.0]));
                    }
                    GpuPrimitive::Chamber {
                        centre,
                        radius_m,
                        floor_z_m,
                    } => {
                        items.push(row_f32([1.0, radius_m, floor_z_m, 0.0]));
                        items.push(row_f32([centre.x, centre.y, centre.z, 0.0]));
                        items.push([0; 4]);
                    }
                }
            }
            noise[0] = Some(&cave.wall_noise);
            let o = cave.grid_origin;
            let [dx, dy, dz] = cave.dims;
            rows[0] = [1, 0, len_u32(cave.primitives.len()), items_offset];
            rows[1] = row_f32([o.x, o.y, o.z, cave.cell_m]);
            rows[2] = [dx, dy, dz, 0];
            rows[3] = row_f32([
                cave.amplitude_m,
                cave.wavelength_m,
                cave.lipschitz,
                cave.rock_clamp_m,
            ]);
        }
    }
    rows[0][1] = match &scene.albedo {
        GpuAlbedo::Checker {
            square_m,
            even,
            odd,
        } => {
            rows[6] = row_f32([*square_m, *even, *odd, 0.0]);
            0
        }
        GpuAlbedo::CaveRock { texture, strata } => {
            noise[1] = Some(texture);
            noise[2] = Some(strata);
            1
        }
        GpuAlbedo::Warehouse { texture } => {
            noise[1] = Some(texture);
            2
        }
        GpuAlbedo::OpenField { texture } => {
            noise[1] = Some(texture);
            3
        }
        GpuAlbedo::Bricks { texture } => {
            noise[1] = Some(texture);
            4
        }
    };
    rows[2][3] = len_u32(words.len());
    let mut lattice_values = Vec::with_capacity(NOISE_SLOTS * PERIOD);
    for slot in noise {
        let (mut perm, mut values) = match slot {
            Some(n) => (n.perm.clone(), n.values.clone()),
            None => (Vec::new(), Vec::new()),
        };
        perm.resize(2 * PERIOD, 0);
        values.resize(PERIOD, 0.0);
        words.extend(perm);
        lattice_values.extend(values.iter().map(|v| v.to_bits()));
    }
    if items.is_empty() {
        items.push([0; 4]);
    }
    PackedScene {
        uniform: rows.concat(),
        words,
        items: items.concat(),
        lattice_values,
    }
}

/// The `Pose` uniform (6 rows of 4) for a camera at `body_pose`.
pub(super) fn pack_pose(cam: &CameraParams, body_pose: &Isometry3<f64>) -> Vec<u32> {
    let t = body_pose.translation.vector;
    let r = body_pose.rotation.to_rotation_matrix();
    let m = r.matrix();
    let k = cam.intrinsics();
    let column = |j: usize| row_f32([m[(0, j)], m[(1, j)], m[(2, j)], 0.0]);
    [
        row_f32([t.x, t.y, t.z, cam.range_m]),
        column(0),
        column(1),
        column(2),
        row_f32([k.fx, k.fy, k.cx, k.cy]),
        [cam.width, cam.height, 0, 0],
    ]
    .concat()
}

/// Little-endian bytes of 32-bit words.
pub(super) fn to_bytes(words: &[u32]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}
