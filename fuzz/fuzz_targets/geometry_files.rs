//! Every mesh and particle file reader of voxstream-geometry: the first byte picks a file-name ending (index modulo
//! the number of endings), the rest is the file, parsed as `read_geometry` would; what parses is then validated as
//! the renderer would (`TriangleMesh::new` for meshes, `ParticleSet::new` for particles).
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use voxstream_geometry::formats::{parse_geometry, RawGeometry, GEOMETRY_FILE_ENDINGS};
use voxstream_geometry::{ParticleSet, TriangleMesh};

fuzz_target!(|data: &[u8]| {
    let Some((&selector, file)) = data.split_first() else { return };
    let ending = GEOMETRY_FILE_ENDINGS[selector as usize % GEOMETRY_FILE_ENDINGS.len()];
    let path = format!("fuzz{ending}");
    match parse_geometry(file, ending, Path::new(&path)) {
        Ok(RawGeometry::Mesh(raw)) => {
            if let Ok(mesh) = TriangleMesh::new(raw) {
                let _ = mesh.bounds();
            }
        }
        Ok(RawGeometry::Particles(raw)) => {
            if let Ok(particles) = ParticleSet::new(raw) {
                let _ = particles.bounds();
            }
        }
        Err(_) => {}
    }
});
