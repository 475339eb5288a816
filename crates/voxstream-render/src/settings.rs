//! Render settings: image size, shading, background, step size and where the volume sits in the world.

use serde::{Deserialize, Serialize};

use crate::clip_plane::{ClipPlane, MAX_CLIP_PLANES};
use crate::error::RenderError;
use crate::instruction_set::InstructionSet;
use crate::isosurface::{IsoSurface, SurfaceNormals, MAX_SURFACES};
use crate::projection::Projection;

/// How samples are lit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Shading {
    /// Emission–absorption only: the transfer function's colour.
    None,
    /// Phong with the density gradient as normal (GigaVoxels [R08] §5), two-sided.
    Phong,
}

/// Phong coefficients (ambient, diffuse, specular, shininess).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhongCoefficients {
    /// Ambient term.
    pub ambient: f32,
    /// Diffuse term.
    pub diffuse: f32,
    /// Specular term.
    pub specular: f32,
    /// Specular exponent.
    pub shininess: f32,
}

impl Default for PhongCoefficients {
    fn default() -> Self {
        PhongCoefficients { ambient: 0.25, diffuse: 0.75, specular: 0.25, shininess: 16.0 }
    }
}

/// Where the unit cube of the tree sits in world space: `world = origin + scale ⊙ volume` (per axis, so anisotropic
/// voxels are fine), and the box of the cube that holds data (rays are clipped to it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VolumePlacement {
    /// World position of the cube's corner `(0, 0, 0)`.
    pub origin: [f64; 3],
    /// World edge of the cube along x, y, z.
    pub scale: [f64; 3],
    /// Lower corner of the data box, volume units.
    pub clip_lower: [f64; 3],
    /// Upper corner of the data box, volume units.
    pub clip_upper: [f64; 3],
}

impl Default for VolumePlacement {
    fn default() -> Self {
        VolumePlacement { origin: [0.0; 3], scale: [1.0; 3], clip_lower: [0.0; 3], clip_upper: [1.0; 3] }
    }
}

impl VolumePlacement {
    /// The cube of edge `size` at `origin`, all of it data.
    pub fn cube(origin: [f64; 3], size: f64) -> VolumePlacement {
        VolumePlacement { origin, scale: [size; 3], ..VolumePlacement::default() }
    }

    /// Geometric mean of the scales: world length of one volume unit, for level-of-detail and steps.
    pub fn mean_scale(&self) -> f64 {
        (self.scale[0] * self.scale[1] * self.scale[2]).cbrt()
    }
}

