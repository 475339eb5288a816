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

struct FeedbackCounters {
    request_count: atomic<u32>,
    request_capacity: u32,
    dropped_requests: atomic<u32>,
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
