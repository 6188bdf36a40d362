//! Minimal readers for triangle meshes: PLY (ASCII and binary little-endian; vertex
//! `x y z` as float or double, optional `red green blue`, faces as a list of vertex
//! indices) and Wavefront OBJ (`v` and `f` lines; polygons are fanned into triangles),
//! giving a [`TriangleMesh`] ([`TriangleMesh::load`]).

use std::path::{Path, PathBuf};

use nalgebra::Point3;

use super::triangle_mesh::{InvalidMesh, TriangleMesh};

/// Why a mesh could not be read.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be read.
    #[error("mesh file `{path}`")]
    Read {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The file is not a mesh we can parse.
    #[error("mesh file `{path}` cannot be parsed")]
    Format {
        /// File.
        path: PathBuf,
        /// What is wrong.
        source: MeshFormatError,
    },
    /// The file parses but its triangles cannot make a world.
    #[error("mesh file `{path}` holds no usable mesh")]
    Invalid {
        /// File.
        path: PathBuf,
        /// What is wrong.
        source: InvalidMesh,
    },
}

/// What is wrong in the text or bytes of a PLY or OBJ file.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum MeshFormatError {
    /// Neither `.ply` nor `.obj`.
    #[error("the file name must end in .ply or .obj")]
    Extension,
    /// An OBJ file that is not UTF-8.
    #[error("an OBJ file must be UTF-8 text")]
    ObjNotText,
    /// An OBJ `v` line without three numbers.
    #[error("line {line}: a vertex needs three numbers")]
    ObjVertex {
        /// 1-based line.
        line: usize,
    },
    /// An OBJ `f` line with an index that is not a number.
    #[error("line {line}: a face index is not a number")]
    ObjIndex {
        /// 1-based line.
        line: usize,
    },
    /// An OBJ `f` line with an index before the first vertex.
    #[error("line {line}: a face index is out of range")]
    ObjIndexRange {
        /// 1-based line.
        line: usize,
    },
    /// An OBJ `f` line with fewer than three corners.
    #[error("line {line}: a face needs at least three vertices")]
    ObjShortFace {
        /// 1-based line.
        line: usize,
    },
    /// No `end_header` line.
    #[error("not a PLY file: no `end_header` line")]
    PlyNoEndHeader,
    /// The first line is not `ply`.
    #[error("not a PLY file: it must start with `ply`")]
    PlyNoMagic,
    /// A PLY header that is not ASCII.
    #[error("the PLY header must be ASCII text")]
    PlyHeaderNotText,
    /// A PLY format other than ASCII or binary little-endian.
    #[error("PLY format `{0}` is not supported")]
    PlyFormat(String),
    /// No `format` line in the PLY header.
    #[error("the PLY header has no `format` line")]
    PlyNoFormat,
    /// A PLY element count that is not a number.
    #[error("bad count for PLY element `{0}`")]
    PlyElementCount(String),
    /// A PLY element with more than 10⁸ items (refused before allocating).
    #[error("PLY element `{0}` is too large")]
    PlyElementTooLarge(String),
    /// A PLY property of an unknown type (the header line).
    #[error("unknown PLY property type in `{0}`")]
    PlyPropertyType(String),
    /// A PLY property before any element.
    #[error("a PLY property before any element")]
    PlyOrphanProperty,
    /// An ASCII PLY body that is not text.
    #[error("an ASCII PLY body must be text")]
    PlyBodyNotText,
    /// A PLY body shorter than its header says.
    #[error("the file ends before its elements do")]
    PlyTruncated,
    /// An ASCII PLY value that is not a number.
    #[error("a PLY value is not a number")]
    PlyNotANumber,
    /// A PLY face list with a negative or absurd length.
    #[error("a face has an impossible vertex count")]
    PlyFaceCount,
    /// A PLY face index that is negative or too large.
    #[error("a face index is out of range")]
    PlyIndexRange,
    /// A PLY face with fewer than three corners.
    #[error("a face needs at least three vertices")]
    PlyShortFace,
    /// A PLY vertex element without `x`, `y` and `z`.
    #[error("vertices need x, y and z properties")]
    PlyVertexXyz,
}