/// Everything about a frame except the camera, the transfer function and the data.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Lighting model.
    pub shading: Shading,
    /// Phong coefficients.
    pub phong: PhongCoefficients,
    /// Direction towards the light, world; `None` = a headlight (from the eye).
    pub light_direction: Option<[f64; 3]>,
    /// Linear background colour.
    pub background: [f32; 3],
    /// Ray-march step as a fraction of the sampled level's voxel edge.
    pub step_factor: f64,
    /// Volume rendering: integrate the transfer function over each segment between two samples, the field taken as
    /// linear between them ([`crate::preintegration`], Engel et al. 2001), instead of taking each sample's value for
    /// its whole step.
    pub preintegrated: bool,
    /// Volume rendering: the error-bounded adaptive step ([`crate::adaptive_step`]) with this tolerance (optical
    /// depth per monotone stretch of a ray): each brick segment steps by up to
    /// [`crate::adaptive_step::MAX_STEP_GROWTH`] times the fixed step where the transfer function varies little
    /// over the brick's values. `None`: the fixed step everywhere.
    pub adaptive_step: Option<f64>,
    /// Shifts the level of detail: positive = finer than one voxel per pixel.
    pub lod_bias: f64,
    /// Placement of the volume in the world.
    pub placement: VolumePlacement,
    /// Accumulated opacity at which a ray stops.
    pub opacity_cutoff: f32,
    /// Requests a ray may report per frame (GigaVoxels: 1).
    pub max_requests_per_ray: u32,
    /// Skip bricks and occupancy blocks the transfer function hides (exact: the image is the same bit for bit;
    /// off only to test that).
    pub skip_empty_space: bool,
    /// Evaluate samples [`crate::sampler::LANES`] at a time where possible (the same bits as one at a time, which
    /// stays as the reference; off only to test that).
    pub sample_batches: bool,
    /// Trace [`crate::sampler::LANES`] rays side by side, their samples taken together (the same bits as one ray
    /// at a time, which stays as the reference; off only to test that). Volume rendering only.
    pub ray_packets: bool,
    /// Find the samples in occupancy blocks that can contribute from bits computed once per brick and pass, eight
    /// samples at a time ([`crate::block_visibility`]), instead of testing each block's range as the ray enters it;
    /// the same image as the range tests, which stay as the reference (off only to test that). Volume rendering
    /// only.
    pub block_visibility_bits: bool,
    /// Keep the nodes of each ray's first descent for the next ray of its lane within a pass, so that that ray's first
    /// descent starts from its neighbour's nodes instead of the root (trees whose N is a power of two only; see
    /// [`crate::DescentPath`]); the same images, counters and feedback as starting every ray from the root, which
    /// stays as the reference (off only to test that and for the isosurface ablation's rows).
    pub shared_descents: bool,
    /// Instructions the ray loop uses (detected at run time by default; the image is the same either way).
    pub instruction_set: InstructionSet,
    /// Isosurfaces to draw instead of the volume, or inside it with [`RenderSettings::surfaces_in_volume`] (Knoll
    /// et al.); empty = volume rendering.
    pub surfaces: Vec<IsoSurface>,
    /// Isosurfaces: hard shadows from the fixed light ([`RenderSettings::light_direction`], with Phong shading).
    pub shadows: bool,
    /// Isosurfaces: where normals come from.
    pub surface_normals: SurfaceNormals,
    /// Isosurfaces: draw the transfer function's volume around them too, composited in depth order (an
    /// isosurface inside a volume rendering, [`crate::surfaces_in_volume`]); `false`: the surfaces alone.
    pub surfaces_in_volume: bool,
    /// A pass traces only the pending pixels whose coordinates are both multiples of this (1: all of them); the
    /// others stay pending. The frame loop uses 4, then 2, for the passes of a converged frame that only gather
    /// requests.
    pub pixel_stride: u32,
    /// Volume rendering: step by the cone's footprint wherever a coarser ancestor stands in for data not yet
    /// resident (missing, not yet subdivided, or still fading in), as if the data were there, instead of by the
    /// stand-in's coarser voxel (but no finer than the voxel two levels below the stand-in for N = 2, one level
    /// below for N ≥ 3, at most four times the samples). Then data arriving changes the values of samples, not
    /// where they fall, unless the wanted level is further away. The frame loop turns it on with level blending
    /// (interactive frames); a final image is the same either way.
    pub steps_ignore_stand_ins: bool,
    /// Where loading is prioritised: a point of the image in `[0, 1]²` (x right, y down), e.g. the centre of the
    /// view or the cursor. Within a level, requests from the image tiles near it count up to
    /// [`MAX_FOCUS_WEIGHT`] times (the screen area waiting on a node, weighted by closeness), so detail arrives
    /// there first. `None`: every tile counts once. Only the order of loading changes, never an image.
    pub focus: Option<[f32; 2]>,
    /// Volume rendering, a diagnostic: each sample takes the colour of the tree level its data comes from
    /// ([`level_colour`]) instead of the transfer function's (opacity and shading stay), so the image shows which
    /// level each part of each pixel used.
    pub colour_by_level: bool,
    /// How the samples along a ray make its pixel: compositing (volume rendering, or isosurfaces), or the largest,
    /// smallest or mean value along it ([`crate::projection`]).
    pub projection: Projection,
    /// Half-spaces the view keeps ([`crate::clip_plane`]); at most [`MAX_CLIP_PLANES`].
    pub clip_planes: Vec<ClipPlane>,
    /// A plane of samples drawn with the volume ([`crate::slice_in_volume`]): the slab's two clipping planes (each
    /// keeping the slab's side); the volume between the eye and it is cut away, its mean value drawn over the volume
    /// beyond it. Volume
    /// rendering only; the clipping planes count towards [`MAX_CLIP_PLANES`].
    pub volume_slice: Option<[ClipPlane; 2]>,
}

