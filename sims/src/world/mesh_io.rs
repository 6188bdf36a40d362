//! Minimal readers for triangle meshes: PLY (ASCII and binary little-endian; vertex
//! `x y z` as float or double, optional `red green blue`, faces as a list of vertex
//! indices) and Wavefront OBJ (`v` and `f` lines; polygons are fanned into triangles),
//! giving a [`TriangleMesh`] ([`TriangleMesh::load`]).

use std::path::{Path, PathBuf};

use nalgebra::Point3;

use super::triangle_mesh::TriangleMesh;

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
    /// The file is not a mesh we can read.
    #[error("mesh file `{path}`: {reason}")]
    Format {
        /// File.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

impl TriangleMesh {
    /// Reads a PLY or OBJ file (by extension).
    ///
    /// # Errors
    ///
    /// A read error, or a format error naming the problem (unknown extension,
    /// malformed header or element, out-of-range index, non-finite coordinate, no
    /// triangles).
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
            _ => Err("the file name must end in .ply or .obj".to_string()),
        }
        .and_then(|m| m.checked())
        .map_err(|reason| MeshError::Format {
            path: path.to_owned(),
            reason,
        })?;
        Ok(mesh)
    }
}

/// Parses an OBJ file.
fn parse_obj(bytes: &[u8]) -> Result<TriangleMesh, String> {
    let text = std::str::from_utf8(bytes).map_err(|_| "an OBJ file must be UTF-8 text")?;
    let mut mesh = TriangleMesh::default();
    for (n, line) in text.lines().enumerate() {
        let at = |what: &str| format!("line {}: {what}", n + 1);
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let c: Vec<f64> = words
                    .take(3)
                    .map(str::parse)
                    .collect::<Result<_, _>>()
                    .map_err(|_| at("a vertex needs three numbers"))?;
                let [x, y, z] = c[..] else {
                    return Err(at("a vertex needs three numbers"));
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
                            .ok_or_else(|| at("a face index is not a number"))?;
                        let i = if i < 0 { count + i } else { i - 1 };
                        u32::try_from(i).map_err(|_| at("a face index is out of range"))
                    })
                    .collect::<Result<_, _>>()?;
                if corners.len() < 3 {
                    return Err(at("a face needs at least three vertices"));
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
    fn next(&mut self, scalar: Scalar) -> Result<f64, String> {
        match self {
            Body::Ascii(words) => words
                .next()
                .ok_or("the file ends before its elements do")?
                .parse()
                .map_err(|_| "a value is not a number".to_string()),
            Body::Binary(bytes) => {
                let n = scalar.size();
                if bytes.len() < n {
                    return Err("the file ends before its elements do".into());
                }
                let v = scalar.read_le(&bytes[..n]);
                *bytes = &bytes[n..];
                Ok(v)
            }
        }
    }
}

/// Parses a PLY file.
fn parse_ply(bytes: &[u8]) -> Result<TriangleMesh, String> {
    let end = find(bytes, b"end_header\n").ok_or("not a PLY file: no `end_header` line")?;
    let header =
        std::str::from_utf8(&bytes[..end]).map_err(|_| "the PLY header must be ASCII text")?;
    let body = &bytes[end + b"end_header\n".len()..];
    let mut lines = header.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err("not a PLY file: it must start with `ply`".into());
    }
    let mut binary = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["format", "ascii", _] => binary = Some(false),
            ["format", "binary_little_endian", _] => binary = Some(true),
            ["format", other, _] => return Err(format!("PLY format `{other}` is not supported")),
            ["element", name, count] => elements.push(Element {
                name: (*name).to_string(),
                count: count
                    .parse()
                    .map_err(|_| format!("bad count for element {name}"))?,
                properties: Vec::new(),
            }),
            ["property", "list", count, item, name] => {
                let (Some(c), Some(i)) = (Scalar::parse(count), Scalar::parse(item)) else {
                    return Err(format!("unknown list types in `{line}`"));
                };
                elements
                    .last_mut()
                    .ok_or("a property before any element")?
                    .properties
                    .push(Property::List((*name).to_string(), c, i));
            }
            ["property", kind, name] => {
                let s = Scalar::parse(kind).ok_or_else(|| format!("unknown type in `{line}`"))?;
                elements
                    .last_mut()
                    .ok_or("a property before any element")?
                    .properties
                    .push(Property::Scalar((*name).to_string(), s));
            }
            _ => {}
        }
    }
    let binary = binary.ok_or("the PLY header has no `format` line")?;
    let mut body = if binary {
        Body::Binary(body)
    } else {
        Body::Ascii(
            std::str::from_utf8(body)
                .map_err(|_| "an ASCII PLY body must be text")?
                .split_ascii_whitespace(),
        )
    };
    let mut mesh = TriangleMesh::default();
    let mut grey = Vec::new();
    for element in &elements {
        // Guard against absurd counts before allocating.
        if element.count > 100_000_000 {
            return Err(format!("element {} is too large", element.name));
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
                            return Err("a face has an impossible vertex count".into());
                        }
                        let mut ids = Vec::with_capacity(n as usize);
                        for _ in 0..n as usize {
                            let i = body.next(*item)?;
                            if !(i >= 0.0 && i <= f64::from(u32::MAX)) {
                                return Err("a face index is out of range".into());
                            }
                            ids.push(i as u32);
                        }
                        if element.name == "face"
                            && (name == "vertex_indices" || name == "vertex_index")
                        {
                            if ids.len() < 3 {
                                return Err("a face needs at least three vertices".into());
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
                    return Err("vertices need x, y and z properties".into());
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
    fn malformed_meshes_are_errors_not_panics() {
        let mut truncated = tetra_ply_binary();
        truncated.truncate(truncated.len() - 3);
        assert!(parse_ply(&truncated).unwrap_err().contains("ends"));
        assert!(parse_ply(b"plx\n").is_err());
        assert!(parse_obj(b"v 0 0\n").unwrap_err().contains("line 1"));
        assert!(
            parse_obj(b"v 0 0 0\nf 1 2\n")
                .unwrap_err()
                .contains("three")
        );
        let out_of_range = parse_obj(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").expect("parses");
        assert!(out_of_range.checked().unwrap_err().contains("beyond"));
        // Random bytes never panic.
        for k in 0..500u64 {
            let junk: Vec<u8> = (0..64)
                .map(|i| (super::super::noise::mix64(k * 64 + i) & 0xff) as u8)
                .collect();
            let mut ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
            ply.extend_from_slice(&junk);
            let _ = parse_ply(&ply).and_then(TriangleMesh::checked);
            let _ = parse_obj(&junk);
        }
    }
}
