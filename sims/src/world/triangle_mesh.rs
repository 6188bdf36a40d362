//! The triangle mesh type: plain vertices and triangles, as read from a file
//! ([`TriangleMesh::load`], in `mesh_io`) and turned into a world by
//! [`MeshWorld`](super::MeshWorld).

use nalgebra::Point3;

use super::Aabb;

/// Why a parsed mesh cannot make a world ([`TriangleMesh::load`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InvalidMesh {
    /// A vertex with a NaN or infinite coordinate.
    #[error("vertex {vertex:?} is not finite")]
    NonFiniteVertex {
        /// The vertex, metres.
        vertex: [f64; 3],
    },
    /// A triangle that names a vertex the file does not have.
    #[error("triangle {triangle:?} refers to a vertex beyond the {vertices} vertices")]
    VertexBeyond {
        /// The triangle's vertex indices.
        triangle: [u32; 3],
        /// How many vertices there are.
        vertices: u32,
    },
    /// Every triangle is degenerate, or there are none.
    #[error("the mesh has no (non-degenerate) triangles")]
    NoTriangles,
}

/// A triangle mesh: vertices and triangles (indices into the vertices), with an
/// optional grey level per vertex.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions, metres.
    pub vertices: Vec<Point3<f64>>,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Grey level per vertex in `[0, 1]`, when the file has colours.
    pub grey: Option<Vec<f64>>,
}

impl TriangleMesh {
    /// Checks indices and coordinates; drops degenerate triangles.
    pub(super) fn checked(mut self) -> Result<TriangleMesh, InvalidMesh> {
        if let Some(v) = self
            .vertices
            .iter()
            .find(|v| !v.coords.iter().all(|c| c.is_finite()))
        {
            return Err(InvalidMesh::NonFiniteVertex {
                vertex: v.coords.into(),
            });
        }
        let n = self.vertices.len() as u32;
        if let Some(t) = self.triangles.iter().find(|t| t.iter().any(|&i| i >= n)) {
            return Err(InvalidMesh::VertexBeyond {
                triangle: *t,
                vertices: n,
            });
        }
        let vertices = &self.vertices;
        self.triangles.retain(|t| {
            let [a, b, c] = t.map(|i| vertices[i as usize]);
            (b - a).cross(&(c - a)).norm() > 1e-12
        });
        if self.triangles.is_empty() {
            return Err(InvalidMesh::NoTriangles);
        }
        Ok(self)
    }

    /// Bounding box of the vertices used by triangles.
    #[must_use]
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::from_point(self.vertices[self.triangles[0][0] as usize]);
        for t in &self.triangles {
            for &i in t {
                b = b.union(&Aabb::from_point(self.vertices[i as usize]));
            }
        }
        b
    }
}
