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
    node_capacity: usize,
    voxel_capacity: usize,
    nodes_per_tile: usize,
    voxels_per_brick: usize,
}

impl GpuPools {
    /// Buffers for pools of `view`'s capacity (everything resident is uploaded by the first [`GpuPools::update`]).
    pub fn new(device: &wgpu::Device, view: &TreeView<'_>, max_storage_bytes: u64) -> Result<GpuPools, GpuError> {
        let nodes_per_tile = view.shape.nodes_per_tile() as usize;
        let voxels_per_brick = view.shape.voxels_per_brick();
        // The pools grow up to their capacity with use; a view may already hold more if built by hand.
        let node_count = (view.capacity.tiles as usize * nodes_per_tile).max(view.nodes.len());
        let voxel_count = (view.capacity.bricks as usize * voxels_per_brick).max(view.voxels.len()).next_multiple_of(2);
        let node_bytes = (node_count * size_of::<Node>()) as u64;
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
            // Empty shadows: what is resident is uploaded on the first update, the rest as the pools grow.
            node_shadow: Vec::with_capacity(node_count),
            voxel_shadow: Vec::with_capacity(voxel_count),
            node_capacity: node_count,
            voxel_capacity: voxel_count,
            nodes_per_tile,
            voxels_per_brick,
        })
    }

    /// Whether these buffers can hold `view`'s pools (same shape, within their capacity).
    pub fn fits(&self, view: &TreeView<'_>) -> bool {
        view.nodes.len() <= self.node_capacity
            && view.voxels.len() <= self.voxel_capacity
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
        // Bricks, slot by slot; writes start and end on whole 32-bit words (the shadow is padded to an even length
        // with a zero that is never read).
        let per_brick = self.voxels_per_brick;
        let resident = view.voxels.len();
        if self.voxel_shadow.len() > resident {
            self.voxel_shadow.truncate(resident);
        }
        let runs = changed_runs(view.voxels, &mut self.voxel_shadow, per_brick);
        if resident % 2 == 1 {
            self.voxel_shadow.push(0);
        }
        for (from, to) in runs {
            let (a, b) = (from * per_brick, (to * per_brick).min(resident));
            let (a, b) = (a & !1, b.next_multiple_of(2));
            let bytes = bytemuck::cast_slice(&self.voxel_shadow[a..b]);
            queue.write_buffer(&self.voxels, (a * 2) as u64, bytes);
            stats.brick_bytes += bytes.len() as u64;
            stats.bricks += (to - from) as u64;
        }
        stats
    }
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
