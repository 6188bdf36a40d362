//! What a world tells the GPU camera about itself ([`World::gpu_scene`](super::World::gpu_scene)): its distance
//! field and texture as plain tables, with no graphics types, so worlds describe
//! themselves without depending on wgpu or on the camera (the camera reads these).
//!
//! The camera's shader (`camera/gpu/trace.wgsl`) evaluates the same formulas as the worlds' CPU code in
//! `f32`; the lookup tables (noise permutations and lattice values, the cave's
//! primitive index) are copied exactly.

use nalgebra::{Point3, Vector3};

use super::noise::{PERIOD, ValueNoise};
use troupe_algorithms::geometry::Aabb;

/// The tables of one [`ValueNoise`]: the doubled permutation and the lattice values.
#[derive(Debug, Clone, PartialEq)]
pub struct GpuNoise {
    /// `2 * PERIOD` entries, each in `0..PERIOD`.
    pub perm: Vec<u32>,
    /// `PERIOD` lattice values in `[-1, 1]`.
    pub values: Vec<f32>,
}

impl From<&ValueNoise> for GpuNoise {
    fn from(noise: &ValueNoise) -> Self {
        let (perm, values) = noise.tables();
        debug_assert_eq!(perm.len(), 2 * PERIOD);
        GpuNoise {
            perm: perm.iter().map(|&p| u32::from(p)).collect(),
            values: values.iter().map(|&v| v as f32).collect(),
        }
    }
}

/// One convex piece of a cave's free space (see `world::cave::field`).
#[derive(Debug, Clone, PartialEq)]
pub enum GpuPrimitive {
    /// Points within `radius_m` of the segment `a`–`a + ab`; `inv_len2 = 1 / |ab|²`
    /// (0 for a point).
    Capsule {
        /// Segment start.
        a: Point3<f64>,
        /// Segment vector.
        ab: Vector3<f64>,
        /// `1 / |ab|²`, or 0.
        inv_len2: f64,
        /// Capsule radius.
        radius_m: f64,
    },
    /// A ball cut by a horizontal floor.
    Chamber {
        /// Ball centre.
        centre: Point3<f64>,
        /// Ball radius.
        radius_m: f64,
        /// Height of the flat floor.
        floor_z_m: f64,
    },
}

/// A cave's field: `sdf(p) = base(p) + A * noise(p / λ)` with the clamped union `base`
/// behind a uniform grid index (module `world::cave`).
#[derive(Debug, Clone, PartialEq)]
pub struct GpuCaveField {
    /// The primitives, indexed by `cell_items`.
    pub primitives: Vec<GpuPrimitive>,
    /// Corner of grid cell `(0, 0, 0)`.
    pub grid_origin: Point3<f64>,
    /// Edge of a grid cell.
    pub cell_m: f64,
    /// Cells along x, y and z.
    pub dims: [u32; 3],
    /// `cell_items[cell_start[c]..cell_start[c + 1]]` are the primitives of cell
    /// `c = x + dims[0] * (y + dims[1] * z)`.
    pub cell_start: Vec<u32>,
    /// Primitive indices, cell after cell.
    pub cell_items: Vec<u32>,
    /// Depth below which rock distances are clamped.
    pub rock_clamp_m: f64,
    /// Wall roughness noise.
    pub wall_noise: GpuNoise,
    /// Roughness amplitude `A`.
    pub amplitude_m: f64,
    /// Roughness wavelength `λ`.
    pub wavelength_m: f64,
    /// Lipschitz bound of the field.
    pub lipschitz: f64,
}

/// The distance field of a world.
#[derive(Debug, Clone, PartialEq)]
pub enum GpuGeometry {
    /// Free space inside `interior` minus solid boxes (`world::solids`): the exact
    /// distance to the nearest wall or box (the CPU's bucket index only caps the value
    /// far from every box, which changes step sizes but not surfaces).
    Boxes {
        /// The free interior.
        interior: Aabb,
        /// Solid boxes inside it.
        solids: Vec<Aabb>,
    },
    /// A procedural cave.
    Cave(GpuCaveField),
}

/// The surface texture of a world: which world's `albedo` formula the shader runs, with
/// its noise tables. The constants live in the shader next to a reference to the CPU
/// formula; the GPU–CPU image tests catch any drift.
#[derive(Debug, Clone, PartialEq)]
pub enum GpuAlbedo {
    /// `BoxRoom`: a checkerboard of `square_m` squares, `even` / `odd` reflectance.
    Checker {
        /// Square edge.
        square_m: f64,
        /// Reflectance where the sum of square indices is even.
        even: f64,
        /// Reflectance where it is odd.
        odd: f64,
    },
    /// `CaveWorld`: grain plus warped horizontal strata.
    CaveRock {
        /// Grain noise.
        texture: GpuNoise,
        /// Strata warp noise.
        strata: GpuNoise,
    },
    /// `Warehouse`: concrete grain with shelf beams every 1.5 m.
    Warehouse {
        /// Grain noise.
        texture: GpuNoise,
    },
    /// `OpenField`: darker ground, plainer boxes and walls.
    OpenField {
        /// Grain noise.
        texture: GpuNoise,
    },
    /// `OpeningScene`: bricks with grain.
    Bricks {
        /// Grain noise.
        texture: GpuNoise,
    },
}

/// A world as the GPU camera sees it (see [`World::gpu_scene`](super::World::gpu_scene)).
#[derive(Debug, Clone, PartialEq)]
pub struct GpuScene {
    /// The distance field.
    pub geometry: GpuGeometry,
    /// The surface texture.
    pub albedo: GpuAlbedo,
}
