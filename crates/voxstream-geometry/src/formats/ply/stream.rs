//! Binary PLY point files read a chunk at a time, for particle sets larger than memory.

use std::path::Path;

use super::body::{BinaryBody, Body, Plan, Role};
use super::header::{parse_header, Encoding, Kind, Scalar};
use crate::error::GeometryError;
use crate::formats::words::shown;
use crate::particles::RawParticles;

/// The most header bytes [`PlyPointStream::open`] reads looking for `end_header`.
const STREAM_HEADER_BYTES: u64 = 1 << 20;

/// About this many body bytes are read and decoded at a time by [`PlyPointStream::for_each_chunk`].
const STREAM_CHUNK_BYTES: usize = 4 << 20;

/// A binary PLY point file read in chunks, for particle sets larger than memory: only its header is held, and each
/// pass over its vertices reads them a few megabytes at a time.
///
/// Takes what [`parse`] reads as particles, in binary bodies whose vertex element has only scalar properties and
/// whose elements before it (if any) too; anything else is refused with a line saying so.
#[derive(Clone, Debug)]
pub struct PlyPointStream {
    path: std::path::PathBuf,
    big: bool,
    /// Byte offset of the first vertex.
    start: u64,
    /// The vertex element's properties: type and role.
    layout: Vec<(Scalar, Role)>,
    record_bytes: usize,
    count: u64,
    pub(super) value_name: String,
}

impl PlyPointStream {
    /// Reads and checks the header of `path`, and that the file holds every vertex it announces.
    pub fn open(path: &Path) -> Result<PlyPointStream, GeometryError> {
        use std::io::Read;
        let io = |error| GeometryError::Io { path: path.to_path_buf(), error };
        let unsupported = |message: String| GeometryError::Unsupported { path: path.to_path_buf(), message };
        let file = std::fs::File::open(path).map_err(io)?;
        let file_len = file.metadata().map_err(io)?.len();
        let mut head = Vec::new();
        file.take(STREAM_HEADER_BYTES).read_to_end(&mut head).map_err(io)?;
        let header = parse_header(&head, path)?;
        let plan = Plan::new(&header, path)?;
        if plan.mesh {
            return Err(unsupported("the file holds faces (a mesh); only point files are read out of core".into()));
        }
        let big = match header.encoding {
            Encoding::Ascii => {
                return Err(unsupported(
                    "an ASCII PLY body is read whole; to read it out of core, write it as binary_little_endian".into(),
                ))
            }
            Encoding::BinaryLittle => false,
            Encoding::BinaryBig => true,
        };
        let mut start = header.body_start as u64;
        let mut vertex = None;
        for (element, roles) in header.elements.iter().zip(&plan.roles) {
            let mut record = 0u64;
            let mut layout = Vec::new();
            for (property, role) in element.properties.iter().zip(roles) {
                match property.kind {
                    Kind::Scalar(ty) => {
                        record += ty.size();
                        layout.push((ty, *role));
                    }
                    Kind::List { .. } if element.count == 0 => {}
                    Kind::List { .. } => {
                        return Err(unsupported(format!(
                            "the '{}' element's list property '{}' gives its records varying sizes; out of core reads \
                             fixed-size vertex records",
                            shown(&element.name),
                            shown(&property.name)
                        )))
                    }
                }
            }
            if element.name == "vertex" {
                vertex = Some((element, layout, record));
                break;
            }
            start = element.count.checked_mul(record).and_then(|n| n.checked_add(start)).unwrap_or(u64::MAX);
        }
        let Some((element, layout, record)) = vertex else {
            return Err(GeometryError::format(path, None, "the header declares no 'vertex' element"));
        };
        let end = element.count.checked_mul(record).and_then(|n| n.checked_add(start)).unwrap_or(u64::MAX);
        if end > file_len {
            return Err(GeometryError::format(
                path,
                Some(element.line),
                format!(
                    "header announces {} vertices ({record} bytes each, from byte {start}) but the file has {file_len} bytes",
                    element.count
                ),
            ));
        }
        Ok(PlyPointStream {
            path: path.to_path_buf(),
            big,
            start,
            record_bytes: record as usize,
            layout,
            count: element.count,
            value_name: plan.value_name,
        })
    }

    /// Number of particles.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The name of the value property (`""` if none).
    pub fn value_name(&self) -> &str {
        &self.value_name
    }