impl TriangleMesh {
    /// Reads a PLY or OBJ file (by extension).
    ///
    /// # Errors
    ///
    /// A read error, a format error naming the problem (unknown extension, malformed
    /// header or element, out-of-range index), or a mesh that cannot make a world
    /// (non-finite coordinate, index beyond the vertices, no triangles).
    pub fn load(path: &Path) -> Result<TriangleMesh, MeshError> {
        let bytes = std::fs::read(path).map_err(|source| MeshError::Read {
            path: path.to_owned(),
            source,
        })?;
        let extension = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        let mesh = match extension.as_deref() {
            Some("ply") => parse_ply(&bytes),
            Some("obj") => parse_obj(&bytes),
            _ => Err(MeshFormatError::Extension),
        }
        .map_err(|source| MeshError::Format {
            path: path.to_owned(),
            source,
        })?;
        mesh.checked().map_err(|source| MeshError::Invalid {
            path: path.to_owned(),
            source,
        })
    }
}

/// Parses an OBJ file.
fn parse_obj(bytes: &[u8]) -> Result<TriangleMesh, MeshFormatError> {
    let text = std::str::from_utf8(bytes).map_err(|_| MeshFormatError::ObjNotText)?;
    let mut mesh = TriangleMesh::default();
    for (n, row) in text.lines().enumerate() {
        let line = n + 1;
        let mut words = row.split_whitespace();
        match words.next() {
            Some("v") => {
                let c: Vec<f64> = words
                    .take(3)
                    .map(str::parse)
                    .collect::<Result<_, _>>()
                    .map_err(|_| MeshFormatError::ObjVertex { line })?;
                let [x, y, z] = c[..] else {
                    return Err(MeshFormatError::ObjVertex { line });
                };
                mesh.vertices.push(Point3::new(x, y, z));
            }
            Some("f") => {
                let count = mesh.vertices.len() as i64;
                let corners: Vec<u32> = words
                    .map(|w| {
                        // `v`, `v/vt`, `v//vn`, `v/vt/vn`; negative = from the end.
                        let i: i64 = w
                            .split('/')
                            .next()
                            .and_then(|s| s.parse().ok())
                            .ok_or(MeshFormatError::ObjIndex { line })?;
                        let i = if i < 0 { count + i } else { i - 1 };
                        u32::try_from(i).map_err(|_| MeshFormatError::ObjIndexRange { line })
                    })
                    .collect::<Result<_, _>>()?;
                if corners.len() < 3 {
                    return Err(MeshFormatError::ObjShortFace { line });
                }
                for k in 1..corners.len() - 1 {
                    mesh.triangles
                        .push([corners[0], corners[k], corners[k + 1]]);
                }
            }
            _ => {}
        }
    }
    Ok(mesh)
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn read_le(self, b: &[u8]) -> f64 {
        match self {
            Scalar::I8 => f64::from(b[0] as i8),
            Scalar::U8 => f64::from(b[0]),
            Scalar::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
            Scalar::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
            Scalar::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::F64 => f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]),
        }
    }
}

