//! A procedural cave: a tree of wiggly tunnels with chambers and rough walls.
//!
//! Free space is the union of capsule chains along the centre-line polylines of the
//! tunnel tree ([`CaveGraph`]) and of floored balls (chambers) at some nodes. The wall is
//! displaced by value noise of amplitude `wall_noise_amplitude_m`:
//!
//! `sdf(p) = base(p) + A * noise(p / λ)`,
//!
//! where `base` is the clamped union distance (exactly 1-Lipschitz, see `field`), so the
//! field is Lipschitz with bound `L = 1 + A * noise::GRADIENT_BOUND / λ`. A coarse grid
//! lists the primitives near each cell, so one evaluation touches only a few capsules.
//! Everything derives from the seed through `ChaCha8Rng` and hashes.

mod field;
mod generate;
mod graph;
mod params;

pub use graph::{
    CaveEdge, CaveGraph, CaveNode, FIRST_START_OFFSET_M, START_SPACING_M, polyline_length,
};
pub use params::{CaveParams, ROUTE_CLEARANCE_M};

use nalgebra::{Point3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use self::field::{Field, Primitive};
use super::gpu_scene::{GpuAlbedo, GpuGeometry, GpuNoise, GpuScene};
use super::noise::{self, ValueNoise};
use super::{Aabb, World};

/// How far below the node a chamber's flat floor lies, as a fraction of its radius.
const CHAMBER_FLOOR_FRACTION: f64 = 0.6;

/// A procedural cave world; see the module documentation.
#[derive(Debug, Clone)]
pub struct CaveWorld {
    params: CaveParams,
    seed: u64,
    graph: CaveGraph,
    field: Field,
    wall_noise: ValueNoise,
    texture: ValueNoise,
    strata: ValueNoise,
    lipschitz: f64,
    bounds: Aabb,
}

impl CaveWorld {
    /// Build the cave for `params` and `seed`. The same inputs give the same cave, bit for
    /// bit. `params` should have passed [`CaveParams::validate`]; the clearance promises
    /// of [`CaveWorld::centreline_route`] rely on it.
    #[must_use]
    pub fn generate(params: &CaveParams, seed: u64) -> CaveWorld {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        CaveWorld::from_graph(params, generate::grow(params, &mut rng), seed)
    }

    /// The cave along a given centre-line tree (scripted worlds such as
    /// [`super::tunnels`]): capsules of each edge's radius, a chamber at every node with a
    /// `chamber_radius_m`, and walls roughened by `params.wall_noise_*` from `seed`; the
    /// other fields of `params` are not used. Edge 0 must leave the entrance.
    #[must_use]
    pub fn from_graph(params: &CaveParams, graph: CaveGraph, seed: u64) -> CaveWorld {
        let mut prims = Vec::new();
        for e in &graph.edges {
            for w in e.points.windows(2) {
                prims.push(Primitive::capsule(w[0], w[1], e.radius_m));
            }
        }
        for n in &graph.nodes {
            if let Some(radius) = n.chamber_radius_m {
                let floor_z = n.position.z - CHAMBER_FLOOR_FRACTION * radius;
                prims.push(Primitive::Chamber {
                    centre: n.position,
                    radius,
                    floor_z,
                });
            }
        }
        let field = Field::new(prims);
        let amplitude = params.wall_noise_amplitude_m;
        let lipschitz = 1.0 + amplitude * noise::GRADIENT_BOUND / params.wall_noise_wavelength_m;
        let bounds = field.free_aabb().expanded(amplitude + 0.05);
        CaveWorld {
            params: params.clone(),
            seed,
            graph,
            field,
            wall_noise: ValueNoise::new(seed ^ 0x0A11_0FCA_FE00),
            texture: ValueNoise::new(seed ^ 0x7E47_0E00),
            strata: ValueNoise::new(seed ^ 0x5712_A7A0),
            lipschitz,
            bounds,
        }
    }

    /// The parameters the cave was built from.
    #[must_use]
    pub fn params(&self) -> &CaveParams {
        &self.params
    }

    /// The seed the cave was built from.
    #[must_use]
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The centre-line tree: nodes, tunnels and the entrance.
    #[must_use]
    pub fn graph(&self) -> &CaveGraph {
        &self.graph
    }

    /// Position of the entrance node.
    #[must_use]
    pub fn entrance(&self) -> Point3<f64> {
        self.graph.nodes[self.graph.entrance].position
    }

    /// Start position of robot `robot_index` of `robot_count` (see
    /// [`CaveGraph::start_position`]): on the entrance tunnel's centre line, at least
    /// [`START_SPACING_M`] apart, with clearance of at least [`ROUTE_CLEARANCE_M`].
    /// `robot_count` is accepted for symmetry with the route; positions do not depend on it.
    #[must_use]
    pub fn start_position(&self, robot_index: usize, robot_count: usize) -> Point3<f64> {
        let _ = robot_count;
        self.graph.start_position(robot_index)
    }

    /// Depth-first exploration route of robot `robot_index` of `robot_count` through the
    /// whole tunnel tree (see [`CaveGraph::route`]); it starts at
    /// [`CaveWorld::start_position`]. Every point on it and on the straight segments
    /// between consecutive points lies on a tunnel centre line, so its clearance is at
    /// least `tunnel_radius_min_m - wall_noise_amplitude_m` (at least
    /// [`ROUTE_CLEARANCE_M`] for validated parameters).
    #[must_use]
    pub fn centreline_route(&self, robot_index: usize, robot_count: usize) -> Vec<Point3<f64>> {
        let _ = robot_count;
        self.graph.route(robot_index)
    }

    /// The noise-free union distance (1-Lipschitz); the walls are this plus roughness.
    #[must_use]
    pub fn base_sdf_m(&self, p: &Point3<f64>) -> f64 {
        self.field.base_m(p)
    }

    fn roughness_m(&self, p: &Point3<f64>) -> f64 {
        let q = Point3::from(p.coords / self.params.wall_noise_wavelength_m);
        self.params.wall_noise_amplitude_m * self.wall_noise.value(&q)
    }
}

impl World for CaveWorld {
    fn sdf_m(&self, p: &Point3<f64>) -> f64 {
        self.field.base_m(p) + self.roughness_m(p)
    }

    fn lipschitz(&self) -> f64 {
        self.lipschitz
    }

    /// Far from the wall, `base - A` is a safe step with no noise evaluation: a surface
    /// point `q` has `base(q) <= A` and `base` is 1-Lipschitz.
    fn safe_step_m(&self, p: &Point3<f64>) -> f64 {
        let base = self.field.base_m(p);
        let a = self.params.wall_noise_amplitude_m;
        if base > 3.0 * a {
            return base - a;
        }
        let near = (base + self.roughness_m(p)) / self.lipschitz;
        near.max(base - a)
    }

    fn albedo(&self, p: &Point3<f64>) -> f64 {
        let grain = self.texture.fbm(&Point3::from(p.coords / 0.35), 3);
        let warp = self.strata.value(&Point3::from(p.coords / 3.0));
        let bands = (2.0 * std::f64::consts::PI * p.z / 0.8 + 2.5 * warp).sin();
        (0.5 + 0.28 * grain + 0.17 * bands).clamp(0.05, 1.0)
    }

    fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// Finite differences on the four vertices of a tetrahedron (four evaluations instead
    /// of six); same step as the default.
    fn normal(&self, p: &Point3<f64>) -> Vector3<f64> {
        let h = super::NORMAL_STEP_M;
        let g = [
            Vector3::new(1.0, -1.0, -1.0),
            Vector3::new(-1.0, -1.0, 1.0),
            Vector3::new(-1.0, 1.0, -1.0),
            Vector3::new(1.0, 1.0, 1.0),
        ]
        .iter()
        .map(|k| k * self.sdf_m(&(p + k * h)))
        .sum::<Vector3<f64>>();
        g.try_normalize(1e-12).unwrap_or_else(Vector3::z)
    }

    fn gpu_scene(&self) -> Option<GpuScene> {
        let field = self.field.to_gpu(
            GpuNoise::from(&self.wall_noise),
            self.params.wall_noise_amplitude_m,
            self.params.wall_noise_wavelength_m,
            self.lipschitz,
        );
        Some(GpuScene {
            geometry: GpuGeometry::Cave(field),
            albedo: GpuAlbedo::CaveRock {
                texture: GpuNoise::from(&self.texture),
                strata: GpuNoise::from(&self.strata),
            },
        })
    }
}

#[cfg(test)]
mod tests;
