//! Worlds from triangle meshes (PLY or OBJ files).
//!
//! The mesh is turned into a sampled signed distance field once, at load: exact
//! point–triangle distances in a narrow band around the surface, a Euclidean distance
//! transform beyond it (a lower bound of the true distance), and the sign from ray
//! parity along +x (the mesh should be closed). Queries interpolate the samples
//! trilinearly, so surfaces are placed to within about one sample spacing.

use std::path::PathBuf;

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};
use troupe_algorithms::grid::distance::distance_to;
use troupe_core::ConfigError;

pub use super::mesh_io::{MeshError, MeshFormatError};
use super::noise::ValueNoise;
pub use super::triangle_mesh::{InvalidMesh, TriangleMesh};
use super::{Aabb, Site, World};

/// Which side of the mesh robots fly in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FreeSpace {
    /// Inside the closed mesh (a cave or a building's interior).
    Inside,
    /// Outside it (objects standing in open space), bounded by the mesh's box plus
    /// `margin_m`.
    Outside,
}

/// The `[world.mesh]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MeshParams {
    /// PLY (ASCII or binary little-endian) or OBJ file; relative paths are taken
    /// from the working directory.
    pub path: PathBuf,
    /// Which side is free.
    pub free_space: FreeSpace,
    /// Spacing of the distance samples, metres.
    pub resolution_m: f64,
    /// Free space kept around the mesh's bounding box (`outside` only), metres.
    pub margin_m: f64,
    /// Start positions, one per robot (cycled, 1 m apart, when there are fewer).
    pub starts_m: Vec<[f64; 3]>,
    /// Waypoint routes: robot `i` visits `routes_m[i % len]` after its start (no
    /// route: it stays at its start).
    pub routes_m: Vec<Vec<[f64; 3]>>,
}

impl Default for MeshParams {
    fn default() -> Self {
        MeshParams {
            path: PathBuf::new(),
            free_space: FreeSpace::Outside,
            resolution_m: 0.1,
            margin_m: 3.0,
            starts_m: Vec::new(),
            routes_m: Vec::new(),
        }
    }
}

impl MeshParams {
    /// Checks the numbers (the file is checked when it is loaded).
    ///
    /// # Errors
    ///
    /// The offending key (relative to `[world.mesh]`), its rule and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.path.as_os_str().is_empty() {
            return Err(ConfigError::new(
                "path",
                "must name a .ply or .obj file",
                "\"\"",
            ));
        }
        if !(self.resolution_m.is_finite() && (0.02..=1.0).contains(&self.resolution_m)) {
            return Err(ConfigError::new(
                "resolution_m",
                "must be in [0.02, 1] m",
                self.resolution_m,
            ));
        }
        ConfigError::non_negative("margin_m", self.margin_m)?;
        if self.starts_m.is_empty() {
            return Err(ConfigError::new(
                "starts_m",
                "must give at least one start position",
                "[]",
            ));
        }
        let finite = |p: &[f64; 3]| p.iter().all(|v| v.is_finite());
        if let Some(p) = self.starts_m.iter().find(|p| !finite(p)) {
            return Err(ConfigError::new(
                "starts_m",
                "must hold finite coordinates",
                format!("{p:?}"),
            ));
        }
        if let Some(p) = self.routes_m.iter().flatten().find(|p| !finite(p)) {
            return Err(ConfigError::new(
                "routes_m",
                "must hold finite coordinates",
                format!("{p:?}"),
            ));
        }
        Ok(())
    }
}

