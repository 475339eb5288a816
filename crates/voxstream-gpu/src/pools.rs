//! The node and brick pools in GPU memory, kept equal to the CPU pools by uploading, each pass, only the node tiles
//! and brick slots whose contents changed (GigaVoxels [P09] §5: the CPU serves requests and the GPU copy follows;
//! Reichl's pools, seed 004). The node pool is a storage buffer of `voxstream_layout::Node`s; the brick pool is a
//! 3D texture atlas (GigaVoxels [P09] §4), bricks side by side in the voxels' native 16-bit format (`R16Uint`,
//! filtered in the shader exactly as the CPU filters, or `R16Unorm`, filtered by the texture units:
//! [`BrickFiltering`]), so it is bounded by the adapter's 3D texture size, not its storage-buffer size.
//!
//! The cache manager does not report which slots it rewrote, so each pass compares the pools with the shadow copy
//! of what was uploaded last, tile by tile and brick by brick, and writes the runs that differ. That comparison reads
//! the whole pool once per pass on the CPU (memory bandwidth: about 10 ms per 100 MB); dirty lists from the cache
//! manager would remove it. The buffer and the atlas are allocated at the pools' capacity, which the memory budget
//! fixed, and never grow past it; a new budget (`Session::set_pool_budget`) allocates them again at the new one.

use voxstream_core::{Node, PoolVoxels, TreeView};

use crate::brick_filtering::BrickFiltering;
use crate::error::GpuError;

/// Bytes a pass uploaded, and what it was.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UploadStats {
    /// Node-tile bytes written.
    pub node_bytes: u64,
    /// Brick bytes written.
    pub brick_bytes: u64,
    /// Node tiles written.
    pub tiles: u64,
    /// Brick slots written.
    pub bricks: u64,
}

impl UploadStats {
    /// Everything written.
    pub fn bytes(&self) -> u64 {
        self.node_bytes + self.brick_bytes
    }

    /// Adds another pass's uploads.
    pub fn add(&mut self, other: &UploadStats) {
        self.node_bytes += other.node_bytes;
        self.brick_bytes += other.brick_bytes;
        self.tiles += other.tiles;
        self.bricks += other.bricks;
    }
}

/// The pools on the GPU and the shadow copies of what they hold.
pub struct GpuPools {
    /// The node pool (`Node` records).
    pub nodes: wgpu::Buffer,
    /// The brick pool: an atlas of bricks of `(M+2)³` voxels, `R16Uint` or `R16Unorm` ([`BrickFiltering`]): the same
    /// 16 bits either way.
    pub bricks: wgpu::Texture,
    /// Brick slots along x, y and z of the atlas.
    pub atlas: [u32; 3],
    node_shadow: Vec<Node>,
    /// What the atlas holds, as the CPU pool stores it: 16-bit voxels, or 8-bit ones (widened to 16 bits on
    /// upload: the atlas stays 16-bit, see `voxstream_core::voxel_format`).
    voxel_shadow: Vec<u16>,
    byte_shadow: Vec<u8>,
    node_capacity: usize,
    voxel_capacity: usize,
    nodes_per_tile: usize,
    voxels_per_brick: usize,
}

impl GpuPools {
    /// Buffers for pools of `view`'s capacity (everything resident is uploaded by the first [`GpuPools::update`]).
    pub fn new(
        device: &wgpu::Device,
        view: &TreeView<'_>,
        limits: &wgpu::Limits,
        filtering: BrickFiltering,
    ) -> Result<GpuPools, GpuError> {
        let nodes_per_tile = view.shape.nodes_per_tile() as usize;
        let voxels_per_brick = view.shape.voxels_per_brick();
        let (node_count, brick_count) = capacity_of(view);
        let node_bytes = (node_count * size_of::<Node>()) as u64;
        let max_storage = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        if node_bytes > max_storage {
            return Err(GpuError::TooLarge { what: "node pool", bytes: node_bytes, limit: max_storage });
        }
        let b = view.shape.stored_brick_size();
        let atlas = atlas_shape(brick_count as u64, b, limits.max_texture_dimension_3d).ok_or(GpuError::TooLarge {
            what: "brick pool (a 3D texture)",
            bytes: (brick_count * voxels_per_brick * 2) as u64,
            limit: (limits.max_texture_dimension_3d as u64 / b as u64).pow(3) * voxels_per_brick as u64 * 2,
        })?;
        let nodes = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("node pool"),
            size: node_bytes.max(8),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bricks = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("brick atlas"),
            size: wgpu::Extent3d { width: atlas[0] * b, height: atlas[1] * b, depth_or_array_layers: atlas[2] * b },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: filtering.texture_format(),
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        Ok(GpuPools {
            nodes,
            bricks,
            atlas,
            // Empty shadows: what is resident is uploaded on the first update, the rest as the pools grow.
            node_shadow: Vec::with_capacity(node_count),
            voxel_shadow: Vec::new(),
            byte_shadow: Vec::new(),
            node_capacity: node_count,
            voxel_capacity: brick_count * voxels_per_brick,
            nodes_per_tile,
            voxels_per_brick,
        })
    }

