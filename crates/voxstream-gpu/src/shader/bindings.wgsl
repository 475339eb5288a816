// The GPU twin of voxstream-render's ray caster: one invocation per pixel walks its ray through the N³-tree exactly
// as `Traversal::trace` does (GigaVoxels [P09] §6: cone-traced level of detail, kd-restart descent from the root at
// every segment, early termination), and writes the feedback of [P09] §5 (tiles and bricks used, nodes missed).
// `march` is the traversal; what its segments feed is the frame's integrand, as on the CPU:
// - emission–absorption (`EmissionAbsorption`): quadrilinear blending with the parent brick (capped by Thiele et
//   al.'s level blending in interactive frames: `BrickBlend` caps and fade-in), opacity correction per step, Phong,
//   front-to-back compositing;
// - exact isosurfaces in the pipeline compiled with ISOSURFACES (`Isosurfaces`, Knoll et al., seed 002): whole brick
//   segments walked cell by cell (`walk_cells`), each cell's cubic solved for its crossings (`iso_cell`), subtrees,
//   bricks, blocks and cells culled by their value ranges, several translucent surfaces, hard shadows from a second
//   `march` towards the light (`SurfaceCaster`); with RAY_FRAME_SURFACES_IN_VOLUME the transfer function's volume
//   around them too (`SurfacesInVolume`: its samples composited between the crossings, `fog_until`).
//
// This file holds the pipeline's constants, bindings and a ray's state; the other files of `src/shader/` (joined
// after it by `shader.rs`) hold the feedback, brick reads, the integrands, the descent's geometry, level blending,
// the segment walk `march` and the entry point `main`.
//
// The records (Node, TreeHeader, RayFrame, SurfaceRecord, TransferTableEntry, FeedbackCounters, RayCounters,
// RequestRecord) come from crates/voxstream-layout/src/layout.wgsl, which is prepended to these files.
//
// Positions are f32 in the anchor frame of `RayFrame` (one unit per node of the anchor level, origin at the anchor
// node that holds the eye), so that deep zooms keep the precision the CPU has in f64: a node is located by its
// corner and edge in that frame, exact integers down to the anchor level, small fractions below it.
//
// Differences from the CPU, all below the image tolerance the tests check: positions are f32 (the CPU's are f64
// between segments), the step ladder's rung and the level search are computed in f32, opacities are computed per
// sample (the CPU reads tables pre-corrected per step), and empty blocks are skipped sample by sample rather than in
// runs (skipping never moves a sample on either side, so it changes only the work, not the image).

// Which integrand this pipeline draws: emission–absorption (false) or isosurfaces (true). A pipeline constant, so
// that each variant is compiled without the other's code (its registers would slow the volume kernel by a third).
override ISOSURFACES: bool = false;

// The constants below that the host or the CPU renderer shares are named the same on the Rust side, and
// voxstream-gpu's tests/shader_interface.rs checks every one (as it checks the bindings' numbers): a value changed
// on one side only fails there.

// The step ladder of `StepLength` (voxstream-render's step_table.rs): 2^(−j/STEPS_PER_OCTAVE) world units for
// j in [−LADDER_HALF, LADDER_HALF), consecutive rungs RUNG_RATIO apart.
const STEPS_PER_OCTAVE: f32 = 4.0;
const LADDER_HALF: f32 = 512.0;
const RUNG_RATIO: f32 = 1.189207115;
// Pixel flags, in and out (shader_interface.rs): in, PIXEL_PENDING = trace this pixel's ray this pass; out,
// PIXEL_UNTRACED = not traced, PIXEL_DONE = traced and complete, PIXEL_MISSED = traced but it missed data (trace it
// again next pass).
const PIXEL_UNTRACED: u32 = 0u;
const PIXEL_PENDING: u32 = 1u;
const PIXEL_DONE: u32 = 1u;
const PIXEL_MISSED: u32 = 2u;
// Edge of a workgroup's square of pixels (the host dispatches width / WORKGROUP_EDGE × height / WORKGROUP_EDGE).
const WORKGROUP_EDGE: u32 = 8u;
// The largest stored voxel (`voxstream_core::VOXEL_MAX`): normalised values are stored / VOXEL_MAX.
const VOXEL_MAX: f32 = 65535.0;

