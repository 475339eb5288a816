//! The streaming producer: bricks with their one-voxel borders, read from a store on the cache manager's worker
//! threads (GigaVoxels' producer reading from disk; Reichl's streaming supplier, seed 004 ch. 4).
//!
//! Tree level `d` reads store level `L − d`, brick `ijk` = chunk `ijk`; the border comes from the neighbouring
//! chunks (clamped at the volume's edge). Values are normalised by the volume's value range. The oracle answers
//! from the per-brick min/max, which covers every full-resolution sample below a brick, so a brick with `min = max`
//! is constant at every finer level too; bricks outside the volume are empty.

use std::sync::Arc;

use voxstream_core::{quantize, NodeContent, NodeKey, ProduceError, Produced, Producer, TreeShape};

use crate::error::StoreError;
use crate::store_reader::StoreReader;

/// Produces bricks from a store.
#[derive(Clone)]
pub struct StoreProducer {
    reader: Arc<StoreReader>,
    shape: TreeShape,
    lower: f32,
    inverse_span: f32,
}

impl StoreProducer {
    /// A producer over an open store.
    pub fn new(reader: Arc<StoreReader>) -> Result<StoreProducer, StoreError> {
        let layout = reader.layout();
        let shape = TreeShape::new(2, layout.brick_size as u32, layout.max_tree_level())
            .map_err(|e| StoreError::store(reader.path(), e.to_string()))?;
        let [lower, upper] = reader.attributes().value_range;
        let span = (upper - lower) as f32;
        Ok(StoreProducer {
            reader,
            shape,
            lower: lower as f32,
            inverse_span: if span > 0.0 { 1.0 / span } else { 0.0 },
        })
    }

    /// The store.
    pub fn reader(&self) -> &StoreReader {
        &self.reader
    }

    fn normalise(&self, value: f32) -> f32 {
        (value - self.lower) * self.inverse_span
    }

    fn store_level(&self, key: &NodeKey) -> usize {
        (self.shape.max_level - key.level) as usize
    }
}

impl Producer for StoreProducer {
    fn shape(&self) -> TreeShape {
        self.shape
    }

    fn oracle(&self, key: NodeKey) -> Option<f32> {
        match self.reader.brick_range(self.store_level(&key), key.ijk) {
            None => Some(0.0),
            Some([min, max]) if min == max => Some(self.normalise(min)),
            Some(_) => None,
        }
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        let level = self.store_level(&key);
        let is_terminal = level == 0;
        let dims = self.reader.layout().level_dims[level];
        let m = self.shape.brick_size as i64;
        let b = m as usize + 2;
        let start = key.ijk.map(|v| v as i64 * m - 1);
        if (0..3).any(|a| start[a] + 1 >= dims[a] as i64) {
            return Ok(Produced { content: NodeContent::Empty, is_terminal: true });
        }
        // The region the brick and its border need, clamped to the level.
        let lower = [0, 1, 2].map(|a| start[a].max(0) as u64);
        let upper = [0, 1, 2].map(|a| ((start[a] + b as i64) as u64).min(dims[a]));
        let size = [0, 1, 2].map(|a| upper[a] - lower[a]);
        let samples = self.reader.read_region(level, lower, size).map_err(|e| ProduceError {
            level: key.level,
            ijk: key.ijk,
            message: e.to_string(),
        })?;
        let (sx, sy) = (size[0] as usize, size[1] as usize);
        let mut index = 0;
        for k in 0..b {
            let z = (start[2] + k as i64).clamp(lower[2] as i64, upper[2] as i64 - 1) as usize - lower[2] as usize;
            for j in 0..b {
                let y = (start[1] + j as i64).clamp(lower[1] as i64, upper[1] as i64 - 1) as usize - lower[1] as usize;
                let row = (z * sy + y) * sx;
                for i in 0..b {
                    let x = (start[0] + i as i64).clamp(lower[0] as i64, upper[0] as i64 - 1) as usize - lower[0] as usize;
                    voxels[index] = quantize(self.normalise(samples[row + x]));
                    index += 1;
                }
            }
        }
        Ok(Produced { content: NodeContent::Brick, is_terminal })
    }
}
