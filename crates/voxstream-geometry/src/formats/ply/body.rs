//! Reading a PLY body: the plan (which property becomes a coordinate, a smoothing length, a mass, the value or the
//! face's vertex indices), the ASCII and binary bodies' values, and the mesh's faces or the point elements read into
//! triangles or particles.

use std::path::Path;

use super::header::{Header, Kind, Property, Scalar};
use crate::error::GeometryError;
use crate::formats::polygon::triangulate;
use crate::formats::words::shown;
use crate::formats::RawGeometry;
use crate::particles::RawParticles;
use crate::triangle_mesh::RawMesh;

/// What a property becomes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Role {
    X,
    Y,
    Z,
    Smoothing,
    Mass,
    Value,
    /// The face element's vertex index list.
    Indices,
    Skip,
}

/// The reading plan: whether the file is a mesh, and each element's properties' roles.
pub(super) struct Plan {
    pub(super) mesh: bool,
    pub(super) roles: Vec<Vec<Role>>,
    pub(super) value_name: String,
}

impl Plan {
    pub(super) fn new(header: &Header, path: &Path) -> Result<Plan, GeometryError> {
        let find = |name: &str| header.elements.iter().find(|e| e.name == name);
        let vertex = find("vertex")
            .ok_or_else(|| GeometryError::format(path, None, "the header declares no 'vertex' element"))?;
        let face = find("face").filter(|f| f.count > 0);
        let mesh = face.is_some();
        if !mesh {
            if let Some(strips) = find("tristrips").filter(|s| s.count > 0) {
                return Err(GeometryError::Unsupported {
                    path: path.to_path_buf(),
                    message: format!("{} triangle strips ('tristrips'): only 'face' lists are read", strips.count),
                });
            }
        }
        for axis in ["x", "y", "z"] {
            if !vertex.properties.iter().any(|p| p.name == axis && matches!(p.kind, Kind::Scalar(_))) {
                return Err(GeometryError::format(
                    path,
                    Some(vertex.line),
                    format!("the vertex element has no scalar '{axis}' property"),
                ));
            }
        }
        if let Some(face) = face {
            let lists = |p: &&Property| matches!(p.kind, Kind::List { .. });
            if !face
                .properties
                .iter()
                .filter(lists)
                .any(|p| matches!(p.name.as_str(), "vertex_indices" | "vertex_index"))
            {
                return Err(GeometryError::format(
                    path,
                    Some(face.line),
                    "the face element has no 'vertex_indices' (or 'vertex_index') list",
                ));
            }
        }
        let mut value_name = String::new();
        let roles = header
            .elements
            .iter()
            .map(|element| {
                let mut taken = Vec::new();
                element
                    .properties
                    .iter()
                    .map(|p| {
                        let role = match (element.name.as_str(), p.kind) {
                            ("vertex", Kind::Scalar(_)) => match p.name.as_str() {
                                "x" => Role::X,
                                "y" => Role::Y,
                                "z" => Role::Z,
                                _ if mesh => Role::Skip,
                                "radius" | "h" | "smoothing_length" | "hsml" => Role::Smoothing,
                                "mass" | "m" => Role::Mass,
                                "nx" | "ny" | "nz" | "red" | "green" | "blue" | "alpha" | "u" | "v" | "s" | "t" => {
                                    Role::Skip
                                }
                                name => {
                                    if value_name.is_empty() && !taken.contains(&Role::Value) {
                                        value_name = name.to_string();
                                    }
                                    Role::Value
                                }
                            },
                            ("face", Kind::List { .. })
                                if matches!(p.name.as_str(), "vertex_indices" | "vertex_index") =>
                            {
                                Role::Indices
                            }
                            _ => Role::Skip,
                        };
                        // Only the first property of each role is read (a repeated `x`, a second smoothing name …).
                        if role != Role::Skip && taken.contains(&role) {
                            return Role::Skip;
                        }
                        taken.push(role);
                        role
                    })
                    .collect()
            })
            .collect();
        Ok(Plan { mesh, roles, value_name })
    }