/// Closest point on triangle `abc` to `p` (Ericson, *Real-Time Collision Detection*,
/// §5.1.5, by Voronoi regions).
#[must_use]
pub fn closest_on_triangle(
    p: &Point3<f64>,
    a: &Point3<f64>,
    b: &Point3<f64>,
    c: &Point3<f64>,
) -> Point3<f64> {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return *a;
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return *b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return *c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// A world whose surfaces are a triangle mesh, as a sampled signed distance field.
#[derive(Clone, Debug)]
pub struct MeshWorld {
    params: MeshParams,
    /// Free-space box.
    bounds: Aabb,
    /// Sample grid: origin (sample 0,0,0), spacing, counts.
    origin: Point3<f64>,
    step_m: f64,
    dims: [usize; 3],
    sdf: Vec<f32>,
    grey: Vec<f32>,
    texture: ValueNoise,
}

impl MeshWorld {
    /// Samples the mesh's signed distance (see the [module docs](self)).
    #[must_use]
    pub fn from_mesh(mesh: &TriangleMesh, params: &MeshParams, seed: u64) -> MeshWorld {
        let step = params.resolution_m;
        let mesh_box = mesh.bounds();
        let bounds = match params.free_space {
            FreeSpace::Inside => mesh_box,
            FreeSpace::Outside => mesh_box.expanded(params.margin_m),
        };
        // One sample beyond the bounds on every side.
        let origin = bounds.min - Vector3::repeat(step);
        let size = bounds.size() + Vector3::repeat(2.0 * step);
        let dims = [0, 1, 2].map(|i| (size[i] / step).ceil() as usize + 1);
        let index = |x: usize, y: usize, z: usize| x + dims[0] * (y + dims[1] * z);
        let node = |x: usize, y: usize, z: usize| {
            origin + Vector3::new(x as f64, y as f64, z as f64) * step
        };
        let total = dims[0] * dims[1] * dims[2];
        let band_m = 3.0 * step;
        let mut unsigned = vec![f64::INFINITY; total];
        let mut grey = vec![0.5f32; total];
        let cell_range = |lo: f64, hi: f64, axis: usize| {
            let a = ((lo - origin[axis]) / step).floor().max(0.0) as usize;
            let b = (((hi - origin[axis]) / step).ceil().max(0.0) as usize).min(dims[axis] - 1);
            a..=b
        };
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            let tri_box = Aabb::from_point(a)
                .union(&Aabb::from_point(b))
                .union(&Aabb::from_point(c))
                .expanded(band_m);
            let vertex_grey = mesh
                .grey
                .as_ref()
                .map(|g| t.map(|i| g[i as usize]).iter().sum::<f64>() / 3.0);
            for z in cell_range(tri_box.min.z, tri_box.max.z, 2) {
                for y in cell_range(tri_box.min.y, tri_box.max.y, 1) {
                    for x in cell_range(tri_box.min.x, tri_box.max.x, 0) {
                        let p = node(x, y, z);
                        let d = (closest_on_triangle(&p, &a, &b, &c) - p).norm();
                        let i = index(x, y, z);
                        if d < unsigned[i] {
                            unsigned[i] = d;
                            if let Some(g) = vertex_grey {
                                grey[i] = g as f32;
                            }
                        }
                    }
                }
            }
        }
        // Beyond the band: a sample `far` from the nearest band sample is at least
        // `far + band − √3·step` from the surface (the surface's band-wide
        // neighbourhood is covered by band samples up to the sampling), so
        // `far + band − 2·step` is a safe lower bound.
        let in_band: Vec<bool> = unsigned.iter().map(|d| *d <= band_m).collect();
        let to_band = distance_to(&in_band, dims, step);
        for (u, far) in unsigned.iter_mut().zip(to_band.iter_m()) {
            if *u > band_m {
                *u = band_m.max(far + band_m - 2.0 * step);
            }
        }
        let inside = inside_by_parity(mesh, origin, step, dims);
        let sdf = unsigned
            .iter()
            .zip(&inside)
            .map(|(d, inside)| {
                let free = match params.free_space {
                    FreeSpace::Inside => *inside,
                    FreeSpace::Outside => !*inside,
                };
                (if free { *d } else { -*d }) as f32
            })
            .collect();
        MeshWorld {
            params: params.clone(),
            bounds,
            origin,
            step_m: step,
            dims,
            sdf,
            grey,
            texture: ValueNoise::new(seed ^ 0x6d65_7368),
        }
    }

    /// Loads the file named in `params` and samples it.
    ///
    /// # Errors
    ///
    /// See [`TriangleMesh::load`].
    pub fn load(params: &MeshParams, seed: u64) -> Result<MeshWorld, MeshError> {
        let mesh = TriangleMesh::load(&params.path)?;
        Ok(MeshWorld::from_mesh(&mesh, params, seed))
    }

    fn sample(&self, field: &[f32], p: &Point3<f64>) -> f64 {
        let g = (p - self.origin) / self.step_m;
        let mut base = [0usize; 3];
        let mut frac = [0.0f64; 3];
        for i in 0..3 {
            let max = (self.dims[i] - 2) as f64;
            let gi = g[i].clamp(0.0, max);
            base[i] = gi.floor().min(max) as usize;
            frac[i] = gi - base[i] as f64;
        }
        let at = |dx: usize, dy: usize, dz: usize| {
            f64::from(
                field[(base[0] + dx)
                    + self.dims[0] * ((base[1] + dy) + self.dims[1] * (base[2] + dz))],
            )
        };
        let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
        let [fx, fy, fz] = frac;
        let c00 = lerp(at(0, 0, 0), at(1, 0, 0), fx);
        let c10 = lerp(at(0, 1, 0), at(1, 1, 0), fx);
        let c01 = lerp(at(0, 0, 1), at(1, 0, 1), fx);
        let c11 = lerp(at(0, 1, 1), at(1, 1, 1), fx);
        lerp(lerp(c00, c10, fy), lerp(c01, c11, fy), fz)
    }
}

