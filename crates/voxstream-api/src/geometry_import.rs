//! `voxstream import` of a mesh or particle file: bakes the producer's finest level into a store, for reuse.
//!
//! The baked volume is the box around the object (plus the band or kernel margin) at the finest level of the tree
//! `--resolution` asks for, read as z slices by the store importer like any volume file. Slices are made a brick row
//! at a time: every brick of the row is produced on the worker threads (bricks the oracle knows constant are filled
//! without producing), so memory stays at one row of bricks (refused above [`MAX_ROW_BYTES`]). Values are `f32`: a mesh's 0 (outside) to 1 (inside),
//! the surface at ½; particles' density in the file's mass per cubic file unit.

use rayon::prelude::*;
use voxstream_core::{NodeContent, NodeKey, Producer};
use voxstream_store::{DType, Orientation, StoreError, VolumeInfo, VolumeSource};

use crate::geometry_source::GeometryProducer;

/// The orientation of mesh and particle files: `+x` the model's left (the viewer's right), `+y` up, `+z` its front.
pub const MESH_CONVENTION: Orientation = Orientation::LSA;

/// The most memory one row of bricks may take while baking (the rest of the import streams).
pub const MAX_ROW_BYTES: u64 = 4 << 30;

/// The resolution `voxstream import` bakes a geometry file at unless `--resolution` says otherwise.
pub const DEFAULT_BAKE_RESOLUTION: u64 = 512;

/// A geometry producer's finest level, cropped to the object, as a volume source.
pub struct BakedGeometry {
    producer: GeometryProducer,
    info: VolumeInfo,
    /// First voxel (at the finest level) of the crop.
    lower: [u64; 3],
    level: u32,
    /// The values the voxel values 0 and 1 stand for: `lower + v·span`.
    value_lower: f32,
    value_span: f32,
    /// Next slice to hand out (0-based within the crop).
    next_slice: u64,
    /// The brick row holding slices `row_first..row_first + brick_size` of the crop (global z), x fastest.
    row: Vec<f32>,
    row_first: Option<u64>,
}

impl BakedGeometry {
    /// Bakes `producer`'s finest level around the object's `bounds` (file units); the voxel values 0 and 1 stand for
    /// `value_range`. Refuses a resolution whose brick row would not fit in [`MAX_ROW_BYTES`].
    pub fn new(
        producer: GeometryProducer,
        value_range: [f64; 2],
        bounds: ([f64; 3], [f64; 3]),
    ) -> anyhow::Result<BakedGeometry> {
        let shape = producer.shape();
        let level = shape.max_level;
        let resolution = shape.virtual_resolution();
        let fit = producer.fit();
        let margin = producer.margin();
        let voxel = 1.0 / resolution as f64;
        let (lower, upper) = (fit.to_unit(bounds.0), fit.to_unit(bounds.1));
        let mut first = [0u64; 3];
        let mut dims = [1u64; 3];
        for a in 0..3 {
            let from = ((lower[a] - margin).max(0.0) / voxel).floor() as u64;
            let to = (((upper[a] + margin).min(1.0) / voxel).ceil() as u64).min(resolution);
            first[a] = from.min(resolution - 1);
            dims[a] = to.saturating_sub(first[a]).max(1);
        }
        let size = fit.size;
        let info = VolumeInfo {
            dims,
            dtype: DType::F32,
            spacing: [size * voxel; 3],
            // Voxel i of the level is centred at (i + ½)·voxel in the cube.
            origin: [0, 1, 2].map(|a| fit.origin[a] + (first[a] as f64 + 0.5) * voxel * size),
            unit: None,
            // Mesh and particle files' convention, `+y` up and `+z` the front (the model faces the viewer of an
            // OpenGL camera), said as an anatomical orientation: the store's default view and `--view anterior`
            // are then the file's own default view and front, not a model lying on its side.
            orientation: Some(MESH_CONVENTION),
        };
        // A row of slices (f32) and, while it is made, its bricks (u16 with borders, about 2× more per voxel).
        let m = u64::from(shape.brick_size);
        let row_bytes = dims[0].saturating_mul(dims[1]).saturating_mul(m).saturating_mul(4 + 2 * 2);
        if row_bytes > MAX_ROW_BYTES {
            anyhow::bail!(
                "baking {}x{}x{} voxels needs {} MiB for one row of bricks, more than {} MiB: lower --resolution",
                dims[0],
                dims[1],
                dims[2],
                row_bytes >> 20,
                MAX_ROW_BYTES >> 20
            );
        }
        Ok(BakedGeometry {
            producer,
            info,
            lower: first,
            level,
            value_lower: value_range[0] as f32,
            value_span: (value_range[1] - value_range[0]) as f32,
            next_slice: 0,
            row: Vec::new(),
            row_first: None,
        })
    }