#[derive(Clone, Debug)]
enum Property {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

/// Reads values one at a time from the body, ASCII or binary little-endian.
enum Body<'a> {
    Ascii(std::str::SplitAsciiWhitespace<'a>),
    Binary(&'a [u8]),
}

impl Body<'_> {
    fn next(&mut self, scalar: Scalar) -> Result<f64, MeshFormatError> {
        match self {
            Body::Ascii(words) => words
                .next()
                .ok_or(MeshFormatError::PlyTruncated)?
                .parse()
                .map_err(|_| MeshFormatError::PlyNotANumber),
            Body::Binary(bytes) => {
                let n = scalar.size();
                if bytes.len() < n {
                    return Err(MeshFormatError::PlyTruncated);
                }
                let v = scalar.read_le(&bytes[..n]);
                *bytes = &bytes[n..];
                Ok(v)
            }
        }
    }
}

/// Parses a PLY file.
fn parse_ply(bytes: &[u8]) -> Result<TriangleMesh, MeshFormatError> {
    let end = find(bytes, b"end_header\n").ok_or(MeshFormatError::PlyNoEndHeader)?;
    let header =
        std::str::from_utf8(&bytes[..end]).map_err(|_| MeshFormatError::PlyHeaderNotText)?;
    let body = &bytes[end + b"end_header\n".len()..];
    let (binary, elements) = parse_ply_header(header)?;
    let mut body = if binary {
        Body::Binary(body)
    } else {
        Body::Ascii(
            std::str::from_utf8(body)
                .map_err(|_| MeshFormatError::PlyBodyNotText)?
                .split_ascii_whitespace(),
        )
    };
    let mut mesh = TriangleMesh::default();
    let mut grey = Vec::new();
    for element in &elements {
        // Guard against absurd counts before allocating.
        if element.count > 100_000_000 {
            return Err(MeshFormatError::PlyElementTooLarge(element.name.clone()));
        }
        for _ in 0..element.count {
            let mut xyz = [f64::NAN; 3];
            let mut rgb = [f64::NAN; 3];
            for property in &element.properties {
                match property {
                    Property::Scalar(name, s) => {
                        let v = body.next(*s)?;
                        match name.as_str() {
                            "x" => xyz[0] = v,
                            "y" => xyz[1] = v,
                            "z" => xyz[2] = v,
                            "red" => rgb[0] = v,
                            "green" => rgb[1] = v,
                            "blue" => rgb[2] = v,
                            _ => {}
                        }
                    }
                    Property::List(name, count, item) => {
                        let n = body.next(*count)?;
                        if !(0.0..=1e6).contains(&n) {
                            return Err(MeshFormatError::PlyFaceCount);
                        }
                        let mut ids = Vec::with_capacity(n as usize);
                        for _ in 0..n as usize {
                            let i = body.next(*item)?;
                            if !(i >= 0.0 && i <= f64::from(u32::MAX)) {
                                return Err(MeshFormatError::PlyIndexRange);
                            }
                            ids.push(i as u32);
                        }
                        if element.name == "face"
                            && (name == "vertex_indices" || name == "vertex_index")
                        {
                            if ids.len() < 3 {
                                return Err(MeshFormatError::PlyShortFace);
                            }
                            for k in 1..ids.len() - 1 {
                                mesh.triangles.push([ids[0], ids[k], ids[k + 1]]);
                            }
                        }
                    }
                }
            }
            if element.name == "vertex" {
                if xyz.iter().any(|v| v.is_nan()) {
                    return Err(MeshFormatError::PlyVertexXyz);
                }
                mesh.vertices.push(Point3::new(xyz[0], xyz[1], xyz[2]));
                if rgb.iter().all(|v| !v.is_nan()) {
                    grey.push((rgb[0] + rgb[1] + rgb[2]) / (3.0 * 255.0));
                }
            }
        }
    }
    if !grey.is_empty() && grey.len() == mesh.vertices.len() {
        mesh.grey = Some(grey);
    }
    Ok(mesh)
}

/// A PLY header: whether the body is binary (little-endian) or text, and its elements.
fn parse_ply_header(header: &str) -> Result<(bool, Vec<Element>), MeshFormatError> {
    let mut lines = header.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err(MeshFormatError::PlyNoMagic);
    }
    let mut binary = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["format", "ascii", _] => binary = Some(false),
            ["format", "binary_little_endian", _] => binary = Some(true),
            ["format", other, _] => return Err(MeshFormatError::PlyFormat((*other).to_owned())),
            ["element", name, count] => elements.push(Element {
                name: (*name).to_string(),
                count: count
                    .parse()
                    .map_err(|_| MeshFormatError::PlyElementCount((*name).to_owned()))?,
                properties: Vec::new(),
            }),
            ["property", "list", count, item, name] => {
                let (Some(c), Some(i)) = (Scalar::parse(count), Scalar::parse(item)) else {
                    return Err(MeshFormatError::PlyPropertyType(line.to_owned()));
                };
                elements
                    .last_mut()
                    .ok_or(MeshFormatError::PlyOrphanProperty)?
                    .properties
                    .push(Property::List((*name).to_string(), c, i));
            }
            ["property", kind, name] => {
                let s = Scalar::parse(kind)
                    .ok_or_else(|| MeshFormatError::PlyPropertyType(line.to_owned()))?;
                elements
                    .last_mut()
                    .ok_or(MeshFormatError::PlyOrphanProperty)?
                    .properties
                    .push(Property::Scalar((*name).to_string(), s));
            }
            _ => {}
        }
    }
    let binary = binary.ok_or(MeshFormatError::PlyNoFormat)?;
    Ok((binary, elements))
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TETRA_OBJ: &str = "# a tetrahedron\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2/1 3/1 4/1\n";

    fn tetra_ply_ascii() -> String {
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0 255 255 255\n1 0 0 0 0 0\n0 1 0 0 0 0\n0 0 1 0 0 0\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n".into()
    }

    fn tetra_ply_binary() -> Vec<u8> {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nelement face 4\nproperty list uchar uint vertex_indices\nend_header\n".to_vec();
        for v in [
            [0.0f64, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ] {
            for c in v {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
        for f in [[0u32, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] {
            b.push(3);
            for i in f {
                b.extend_from_slice(&i.to_le_bytes());
            }
        }
        b
    }

    #[test]
    fn the_three_encodings_of_one_mesh_agree() {
        let obj = parse_obj(TETRA_OBJ.as_bytes()).expect("obj");
        let ascii = parse_ply(tetra_ply_ascii().as_bytes()).expect("ascii ply");
        let binary = parse_ply(&tetra_ply_binary()).expect("binary ply");
        assert_eq!(obj.vertices, ascii.vertices);
        assert_eq!(ascii.vertices, binary.vertices);
        assert_eq!(ascii.triangles, binary.triangles);
        assert_eq!(obj.triangles.len(), 4);
        assert_eq!(ascii.grey.as_deref(), Some(&[1.0, 0.0, 0.0, 0.0][..]));
        assert!(obj.checked().is_ok());
    }

    #[test]
    fn load_names_the_file_and_gives_the_problem_as_its_source() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("bad.obj");
        std::fs::write(&path, "v 0 0\n").expect("write");
        let error = TriangleMesh::load(&path).expect_err("malformed");
        assert!(matches!(
            &error,
            MeshError::Format {
                source: MeshFormatError::ObjVertex { line: 1 },
                ..
            }
        ));
        let chain = troupe_core::ErrorChain(&error).to_string();
        assert!(
            chain.ends_with("bad.obj` cannot be parsed: line 1: a vertex needs three numbers"),
            "{chain}"
        );
        std::fs::write(&path, "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n").expect("write");
        let error = TriangleMesh::load(&path).expect_err("degenerate");
        assert!(matches!(
            error,
            MeshError::Invalid {
                source: InvalidMesh::NoTriangles,
                ..
            }
        ));
    }

    #[test]
    fn malformed_meshes_are_errors_not_panics() {
        let mut truncated = tetra_ply_binary();
        truncated.truncate(truncated.len() - 3);
        assert_eq!(parse_ply(&truncated), Err(MeshFormatError::PlyTruncated));
        assert_eq!(parse_ply(b"plx\n"), Err(MeshFormatError::PlyNoEndHeader));
        assert_eq!(
            parse_obj(b"v 0 0\n"),
            Err(MeshFormatError::ObjVertex { line: 1 })
        );
        assert_eq!(
            parse_obj(b"v 0 0 0\nf 1 2\n"),
            Err(MeshFormatError::ObjShortFace { line: 2 })
        );
        let out_of_range = parse_obj(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").expect("parses");
        assert!(matches!(
            out_of_range.checked(),
            Err(InvalidMesh::VertexBeyond { vertices: 3, .. })
        ));
        // Random bytes never panic.
        for k in 0..500u64 {
            let junk: Vec<u8> = (0..64)
                .map(|i| (super::super::noise::mix64(k * 64 + i) & 0xff) as u8)
                .collect();
            let mut ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
            ply.extend_from_slice(&junk);
            let _ = parse_ply(&ply).map(TriangleMesh::checked);
            let _ = parse_obj(&junk);
        }
    }
}