    pub(super) fn vertex_has(&self, header: &Header, role: Role) -> bool {
        header.elements.iter().zip(&self.roles).any(|(e, roles)| e.name == "vertex" && roles.contains(&role))
    }
}

/// Why a value could not be read.
pub(super) enum Miss {
    /// The body ended.
    End,
    /// An ASCII word that is not a number.
    Bad(String),
}

/// The values of a body, in order.
pub(super) trait Body {
    /// The next value, of type `ty`.
    fn scalar(&mut self, ty: Scalar) -> Result<f64, Miss>;
    /// Reads past `count` values of type `ty`.
    fn skip(&mut self, ty: Scalar, count: u64) -> Result<(), Miss>;
    /// The line being read (ASCII bodies), for errors.
    fn line(&self) -> Option<u64>;
}

/// An ASCII body: values are words separated by white space.
pub(super) struct AsciiBody<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) pos: usize,
    pub(super) line: u64,
}

impl<'a> AsciiBody<'a> {
    pub(super) fn word(&mut self) -> Option<&'a [u8]> {
        while let Some(&b) = self.bytes.get(self.pos).filter(|b| b.is_ascii_whitespace()) {
            self.line += u64::from(b == b'\n');
            self.pos += 1;
        }
        let start = self.pos;
        while self.bytes.get(self.pos).is_some_and(|b| !b.is_ascii_whitespace()) {
            self.pos += 1;
        }
        self.bytes.get(start..self.pos).filter(|w| !w.is_empty())
    }
}

impl Body for AsciiBody<'_> {
    fn scalar(&mut self, _ty: Scalar) -> Result<f64, Miss> {
        let word = self.word().ok_or(Miss::End)?;
        std::str::from_utf8(word)
            .ok()
            .and_then(|w| w.parse::<f64>().ok())
            .ok_or_else(|| Miss::Bad(shown(&String::from_utf8_lossy(word))))
    }

    fn skip(&mut self, _ty: Scalar, count: u64) -> Result<(), Miss> {
        for _ in 0..count {
            self.word().ok_or(Miss::End)?;
        }
        Ok(())
    }

    fn line(&self) -> Option<u64> {
        Some(self.line)
    }
}

/// A binary body, little- or big-endian.
pub(super) struct BinaryBody<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) pos: usize,
    pub(super) big: bool,
}

impl BinaryBody<'_> {
    pub(super) fn take<const N: usize>(&mut self) -> Result<[u8; N], Miss> {
        let chunk = self.bytes.get(self.pos..).and_then(|rest| rest.first_chunk::<N>()).ok_or(Miss::End)?;
        self.pos += N;
        Ok(*chunk)
    }
}

impl Body for BinaryBody<'_> {
    fn scalar(&mut self, ty: Scalar) -> Result<f64, Miss> {
        macro_rules! read {
            ($t:ty, $n:literal) => {{
                let b = self.take::<$n>()?;
                f64::from(if self.big { <$t>::from_be_bytes(b) } else { <$t>::from_le_bytes(b) })
            }};
        }
        Ok(match ty {
            Scalar::I8 => read!(i8, 1),
            Scalar::U8 => read!(u8, 1),
            Scalar::I16 => read!(i16, 2),
            Scalar::U16 => read!(u16, 2),
            Scalar::I32 => read!(i32, 4),
            Scalar::U32 => read!(u32, 4),
            Scalar::F32 => read!(f32, 4),
            Scalar::F64 => read!(f64, 8),
        })
    }

    fn skip(&mut self, ty: Scalar, count: u64) -> Result<(), Miss> {
        let left = self.bytes.len().saturating_sub(self.pos) as u64;
        match count.checked_mul(ty.size()) {
            Some(n) if n <= left => {
                self.pos += n as usize;
                Ok(())
            }
            _ => Err(Miss::End),
        }
    }

    fn line(&self) -> Option<u64> {
        None
    }
}