/// The colour [`RenderSettings::colour_by_level`] gives tree level `level`: eight hues around the colour wheel,
/// repeating.
pub fn level_colour(level: u32) -> [f32; 3] {
    const PALETTE: [[f32; 3]; 8] = [
        [0.85, 0.2, 0.2],
        [0.95, 0.6, 0.1],
        [0.9, 0.9, 0.2],
        [0.3, 0.8, 0.2],
        [0.1, 0.75, 0.75],
        [0.2, 0.4, 0.95],
        [0.6, 0.3, 0.9],
        [0.95, 0.4, 0.75],
    ];
    PALETTE[level as usize % PALETTE.len()]
}

/// The most a tile's requests count when it lies at [`RenderSettings::focus`] (1 at half the image's diagonal or
/// further).
pub const MAX_FOCUS_WEIGHT: usize = 4;

/// How many times the requests of the tile covering `[x0, x1) × [y0, y1)` of a `width × height` image count, with
/// `focus` in `[0, 1]²`: [`MAX_FOCUS_WEIGHT`] at the focus, falling linearly to 1 at half the diagonal.
pub fn focus_weight(focus: Option<[f32; 2]>, tile: [u32; 4], width: u32, height: u32) -> usize {
    let Some([fx, fy]) = focus else { return 1 };
    let [x0, y0, x1, y1] = tile;
    let cx = (x0 + x1) as f32 * 0.5 / width.max(1) as f32;
    let cy = (y0 + y1) as f32 * 0.5 / height.max(1) as f32;
    let distance = ((cx - fx).powi(2) + (cy - fy).powi(2)).sqrt();
    let closeness = (1.0 - distance / std::f32::consts::FRAC_1_SQRT_2).clamp(0.0, 1.0);
    1 + (closeness * (MAX_FOCUS_WEIGHT - 1) as f32).round() as usize
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 512,
            height: 512,
            shading: Shading::None,
            phong: PhongCoefficients::default(),
            light_direction: None,
            background: [0.0; 3],
            step_factor: 0.5,
            preintegrated: false,
            adaptive_step: None,
            lod_bias: 0.0,
            placement: VolumePlacement::default(),
            opacity_cutoff: 0.998,
            max_requests_per_ray: 4,
            skip_empty_space: true,
            instruction_set: InstructionSet::Detect,
            sample_batches: true,
            ray_packets: true,
            block_visibility_bits: true,
            shared_descents: true,
            surfaces: Vec::new(),
            shadows: false,
            surface_normals: SurfaceNormals::Cell,
            surfaces_in_volume: false,
            pixel_stride: 1,
            steps_ignore_stand_ins: false,
            focus: None,
            colour_by_level: false,
            projection: Projection::Composite,
            clip_planes: Vec::new(),
            volume_slice: None,
        }
    }
}

