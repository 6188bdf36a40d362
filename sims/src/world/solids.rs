//! Worlds built from axis-aligned solid boxes inside an enclosing room.
//!
//! The signed distance is exact near surfaces: the distance to the room's walls, the
//! floor and the ceiling, and to the nearest solid box found through a uniform 2D
//! bucket index in (x, y). Far from every box the value is capped by the distance to
//! the edge of the searched buckets, which keeps it a lower bound of the true distance
//! (all the sphere tracer needs) while each query looks at a handful of boxes only.

use nalgebra::Point3;

use super::Aabb;
use super::gpu_scene::GpuGeometry;

/// Solid boxes inside a free interior; everything outside the interior is rock.
#[derive(Clone, Debug)]
pub struct BoxSolids {
    interior: Aabb,
    solids: Vec<Aabb>,
    bucket_m: f64,
    columns: usize,
    rows: usize,
    /// Per bucket, the indices of the solids that overlap it (expanded by one bucket).
    buckets: Vec<Vec<u32>>,
}

impl BoxSolids {
    /// Builds the index; `bucket_m` is the edge of a bucket (a few metres; queries are
    /// exact within one bucket of the query point).
    #[must_use]
    pub fn new(interior: Aabb, solids: Vec<Aabb>, bucket_m: f64) -> Self {
        let bucket_m = bucket_m.max(0.1);
        let size = interior.size();
        let columns = ((size.x / bucket_m).ceil() as usize).max(1);
        let rows = ((size.y / bucket_m).ceil() as usize).max(1);
        let mut buckets = vec![Vec::new(); columns * rows];
        for (index, solid) in solids.iter().enumerate() {
            let reach = solid.expanded(bucket_m);
            let (c0, r0) = Self::bucket_of_xy(&interior, bucket_m, reach.min.x, reach.min.y);
            let (c1, r1) = Self::bucket_of_xy(&interior, bucket_m, reach.max.x, reach.max.y);
            for r in r0..=r1.min(rows - 1) {
                for c in c0..=c1.min(columns - 1) {
                    buckets[r * columns + c].push(index as u32);
                }
            }
        }
        BoxSolids {
            interior,
            solids,
            bucket_m,
            columns,
            rows,
            buckets,
        }
    }

    fn bucket_of_xy(interior: &Aabb, bucket_m: f64, x: f64, y: f64) -> (usize, usize) {
        let c = ((x - interior.min.x) / bucket_m).floor().max(0.0) as usize;
        let r = ((y - interior.min.y) / bucket_m).floor().max(0.0) as usize;
        (c, r)
    }

    /// The free interior (floor, walls and ceiling are its faces).
    #[must_use]
    pub fn interior(&self) -> Aabb {
        self.interior
    }

    /// The solid boxes.
    #[must_use]
    pub fn solids(&self) -> &[Aabb] {
        &self.solids
    }

    /// The room and its boxes for the GPU camera (which uses the exact distance, without
    /// the index).
    #[must_use]
    pub fn gpu_geometry(&self) -> GpuGeometry {
        GpuGeometry::Boxes {
            interior: self.interior,
            solids: self.solids.clone(),
        }
    }

    /// Signed distance: positive in free space, negative in a solid or outside the room.
    #[must_use]
    pub fn sdf_m(&self, p: &Point3<f64>) -> f64 {
        let b = &self.interior;
        if !b.contains(p) {
            return -b.distance_m(p);
        }
        let walls = (0..3)
            .map(|i| (p[i] - b.min[i]).min(b.max[i] - p[i]))
            .fold(f64::INFINITY, f64::min);
        let (c, r) = Self::bucket_of_xy(b, self.bucket_m, p.x, p.y);
        let (c, r) = (c.min(self.columns - 1), r.min(self.rows - 1));
        // Every solid not indexed in this bucket is at least this far away.
        let cell_min_x = b.min.x + c as f64 * self.bucket_m;
        let cell_min_y = b.min.y + r as f64 * self.bucket_m;
        let cap = self.bucket_m
            + (p.x - cell_min_x)
                .min(cell_min_x + self.bucket_m - p.x)
                .min(p.y - cell_min_y)
                .min(cell_min_y + self.bucket_m - p.y)
                .max(0.0);
        self.buckets[r * self.columns + c]
            .iter()
            .map(|&i| box_sdf_m(&self.solids[i as usize], p))
            .fold(walls.min(cap), f64::min)
    }
}

/// Signed distance to a solid box: positive outside, negative inside (exact).
#[must_use]
pub fn box_sdf_m(solid: &Aabb, p: &Point3<f64>) -> f64 {
    if solid.contains(p) {
        -(0..3)
            .map(|i| (p[i] - solid.min[i]).min(solid.max[i] - p[i]))
            .fold(f64::INFINITY, f64::min)
    } else {
        solid.distance_m(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn brute(world: &BoxSolids, p: &Point3<f64>) -> f64 {
        let b = world.interior();
        if !b.contains(p) {
            return -b.distance_m(p);
        }
        let walls = (0..3)
            .map(|i| (p[i] - b.min[i]).min(b.max[i] - p[i]))
            .fold(f64::INFINITY, f64::min);
        world
            .solids()
            .iter()
            .map(|s| box_sdf_m(s, p))
            .fold(walls, f64::min)
    }

    #[test]
    fn indexed_distance_is_a_lower_bound_and_exact_near_surfaces() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let interior = Aabb::new(Point3::new(0.0, 0.0, 0.0), Point3::new(40.0, 20.0, 8.0));
        let solids: Vec<Aabb> = (0..30)
            .map(|_| {
                let c = Point3::new(
                    rng.random_range(2.0..38.0),
                    rng.random_range(2.0..18.0),
                    rng.random_range(0.0..6.0),
                );
                let h = nalgebra::Vector3::new(
                    rng.random_range(0.1..1.5),
                    rng.random_range(0.1..1.5),
                    rng.random_range(0.1..2.0),
                );
                Aabb::new(c - h, c + h)
            })
            .collect();
        let world = BoxSolids::new(interior, solids, 3.0);
        for _ in 0..20_000 {
            let p = Point3::new(
                rng.random_range(-1.0..41.0),
                rng.random_range(-1.0..21.0),
                rng.random_range(-1.0..9.0),
            );
            let exact = brute(&world, &p);
            let fast = world.sdf_m(&p);
            assert!(
                fast <= exact + 1e-12,
                "not a lower bound at {p}: {fast} > {exact}"
            );
            if exact < 3.0 {
                assert!(
                    (fast - exact).abs() < 1e-12,
                    "inexact near a surface at {p}"
                );
            }
        }
    }
}
