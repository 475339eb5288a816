//! The GPU device: a headless wgpu adapter (Vulkan), opened with the adapter's own limits so that pools as large as
//! the budget and the adapter allow can be bound, and described for `--stats`. Where the only adapter is a CPU
//! emulation (Mesa's lavapipe, "llvmpipe"), [`cpu_emulation_warning`] says so: it draws about 12× slower than the
//! CPU renderer (measured on a 2-core machine), which is never what `--backend gpu` was asked for.

use crate::error::GpuError;

/// An open GPU device and what it is.
pub struct GpuContext {
    /// The device resources are created on.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// What the adapter says of itself.
    pub info: wgpu::AdapterInfo,
    /// The limits the device was opened with (the adapter's own).
    pub limits: wgpu::Limits,
    /// Whether the device can hold bricks as `R16Unorm` and filter them in hardware (wgpu's
    /// `TEXTURE_FORMAT_16BIT_NORM`, requested where the adapter has it, and the format filterable there).
    pub filters_16bit_norm: bool,
}

impl GpuContext {
    /// Opens the first Vulkan adapter that can run compute shaders (a discrete GPU preferred), without a window.
    pub fn new() -> Result<GpuContext, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::VULKAN,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|_| GpuError::NoAdapter)?;
        let info = adapter.get_info();
        let limits = adapter.limits();
        let norm16 = wgpu::Features::TEXTURE_FORMAT_16BIT_NORM;
        let filters_16bit_norm = adapter.features().contains(norm16)
            && adapter
                .get_texture_format_features(wgpu::TextureFormat::R16Unorm)
                .flags
                .contains(wgpu::TextureFormatFeatureFlags::FILTERABLE);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("voxstream"),
            required_features: if filters_16bit_norm { norm16 } else { wgpu::Features::empty() },
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device { adapter: info.name.clone(), reason: e.to_string() })?;
        Ok(GpuContext { device, queue, info, limits, filters_16bit_norm })
    }

    /// One line naming the adapter, its kind, backend and driver (what `--stats` prints).
    pub fn describe(&self) -> String {
        let info = &self.info;
        let kind = match info.device_type {
            wgpu::DeviceType::Cpu => "CPU emulation",
            wgpu::DeviceType::DiscreteGpu => "discrete GPU",
            wgpu::DeviceType::IntegratedGpu => "integrated GPU",
            wgpu::DeviceType::VirtualGpu => "virtual GPU",
            wgpu::DeviceType::Other => "other",
        };
        let driver = if info.driver_info.is_empty() {
            info.driver.clone()
        } else {
            format!("{} {}", info.driver, info.driver_info)
        };
        format!("{} ({kind}, {:?}, {driver})", info.name, info.backend)
    }

    /// A warning when the adapter is a CPU emulation of a GPU ([`cpu_emulation_warning`]).
    pub fn cpu_emulation_warning(&self) -> Option<String> {
        cpu_emulation_warning(self.info.device_type, &self.info.name)
    }

    /// The largest buffer a shader can bind as storage, bytes.
    pub fn max_storage_bytes(&self) -> u64 {
        self.limits.max_storage_buffer_binding_size.min(self.limits.max_buffer_size)
    }
}

/// One line for an adapter of `device_type` named `adapter` that is a CPU emulation of a GPU (wgpu's
/// [`wgpu::DeviceType::Cpu`]: Mesa's lavapipe, SwiftShader, WARP), pointing to the CPU renderer; `None` for a GPU.
pub fn cpu_emulation_warning(device_type: wgpu::DeviceType, adapter: &str) -> Option<String> {
    (device_type == wgpu::DeviceType::Cpu).then(|| {
        format!(
            "the GPU adapter \"{adapter}\" is a CPU emulation of a GPU (no GPU driver was found), which draws about \
             12x slower than the CPU renderer: use --backend cpu"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_cpu_emulation_is_warned_of() {
        let warning = cpu_emulation_warning(wgpu::DeviceType::Cpu, "llvmpipe (LLVM 15.0.6, 256 bits)").unwrap();
        assert!(
            warning.contains("\"llvmpipe (LLVM 15.0.6, 256 bits)\"") && warning.contains("CPU emulation"),
            "{warning}"
        );
        assert!(warning.ends_with("use --backend cpu") && !warning.contains('\n'), "one line: {warning}");
        for gpu in [
            wgpu::DeviceType::DiscreteGpu,
            wgpu::DeviceType::IntegratedGpu,
            wgpu::DeviceType::VirtualGpu,
            wgpu::DeviceType::Other,
        ] {
            assert_eq!(cpu_emulation_warning(gpu, "NVIDIA H100"), None, "{gpu:?}");
        }
    }
}