    /// Fills `self.row` with the brick row holding global voxel slice `z`.
    fn make_row(&mut self, z: u64) -> Result<(), StoreError> {
        let shape = self.producer.shape();
        let m = u64::from(shape.brick_size);
        let b = shape.stored_brick_size() as usize;
        let row_first = z / m * m;
        let [dx, dy, _] = self.info.dims;
        let bricks_x = (self.lower[0] / m)..=((self.lower[0] + dx - 1) / m);
        let bricks_y = (self.lower[1] / m)..=((self.lower[1] + dy - 1) / m);
        let keys: Vec<NodeKey> = bricks_y
            .flat_map(|by| bricks_x.clone().map(move |bx| [bx, by]))
            .map(|[bx, by]| NodeKey { level: self.level, ijk: [bx, by, row_first / m] })
            .collect();
        let producer = &self.producer;
        let bricks: Vec<(NodeKey, Option<Vec<u16>>, f32)> = keys
            .par_iter()
            .map(|&key| {
                if let Some(value) = producer.oracle(key) {
                    return Ok((key, None, value));
                }
                let mut voxels = vec![0u16; shape.voxels_per_brick()];
                let produced = producer.produce(key, &mut voxels)?;
                Ok(match produced.content {
                    NodeContent::Brick => (key, Some(voxels), 0.0),
                    NodeContent::Empty => (key, None, 0.0),
                    NodeContent::Constant(value) => (key, None, value),
                })
            })
            .collect::<Result<_, voxstream_core::ProduceError>>()
            .map_err(|error| StoreError::format(std::path::Path::new("(geometry)"), error.to_string()))?;
        let (dx, dy) = (dx as usize, dy as usize);
        self.row.clear();
        self.row.resize(dx * dy * m as usize, 0.0);
        for (key, voxels, constant) in bricks {
            for k in 0..m as usize {
                for j in 0..m as usize {
                    let gy = key.ijk[1] * m + j as u64;
                    if gy < self.lower[1] || gy >= self.lower[1] + dy as u64 {
                        continue;
                    }
                    for i in 0..m as usize {
                        let gx = key.ijk[0] * m + i as u64;
                        if gx < self.lower[0] || gx >= self.lower[0] + dx as u64 {
                            continue;
                        }
                        let normalised = match &voxels {
                            Some(v) => f32::from(v[((k + 1) * b + j + 1) * b + i + 1]) / 65535.0,
                            None => constant,
                        };
                        let at = (k * dy + (gy - self.lower[1]) as usize) * dx + (gx - self.lower[0]) as usize;
                        self.row[at] = self.value_lower + normalised * self.value_span;
                    }
                }
            }
        }
        self.row_first = Some(row_first);
        Ok(())
    }
}

impl VolumeSource for BakedGeometry {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn read_slices(&mut self, count: usize, out: &mut Vec<f32>) -> Result<(), StoreError> {
        let m = u64::from(self.producer.shape().brick_size);
        let slice = (self.info.dims[0] * self.info.dims[1]) as usize;
        for _ in 0..count {
            let z = self.lower[2] + self.next_slice;
            if self.row_first != Some(z / m * m) {
                self.make_row(z)?;
            }
            let k = (z - z / m * m) as usize;
            out.extend_from_slice(&self.row[k * slice..(k + 1) * slice]);
            self.next_slice += 1;
        }
        Ok(())
    }
}
