//! voxstream's fluid preview: giga-particle fluids as binary voxels (Reichl, seed 004 ch. 6;
//! `../shared/notes/reichl-framework.md` "Chapter 6").
//!
//! A fluid simulation's particles have one small, constant radius, so what a preview needs of them is where they
//! are, not a resampled density: the particles are binned once into bricks of a cell grid (the only preprocess,
//! [`binning`]), and a brick is turned into one bit per cell ([`bit_brick`]) only when a ray asks for it. Rays
//! cast spheres at the set cells ([`sphere_caster`]), coarser levels are the finer bits OR-ed (larger spheres),
//! isolated particles are classified as foam and drawn as a translucent volume ([`foam`]), and the depth image of
//! the spheres is smoothed in screen space by Rudin–Osher–Fatemi total variation ([`screen_space`]) before it is
//! shaded ([`shading`]). [`FluidScene`] ties them together under a memory budget.

pub mod binning;
pub mod bit_brick;
pub mod coarse_grid;
pub mod grid;
pub mod scene;
pub mod screen_space;
pub mod shading;
pub mod sphere_caster;

pub use binning::{FluidBins, FluidSettings};
pub use grid::{BrickKey, FluidGrid};

/// What can go wrong opening or rendering a fluid.
#[derive(Debug, thiserror::Error)]
pub enum FluidError {
    /// The particle file could not be read.
    #[error(transparent)]
    Geometry(#[from] voxstream_geometry::GeometryError),
    /// A setting (or what the particles imply for one) is out of range; the message names the flag.
    #[error("{0}")]
    Settings(String),
    /// The camera or image size is unusable.
    #[error(transparent)]
    Render(#[from] voxstream_render::RenderError),
}
