//! How the shader reads the brick atlas: exact trilinear filtering in the shader (8 texel loads per sample, the
//! CPU's arithmetic) or the texture unit's trilinear filtering (one fetch per sample), the way GigaVoxels reads its
//! brick pool ([P09] §4: "the 3D texture hardware trilinear interpolation").
//!
//! Bricks are 16-bit on the CPU (`voxstream_core::BrickPool`), so the atlas keeps them at 16 bits in both modes:
//! `R16Uint` for exact filtering (integers are not filterable), `R16Unorm` for the hardware (wgpu's
//! `TEXTURE_FORMAT_16BIT_NORM`, which Vulkan adapters generally have). `R8Unorm` would halve the atlas for 8-bit
//! sources but the CPU pool has already widened them to 16 bits; `R16Float` holds only 11 significant bits and
//! would quantise the voxels themselves, not only the weights.
//!
//! What hardware filtering changes: texture units compute the weights at reduced precision (8 fractional bits on
//! most GPUs, as the Vulkan and D3D specifications allow), so values between voxels move by up to 1/512 of a voxel
//! step. The image tests compare both modes with the CPU at the same 40 dB. Only samples whose gradient is not
//! needed are fetched this way: unshaded volume samples. Phong-shaded samples (their analytic gradient needs the
//! eight corners anyway), isosurface cells (Marmitt's cubic needs the corners) and central-difference normals read
//! texels with `textureLoad` in both modes.

use crate::error::GpuError;

/// How the ray caster filters brick samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BrickFiltering {
    /// Trilinear filtering in the shader from eight `textureLoad`s (`R16Uint` atlas): the CPU's arithmetic.
    Exact,
    /// The texture unit's trilinear filtering (`R16Unorm` atlas, one `textureSampleLevel` per sample).
    Hardware,
}

impl BrickFiltering {
    /// The hardware where the device can filter 16-bit normalised textures, else exact.
    pub fn best_for(filters_16bit_norm: bool) -> BrickFiltering {
        if filters_16bit_norm {
            BrickFiltering::Hardware
        } else {
            BrickFiltering::Exact
        }
    }

    /// `self` on a device that can (`filters_16bit_norm`) or cannot filter 16-bit normalised textures: an error
    /// naming the fix where it cannot do what was asked.
    pub fn check(self, filters_16bit_norm: bool, adapter: &str) -> Result<BrickFiltering, GpuError> {
        if self == BrickFiltering::Hardware && !filters_16bit_norm {
            return Err(GpuError::NoHardwareFiltering { adapter: adapter.to_string() });
        }
        Ok(self)
    }

    /// The atlas's texel format.
    pub fn texture_format(self) -> wgpu::TextureFormat {
        match self {
            BrickFiltering::Exact => wgpu::TextureFormat::R16Uint,
            BrickFiltering::Hardware => wgpu::TextureFormat::R16Unorm,
        }
    }

    /// The shader's sample type for the atlas binding.
    pub fn sample_type(self) -> wgpu::TextureSampleType {
        match self {
            BrickFiltering::Exact => wgpu::TextureSampleType::Uint,
            BrickFiltering::Hardware => wgpu::TextureSampleType::Float { filterable: true },
        }
    }

    /// The WGSL that declares the atlas (binding 3; the sampler at binding 12 for the hardware) and defines
    /// `voxel(at)` (one stored voxel, 0‥65535) and `filtered_value(slot, x)` (the trilinear value, normalised),
    /// placed before the ray caster's files (`shader.rs`), which uses them.
    pub fn wgsl(self) -> &'static str {
        match self {
            BrickFiltering::Exact => {
                "@group(0) @binding(3) var bricks: texture_3d<u32>;\n\
                 fn voxel(at: vec3<u32>) -> f32 {\n\
                 \x20   return f32(textureLoad(bricks, at, 0).r);\n\
                 }\n\
                 fn filtered_value(slot: u32, x: vec3<f32>) -> f32 {\n\
                 \x20   return sample_brick(slot, x).x;\n\
                 }\n"
            }
            BrickFiltering::Hardware => {
                "@group(0) @binding(3) var bricks: texture_3d<f32>;\n\
                 @group(0) @binding(12) var brick_sampler: sampler;\n\
                 fn voxel(at: vec3<u32>) -> f32 {\n\
                 \x20   return round(textureLoad(bricks, at, 0).r * VOXEL_MAX);\n\
                 }\n\
                 fn filtered_value(slot: u32, x: vec3<f32>) -> f32 {\n\
                 \x20   let c = clamp(x, vec3<f32>(0.0), vec3<f32>(f32(tree.stored_brick_size - 1u)));\n\
                 \x20   let texel = vec3<f32>(brick_origin(slot)) + c + 0.5;\n\
                 \x20   return textureSampleLevel(bricks, brick_sampler, texel / vec3<f32>(textureDimensions(bricks)), 0.0).r;\n\
                 }\n"
            }
        }
    }

    /// How `--stats` names it.
    pub fn describe(self) -> &'static str {
        match self {
            BrickFiltering::Exact => "bricks filtered exactly in the shader (R16Uint)",
            BrickFiltering::Hardware => "bricks filtered by the texture units (R16Unorm)",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hardware_filtering_is_refused_where_the_format_cannot_be_filtered() {
        assert_eq!(BrickFiltering::best_for(true), BrickFiltering::Hardware);
        assert_eq!(BrickFiltering::best_for(false), BrickFiltering::Exact);
        assert!(BrickFiltering::Exact.check(false, "a").is_ok());
        let message = BrickFiltering::Hardware.check(false, "a").unwrap_err().to_string();
        assert!(message.contains("R16Unorm") && message.contains("--gpu-filter exact"), "{message}");
    }

    /// Both variants of the whole shader parse and validate with wgpu's compiler (naga), without a device: a WGSL
    /// error fails here on any machine, not only where a GPU test runs.
    #[test]
    fn both_shader_variants_are_valid_wgsl() {
        for filtering in [BrickFiltering::Exact, BrickFiltering::Hardware] {
            let source = crate::shader::ray_caster_source(filtering);
            let module = naga::front::wgsl::parse_str(&source)
                .unwrap_or_else(|e| panic!("{filtering:?}: {}", e.emit_to_string(&source)));
            let mut validator =
                naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all());
            if let Err(error) = validator.validate(&module) {
                panic!("{filtering:?}: {}", error.emit_to_string(&source));
            }
            let sampled = source.contains("textureSampleLevel(bricks");
            assert_eq!(sampled, filtering == BrickFiltering::Hardware, "{filtering:?}: the sampler is used");
        }
    }
}
