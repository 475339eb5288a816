//! The frame's ray parameters: the uniform a GPU ray caster reads beside the [`TreeHeader`](crate::TreeHeader).
//!
//! Everything the CPU ray caster derives per frame from the camera and the render settings (GigaVoxels [P09] §6:
//! one cone per pixel, its spread picking the level of detail), flattened to scalars so that the WGSL mirror is a
//! list of `f32`/`u32` fields. Vectors are in the volume's unit cube where the traversal works, except `forward`,
//! `right` and `up`, which are the camera's world-space frame (a ray's world direction is normalised before it is
//! divided by the placement's scale, as on the CPU).
//!
//! | offset | fields | meaning |
//! |---|---|---|
//! | 0 | `width`, `height`, `pixel_stride`, `max_requests_per_ray` | image size, the stride of the pixels traced this pass, the misses one ray may report |
//! | 16 | `flags`, `stand_in_levels`, `request_capacity`, `max_segments` | [`RAY_FRAME_PHONG`] …, levels a stand-in is stepped below itself, the request list's length, a bound on segments per ray |
//! | 32 | `eye_x`, `eye_y`, `eye_z`, `pixel_spread` | the eye, anchor frame; the cone's footprint per unit distance |
//! | 48 | `forward_*`, `world_per_volume` | unit view direction (world); world units per volume unit (mean of the placement's scale) |
//! | 64 | `right_*`, `lod_bias` | right vector scaled by the half-width of the image plane at distance 1; the level bias |
//! | 80 | `up_*`, `step_factor` | up vector scaled by the half-height; samples per voxel of the footprint, inverted |
//! | 96 | `inverse_scale_*`, `bias_scale` | `1 / placement.scale` per axis; `N^(−lod_bias)` |
//! | 112 | `clip_lower_*`, `stop_below` | the clip box's lower corner, anchor frame; transmittance below which a ray stops |
//! | 128 | `clip_upper_*`, `ambient` | the clip box's upper corner; Phong's ambient coefficient |
//! | 144 | `background_*`, `diffuse` | linear background colour; Phong's diffuse coefficient |
//! | 160 | `light_*`, `specular` | unit light direction (world; zero: a headlight); Phong's specular coefficient |
//! | 176 | `shininess`, `atlas_bricks_x`, `atlas_bricks_y`, `anchor_level` | Phong's exponent; brick slots per row and per column of the brick atlas (slot `s` sits at brick `(s mod x, (s div x) mod y, s div xy)`); the anchor's level |
//! | 192 | `anchor_x`, `anchor_y`, `anchor_z`, `anchor_scale` | the anchor's integer coordinates at its level; `N^anchor_level` |
//! | 208 | `surface_count`, `finest_voxel`, `adaptive_tolerance`, `reserved1` | isosurfaces drawn (0: emission–absorption), each a [`SurfaceRecord`]; world length of the finest voxel (the least shadow offset); the adaptive step's tolerance (with [`RAY_FRAME_ADAPTIVE_STEP`]); zero |
//!
//! Size 224 bytes (a multiple of 16, as uniforms need).
//!
//! [`SurfaceRecord`], 32 bytes: one isosurface (Knoll et al., seed 002), as `voxstream-render`'s `SurfaceSettings`
//! holds it.
//!
//! | offset | fields | meaning |
//! |---|---|---|
//! | 0 | `iso`, `lower`, `upper`, `opacity` | the isovalue in stored units (`[0, 65535]`); the normalised isovalue less and plus the culling margin; opacity |
//! | 16 | `r`, `g`, `b`, `reserved` | linear colour premultiplied by the opacity; zero |

use bytemuck::{Pod, Zeroable};