struct Feedback {
    counters: FeedbackCounters,
    rays: RayCounters,
    records: array<RequestRecord>,
}

@group(0) @binding(0) var<uniform> tree: TreeHeader;
@group(0) @binding(1) var<uniform> frame: RayFrame;
@group(0) @binding(2) var<storage, read> nodes: array<Node>;
// The brick pool (binding 3: bricks of (M+2)³ voxels side by side in a 3D atlas, 16-bit), `voxel` and
// `filtered_value` are declared before this file by the renderer's `BrickFiltering` (brick_filtering.rs): an R16Uint
// atlas filtered here as on the CPU, or an R16Unorm atlas filtered by the texture units (with its sampler, binding 12).
// The transfer function: LUT entries of linear colour and extinction per world unit (TABLE_HOLDS_EXTINCTION).
@group(0) @binding(4) var<storage, read> table: array<TransferTableEntry>;
@group(0) @binding(5) var<storage, read_write> pixels: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> pixel_flags: array<u32>;
@group(0) @binding(7) var<storage, read_write> feedback: Feedback;
// One flag per node tile, then one per brick slot (GigaVoxels [P09] §5's usage lists).
@group(0) @binding(8) var<storage, read_write> usage: array<u32>;
// For empty-space skipping: the transfer table's entries with non-zero extinction before each index (one more than
// the table's length), then each brick slot's [min, max] voxel (min | max << 16), then each slot's occupancy
// blocks' (blocks_per_axis³, x fastest).
@group(0) @binding(9) var<storage, read> ranges: array<u32>;
// The frame's isosurfaces (`RayFrame::surface_count` of them; one unused record where there are none).
@group(0) @binding(10) var<storage, read> surfaces: array<SurfaceRecord>;
// Thiele et al.'s level blending (`RAY_FRAME_BLENDING`): per brick slot, the caps on its weight against its parent at
// its corners and its own fade-in (`BrickBlend`; one unused record when off).
@group(0) @binding(11) var<storage, read> blends: array<BrickBlend>;

struct RayState {
    // The ray in the anchor frame: origin, anchor units per world unit of t, and its inverse.
    origin: vec3<f32>,
    direction: vec3<f32>,
    inverse_direction: vec3<f32>,
    // Unit-cube units per world unit of t (what sets the step).
    speed: f32,
    color: vec3<f32>,
    transmittance: f32,
    requests_left: u32,
    requested: bool,
    samples: u32,
    // The current rung of the step ladder (valid once has_step).
    has_step: bool,
    step: f32,
    // Phong: the light and half vectors (volume shading is two-sided, as on the CPU).
    light: vec3<f32>,
    half_vector: vec3<f32>,
    // Where the ray starts (0 for a primary ray; a shadow ray starts past its surface point), and its descents.
    start: f32,
    descents: u32,
    // Isosurfaces: per surface (bit i) whether the ray is inside, and whether that is known yet; the first
    // crossing, what its light added beyond the ambient term, and whether any crossing ends the ray (shadow rays).
    inside: u32,
    known: bool,
    has_hit: bool,
    first_hit: f32,
    first_lit: vec3<f32>,
    any_hit: bool,
    // Surfaces inside a volume (`RAY_FRAME_SURFACES_IN_VOLUME`, `SurfacesInVolume`): the distance up to which the
    // volume is accounted for when the current segment began, its first sample's centre, and the index of its
    // next sample (sample k at fog_first + k·step).
    fog_covered: f32,
    fog_first: f32,
    fog_next: u32,
}
