//! # voxstream-geometry: sources that are not voxel grids
//!
//! Producers sit at the far end of the loop (camera → renderer → feedback → cache manager → **producers** → pools).
//! This crate's producers make each brick when a ray asks for it, at the resolution the ray needs, from a spatial
//! index over triangles or particles: no preprocessing pass and no resolution fixed in advance (GigaVoxels [R08] §4;
//! Reichl, seed 004, ch. 5 and 7).
//!
//! The producers:
//!
//! - [`MeshProducer`] ([`mesh_producer`]): bricks of a triangle mesh's signed distance (optionally amplified with
//!   noise into a hypertexture), from [`MeshDistance`] over a [`triangle_bvh`] (Reichl ch. 7; GigaVoxels [R08] §7).
//! - [`ParticleProducer`] ([`particle_producer`]): SPH density (or a scalar attribute) resampled from particles held
//!   in memory, through the support-class index of [`particle_index`] (Reichl ch. 5).
//! - [`SuperbrickParticleProducer`] ([`superbrick_particles`]): the same bricks from particle sets larger than
//!   memory, binned once on disk into superbricks and loaded into a bounded cache (Reichl ch. 5).
//!
//! What they are made from:
//!
//! - [`formats`]: readers for PLY, OBJ, OFF, STL (meshes), and PLY points, `x y z` text, GRO, PDB, VTK legacy and
//!   VTK XML `.vtp`/`.vtu` (particles).
//! - [`TriangleMesh`] and [`ParticleSet`]: the validated data.

pub mod error;
pub mod formats;
pub mod particles;
pub mod triangle_mesh;

pub use error::GeometryError;
pub use particles::{ParticleSet, RawParticles};
pub use triangle_mesh::{RawMesh, TriangleMesh};
pub mod mesh_distance;
pub mod mesh_producer;
mod neighbour_spacing;
pub mod particle_index;
pub mod particle_producer;
pub mod superbrick_particles;
pub mod triangle_bvh;

pub use mesh_distance::{MeshDistance, UnitCubeFit};
pub use mesh_producer::{Amplification, MeshProducer, MeshTreeSettings};
pub use particle_producer::{ParticleProducer, ParticleTreeSettings};
pub use superbrick_particles::{OutOfCoreSettings, ParticleChunks, SuperbrickParticleProducer, SuperbrickStatistics};
