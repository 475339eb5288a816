// The GPU side of crates/voxstream-layout: keep in sync with the Rust structs (src/*.rs).
// tests/wgsl_mirror.rs checks that every struct here has the Rust struct's fields, in the same order, at the same
// offsets, and that the constants have the same values.

// node.rs: one node of the N³-tree (GigaVoxels [P09] §4).
const NODE_CONSTANT_BIT: u32 = 0x80000000u;
const NODE_TERMINAL_BIT: u32 = 0x40000000u;
const NODE_CHILD_MASK: u32 = 0x3fffffffu;

struct Node {
    child_word: u32,
    data_word: u32,
}

// tree_header.rs: the shape of the tree and the sizes of its pools.
struct TreeHeader {
    n: u32,
    nodes_per_tile: u32,
    brick_size: u32,
    stored_brick_size: u32,
    max_level: u32,
    blocks_per_axis: u32,
    block_cells: u32,
    voxels_per_brick: u32,
    node_count: u32,
    brick_count: u32,
    padding0: u32,
    padding1: u32,
}

// transfer_table.rs: the transfer-function table.
const TABLE_HOLDS_EXTINCTION: u32 = 0u;
const TABLE_HOLDS_STEP_OPACITY: u32 = 1u;

struct TransferTableHeader {
    entry_count: u32,
    contents: u32,
    step: f32,
    padding: u32,
}

struct TransferTableEntry {
    r: f32,
    g: f32,
    b: f32,
    a: f32,
}

// feedback_records.rs: what the rays write for the cache manager (GigaVoxels [P09] §5).
const REQUEST_PRODUCE: u32 = 0u;
const REQUEST_SUBDIVIDE: u32 = 1u;
const REQUEST_KIND_MASK: u32 = 0xffu;
const REQUEST_DEFICIT_SHIFT: u32 = 8u;
const REQUEST_MAX_DEFICIT: u32 = 0xffu;

struct FeedbackCounters {
    request_count: atomic<u32>,
    request_capacity: u32,
    dropped_requests: atomic<u32>,
    padding: u32,
}

struct RayCounters {
    rays: atomic<u32>,
    samples: atomic<u32>,
    descents: atomic<u32>,
    padding: u32,
}

struct UsageFlag {
    used: u32,
}

struct RequestRecord {
    node: u32,
    kind: u32,
}

// brick_blend.rs: per brick slot, the cap on its weight against its parent at its eight corners (x + 2y + 4z), and
// its own fade-in (below 1, its descendants are not drawn).
struct BrickBlend {
    corner0: f32,
    corner1: f32,
    corner2: f32,
    corner3: f32,
    corner4: f32,
    corner5: f32,
    corner6: f32,
    corner7: f32,
    fade: f32,
}

// ray_frame.rs: the frame's camera and ray settings, flattened (GigaVoxels [P09] §6).
const RAY_FRAME_PHONG: u32 = 1u;
const RAY_FRAME_STEPS_IGNORE_STAND_INS: u32 = 2u;
const RAY_FRAME_COLOUR_BY_LEVEL: u32 = 4u;
const RAY_FRAME_SKIP_EMPTY_SPACE: u32 = 8u;
const RAY_FRAME_CENTRAL_NORMALS: u32 = 16u;
const RAY_FRAME_SHADOWS: u32 = 32u;
const RAY_FRAME_BLENDING: u32 = 64u;
const RAY_FRAME_SURFACES_IN_VOLUME: u32 = 128u;
const RAY_FRAME_ADAPTIVE_STEP: u32 = 256u;

struct RayFrame {
    width: u32,
    height: u32,
    pixel_stride: u32,
    max_requests_per_ray: u32,
    flags: u32,
    stand_in_levels: u32,
    request_capacity: u32,
    max_segments: u32,
    eye_x: f32,
    eye_y: f32,
    eye_z: f32,
    pixel_spread: f32,
    forward_x: f32,
    forward_y: f32,
    forward_z: f32,
    world_per_volume: f32,
    right_x: f32,
    right_y: f32,
    right_z: f32,
    lod_bias: f32,
    up_x: f32,
    up_y: f32,
    up_z: f32,
    step_factor: f32,
    inverse_scale_x: f32,
    inverse_scale_y: f32,
    inverse_scale_z: f32,
    bias_scale: f32,
    clip_lower_x: f32,
    clip_lower_y: f32,
    clip_lower_z: f32,
    stop_below: f32,
    clip_upper_x: f32,
    clip_upper_y: f32,
    clip_upper_z: f32,
    ambient: f32,
    background_r: f32,
    background_g: f32,
    background_b: f32,
    diffuse: f32,
    light_x: f32,
    light_y: f32,
    light_z: f32,
    specular: f32,
    shininess: f32,
    atlas_bricks_x: u32,
    atlas_bricks_y: u32,
    anchor_level: u32,
    anchor_x: u32,
    anchor_y: u32,
    anchor_z: u32,
    anchor_scale: f32,
    surface_count: u32,
    finest_voxel: f32,
    adaptive_tolerance: f32,
    reserved1: u32,
}

// One isosurface (ray_frame.rs, `SurfaceRecord`).
struct SurfaceRecord {
    iso: f32,
    lower: f32,
    upper: f32,
    opacity: f32,
    r: f32,
    g: f32,
    b: f32,
    reserved: u32,
}
