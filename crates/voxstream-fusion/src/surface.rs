//! The fused surface as points: the centre of every face between a confident voxel behind the surface and a voxel
//! known to be in front of it (confident, or in a brick removed as empty, which is what an absent brick means).
//! Faces towards voxels no window was sure of are not surface: behind the band the sensor never saw, the inside
//! region simply ends. These points are what surface error is measured on, and what `fuse --points` writes.
//!
//! Where voxels keep surface offsets ([`crate::brick`]), the points are where the offsets of two neighbours cross
//! zero, on the segment between their centres, as a TSDF's surface is found (so the offsets, averaged over every
//! window, also decide where the surface is, not only the bits), and [`smooth_points`] leaves their positions alone;
//! faces of the bits where neither voxel keeps an offset still give their centres. (One voxel's distance
//! alone does not place a point: distances are projective, along the line of sight, so only the ratio of two is a
//! position on the segment.)
//!
//! Face centres make stairs: a plane at a slant is drawn as voxel faces up to half a voxel from it. [`smooth_points`]
//! moves every other point to the average of the points within 1.5 voxels that face its way (normals no more than 90°
//! apart, so the two sides of a thin wall never mix), which puts the stairs' points on the plane they approximate: the
//! object-space counterpart of the screen-space smoothing rendered views get, and what the thesis suggests for
//! extracting a surface from the bits ("mesh-based smoothing algorithms", §8.3).

use std::io::Write;
use std::path::Path;

use glam::{DVec3, IVec3};
use rayon::prelude::*;

use crate::brick::{voxel_index, BRICK};
use crate::brick_map::BrickMap;
use crate::FusionError;

/// Whether voxel `v` is known to be in front of the surface.
fn known_outside(map: &BrickMap, v: IVec3) -> bool {
    let (key, local) = BrickMap::split(v);
    match map.brick(key) {
        None => true,
        Some(b) => {
            let i = voxel_index(local.x, local.y, local.z);
            !b.inside.get(i) && b.confident.get(i)
        }
    }
}

/// A surface point with the colour of its voxel, where it has one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub position: DVec3,
    pub normal: DVec3,
    pub colour: Option<[u8; 3]>,
    /// Placed where two voxels' surface offsets cross zero (not moved by [`smooth_points`]).
    pub interpolated: bool,
}

/// The surface offset of voxel `v`, where it keeps one.
fn offset_at(map: &BrickMap, v: IVec3) -> Option<f32> {
    let (key, local) = BrickMap::split(v);
    map.brick(key)?.offset(local.x, local.y, local.z)
}

/// The surface points of the resident bricks.
pub fn surface_points(map: &BrickMap) -> Vec<SurfacePoint> {
    let keys: Vec<IVec3> = map.iter().map(|(k, _)| *k).collect();
    let voxel = map.voxel();
    const AXES: [IVec3; 6] = [IVec3::X, IVec3::Y, IVec3::Z, IVec3::NEG_X, IVec3::NEG_Y, IVec3::NEG_Z];
    keys.par_iter()
        .flat_map_iter(|&key| {
            let brick = map.brick(key).expect("listed");
            let mut points = Vec::new();
            let both = brick.inside.and(&brick.confident);
            if both.is_empty() && brick.offsets.is_empty() {
                return points.into_iter();
            }
            for z in 0..BRICK {
                for y in 0..BRICK {
                    for x in 0..BRICK {
                        let v = key * BRICK + IVec3::new(x, y, z);
                        let offset = brick.offset(x, y, z);
                        // Zero crossings of the offsets, from the voxel behind the surface to each neighbour in
                        // front of it, as a TSDF's surface is found.
                        if let Some(a) = offset.filter(|&a| a < 0.0) {
                            for axis in AXES {
                                let Some(b) = offset_at(map, v + axis).filter(|&b| b >= 0.0) else { continue };
                                let t = f64::from(-a) / f64::from(b - a);
                                let normal = axis.as_dvec3();
                                points.push(SurfacePoint {
                                    position: map.centre(v) + normal * (t * voxel),
                                    normal,
                                    colour: brick.colour(x, y, z),
                                    interpolated: true,
                                });
                            }
                        }
                        if !both.get(voxel_index(x, y, z)) {
                            continue;
                        }
                        // Faces of the bits where neither voxel keeps an offset.
                        for axis in AXES {
                            if known_outside(map, v + axis) && offset.is_none() && offset_at(map, v + axis).is_none() {
                                let normal = axis.as_dvec3();
                                points.push(SurfacePoint {
                                    position: map.centre(v) + normal * (0.5 * voxel),
                                    normal,
                                    colour: brick.colour(x, y, z),
                                    interpolated: false,
                                });
                            }
                        }
                    }
                }
            }
            points.into_iter()
        })
        .collect()
}

/// Each point given the average normal of the points within `radius` (metres) whose normals are within 90° of its
/// own, itself included, and, unless it was interpolated from surface offsets, their average position.
pub fn smooth_points(points: &[SurfacePoint], radius: f64) -> Vec<SurfacePoint> {
    let cell = |p: DVec3| (p / radius).floor().as_ivec3();
    let mut grid: rustc_hash::FxHashMap<IVec3, Vec<u32>> = rustc_hash::FxHashMap::default();
    for (i, p) in points.iter().enumerate() {
        grid.entry(cell(p.position)).or_default().push(i as u32);
    }
    let radius_squared = radius * radius;
    points
        .par_iter()
        .map(|p| {
            let c = cell(p.position);
            let (mut sum, mut normal, mut count) = (DVec3::ZERO, DVec3::ZERO, 0.0);
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        for &j in grid.get(&(c + IVec3::new(dx, dy, dz))).into_iter().flatten() {
                            let q = &points[j as usize];
                            if q.normal.dot(p.normal) >= 0.0
                                && q.position.distance_squared(p.position) <= radius_squared
                            {
                                sum += q.position;
                                normal += q.normal;
                                count += 1.0;
                            }
                        }
                    }
                }
            }
            SurfacePoint {
                position: if p.interpolated { p.position } else { sum / count },
                normal: normal.normalize_or(p.normal),
                colour: p.colour,
                interpolated: p.interpolated,
            }
        })
        .collect()
}

/// Writes points as a binary little-endian PLY (x, y, z as float; nx, ny, nz; red, green, blue as uchar, grey
/// where a voxel has no colour), readable by Open3D, MeshLab and `voxstream render`.
pub fn write_points_ply(path: &Path, points: &[SurfacePoint]) -> Result<(), FusionError> {
    let error = |e: std::io::Error| FusionError::File { path: path.to_path_buf(), message: e.to_string() };
    let file = std::fs::File::create(path).map_err(error)?;
    let mut out = std::io::BufWriter::new(file);
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment voxstream fuse: surface voxel faces\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\n\
         property float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        points.len()
    )
    .map_err(error)?;
    for p in points {
        for c in p.position.to_array().into_iter().chain(p.normal.to_array()) {
            out.write_all(&(c as f32).to_le_bytes()).map_err(error)?;
        }
        out.write_all(&p.colour.unwrap_or([160, 160, 160])).map_err(error)?;
    }
    out.flush().map_err(error)
}