/// Inside/outside of every sample by counting crossings of a ray along +x (slightly
/// offset so that it does not run along mesh edges).
fn inside_by_parity(
    mesh: &TriangleMesh,
    origin: Point3<f64>,
    step: f64,
    dims: [usize; 3],
) -> Vec<bool> {
    let (ny, nz) = (dims[1], dims[2]);
    // Triangles bucketed by the (y, z) rows their projection covers.
    let mut rows: Vec<Vec<u32>> = vec![Vec::new(); ny * nz];
    for (k, t) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let lo = |i: usize| a[i].min(b[i]).min(c[i]);
        let hi = |i: usize| a[i].max(b[i]).max(c[i]);
        let range = |axis: usize, n: usize| {
            let s = ((lo(axis) - origin[axis]) / step).floor().max(0.0) as usize;
            let e = (((hi(axis) - origin[axis]) / step).ceil().max(0.0) as usize).min(n - 1);
            s..=e
        };
        for z in range(2, nz) {
            for y in range(1, ny) {
                rows[y + ny * z].push(k as u32);
            }
        }
    }
    let mut inside = vec![false; dims[0] * ny * nz];
    let mut crossings = Vec::new();
    for z in 0..nz {
        for y in 0..ny {
            let py = origin.y + y as f64 * step + 1.37e-7;
            let pz = origin.z + z as f64 * step + 2.71e-7;
            crossings.clear();
            for &k in &rows[y + ny * z] {
                let [a, b, c] = mesh.triangles[k as usize].map(|i| mesh.vertices[i as usize]);
                // Barycentric test of (py, pz) in the triangle's (y, z) projection.
                let d = (b.y - a.y) * (c.z - a.z) - (c.y - a.y) * (b.z - a.z);
                if d.abs() < 1e-15 {
                    continue;
                }
                let u = ((py - a.y) * (c.z - a.z) - (c.y - a.y) * (pz - a.z)) / d;
                let v = ((b.y - a.y) * (pz - a.z) - (py - a.y) * (b.z - a.z)) / d;
                if u >= 0.0 && v >= 0.0 && u + v <= 1.0 {
                    crossings.push(a.x + u * (b.x - a.x) + v * (c.x - a.x));
                }
            }
            crossings.sort_by(f64::total_cmp);
            let mut k = 0;
            for x in 0..dims[0] {
                let px = origin.x + x as f64 * step;
                while k < crossings.len() && crossings[k] < px {
                    k += 1;
                }
                inside[x + dims[0] * (y + ny * z)] = k % 2 == 1;
            }
        }
    }
    inside
}

impl World for MeshWorld {
    fn sdf_m(&self, p: &Point3<f64>) -> f64 {
        // Outside the free box is rock (the box is the world's edge).
        let edge = -self.bounds.distance_m(p);
        if edge < 0.0 {
            return edge;
        }
        let walls = (0..3)
            .map(|i| (p[i] - self.bounds.min[i]).min(self.bounds.max[i] - p[i]))
            .fold(f64::INFINITY, f64::min);
        self.sample(&self.sdf, p).min(walls)
    }

    /// Trilinear interpolation of distance samples has a gradient of at most √3.
    fn lipschitz(&self) -> f64 {
        3f64.sqrt()
    }

    fn albedo(&self, p: &Point3<f64>) -> f64 {
        let grain = self.texture.fbm(&Point3::from(p.coords / 0.3), 3);
        (self.sample(&self.grey, p) + 0.2 * grain).clamp(0.05, 1.0)
    }

    fn bounds(&self) -> Aabb {
        self.bounds
    }
}

