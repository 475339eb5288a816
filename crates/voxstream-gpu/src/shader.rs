//! The ray caster's WGSL: one compute shader, kept in files along the CPU traversal's seams (`src/shader/`) and
//! joined here into one module (WGSL has no imports; module-scope declarations may come in any order).
//!
//! The shared records of `voxstream-layout` (`layout.wgsl`, checked against the Rust records by its mirror test)
//! come first, then the brick atlas's declaration and reads for the chosen filtering ([`BrickFiltering::wgsl`]), then
//! the files of [`RAY_CASTER_FILES`]: the bindings and a ray's state, its feedback, brick reads, the
//! emission–absorption integrand, level of detail and the descent's geometry, level blending, one trilinear cell's
//! cubic, the isosurfaces integrand, the segment walk (`march`) and the entry point.
//!
//! Each file is a stage of the CPU traversal and names its twin there. Two tests guard the seams: the constants and
//! bindings shared with Rust (`tests/shader_interface.rs`, against [`crate::shader_interface`] and the CPU's
//! constants), and a file's functions against the CPU's, run on the GPU alone (`tests/cell_cubic_twin/`:
//! `cell_cubic.wgsl`, which reads no binding so that it compiles on its own, against `CellCubic`).

use crate::brick_filtering::BrickFiltering;

/// The records shared with the Rust side (`voxstream_layout`).
const LAYOUT_WGSL: &str = include_str!("../../voxstream-layout/src/layout.wgsl");

/// The shader's files, by name, in the order they are joined.
pub const RAY_CASTER_FILES: [(&str, &str); 10] = [
    ("bindings.wgsl", include_str!("shader/bindings.wgsl")),
    ("feedback.wgsl", include_str!("shader/feedback.wgsl")),
    ("bricks.wgsl", include_str!("shader/bricks.wgsl")),
    ("emission_absorption.wgsl", include_str!("shader/emission_absorption.wgsl")),
    ("descent.wgsl", include_str!("shader/descent.wgsl")),
    ("blending.wgsl", include_str!("shader/blending.wgsl")),
    ("cell_cubic.wgsl", include_str!("shader/cell_cubic.wgsl")),
    ("isosurfaces.wgsl", include_str!("shader/isosurfaces.wgsl")),
    ("march.wgsl", include_str!("shader/march.wgsl")),
    ("main.wgsl", include_str!("shader/main.wgsl")),
];

/// The whole shader for bricks filtered as `filtering` says.
pub fn ray_caster_source(filtering: BrickFiltering) -> String {
    let mut source = String::from(LAYOUT_WGSL);
    source.push_str(filtering.wgsl());
    for (_, text) in RAY_CASTER_FILES {
        source.push_str(text);
    }
    source
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every file opens with a comment saying what it holds, and every function is defined in exactly one file
    /// (a name defined twice would make the joined module invalid; one left in no file would not be found).
    #[test]
    fn each_file_says_what_it_holds_and_functions_are_defined_once() {
        let mut defined: Vec<(&str, &str)> = Vec::new();
        for (file, text) in RAY_CASTER_FILES {
            assert!(text.starts_with("// "), "{file} opens with what it is for");
            for line in text.lines() {
                if let Some(rest) = line.strip_prefix("fn ") {
                    let name = rest.split('(').next().unwrap();
                    assert!(!defined.iter().any(|(_, n)| *n == name), "{name} defined twice ({file})");
                    defined.push((file, name));
                }
            }
        }
        assert!(defined.iter().any(|&(file, name)| file == "main.wgsl" && name == "main"));
        assert!(defined.iter().any(|&(file, name)| file == "march.wgsl" && name == "march"));
        assert!(defined.len() > 50, "{} functions", defined.len());
    }

    /// `cell_cubic.wgsl` is valid WGSL on its own: it reads no binding and calls nothing from the other files, so
    /// its twin test (`tests/cell_cubic_twin/`) can run it alone on the GPU. Checked here without a GPU.
    #[test]
    fn the_cell_solver_stands_alone() {
        let (_, text) = RAY_CASTER_FILES.iter().find(|(name, _)| *name == "cell_cubic.wgsl").expect("the file");
        let module = naga::front::wgsl::parse_str(text).unwrap_or_else(|e| panic!("{}", e.emit_to_string(text)));
        let mut validator =
            naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all());
        if let Err(error) = validator.validate(&module) {
            panic!("{}", error.emit_to_string(text));
        }
        assert!(module.global_variables.is_empty(), "cell_cubic.wgsl declares no binding or global");
        for name in ["cell_cubic", "cubic_pieces", "cubic_crossings", "cubic_refine"] {
            assert!(module.functions.iter().any(|(_, f)| f.name.as_deref() == Some(name)), "{name}");
        }
    }
}