/// Reads every element of the body as `plan` says.
pub(super) fn read_body(
    body: &mut impl Body,
    body_len: usize,
    header: &Header,
    plan: Plan,
    path: &Path,
) -> Result<RawGeometry, GeometryError> {
    let vertex_count = header.elements.iter().find(|e| e.name == "vertex").map_or(0, |e| e.count) as usize;
    let face_count = header.elements.iter().find(|e| e.name == "face").map_or(0, |e| e.count) as usize;
    let column = |role| if !plan.mesh && plan.vertex_has(header, role) { vertex_count } else { 0 };
    let mut mesh = RawMesh {
        positions: Vec::with_capacity(if plan.mesh { vertex_count } else { 0 }),
        // A valid face takes at least 4 bytes (a length and 3 one-byte indices), or 4 words.
        triangles: Vec::with_capacity(face_count.min(body_len / 4)),
    };
    // One face's corners (each read from the body: bounded by the file).
    let mut corners: Vec<u32> = Vec::new();
    let mut particles = RawParticles {
        positions: Vec::with_capacity(if plan.mesh { 0 } else { vertex_count }),
        smoothing: Vec::with_capacity(column(Role::Smoothing)),
        masses: Vec::with_capacity(column(Role::Mass)),
        values: Vec::with_capacity(column(Role::Value)),
        value_name: plan.value_name.clone(),
    };
    for (element, roles) in header.elements.iter().zip(&plan.roles) {
        if element.properties.is_empty() {
            continue;
        }
        for index in 0..element.count {
            let fail = |body: &dyn Body, message: String| GeometryError::format(path, body.line(), message);
            let missed = |body: &dyn Body, miss: Miss| match miss {
                Miss::End => fail(
                    body,
                    format!("header announces {} {} but the file ends after {index}", element.count, element.plural()),
                ),
                Miss::Bad(word) => fail(body, format!("{} {index}: '{word}' is not a number", element.singular())),
            };
            let mut xyz = [0.0f64; 3];
            for (property, role) in element.properties.iter().zip(roles) {
                match property.kind {
                    Kind::Scalar(ty) => {
                        let v = body.scalar(ty).map_err(|m| missed(body, m))?;
                        match role {
                            Role::X => xyz[0] = v,
                            Role::Y => xyz[1] = v,
                            Role::Z => xyz[2] = v,
                            Role::Smoothing => particles.smoothing.push(v as f32),
                            Role::Mass => particles.masses.push(v as f32),
                            Role::Value => particles.values.push(v as f32),
                            Role::Indices | Role::Skip => {}
                        }
                    }
                    Kind::List { count, item } => {
                        let length = body.scalar(count).map_err(|m| missed(body, m))?;
                        if !(length >= 0.0 && length.fract() == 0.0) {
                            return Err(fail(
                                body,
                                format!("{} {index}: list length {length} is not a count", element.singular()),
                            ));
                        }
                        let length = length as u64;
                        if *role != Role::Indices {
                            body.skip(item, length).map_err(|m| missed(body, m))?;
                            continue;
                        }
                        if length < 3 {
                            return Err(fail(
                                body,
                                format!("face {index} uses {length} vertices: a face needs at least 3"),
                            ));
                        }
                        corners.clear();
                        for _ in 0..length {
                            let v = body.scalar(item).map_err(|m| missed(body, m))?;
                            corners.push(
                                vertex_index(v).map_err(|problem| {
                                    fail(body, format!("face {index} uses vertex {v}: {problem}"))
                                })?,
                            );
                        }
                        triangulate(&corners, &mut mesh.triangles);
                    }
                }
            }
            if element.name == "vertex" {
                if plan.mesh {
                    mesh.positions.push(xyz.map(|c| c as f32));
                } else {
                    particles.positions.push(xyz);
                }
            }
        }
    }
    Ok(if plan.mesh { RawGeometry::Mesh(mesh) } else { RawGeometry::Particles(particles) })
}

/// A vertex index read as a number, or what is wrong with it.
pub(super) fn vertex_index(v: f64) -> Result<u32, &'static str> {
    if v.fract() != 0.0 {
        Err("vertex indices are whole numbers")
    } else if v < 0.0 {
        Err("vertex indices cannot be negative")
    } else if v > f64::from(u32::MAX) {
        Err("voxstream reads at most 2^32 vertices")
    } else {
        Ok(v as u32)
    }
}
