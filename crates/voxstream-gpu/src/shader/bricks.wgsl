// Reading the brick atlas: a brick's place in it, trilinear samples with analytic gradients (`Cell` in
// voxstream-render's sampler), and the value ranges of bricks and occupancy blocks that empty-space skipping tests.

// The atlas position of voxel (0, 0, 0) of the brick in `slot`.
fn brick_origin(slot: u32) -> vec3<u32> {
    let x = frame.atlas_bricks_x;
    let y = frame.atlas_bricks_y;
    return vec3<u32>(slot % x, (slot / x) % y, slot / (x * y)) * tree.stored_brick_size;
}

// Trilinear value (normalised) and analytic gradient (value per voxel) at continuous voxel index x of the brick in
// `slot`: the arithmetic of voxstream-render's `Cell::locate` and `Cell::value_and_gradient`.
fn sample_brick(slot: u32, x: vec3<f32>) -> vec4<f32> {
    let b = tree.stored_brick_size;
    let c = clamp(x, vec3<f32>(0.0), vec3<f32>(f32(b - 1u)));
    let i = min(vec3<u32>(c), vec3<u32>(b - 2u));
    let f = c - vec3<f32>(i);
    let base = brick_origin(slot) + i;
    let v000 = voxel(base);
    let v100 = voxel(base + vec3<u32>(1u, 0u, 0u));
    let v010 = voxel(base + vec3<u32>(0u, 1u, 0u));
    let v110 = voxel(base + vec3<u32>(1u, 1u, 0u));
    let v001 = voxel(base + vec3<u32>(0u, 0u, 1u));
    let v101 = voxel(base + vec3<u32>(1u, 0u, 1u));
    let v011 = voxel(base + vec3<u32>(0u, 1u, 1u));
    let v111 = voxel(base + vec3<u32>(1u, 1u, 1u));
    let c00 = mix(v000, v100, f.x);
    let c10 = mix(v010, v110, f.x);
    let c01 = mix(v001, v101, f.x);
    let c11 = mix(v011, v111, f.x);
    let c0 = mix(c00, c10, f.y);
    let c1 = mix(c01, c11, f.y);
    let value = mix(c0, c1, f.z);
    let gz = c1 - c0;
    let gy = mix(c10 - c00, c11 - c01, f.z);
    let gx = mix(mix(v100 - v000, v110 - v010, f.y), mix(v101 - v001, v111 - v011, f.y), f.z);
    return vec4<f32>(value, gx, gy, gz) * (1.0 / VOXEL_MAX);
}

// The sample at continuous voxel index x of the brick in `slot`: with its analytic gradient when `gradient`
// (`sample_brick`), else the value alone (`filtered_value`: the texture unit's filtering where the atlas has it).
fn sample_at(slot: u32, x: vec3<f32>, gradient: bool) -> vec4<f32> {
    if gradient {
        return sample_brick(slot, x);
    }
    return vec4<f32>(filtered_value(slot, x), 0.0, 0.0, 0.0);
}

// A packed [min, max] of `ranges` (`range_words` in shader_records.rs), normalised.
const RANGE_HIGH_SHIFT: u32 = 16u;
const RANGE_LOW_MASK: u32 = 0xffffu;
fn unpack_range(packed: u32) -> vec2<f32> {
    return vec2<f32>(f32(packed & RANGE_LOW_MASK), f32(packed >> RANGE_HIGH_SHIFT)) * (1.0 / VOXEL_MAX);
}

// The [min, max] of the brick in `slot`, normalised.
fn brick_range(slot: u32) -> vec2<f32> {
    return unpack_range(ranges[arrayLength(&table) + 1u + slot]);
}

// The [min, max] (normalised) of occupancy block `block` (x fastest) of the brick in `slot`.
fn block_range(slot: u32, block: vec3<u32>) -> vec2<f32> {
    let blocks = tree.blocks_per_axis;
    let index = (block.z * blocks + block.y) * blocks + block.x;
    return unpack_range(ranges[arrayLength(&table) + 1u + tree.brick_count + slot * blocks * blocks * blocks + index]);
}

// The occupancy block holding the cell that trilinear filtering reads at continuous voxel index x
// (`Cell::locate` then `Cell::block_ijk`).
fn block_of(x: vec3<f32>) -> vec3<u32> {
    let b = tree.stored_brick_size;
    let c = clamp(x, vec3<f32>(0.0), vec3<f32>(f32(b - 1u)));
    return min(vec3<u32>(c), vec3<u32>(b - 2u)) / tree.block_cells;
}