    /// GPU memory the pools occupy, bytes.
    pub fn bytes(&self) -> u64 {
        let size = self.bricks.size();
        self.nodes.size() + size.width as u64 * size.height as u64 * size.depth_or_array_layers as u64 * 2
    }

    /// Whether these buffers are `view`'s pools: the same shape and the same capacity (a budget changed since, up
    /// or down, allocates them again, so the GPU copy never holds more than the budget gives).
    pub fn fits(&self, view: &TreeView<'_>) -> bool {
        let (node_count, brick_count) = capacity_of(view);
        node_count == self.node_capacity
            && brick_count * view.shape.voxels_per_brick() == self.voxel_capacity
            && self.nodes_per_tile == view.shape.nodes_per_tile() as usize
            && self.voxels_per_brick == view.shape.voxels_per_brick()
    }

    /// Writes the tiles and bricks of `view` that differ from what was uploaded (or are new since), merged into
    /// runs of neighbours.
    pub fn update(&mut self, queue: &wgpu::Queue, view: &TreeView<'_>) -> UploadStats {
        let mut stats = UploadStats::default();
        // Nodes, tile by tile.
        let per_tile = self.nodes_per_tile;
        for (from, to) in changed_runs(view.nodes, &mut self.node_shadow, per_tile) {
            let (a, b) = (from * per_tile, (to * per_tile).min(view.nodes.len()));
            let bytes = bytemuck::cast_slice(&self.node_shadow[a..b]);
            queue.write_buffer(&self.nodes, (a * size_of::<Node>()) as u64, bytes);
            stats.node_bytes += bytes.len() as u64;
            stats.tiles += (to - from) as u64;
        }
        // Bricks, slot by slot: each one box of the atlas.
        let per_brick = self.voxels_per_brick;
        let resident = view.voxels.len() - view.voxels.len() % per_brick;
        let runs = match view.voxels {
            PoolVoxels::Wide(voxels) => changed_runs(&voxels[..resident], &mut self.voxel_shadow, per_brick),
            PoolVoxels::Narrow(voxels) => changed_runs(&voxels[..resident], &mut self.byte_shadow, per_brick),
        };
        let b = view.shape.stored_brick_size();
        let [ax, ay, _] = self.atlas;
        let mut widened = Vec::new();
        for (from, to) in runs {
            for slot in from as u32..to as u32 {
                let start = slot as usize * per_brick;
                let voxels = match view.voxels {
                    PoolVoxels::Wide(_) => &self.voxel_shadow[start..][..per_brick],
                    PoolVoxels::Narrow(_) => {
                        widened.clear();
                        widened.extend((start..start + per_brick).map(|i| view.voxels.wide(i, view.voxel_format)));
                        &widened[..]
                    }
                };
                let origin = [slot % ax, (slot / ax) % ay, slot / (ax * ay)].map(|c| c * b);
                queue.write_texture(
                    wgpu::TexelCopyTextureInfo {
                        texture: &self.bricks,
                        mip_level: 0,
                        origin: wgpu::Origin3d { x: origin[0], y: origin[1], z: origin[2] },
                        aspect: wgpu::TextureAspect::All,
                    },
                    bytemuck::cast_slice(voxels),
                    wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(2 * b), rows_per_image: Some(b) },
                    wgpu::Extent3d { width: b, height: b, depth_or_array_layers: b },
                );
                stats.brick_bytes += (per_brick * 2) as u64;
            }
            stats.bricks += (to - from) as u64;
        }
        stats
    }
}

/// Nodes and bricks the GPU pools hold for `view`: the CPU pools' capacity (they grow up to it with use; a view
/// built by hand may already hold more).
fn capacity_of(view: &TreeView<'_>) -> (usize, usize) {
    let nodes = (view.capacity.tiles as usize * view.shape.nodes_per_tile() as usize).max(view.nodes.len());
    let bricks = (view.capacity.bricks as usize).max(view.voxels.len() / view.shape.voxels_per_brick()).max(1);
    (nodes, bricks)
}

