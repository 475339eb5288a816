//! `src/layout.wgsl` mirrors the Rust records: same structs, same fields in the same order, same offsets and sizes,
//! same constants.
//!
//! The WGSL is read with a small parser of its own rather than `naga`: the mirror only uses scalar fields
//! (`u32`, `i32`, `f32`, their atomics) and `const` scalars, which a few lines parse exactly, while `naga` would add a
//! large dependency tree to every build of the workspace for this one test. The offsets follow WGSL's layout rules
//! for scalars (size 4, alignment 4); a field of any other type fails the test, so the parser has to be extended
//! (with those rules) before the mirror can use it.

use std::collections::BTreeMap;
use std::mem::{offset_of, size_of};

use voxstream_layout::*;

const WGSL: &str = include_str!("../src/layout.wgsl");

/// One struct as parsed from WGSL: field names with their offsets, and the struct's size.
#[derive(Debug, PartialEq)]
struct StructLayout {
    fields: Vec<(String, usize)>,
    size: usize,
}

/// Size and alignment of a WGSL type, for the types the mirror may use.
fn wgsl_size_align(ty: &str) -> Option<(usize, usize)> {
    match ty {
        "u32" | "i32" | "f32" | "atomic<u32>" | "atomic<i32>" => Some((4, 4)),
        _ => None,
    }
}