    /// Whether the vertices carry a smoothing length, a mass and a value.
    pub fn columns(&self) -> [bool; 3] {
        [Role::Smoothing, Role::Mass, Role::Value].map(|r| self.layout.iter().any(|(_, role)| *role == r))
    }

    /// Calls `f` with consecutive runs of the particles, each with the index of its first, in file order; stops at
    /// the first error, from the file or from `f`.
    pub fn for_each_chunk(
        &self,
        f: &mut dyn FnMut(u64, &RawParticles) -> Result<(), GeometryError>,
    ) -> Result<(), GeometryError> {
        use std::io::{Read, Seek, SeekFrom};
        let io = |error| GeometryError::Io { path: self.path.clone(), error };
        let mut file = std::fs::File::open(&self.path).map_err(io)?;
        file.seek(SeekFrom::Start(self.start)).map_err(io)?;
        let mut reader = std::io::BufReader::new(file);
        let per_chunk = (STREAM_CHUNK_BYTES / self.record_bytes.max(1)).max(1) as u64;
        let [smoothing, masses, values] = self.columns();
        let mut bytes = Vec::new();
        let mut chunk = RawParticles { value_name: self.value_name.clone(), ..RawParticles::default() };
        let mut first = 0u64;
        while first < self.count {
            let n = per_chunk.min(self.count - first) as usize;
            bytes.resize(n * self.record_bytes, 0);
            reader.read_exact(&mut bytes).map_err(|error| {
                GeometryError::format(&self.path, None, format!("the vertices end early, after {first} ({error})"))
            })?;
            chunk.positions.clear();
            chunk.smoothing.clear();
            chunk.masses.clear();
            chunk.values.clear();
            let mut body = BinaryBody { bytes: &bytes, pos: 0, big: self.big };
            for _ in 0..n {
                let mut xyz = [0.0f64; 3];
                for &(ty, role) in &self.layout {
                    // The buffer holds n whole records: a read cannot miss.
                    let v = body.scalar(ty).unwrap_or(0.0);
                    match role {
                        Role::X => xyz[0] = v,
                        Role::Y => xyz[1] = v,
                        Role::Z => xyz[2] = v,
                        Role::Smoothing if smoothing => chunk.smoothing.push(v as f32),
                        Role::Mass if masses => chunk.masses.push(v as f32),
                        Role::Value if values => chunk.values.push(v as f32),
                        _ => {}
                    }
                }
                chunk.positions.push(xyz);
            }
            f(first, &chunk)?;
            first += n as u64;
        }
        Ok(())
    }
}

/// The points a PLY point file (`.ply`, or `.ply.gz` decompressed only as far as its header) declares, read from its
/// header alone, before anything is allocated for them: `None` for a mesh, an unreadable file or a header this
/// reader refuses (reading the file then names the problem).
pub fn declared_points(path: &Path) -> Option<u64> {
    use std::io::Read;
    let file = std::fs::File::open(path).ok()?;
    let file_len = file.metadata().ok()?.len();
    let gz = path.to_string_lossy().to_lowercase().ends_with(".gz");
    let mut head = Vec::new();
    if gz {
        let decoder = flate2::read::MultiGzDecoder::new(std::io::BufReader::new(file));
        // A header shorter than the limit ends the read early; a gzip error leaves what was decoded before it.
        let _ = decoder.take(STREAM_HEADER_BYTES).read_to_end(&mut head);
    } else {
        file.take(STREAM_HEADER_BYTES).read_to_end(&mut head).ok()?;
    }
    let header = parse_header(&head, path).ok()?;
    let plan = Plan::new(&header, path).ok()?;
    if plan.mesh {
        return None;
    }
    let vertex = header.elements.iter().find(|e| e.name == "vertex")?;
    // An uncompressed file too short for its count is the reader's to name (a truncated body, not a budget).
    let least_bytes: u64 = vertex
        .properties
        .iter()
        .map(|p| match (&header.encoding, &p.kind) {
            (Encoding::Ascii, _) => 2,
            (_, Kind::Scalar(ty)) => ty.size(),
            (_, Kind::List { .. }) => 1,
        })
        .sum();
    let body = file_len.saturating_sub(header.body_start as u64);
    if !gz && vertex.count.saturating_mul(least_bytes) > body {
        return None;
    }
    Some(vertex.count)
}
