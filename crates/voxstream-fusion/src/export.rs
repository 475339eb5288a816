//! The fused scene saved as a store that `render` and `view` open like any other (seed 004 §8.3: "once the scene
//! has been scanned, a smooth surface can be reconstructed from the binary representation").
//!
//! Each sample is a weighted share of confident voxels behind the surface around it, as `u8` (0–255): the voxel itself
//! weighs 6, its six face neighbours 1 each. The isosurface at 127.5 (`render SCENE --iso 128`) then runs along the
//! voxel faces with its stairs rounded off, and a sheet one voxel thick (a floor seen from above, whose inside the
//! sensor never saw deeper) keeps its surface: a 3×3×3 box filter would lower it to 9/27 and lose it. The volume spans
//! the bricks' bounds plus one voxel; slices are made one at a time from the bricks of their brick layer, and
//! [`crate::export::FusedVolume::new`] refuses a scene whose import slab would not fit the memory it is given, naming
//! the numbers.
//!
//! A voxel that keeps a surface offset ([`crate::brick`]) is sampled from it instead: `127.5 · (1 − d / R)` for its
//! distance `d` in voxels and the offsets' range `R` (255 at `R` voxels behind the surface, 0 at `R` in front), so
//! the isosurface at 127.5 passes where the frames' averaged distances cross zero, between voxel centres, rather
//! than along the faces.

use glam::IVec3;
use rustc_hash::FxHashMap;
use voxstream_store::volume::{DType, VolumeInfo, VolumeSource};
use voxstream_store::StoreError;

use crate::brick::{voxel_index, BRICK, NO_OFFSET, OFFSET_RANGE};
use crate::brick_map::BrickMap;
use crate::FusionError;

/// The import keeps one slab of this many slices per level (its default brick size) in ~2.4 bytes per sample.
const SLAB_SLICES: u64 = 32;
const SLAB_BYTES_PER_SAMPLE: f64 = 2.4;

/// A fused scene as a volume of `u8` samples, made slice by slice.
pub struct FusedVolume<'a> {
    map: &'a BrickMap,
    info: VolumeInfo,
    /// The first voxel of the volume.
    lo: IVec3,
    /// Brick keys by brick z.
    layers: FxHashMap<i32, Vec<IVec3>>,
    /// Keys of the bricks that keep surface offsets (also outside-only ones), by brick z.
    surface_layers: FxHashMap<i32, Vec<IVec3>>,
    /// The next slice to hand out.
    next: i64,
    /// Occupancy planes of slices `next - 1`, `next`, `next + 1` (0 or 1 per sample).
    planes: [Vec<u8>; 3],
    /// Class planes of slices `next`, `next + 1`, `next + 2` (see [`FusedVolume::classes`]).
    classes: [Vec<u8>; 3],
}