/// Text with `//` comments removed.
fn without_comments(text: &str) -> String {
    text.lines().map(|line| line.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n")
}

/// Every `struct Name { field: type, … }` of the text, laid out by WGSL's rules.
fn parse_structs(text: &str) -> BTreeMap<String, StructLayout> {
    let text = without_comments(text);
    let mut structs = BTreeMap::new();
    let mut rest = text.as_str();
    while let Some(start) = rest.find("struct ") {
        let after = &rest[start + "struct ".len()..];
        let open = after.find('{').expect("struct without '{'");
        let close = after.find('}').expect("struct without '}'");
        let name = after[..open].trim().to_string();
        let (mut offset, mut align) = (0usize, 1usize);
        let mut fields = Vec::new();
        for field in after[open + 1..close].split(',').map(str::trim).filter(|f| !f.is_empty()) {
            let (field_name, ty) = field.split_once(':').unwrap_or_else(|| panic!("{name}: bad field {field:?}"));
            let ty = ty.trim();
            let (size, field_align) = wgsl_size_align(ty)
                .unwrap_or_else(|| panic!("{name}.{field_name}: type {ty} not handled by this test"));
            offset = offset.next_multiple_of(field_align);
            fields.push((field_name.trim().to_string(), offset));
            offset += size;
            align = align.max(field_align);
        }
        structs.insert(name.clone(), StructLayout { fields, size: offset.next_multiple_of(align) });
        rest = &after[close + 1..];
    }
    structs
}

/// Every `const NAME: u32 = value;` of the text.
fn parse_constants(text: &str) -> BTreeMap<String, u32> {
    without_comments(text)
        .lines()
        .filter_map(|line| line.trim().strip_prefix("const "))
        .map(|declaration| {
            let (name, rest) = declaration.split_once(':').expect("const without type");
            let (ty, value) = rest.split_once('=').expect("const without value");
            assert_eq!(ty.trim(), "u32", "{name}: only u32 constants are mirrored");
            let value = value.trim().trim_end_matches(';').trim_end_matches('u');
            let parsed = match value.strip_prefix("0x") {
                Some(hex) => u32::from_str_radix(hex, 16),
                None => value.parse(),
            };
            (name.trim().to_string(), parsed.unwrap_or_else(|e| panic!("{name}: {value}: {e}")))
        })
        .collect()
}

/// The Rust side of a struct: its fields' names and offsets, in declaration order, and its size.
macro_rules! rust_layout {
    ($ty:ident { $($field:ident),* $(,)? }) => {
        (
            stringify!($ty).to_string(),
            StructLayout {
                fields: vec![$((stringify!($field).to_string(), offset_of!($ty, $field))),*],
                size: size_of::<$ty>(),
            },
        )
    };
}

#[test]
fn every_struct_matches_its_rust_twin() {
    let rust: BTreeMap<String, StructLayout> = [
        rust_layout!(Node { child_word, data_word }),
        rust_layout!(TreeHeader {
            n,
            nodes_per_tile,
            brick_size,
            stored_brick_size,
            max_level,
            blocks_per_axis,
            block_cells,
            voxels_per_brick,
            node_count,
            brick_count,
            padding0,
            padding1,
        }),
        rust_layout!(TransferTableHeader { entry_count, contents, step, padding }),
        rust_layout!(TransferTableEntry { r, g, b, a }),
        rust_layout!(FeedbackCounters { request_count, request_capacity, dropped_requests, padding }),
        rust_layout!(RayCounters { rays, samples, descents, padding }),
        rust_layout!(UsageFlag { used }),
        rust_layout!(RayFrame {
            width,
            height,
            pixel_stride,
            max_requests_per_ray,
            flags,
            stand_in_levels,
            request_capacity,
            max_segments,
            eye_x,
            eye_y,
            eye_z,
            pixel_spread,
            forward_x,
            forward_y,
            forward_z,
            world_per_volume,
            right_x,
            right_y,
            right_z,
            lod_bias,
            up_x,
            up_y,
            up_z,
            step_factor,
            inverse_scale_x,
            inverse_scale_y,
            inverse_scale_z,
            bias_scale,
            clip_lower_x,
            clip_lower_y,
            clip_lower_z,
            stop_below,
            clip_upper_x,
            clip_upper_y,
            clip_upper_z,
            ambient,
            background_r,
            background_g,
            background_b,
            diffuse,
            light_x,
            light_y,
            light_z,
            specular,
            shininess,
            atlas_bricks_x,
            atlas_bricks_y,
            anchor_level,
            anchor_x,
            anchor_y,
            anchor_z,
            anchor_scale,
            surface_count,
            finest_voxel,
            adaptive_tolerance,
            reserved1,
        }),
        rust_layout!(SurfaceRecord { iso, lower, upper, opacity, r, g, b, reserved }),
        rust_layout!(RequestRecord { node, kind }),
        rust_layout!(BrickBlend { corner0, corner1, corner2, corner3, corner4, corner5, corner6, corner7, fade }),
    ]
    .into_iter()
    .collect();
    let wgsl = parse_structs(WGSL);
    assert_eq!(wgsl.keys().collect::<Vec<_>>(), rust.keys().collect::<Vec<_>>(), "structs differ");
    for (name, rust_layout) in &rust {
        assert_eq!(&wgsl[name], rust_layout, "{name}: WGSL (left) and Rust (right) differ");
    }
}

#[test]
fn every_constant_matches_its_rust_twin() {
    let rust: BTreeMap<String, u32> = [
        ("NODE_CONSTANT_BIT", CONSTANT_BIT),
        ("NODE_TERMINAL_BIT", TERMINAL_BIT),
        ("NODE_CHILD_MASK", CHILD_MASK),
        ("TABLE_HOLDS_EXTINCTION", TABLE_HOLDS_EXTINCTION),
        ("TABLE_HOLDS_STEP_OPACITY", TABLE_HOLDS_STEP_OPACITY),
        ("REQUEST_PRODUCE", REQUEST_PRODUCE),
        ("REQUEST_SUBDIVIDE", REQUEST_SUBDIVIDE),
        ("REQUEST_KIND_MASK", REQUEST_KIND_MASK),
        ("REQUEST_DEFICIT_SHIFT", REQUEST_DEFICIT_SHIFT),
        ("REQUEST_MAX_DEFICIT", REQUEST_MAX_DEFICIT),
        ("RAY_FRAME_PHONG", RAY_FRAME_PHONG),
        ("RAY_FRAME_STEPS_IGNORE_STAND_INS", RAY_FRAME_STEPS_IGNORE_STAND_INS),
        ("RAY_FRAME_COLOUR_BY_LEVEL", RAY_FRAME_COLOUR_BY_LEVEL),
        ("RAY_FRAME_SKIP_EMPTY_SPACE", RAY_FRAME_SKIP_EMPTY_SPACE),
        ("RAY_FRAME_CENTRAL_NORMALS", RAY_FRAME_CENTRAL_NORMALS),
        ("RAY_FRAME_SHADOWS", RAY_FRAME_SHADOWS),
        ("RAY_FRAME_BLENDING", RAY_FRAME_BLENDING),
        ("RAY_FRAME_SURFACES_IN_VOLUME", RAY_FRAME_SURFACES_IN_VOLUME),
        ("RAY_FRAME_ADAPTIVE_STEP", RAY_FRAME_ADAPTIVE_STEP),
    ]
    .into_iter()
    .map(|(name, value)| (name.to_string(), value))
    .collect();
    assert_eq!(parse_constants(WGSL), rust);
}

#[test]
fn the_parser_sees_a_reordered_field() {
    // The check above could pass vacuously if the parser lost fields; a swapped pair must change the layout.
    let swapped = "struct RequestRecord { kind: u32, node: u32, }";
    let (_, rust) = rust_layout!(RequestRecord { node, kind });
    assert_ne!(parse_structs(swapped)["RequestRecord"], rust);
    assert_eq!(parse_structs("struct RequestRecord { node: u32, kind: u32 }")["RequestRecord"], rust);
}
