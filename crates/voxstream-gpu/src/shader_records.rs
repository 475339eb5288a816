//! The frame's records as the ray caster's shader reads them: the [`RayFrame`] uniform (camera, settings, the anchor
//! of its positions), the isosurfaces' [`SurfaceRecord`]s, and the value ranges that empty-space skipping reads.
//! Plain CPU code: [`crate::renderer`] uploads what these return.

use voxstream_core::TreeView;
use voxstream_layout::{
    RayFrame, SurfaceRecord, RAY_FRAME_ADAPTIVE_STEP, RAY_FRAME_CENTRAL_NORMALS, RAY_FRAME_COLOUR_BY_LEVEL,
    RAY_FRAME_PHONG, RAY_FRAME_SHADOWS, RAY_FRAME_SKIP_EMPTY_SPACE, RAY_FRAME_STEPS_IGNORE_STAND_INS,
    RAY_FRAME_SURFACES_IN_VOLUME,
};
use voxstream_render::{CameraFrame, RenderSettings, Shading, SurfaceNormals, SurfaceSettings, TransferLut};

use crate::shader_interface::RANGE_HIGH_SHIFT;

/// A ray may not cross more segments than this (the CPU's bound).
const MAX_SEGMENTS: u32 = 1 << 20;
/// What empty-space skipping reads: per transfer-table index, the entries with non-zero extinction before it (one
/// more than the table's length), then per brick slot its `[min, max]` voxel as `min | max << 16`, then per slot
/// its occupancy blocks' ranges, packed the same way.
pub(crate) fn range_words(lut: &TransferLut, view: &TreeView<'_>, adaptive_step: bool) -> Vec<u32> {
    let entries = lut.entries();
    let mut words = Vec::with_capacity(entries.len() + 1 + view.brick_ranges.len());
    let mut visible = 0u32;
    words.push(0);
    for entry in entries {
        visible += (entry.sigma > 0.0) as u32;
        words.push(visible);
    }
    let pack = |&[lo, hi]: &[u16; 2]| lo as u32 | (hi as u32) << RANGE_HIGH_SHIFT;
    words.extend(view.brick_ranges.iter().map(pack));
    words.extend(view.block_ranges.iter().map(pack));
    // The adaptive step's variation sums (`StepVariation`), last: the shader finds them from the list's end.
    if adaptive_step {
        words.extend(lut.variation().prefix().iter().map(|&v| (v as f32).to_bits()));
    }
    words
}

/// The anchor of the shader's positions (see `voxstream_layout::ray_frame`): the deepest level whose node
/// coordinates fit in an `i32` (`N^level < 2³¹`, and no deeper than the tree), and the node there that holds `eye`
/// (clamped into the clip box and the unit cube). Returns the level, its scale `N^level` and the node's coordinates.
pub fn anchor(eye: [f64; 3], clip: [[f64; 3]; 2], n: u32, max_level: u32) -> (u32, f64, [u32; 3]) {
    let (mut level, mut scale) = (0u32, 1u64);
    while level < max_level && scale * n as u64 <= i32::MAX as u64 {
        level += 1;
        scale *= n as u64;
    }
    let coordinates = std::array::from_fn(|a| {
        let lower = clip[0][a].max(0.0);
        let upper = clip[1][a].min(1.0).max(lower);
        let inside = if eye[a].is_finite() { eye[a].clamp(lower, upper) } else { lower };
        ((inside * scale as f64).floor().max(0.0) as u64).min(scale - 1) as u32
    });
    (level, scale as f64, coordinates)
}