/// [`RayFrame::flags`]: shade samples with Phong's model (the trilinear field's gradient as the normal).
pub const RAY_FRAME_PHONG: u32 = 1;
/// [`RayFrame::flags`]: a stand-in brick is stepped as the data it stands in for will be
/// (`RenderSettings::steps_ignore_stand_ins`).
pub const RAY_FRAME_STEPS_IGNORE_STAND_INS: u32 = 2;
/// [`RayFrame::flags`]: samples take their tree level's colour (`RenderSettings::colour_by_level`).
pub const RAY_FRAME_COLOUR_BY_LEVEL: u32 = 4;
/// [`RayFrame::flags`]: skip segments whose bricks hold no value the transfer function shows
/// (`RenderSettings::skip_empty_space`).
pub const RAY_FRAME_SKIP_EMPTY_SPACE: u32 = 8;
/// [`RayFrame::flags`]: isosurface normals from central differences at the cell's corners, interpolated
/// (`SurfaceNormals::CentralDifferences`), instead of the cell's analytic gradient.
pub const RAY_FRAME_CENTRAL_NORMALS: u32 = 16;
/// [`RayFrame::flags`]: isosurfaces cast hard shadows from the fixed light (`RenderSettings::shadows`).
pub const RAY_FRAME_SHADOWS: u32 = 32;
/// [`RayFrame::flags`]: Thiele et al.'s level blending: each brick's [`BrickBlend`](crate::BrickBlend) caps its
/// weight against its parent, and a brick still fading in is drawn instead of its descendants.
pub const RAY_FRAME_BLENDING: u32 = 64;
/// [`RayFrame::flags`]: isosurfaces are drawn inside the transfer function's volume, composited in depth order
/// (`RenderSettings::surfaces_in_volume`).
pub const RAY_FRAME_SURFACES_IN_VOLUME: u32 = 128;
/// [`RayFrame::flags`]: the error-bounded adaptive step (`RenderSettings::adaptive_step`): each brick segment's
/// step from the transfer function's variation over the brick's range, which follows the range list as `f32`
/// prefix sums, with [`RayFrame::adaptive_tolerance`].
pub const RAY_FRAME_ADAPTIVE_STEP: u32 = 256;

/// The frame's ray parameters, as a GPU reads them (see the module docs for the offsets).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[allow(missing_docs)]
pub struct RayFrame {
    pub width: u32,
    pub height: u32,
    pub pixel_stride: u32,
    pub max_requests_per_ray: u32,
    pub flags: u32,
    pub stand_in_levels: u32,
    pub request_capacity: u32,
    pub max_segments: u32,
    pub eye_x: f32,
    pub eye_y: f32,
    pub eye_z: f32,
    pub pixel_spread: f32,
    pub forward_x: f32,
    pub forward_y: f32,
    pub forward_z: f32,
    pub world_per_volume: f32,
    pub right_x: f32,
    pub right_y: f32,
    pub right_z: f32,
    pub lod_bias: f32,
    pub up_x: f32,
    pub up_y: f32,
    pub up_z: f32,
    pub step_factor: f32,
    pub inverse_scale_x: f32,
    pub inverse_scale_y: f32,
    pub inverse_scale_z: f32,
    pub bias_scale: f32,
    pub clip_lower_x: f32,
    pub clip_lower_y: f32,
    pub clip_lower_z: f32,
    pub stop_below: f32,
    pub clip_upper_x: f32,
    pub clip_upper_y: f32,
    pub clip_upper_z: f32,
    pub ambient: f32,
    pub background_r: f32,
    pub background_g: f32,
    pub background_b: f32,
    pub diffuse: f32,
    pub light_x: f32,
    pub light_y: f32,
    pub light_z: f32,
    pub specular: f32,
    pub shininess: f32,
    pub atlas_bricks_x: u32,
    pub atlas_bricks_y: u32,
    pub anchor_level: u32,
    pub anchor_x: u32,
    pub anchor_y: u32,
    pub anchor_z: u32,
    pub anchor_scale: f32,
    pub surface_count: u32,
    pub finest_voxel: f32,
    pub adaptive_tolerance: f32,
    pub reserved1: u32,
}

/// One isosurface, as a GPU reads it (see the module docs for the offsets).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[allow(missing_docs)]
pub struct SurfaceRecord {
    pub iso: f32,
    pub lower: f32,
    pub upper: f32,
    pub opacity: f32,
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub reserved: u32,
}

/// Bytes of a [`RayFrame`].
pub const RAY_FRAME_BYTES: usize = core::mem::size_of::<RayFrame>();

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn offsets_are_as_documented() {
        assert_eq!(RAY_FRAME_BYTES, 224);
        assert_eq!(align_of::<RayFrame>(), 4);
        assert_eq!(offset_of!(RayFrame, flags), 16);
        assert_eq!(offset_of!(RayFrame, eye_x), 32);
        assert_eq!(offset_of!(RayFrame, forward_x), 48);
        assert_eq!(offset_of!(RayFrame, right_x), 64);
        assert_eq!(offset_of!(RayFrame, up_x), 80);
        assert_eq!(offset_of!(RayFrame, inverse_scale_x), 96);
        assert_eq!(offset_of!(RayFrame, clip_lower_x), 112);
        assert_eq!(offset_of!(RayFrame, clip_upper_x), 128);
        assert_eq!(offset_of!(RayFrame, background_r), 144);
        assert_eq!(offset_of!(RayFrame, light_x), 160);
        assert_eq!(offset_of!(RayFrame, shininess), 176);
        assert_eq!(offset_of!(RayFrame, anchor_x), 192);
        assert_eq!(offset_of!(RayFrame, surface_count), 208);
        assert_eq!(size_of::<SurfaceRecord>(), 32);
        assert_eq!(offset_of!(SurfaceRecord, r), 16);
    }
}