impl<'a> FusedVolume<'a> {
    /// The volume of `map`'s resident bricks; `memory` bounds the import's slab. `None` when there is nothing
    /// confident to save.
    pub fn new(map: &'a BrickMap, memory: u64) -> Result<Option<FusedVolume<'a>>, FusionError> {
        let mut bounds: Option<(IVec3, IVec3)> = None;
        let mut layers: FxHashMap<i32, Vec<IVec3>> = FxHashMap::default();
        let mut surface_layers: FxHashMap<i32, Vec<IVec3>> = FxHashMap::default();
        for (key, brick) in map.iter() {
            if !brick.offsets.is_empty() {
                surface_layers.entry(key.z).or_default().push(*key);
            }
            if brick.inside.and(&brick.confident).is_empty() {
                continue;
            }
            layers.entry(key.z).or_default().push(*key);
            bounds = Some(match bounds {
                None => (*key, *key),
                Some((lo, hi)) => (lo.min(*key), hi.max(*key)),
            });
        }
        let Some((lo, hi)) = bounds else { return Ok(None) };
        let lo = lo * BRICK - IVec3::ONE;
        let hi = (hi + IVec3::ONE) * BRICK + IVec3::ONE;
        let dims = (hi - lo).as_i64vec3();
        let dims = [dims.x as u64, dims.y as u64, dims.z as u64];
        let slab = (SLAB_SLICES * dims[0] * dims[1]) as f64 * SLAB_BYTES_PER_SAMPLE;
        if slab > memory as f64 {
            let voxel = map.voxel();
            return Err(FusionError::Budget(format!(
                "the scene spans {:.1} × {:.1} × {:.1} m ({} × {} × {} voxels): saving it as a store needs {} MiB \
                 for one slab, over --memory {} MiB; raise --memory or fuse with a coarser --voxel",
                dims[0] as f64 * voxel,
                dims[1] as f64 * voxel,
                dims[2] as f64 * voxel,
                dims[0],
                dims[1],
                dims[2],
                (slab as u64) >> 20,
                memory >> 20
            )));
        }
        let voxel = map.voxel();
        let origin = map.centre(lo);
        let info = VolumeInfo {
            dims,
            dtype: DType::U8,
            spacing: [voxel; 3],
            origin: origin.to_array(),
            unit: None,
            orientation: None,
        };
        let area = (dims[0] * dims[1]) as usize;
        let mut volume = FusedVolume {
            map,
            info,
            lo,
            layers,
            surface_layers,
            next: 0,
            planes: [vec![0; area], vec![0; area], vec![0; area]],
            classes: [vec![OUTSIDE; area], vec![OUTSIDE; area], vec![OUTSIDE; area]],
        };
        // Occupancy of slice 0 needs the classes of slices -1, 0 and 1.
        volume.classes = [volume.classes(-1), volume.classes(0), volume.classes(1)];
        volume.planes[2] = volume.occupancy(&volume.classes);
        volume.classes = [volume.classes(0), volume.classes(1), volume.classes(2)];
        Ok(Some(volume))
    }

    /// Classes of slice `z`'s samples: [`OUTSIDE`] (known to be in front of the surface: confident, or in no
    /// brick), [`UNSURE`] (in a brick, not confident) or [`INSIDE`] (confident, behind the surface).
    fn classes(&self, z: i64) -> Vec<u8> {
        let [nx, ny, nz] = self.info.dims;
        let mut plane = vec![OUTSIDE; (nx * ny) as usize];
        if z < 0 || z >= nz as i64 {
            return plane;
        }
        let world_z = self.lo.z + z as i32;
        let (brick_z, local_z) = (world_z.div_euclid(BRICK), world_z.rem_euclid(BRICK));
        for key in self.layers.get(&brick_z).into_iter().flatten() {
            let brick = self.map.brick(*key).expect("listed from the map");
            for y in 0..BRICK {
                for x in 0..BRICK {
                    let i = voxel_index(x, y, local_z);
                    let class = match (brick.confident.get(i), brick.inside.get(i)) {
                        (true, true) => INSIDE,
                        (true, false) => OUTSIDE,
                        (false, _) => UNSURE,
                    };
                    let v = *key * BRICK + IVec3::new(x, y, local_z) - self.lo;
                    plane[v.y as usize * nx as usize + v.x as usize] = class;
                }
            }
        }
        plane
    }

    /// Surface offsets of slice `z`'s samples as `d / R · 127` (distance `d` in voxels, range `R`), [`NO_OFFSET`]
    /// where a sample keeps none.
    fn offsets(&self, z: i64) -> Vec<i8> {
        let [nx, ny, nz] = self.info.dims;
        let mut plane = vec![NO_OFFSET; (nx * ny) as usize];
        if z < 0 || z >= nz as i64 {
            return plane;
        }
        let world_z = self.lo.z + z as i32;
        let (brick_z, local_z) = (world_z.div_euclid(BRICK), world_z.rem_euclid(BRICK));
        for key in self.surface_layers.get(&brick_z).into_iter().flatten() {
            let brick = self.map.brick(*key).expect("listed from the map");
            for y in 0..BRICK {
                for x in 0..BRICK {
                    let v = *key * BRICK + IVec3::new(x, y, local_z) - self.lo;
                    if v.x < 0 || v.y < 0 || v.x as u64 >= nx || v.y as u64 >= ny {
                        continue;
                    }
                    if let Some(d) = brick.offset(x, y, local_z) {
                        plane[v.y as usize * nx as usize + v.x as usize] = (d / OFFSET_RANGE * 127.0).round() as i8;
                    }
                }
            }
        }
        plane
    }

    /// Occupancy (0/1) of the middle of three class planes: confident inside voxels, thickened by one voxel into
    /// unsure neighbours. An unsure voxel next to an inside one lies behind the surface (in front of it the voxels
    /// are known outside), so this never moves the surface the sensor saw; it closes the cracks a sheet one voxel
    /// thick shows where a tilted floor steps from one layer to the next.
    fn occupancy(&self, classes: &[Vec<u8>]) -> Vec<u8> {
        let [nx, ny, _] = self.info.dims.map(|d| d as usize);
        let [below, here, above] = [&classes[0], &classes[1], &classes[2]];
        let mut plane = vec![0u8; nx * ny];
        for y in 0..ny {
            for x in 0..nx {
                let i = y * nx + x;
                plane[i] = match here[i] {
                    INSIDE => 1,
                    UNSURE => {
                        let near = below[i] == INSIDE
                            || above[i] == INSIDE
                            || (x > 0 && here[i - 1] == INSIDE)
                            || (x + 1 < nx && here[i + 1] == INSIDE)
                            || (y > 0 && here[i - nx] == INSIDE)
                            || (y + 1 < ny && here[i + nx] == INSIDE);
                        u8::from(near)
                    }
                    _ => 0,
                };
            }
        }
        plane
    }
}

/// Sample classes of [`FusedVolume::classes`].
const OUTSIDE: u8 = 0;
const UNSURE: u8 = 1;
const INSIDE: u8 = 2;

impl VolumeSource for FusedVolume<'_> {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn read_slices(&mut self, count: usize, out: &mut Vec<f32>) -> Result<(), StoreError> {
        let [nx, ny, _] = self.info.dims.map(|d| d as usize);
        for _ in 0..count {
            let z = self.next;
            // Now: classes of z, z + 1, z + 2; occupancy of z + 1 from them, then the classes move on.
            self.planes.rotate_left(1);
            self.planes[2] = self.occupancy(&self.classes);
            self.classes.rotate_left(1);
            self.classes[2] = self.classes(z + 3);
            // 6 × the voxel + its six face neighbours, of 12 (the volume's one-voxel margin is empty, so edges
            // read zeros).
            let offsets = self.offsets(z);
            let [below, here, above] = &self.planes;
            for y in 0..ny {
                for x in 0..nx {
                    let i = y * nx + x;
                    if offsets[i] != NO_OFFSET {
                        out.push((127.5 * (1.0 - f32::from(offsets[i]) / 127.0)).round().clamp(0.0, 255.0));
                        continue;
                    }
                    let mut s = 6 * here[i] + below[i] + above[i];
                    if x > 0 {
                        s += here[i - 1];
                    }
                    if x + 1 < nx {
                        s += here[i + 1];
                    }
                    if y > 0 {
                        s += here[i - nx];
                    }
                    if y + 1 < ny {
                        s += here[i + nx];
                    }
                    out.push((f32::from(s) * 255.0 / 12.0).round());
                }
            }
            self.next += 1;
        }
        Ok(())
    }
}
