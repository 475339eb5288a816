//! The GPU device: a headless wgpu adapter (Vulkan), opened with the adapter's own limits so that pools as large as
//! the budget and the adapter allow can be bound, and described for `--stats`.

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

    /// The largest buffer a shader can bind as storage, bytes.
    pub fn max_storage_bytes(&self) -> u64 {
        self.limits.max_storage_buffer_binding_size.min(self.limits.max_buffer_size)
    }
}