/// Brick slots per axis of an atlas holding `bricks` bricks of `b³` voxels within `max_dimension` voxels per axis
/// (`None` if they do not fit): as few rows as hold them, rows of at most the texture's width, spread over as few
/// slices as the texture's height allows, then the rows evened out, so that fewer than one slot per row is left
/// over. The atlas then stays within the bricks' share of the budget, as the CPU pool does.
fn atlas_shape(bricks: u64, b: u32, max_dimension: u32) -> Option<[u32; 3]> {
    let per_axis = (max_dimension / b.max(1)) as u64;
    if per_axis == 0 {
        return None;
    }
    let bricks = bricks.max(1);
    let rows = bricks.div_ceil(per_axis);
    let z = rows.div_ceil(per_axis);
    let y = rows.div_ceil(z);
    let x = bricks.div_ceil(y * z);
    (z <= per_axis).then_some([x as u32, y as u32, z as u32])
}

/// The runs `[from, to)` of chunks of `chunk` items where `current` differs from `shadow`, or lies past its end,
/// with neighbouring changed chunks merged; `shadow` is made equal to `current` on the way.
fn changed_runs<T: PartialEq + Copy>(current: &[T], shadow: &mut Vec<T>, chunk: usize) -> Vec<(usize, usize)> {
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let common = shadow.len().min(current.len());
    for (index, (now, then)) in current[..common].chunks(chunk).zip(shadow[..common].chunks_mut(chunk)).enumerate() {
        if now != then {
            then.copy_from_slice(now);
            match runs.last_mut() {
                Some((_, to)) if *to == index => *to = index + 1,
                _ => runs.push((index, index + 1)),
            }
        }
    }
    if current.len() > common {
        // New chunks (the pool grew); a partly known last chunk was compared above and is written again here.
        let first_new = common / chunk;
        shadow.truncate(first_new * chunk);
        shadow.extend_from_slice(&current[first_new * chunk..]);
        let last = current.len().div_ceil(chunk);
        match runs.last_mut() {
            Some((_, to)) if *to >= first_new => *to = last,
            _ => runs.push((first_new, last)),
        }
    }
    shadow.truncate(current.len());
    runs
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn changed_chunks_merge_into_runs() {
        let mut shadow = vec![0u16; 10];
        let mut current = [0u16; 10];
        assert!(changed_runs(&current, &mut shadow, 2).is_empty());
        current[0] = 1; // chunk 0
        current[3] = 1; // chunk 1
        current[9] = 1; // chunk 4 (the last)
        assert_eq!(changed_runs(&current, &mut shadow, 2), vec![(0, 2), (4, 5)]);
        assert_eq!(shadow, current, "the shadow follows");
        assert!(changed_runs(&current, &mut shadow, 2).is_empty(), "nothing changed since");
    }

    #[test]
    fn the_atlas_holds_every_brick_within_the_texture_size() {
        assert_eq!(atlas_shape(1, 10, 2048), Some([1, 1, 1]));
        assert_eq!(atlas_shape(300, 10, 2048), Some([150, 2, 1]));
        assert_eq!(atlas_shape(1323, 10, 2048), Some([189, 7, 1]), "no padding where the rows divide evenly");
        assert_eq!(atlas_shape(204 * 204 * 204, 10, 2048), Some([204, 204, 204]));
        assert_eq!(atlas_shape(204 * 204 * 204 + 1, 10, 2048), None);
        assert_eq!(atlas_shape(5, 4096, 2048), None);
        for bricks in [1u64, 7, 1000, 99_999, 204 * 204 + 1, 3_000_000] {
            let [x, y, z] = atlas_shape(bricks, 10, 2048).expect("fits");
            assert!([x, y, z].iter().all(|&a| a <= 204), "{bricks}: {x}x{y}x{z} exceeds the texture");
            let slots = x as u64 * y as u64 * z as u64;
            assert!(slots >= bricks, "{bricks}: {x}x{y}x{z} holds fewer");
            assert!(slots - bricks < (y * z) as u64, "{bricks}: {x}x{y}x{z} leaves a slot or more per row unused");
        }
    }

    #[test]
    fn a_grown_pool_uploads_its_new_chunks() {
        let mut shadow = vec![0u16; 4];
        let mut current = vec![0u16; 9];
        current[8] = 5;
        // Chunks of 4: chunk 0 is known and equal; chunks 1 and 2 (the last one short) are new.
        assert_eq!(changed_runs(&current, &mut shadow, 4), vec![(1, 3)]);
        assert_eq!(shadow, current);
        // A change in the first chunk, and growth of the last: chunk 1 stays as it was.
        current[0] = 1;
        current.extend_from_slice(&[7, 7, 7]);
        assert_eq!(changed_runs(&current, &mut shadow, 4), vec![(0, 1), (2, 3)]);
        assert_eq!(shadow, current);
        // Growth from a shadow ending inside a chunk rewrites that chunk.
        let mut shadow = vec![0u16; 6];
        assert_eq!(changed_runs(&[0u16; 10], &mut shadow, 4), vec![(1, 3)]);
    }
}