impl RenderSettings {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), RenderError> {
        let bad = |m: String| Err(RenderError::InvalidSetting(m));
        if self.width == 0 || self.height == 0 {
            return bad(format!("image size must be positive, got {}x{}", self.width, self.height));
        }
        if self.width > 16384 || self.height > 16384 {
            return bad(format!("image size {}x{} exceeds 16384x16384", self.width, self.height));
        }
        if !(self.step_factor.is_finite() && self.step_factor > 0.01 && self.step_factor <= 4.0) {
            return bad(format!("step factor must be in (0.01, 4], got {}", self.step_factor));
        }
        if let Some(tolerance) = self.adaptive_step {
            if !(tolerance.is_finite() && tolerance > 0.0 && tolerance <= 10.0) {
                return bad(format!("adaptive step tolerance must be in (0, 10], got {tolerance}"));
            }
        }
        if !self.lod_bias.is_finite() {
            return bad("lod bias must be finite".into());
        }
        if self.background.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return bad("background components must be in [0, 1]".into());
        }
        if let Some(light) = self.light_direction {
            let length = light.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !(length.is_finite() && length > 0.0) {
                return bad("light direction must be a non-zero finite vector".into());
            }
        }
        if !(1..=16).contains(&self.pixel_stride) {
            return bad(format!("pixel stride must be in 1..=16, got {}", self.pixel_stride));
        }
        if self.surfaces_in_volume && self.surfaces.is_empty() {
            return bad("a volume around isosurfaces needs at least one isosurface".into());
        }
        if !self.surfaces.is_empty() && (self.preintegrated || self.adaptive_step.is_some()) {
            return bad("pre-integration and the adaptive step are for volume rendering: drop them with isosurfaces \
                 (--iso), whose volume around them steps by the fixed step"
                .into());
        }
        if self.surfaces.len() > MAX_SURFACES {
            return bad(format!("at most {MAX_SURFACES} isosurfaces, got {}", self.surfaces.len()));
        }
        for (i, surface) in self.surfaces.iter().enumerate() {
            if !surface.value.is_finite() {
                return bad(format!("isovalue {} is not finite", i + 1));
            }
            if surface.color.iter().any(|c| !(0.0..=1.0).contains(c)) {
                return bad(format!("isosurface {} colour components must be in [0, 1]", i + 1));
            }
            if !(surface.opacity > 0.0 && surface.opacity <= 1.0) {
                return bad(format!("isosurface {} opacity must be in (0, 1], got {}", i + 1, surface.opacity));
            }
        }
        if self.projection != Projection::Composite && !self.surfaces.is_empty() {
            return bad(format!(
                "an intensity projection (--projection {}) draws values, not isosurfaces: drop --iso or the projection",
                self.projection.name()
            ));
        }
        if self.projection != Projection::Composite && self.preintegrated {
            return bad("pre-integration is for compositing: drop --preintegrate with --projection".into());
        }
        if self.clip_planes.len() > MAX_CLIP_PLANES {
            return bad(format!("at most {MAX_CLIP_PLANES} clipping planes, got {}", self.clip_planes.len()));
        }
        if let Some(i) = self.clip_planes.iter().position(|p| !p.is_valid()) {
            return bad(format!("clipping plane {} needs a finite point and a non-zero finite normal", i + 1));
        }
        if let Some(slab) = &self.volume_slice {
            if self.projection != Projection::Composite || !self.surfaces.is_empty() {
                return bad("a slice drawn with the volume goes with volume rendering: drop --iso and --projection, \
                            or --with-volume"
                    .into());
            }
            if self.clip_planes.len() + slab.len() > MAX_CLIP_PLANES {
                return bad(format!(
                    "a slice drawn with the volume takes 2 of the {MAX_CLIP_PLANES} clipping planes; {} are given",
                    self.clip_planes.len()
                ));
            }
            if !slab.iter().all(ClipPlane::is_valid) {
                return bad("the slice's planes need finite points and non-zero finite normals".into());
            }
        }
        let p = &self.placement;
        if !(p.scale.iter().all(|s| s.is_finite() && *s > 0.0) && p.origin.iter().all(|v| v.is_finite())) {
            return bad("volume placement must be finite with a positive scale".into());
        }
        if (0..3).any(|a| !(p.clip_lower[a] < p.clip_upper[a])) {
            return bad("volume clip box is empty".into());
        }
        Ok(())
    }
}