impl Site for MeshWorld {
    fn start_position(&self, robot_index: usize, _robot_count: usize) -> Point3<f64> {
        let starts = &self.params.starts_m;
        let base = Point3::from(starts[robot_index % starts.len()]);
        base + Vector3::y() * (robot_index / starts.len()) as f64
    }

    fn route(&self, robot_index: usize, robot_count: usize) -> Vec<Point3<f64>> {
        let routes = &self.params.routes_m;
        let waypoints = if routes.is_empty() {
            &[][..]
        } else {
            &routes[robot_index % routes.len()][..]
        };
        std::iter::once(self.start_position(robot_index, robot_count))
            .chain(waypoints.iter().map(|p| Point3::from(*p)))
            .collect()
    }

    fn route_length_m(&self) -> f64 {
        super::warehouse::polyline_length_m(&self.route(0, 1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::solids::box_sdf_m;

    /// A closed axis-aligned box as 12 triangles, outward normals.
    pub(crate) fn box_mesh(b: &Aabb) -> TriangleMesh {
        let v = |x: usize, y: usize, z: usize| {
            Point3::new(
                if x == 0 { b.min.x } else { b.max.x },
                if y == 0 { b.min.y } else { b.max.y },
                if z == 0 { b.min.z } else { b.max.z },
            )
        };
        let vertices: Vec<Point3<f64>> = (0..8).map(|i| v(i & 1, (i >> 1) & 1, i >> 2)).collect();
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let triangles = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        TriangleMesh {
            vertices,
            triangles,
            grey: None,
        }
    }

    #[test]
    fn sampled_field_matches_an_analytic_box() {
        let solid = Aabb::new(Point3::new(0.0, 0.0, 0.0), Point3::new(2.0, 1.0, 1.5));
        let params = MeshParams {
            path: "box.obj".into(),
            free_space: FreeSpace::Outside,
            resolution_m: 0.1,
            margin_m: 2.0,
            starts_m: vec![[-1.0, 0.5, 0.5]],
            routes_m: vec![vec![[3.0, 0.5, 0.5]]],
        };
        let world = MeshWorld::from_mesh(&box_mesh(&solid), &params, 1);
        let mut worst: f64 = 0.0;
        for k in 0..2000 {
            let f = |s: u64| super::super::noise::unit_f64(super::super::noise::mix64(k * 3 + s));
            let p = Point3::new(-1.5 + 5.0 * f(0), -1.5 + 4.0 * f(1), -1.5 + 4.5 * f(2));
            // Free space is outside the solid.
            let exact = box_sdf_m(&solid, &p);
            let walls = (0..3)
                .map(|i| (p[i] - world.bounds().min[i]).min(world.bounds().max[i] - p[i]))
                .fold(f64::INFINITY, f64::min);
            let got = world.sdf_m(&p);
            // A lower bound in free space (up to the interpolation error), exact
            // near the surface to within a sample spacing.
            if exact > 0.0 {
                assert!(got <= exact.min(walls) + 0.1, "{p}: {got} vs {exact}");
            }
            if exact.abs() < 0.25 {
                worst = worst.max((got - exact).abs());
            }
            if exact.abs() > 0.1 && walls > 0.1 {
                assert_eq!(got < 0.0, exact < 0.0, "sign at {p}: {got} vs {exact}");
            }
        }
        assert!(worst < 0.1, "worst error near the surface {worst}");
    }

    #[test]
    fn shipped_mesh_scenario_loads_and_its_routes_are_clear() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/mesh_pillars.toml");
        let scenario = crate::scenario::Scenario::load(&path).expect("scenario");
        let world = scenario.world.build().expect("mesh loads");
        for i in 0..2 {
            let route = world.route(i, 2);
            let clearance =
                super::super::warehouse::route_clearance_m(world.as_ref(), &route, 0.05);
            assert!(clearance > 0.6, "robot {i}: clearance {clearance}");
        }
        // Inside a pillar is rock.
        assert!(world.sdf_m(&Point3::new(4.0, 2.0, 2.0)) < 0.0);
        let missing = MeshParams {
            path: "no/such/file.obj".into(),
            ..scenario.world.mesh.clone()
        };
        let error = MeshWorld::load(&missing, 1).expect_err("missing file");
        assert!(error.to_string().contains("no/such/file.obj"));
    }
}
