//! # voxstream-render: the CPU cone-tracing ray caster
//!
//! Where it sits in the loop:
//!
//! ```text
//! camera → [renderer] → feedback → cache manager → producers → pools → [renderer]
//! ```
//!
//! The renderer reads a [`voxstream_core::TreeView`] (flat node and brick pools, shared layout with a GPU backend)
//! and writes a [`voxstream_core::FeedbackBuffer`]. It knows nothing of producers or the cache manager.
//!
//! - [`Camera`]: eye/target/up/fov, right-handed like `vtkCamera`.
//! - [`TransferFunction`] / [`TransferLut`]: piecewise-linear 1-D transfer function, VTK's opacity unit distance.
//! - [`Traversal`]: one ray through the tree (descent, cone LOD, skipping, samples), handing samples to an
//!   [`Integrand`]; [`emission_absorption`] is the volume-rendering integrand, with tables pre-corrected for the
//!   step ([`step_table`]); [`isosurface`] is the exact first-hit integrand (Knoll et al.), which takes whole brick
//!   segments and intersects each trilinear cell ([`cell_walk`], [`cell_intersection`]); [`surfaces_in_volume`]
//!   draws those surfaces inside the volume rendering; [`projection`] keeps the largest, smallest or mean value
//!   along each ray (MIP, MinIP); [`clip_plane`] cuts rays to half-spaces before they start.
//! - [`render_frame`]: rayon over 16×16 image tiles, one ray per pixel: [`RayCaster`] for volumes,
//!   [`surface_caster::SurfaceCaster`] when the settings name isosurfaces.
//!
//! ```
//! use voxstream_render::{TransferFunction, TransferLut};
//! let tf = TransferFunction::from_json(r#"{"points": [[0, 0,0,0, 0], [1, 1,1,1, 1]]}"#).unwrap();
//! let lut = TransferLut::new(&tf, 0.0, 1.0, 0.01);
//! assert!(lut.lookup(1.0).sigma > lut.lookup(0.5).sigma);
//! ```

pub mod adaptive_step;
pub mod annotations;
pub mod block_visibility;
pub mod camera;
pub mod cell_intersection;
pub mod cell_walk;
pub mod clip_plane;
pub mod emission_absorption;
pub mod error;
pub mod frame;
pub mod gathered_corners;
pub mod image;
pub mod instruction_set;
pub mod integrand;
pub mod isosurface;
pub mod lighting;
pub mod paraview_colormap;
pub mod preintegration;
pub mod projection;
pub mod ray_caster;
pub mod sampler;
pub mod settings;
pub mod slice_in_volume;
pub mod step_table;
pub mod surface_caster;
pub mod surfaces_in_volume;
pub mod transfer_function;
pub mod traversal;

pub use block_visibility::BlockVisibility;
pub use camera::{Camera, CameraFrame};
pub use clip_plane::{ClipPlane, MAX_CLIP_PLANES};
pub use error::RenderError;
pub use frame::{
    frame_buffer_bytes, render_frame, render_pass, PassInputs, ProgressiveImage, RenderedFrame, FRAME_BYTES_PER_PIXEL,
    IMAGE_TILE,
};
pub use image::{psnr, Image};
pub use instruction_set::{InstructionSet, RayLoopBuild};
pub use integrand::{BrickSpan, Integrand, Sample};
pub use isosurface::{IsoSurface, SurfaceNormals, SurfaceParameters, SurfaceSettings, MAX_SURFACES};
pub use projection::{Projection, ProjectionCaster};
pub use ray_caster::RayCaster;
pub use settings::{level_colour, PhongCoefficients, RenderSettings, Shading, VolumePlacement};
pub use transfer_function::{TransferFunction, TransferLut};
pub use traversal::{DescentPath, Ray, RaySource, RayStats, Traversal};