/// The frame's camera and settings as the shader reads them.
pub(crate) fn ray_frame(
    frame: &CameraFrame,
    settings: &RenderSettings,
    n: u32,
    max_level: u32,
    request_capacity: u32,
) -> RayFrame {
    let placement = &settings.placement;
    let eye: [f64; 3] = std::array::from_fn(|a| (frame.eye[a] - placement.origin[a]) / placement.scale[a]);
    let (anchor_level, anchor_scale, anchor) = anchor(eye, [placement.clip_lower, placement.clip_upper], n, max_level);
    // Unit cube → anchor frame, in f64, rounded once.
    let to_anchor =
        |p: [f64; 3]| -> [f32; 3] { std::array::from_fn(|a| (p[a] * anchor_scale - anchor[a] as f64) as f32) };
    let (eye, clip_lower, clip_upper) =
        (to_anchor(eye), to_anchor(placement.clip_lower), to_anchor(placement.clip_upper));
    let light = settings.light_direction.map_or([0.0; 3], |l| {
        let length = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
        if length > 0.0 {
            l.map(|c| (c / length) as f32)
        } else {
            [0.0; 3]
        }
    });
    let mut flags = 0;
    if settings.shading == Shading::Phong {
        flags |= RAY_FRAME_PHONG;
    }
    if settings.steps_ignore_stand_ins {
        flags |= RAY_FRAME_STEPS_IGNORE_STAND_INS;
    }
    if settings.colour_by_level {
        flags |= RAY_FRAME_COLOUR_BY_LEVEL;
    }
    if settings.skip_empty_space {
        flags |= RAY_FRAME_SKIP_EMPTY_SPACE;
    }
    if settings.surface_normals == SurfaceNormals::CentralDifferences {
        flags |= RAY_FRAME_CENTRAL_NORMALS;
    }
    if settings.surfaces_in_volume {
        flags |= RAY_FRAME_SURFACES_IN_VOLUME;
    }
    // Volume rendering only, as on the CPU (surfaces inside a volume step by `BrickSpan::step`, fixed).
    if settings.adaptive_step.is_some() && settings.surfaces.is_empty() {
        flags |= RAY_FRAME_ADAPTIVE_STEP;
    }
    // As `SurfaceCaster`: shadows from a fixed light, with Phong shading.
    if settings.shadows && settings.shading == Shading::Phong && light != [0.0; 3] {
        flags |= RAY_FRAME_SHADOWS;
    }
    RayFrame {
        width: settings.width,
        height: settings.height,
        pixel_stride: settings.pixel_stride.max(1),
        max_requests_per_ray: settings.max_requests_per_ray,
        flags,
        stand_in_levels: if n <= 2 { 2 } else { 1 },
        request_capacity,
        max_segments: MAX_SEGMENTS,
        eye_x: eye[0],
        eye_y: eye[1],
        eye_z: eye[2],
        pixel_spread: frame.pixel_spread as f32,
        forward_x: frame.forward.x as f32,
        forward_y: frame.forward.y as f32,
        forward_z: frame.forward.z as f32,
        world_per_volume: placement.mean_scale() as f32,
        right_x: frame.right.x as f32,
        right_y: frame.right.y as f32,
        right_z: frame.right.z as f32,
        lod_bias: settings.lod_bias as f32,
        up_x: frame.up.x as f32,
        up_y: frame.up.y as f32,
        up_z: frame.up.z as f32,
        step_factor: settings.step_factor as f32,
        inverse_scale_x: (1.0 / placement.scale[0]) as f32,
        inverse_scale_y: (1.0 / placement.scale[1]) as f32,
        inverse_scale_z: (1.0 / placement.scale[2]) as f32,
        bias_scale: (-settings.lod_bias * (n as f64).ln()).exp() as f32,
        clip_lower_x: clip_lower[0],
        clip_lower_y: clip_lower[1],
        clip_lower_z: clip_lower[2],
        stop_below: 1.0 - settings.opacity_cutoff,
        clip_upper_x: clip_upper[0],
        clip_upper_y: clip_upper[1],
        clip_upper_z: clip_upper[2],
        ambient: settings.phong.ambient,
        background_r: settings.background[0],
        background_g: settings.background[1],
        background_b: settings.background[2],
        diffuse: settings.phong.diffuse,
        light_x: light[0],
        light_y: light[1],
        light_z: light[2],
        specular: settings.phong.specular,
        shininess: settings.phong.shininess,
        atlas_bricks_x: 1,
        atlas_bricks_y: 1,
        anchor_level,
        anchor_x: anchor[0],
        anchor_y: anchor[1],
        anchor_z: anchor[2],
        anchor_scale: anchor_scale as f32,
        surface_count: 0,
        finest_voxel: 0.0,
        adaptive_tolerance: settings.adaptive_step.unwrap_or(0.0) as f32,
        reserved1: 0,
    }
}

/// The frame's isosurfaces as the shader reads them; one unused record where there are none (a binding may not be
/// empty).
pub(crate) fn surface_records(surfaces: &SurfaceSettings) -> Vec<SurfaceRecord> {
    let mut records: Vec<SurfaceRecord> = (0..surfaces.count())
        .map(|i| {
            let s = surfaces.surface(i);
            SurfaceRecord {
                iso: s.iso,
                lower: s.lower,
                upper: s.upper,
                opacity: s.opacity,
                r: s.color[0],
                g: s.color[1],
                b: s.color[2],
                reserved: 0,
            }
        })
        .collect();
    if records.is_empty() {
        records.push(SurfaceRecord::default());
    }
    records
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_anchor_is_the_deepest_node_holding_the_eye_that_an_i32_can_name() {
        let clip = [[0.0; 3], [1.0; 3]];
        // N = 3: 3^19 < 2^31 < 3^20.
        let (level, scale, node) = anchor([0.5, 0.25, 1.0 + 1e-9], clip, 3, 25);
        assert_eq!((level, scale), (19, 3f64.powi(19)));
        assert_eq!(node[0] as f64, (0.5 * scale).floor());
        assert_eq!(node[1] as f64, (0.25 * scale).floor());
        assert_eq!(node[2] as f64, scale - 1.0, "an eye outside is clamped to the last node");
        // N = 2: 2^30; a shallow tree stops at its deepest level.
        assert_eq!(anchor([0.5; 3], clip, 2, 40).0, 30);
        assert_eq!(anchor([0.5; 3], clip, 2, 7), (7, 128.0, [64; 3]));
        // Far outside, below the clip box, or not finite: the nearest node inside.
        assert_eq!(anchor([-5.0, f64::NAN, 0.3], [[0.25; 3], [0.75; 3]], 2, 2).2, [1, 1, 1]);
    }
}
