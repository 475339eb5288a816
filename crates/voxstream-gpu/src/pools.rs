//! The node and brick pools in GPU memory: storage buffers the ray caster reads, kept equal to the CPU pools by
//! uploading, each pass, only the node tiles and brick slots whose contents changed (GigaVoxels [P09] §5: the CPU
//! serves requests and the GPU copy follows; Reichl's pools, seed 004).
//!
//! The cache manager does not report which slots it rewrote, so each pass compares the pools with the shadow copy
//! of what was uploaded last, tile by tile and brick by brick, and writes the runs that differ. That comparison reads
//! the whole pool once per pass on the CPU (memory bandwidth: about 10 ms per 100 MB); dirty lists from the cache
//! manager would remove it. Bricks are stored as they are in the CPU pool (16-bit voxels, two to a 32-bit word);
//! the buffers are allocated once at the pools' size, which the memory budget fixed, and never grow past it.

use voxstream_core::{Node, TreeView};

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
    /// The brick pool (16-bit voxels, padded to whole 32-bit words).
    pub voxels: wgpu::Buffer,
    node_shadow: Vec<Node>,
    voxel_shadow: Vec<u16>,
    nodes_per_tile: usize,
    voxels_per_brick: usize,
}

impl GpuPools {
    /// Buffers for pools of `view`'s size (everything uploaded on the first [`GpuPools::update`]).
    pub fn new(device: &wgpu::Device, view: &TreeView<'_>, max_storage_bytes: u64) -> Result<GpuPools, GpuError> {
        let node_bytes = (view.nodes.len() * size_of::<Node>()) as u64;
        let voxel_count = view.voxels.len().next_multiple_of(2);
        let voxel_bytes = (voxel_count * 2) as u64;
        for (what, bytes) in [("node pool", node_bytes), ("brick pool", voxel_bytes)] {
            if bytes > max_storage_bytes {
                return Err(GpuError::TooLarge { what, bytes, limit: max_storage_bytes });
            }
        }
        let buffer = |label, size: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size.max(4),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        Ok(GpuPools {
            nodes: buffer("node pool", node_bytes),
            voxels: buffer("brick pool", voxel_bytes),
            // Shadows that differ from any pool everywhere, so the first update writes everything: the GPU buffers
            // start as zeros, and a zero node or voxel would otherwise be taken as already there.
            node_shadow: vec![Node { child_word: u32::MAX, data_word: u32::MAX }; view.nodes.len()],
            voxel_shadow: vec![u16::MAX; voxel_count],
            nodes_per_tile: view.shape.nodes_per_tile() as usize,
            voxels_per_brick: view.shape.voxels_per_brick(),
        })
        .map(|mut pools| {
            // Voxels past the pool's end (padding) are never read; make them equal so they are never written.
            if voxel_count > view.voxels.len() {
                pools.voxel_shadow[voxel_count - 1] = 0;
            }
            pools
        })
    }

    /// Whether these buffers hold pools of `view`'s size and shape.
    pub fn fits(&self, view: &TreeView<'_>) -> bool {
        self.node_shadow.len() == view.nodes.len()
            && self.voxel_shadow.len() == view.voxels.len().next_multiple_of(2)
            && self.nodes_per_tile == view.shape.nodes_per_tile() as usize
            && self.voxels_per_brick == view.shape.voxels_per_brick()
    }

    /// Writes the tiles and bricks of `view` that differ from what was uploaded, merged into runs of neighbours.
    pub fn update(&mut self, queue: &wgpu::Queue, view: &TreeView<'_>) -> UploadStats {
        let mut stats = UploadStats::default();
        // Nodes, tile by tile.
        let per_tile = self.nodes_per_tile;
        let runs = changed_runs(view.nodes, &self.node_shadow, per_tile);
        for (from, to) in runs {
            let (a, b) = (from * per_tile, (to * per_tile).min(view.nodes.len()));
            self.node_shadow[a..b].copy_from_slice(&view.nodes[a..b]);
            let bytes = bytemuck::cast_slice(&self.node_shadow[a..b]);
            queue.write_buffer(&self.nodes, (a * size_of::<Node>()) as u64, bytes);
            stats.node_bytes += bytes.len() as u64;
            stats.tiles += (to - from) as u64;
        }
        // Bricks, slot by slot; writes start and end on whole words (the shadow is padded to an even length).
        let per_brick = self.voxels_per_brick;
        let runs = changed_runs(view.voxels, &self.voxel_shadow[..view.voxels.len()], per_brick);
        for (from, to) in runs {
            let (a, b) = (from * per_brick, (to * per_brick).min(view.voxels.len()));
            self.voxel_shadow[a..b].copy_from_slice(&view.voxels[a..b]);
            let (a, b) = (a & !1, b.next_multiple_of(2));
            let bytes = bytemuck::cast_slice(&self.voxel_shadow[a..b]);
            queue.write_buffer(&self.voxels, (a * 2) as u64, bytes);
            stats.brick_bytes += bytes.len() as u64;
            stats.bricks += (to - from) as u64;
        }
        stats
    }
}

/// The runs `[from, to)` of chunks of `chunk` items where `current` differs from `shadow` (equal lengths), with
/// neighbouring changed chunks merged.
fn changed_runs<T: PartialEq>(current: &[T], shadow: &[T], chunk: usize) -> Vec<(usize, usize)> {
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for (index, (now, then)) in current.chunks(chunk).zip(shadow.chunks(chunk)).enumerate() {
        if now != then {
            match runs.last_mut() {
                Some((_, to)) if *to == index => *to = index + 1,
                _ => runs.push((index, index + 1)),
            }
        }
    }
    runs
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn changed_chunks_merge_into_runs() {
        let shadow = [0u16; 10];
        let mut current = shadow;
        assert!(changed_runs(&current, &shadow, 2).is_empty());
        current[0] = 1; // chunk 0
        current[3] = 1; // chunk 1
        current[9] = 1; // chunk 4 (the last)
        assert_eq!(changed_runs(&current, &shadow, 2), vec![(0, 2), (4, 5)]);
        // A last chunk shorter than the others.
        assert_eq!(changed_runs(&current[..9], &shadow[..9], 4), vec![(0, 1)]);
    }
}
