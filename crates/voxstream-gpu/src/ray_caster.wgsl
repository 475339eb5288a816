// The GPU twin of voxstream-render's ray caster: one invocation per pixel walks its ray through the N³-tree exactly
// as `Traversal::trace` does with the `EmissionAbsorption` integrand (GigaVoxels [P09] §6: cone-traced level of
// detail, kd-restart descent from the root at every segment, quadrilinear blending with the parent brick, opacity
// correction per step, front-to-back compositing, early termination), and writes the feedback of [P09] §5 (tiles and
// bricks used, nodes missed).
//
// The records (Node, TreeHeader, RayFrame, TransferTableEntry, FeedbackCounters, RayCounters, RequestRecord) come
// from crates/voxstream-layout/src/layout.wgsl, which is prepended to this file.
//
// Positions are f32 in the anchor frame of `RayFrame` (one unit per node of the anchor level, origin at the anchor
// node that holds the eye), so that deep zooms keep the precision the CPU has in f64: a node is located by its
// corner and edge in that frame, exact integers down to the anchor level, small fractions below it.
//
// Differences from the CPU, all below the image tolerance the tests check: positions are f32 (the CPU's are f64
// between segments), the step ladder's rung and the level search are computed in f32, opacities are computed per
// sample (the CPU reads tables pre-corrected per step), and empty blocks are skipped sample by sample rather than in
// runs (skipping never moves a sample on either side, so it changes only the work, not the image).

const MAX_LEVELS: u32 = 32u;
const RUNG_RATIO: f32 = 1.189207115;
// Pixel flags, in and out: in, 1 = trace this pixel's ray this pass; out, 0 = not traced, 1 = traced and complete,
// 2 = traced but it missed data (trace it again next pass).
const PIXEL_DONE: u32 = 1u;
const PIXEL_MISSED: u32 = 2u;

struct Feedback {
    counters: FeedbackCounters,
    rays: RayCounters,
    records: array<RequestRecord>,
}

@group(0) @binding(0) var<uniform> tree: TreeHeader;
@group(0) @binding(1) var<uniform> frame: RayFrame;
@group(0) @binding(2) var<storage, read> nodes: array<Node>;
// The brick pool: bricks of (M+2)³ voxels side by side in a 3D atlas, 16-bit, filtered here as on the CPU.
@group(0) @binding(3) var bricks: texture_3d<u32>;
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
}

fn level_colour(level: u32) -> vec3<f32> {
    var palette = array<vec3<f32>, 8>(
        vec3<f32>(0.85, 0.2, 0.2), vec3<f32>(0.95, 0.6, 0.1), vec3<f32>(0.9, 0.9, 0.2), vec3<f32>(0.3, 0.8, 0.2),
        vec3<f32>(0.1, 0.75, 0.75), vec3<f32>(0.2, 0.4, 0.95), vec3<f32>(0.6, 0.3, 0.9), vec3<f32>(0.95, 0.4, 0.75),
    );
    return palette[level % 8u];
}

fn mark_tile(tile: u32) {
    usage[tile] = 1u;
}

fn mark_brick(slot: u32) {
    usage[tree.node_count / tree.nodes_per_tile + slot] = 1u;
}

fn request(state: ptr<function, RayState>, node: u32, kind: u32) {
    if (*state).requests_left == 0u {
        return;
    }
    (*state).requests_left -= 1u;
    (*state).requested = true;
    let index = atomicAdd(&feedback.counters.request_count, 1u);
    if index < feedback.counters.request_capacity {
        feedback.records[index] = RequestRecord(node, kind);
    } else {
        atomicAdd(&feedback.counters.dropped_requests, 1u);
    }
}

// The atlas position of voxel (0, 0, 0) of the brick in `slot`.
fn brick_origin(slot: u32) -> vec3<u32> {
    let x = frame.atlas_bricks_x;
    let y = frame.atlas_bricks_y;
    return vec3<u32>(slot % x, (slot / x) % y, slot / (x * y)) * tree.stored_brick_size;
}

// One stored voxel (0‥65535).
fn voxel(at: vec3<u32>) -> f32 {
    return f32(textureLoad(bricks, at, 0).r);
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
    return vec4<f32>(value, gx, gy, gz) * (1.0 / 65535.0);
}

// 1 − exp(−x) for x ≥ 0 without the cancellation of f32 near 0 (the CPU uses f64 `exp_m1`): a faint medium's
// opacity per step stays exact to f32 precision instead of rounding to 0.
fn opacity(x: f32) -> f32 {
    return select(1.0 - exp(-x), x * (1.0 - x * (0.5 - x / 6.0)), x < 1e-3);
}

// Table position of a normalised value: entries i and i + 1 with weight f on the latter.
fn table_position(value: f32) -> vec2<f32> {
    let last = f32(arrayLength(&table) - 1u);
    let x = clamp(value * last, 0.0, last);
    let i = min(floor(x), last - 1.0);
    return vec2<f32>(i, x - i);
}

// Premultiplied colour and opacity of one step of `step` world units at `value`: the CPU's `StepTable::lookup`
// (each entry corrected for the step, then interpolated).
fn step_lookup(value: f32, step: f32) -> vec4<f32> {
    let p = table_position(value);
    let a = table[u32(p.x)];
    let b = table[u32(p.x) + 1u];
    let alpha_a = select(0.0, opacity(a.a * step), a.a > 0.0);
    let alpha_b = select(0.0, opacity(b.a * step), b.a > 0.0);
    let ea = vec4<f32>(vec3<f32>(a.r, a.g, a.b) * alpha_a, alpha_a);
    let eb = vec4<f32>(vec3<f32>(b.r, b.g, b.b) * alpha_b, alpha_b);
    return mix(ea, eb, p.y);
}

// Whether some value in [lower, upper] (normalised) has non-zero extinction: `TransferLut::is_visible_in`.
fn visible_in(lower: f32, upper: f32) -> bool {
    let last = f32(arrayLength(&table) - 1u);
    let slack = select(1e-3, 0.0, lower == upper);
    let first = u32(max(clamp(lower * last, 0.0, last) - slack, 0.0));
    let end = min(u32(ceil(clamp(upper * last, 0.0, last) + slack)), u32(last));
    return ranges[end + 1u] > ranges[first];
}

// The [min, max] of the brick in `slot`, normalised.
fn brick_range(slot: u32) -> vec2<f32> {
    let packed = ranges[arrayLength(&table) + 1u + slot];
    return vec2<f32>(f32(packed & 0xffffu), f32(packed >> 16u)) * (1.0 / 65535.0);
}

// The [min, max] (normalised) of occupancy block `block` (x fastest) of the brick in `slot`.
fn block_range(slot: u32, block: vec3<u32>) -> vec2<f32> {
    let blocks = tree.blocks_per_axis;
    let index = (block.z * blocks + block.y) * blocks + block.x;
    let packed = ranges[arrayLength(&table) + 1u + tree.brick_count + slot * blocks * blocks * blocks + index];
    return vec2<f32>(f32(packed & 0xffffu), f32(packed >> 16u)) * (1.0 / 65535.0);
}

// The occupancy block holding the cell that trilinear filtering reads at continuous voxel index x
// (`Cell::locate` then `Cell::block_ijk`).
fn block_of(x: vec3<f32>) -> vec3<u32> {
    let b = tree.stored_brick_size;
    let c = clamp(x, vec3<f32>(0.0), vec3<f32>(f32(b - 1u)));
    return min(vec3<u32>(c), vec3<u32>(b - 2u)) / tree.block_cells;
}

fn power(base: f32, exponent: f32) -> f32 {
    if base <= 0.0 {
        return select(0.0, 1.0, exponent == 0.0);
    }
    return pow(base, exponent);
}

// Two-sided Phong with the gradient as the normal: `RayLight::shade`.
fn shade(state: ptr<function, RayState>, color: vec3<f32>, alpha: f32, gradient: vec3<f32>) -> vec3<f32> {
    let length_ = length(gradient);
    if length_ < 1e-6 {
        return color * (frame.ambient + frame.diffuse);
    }
    let normal = gradient / length_;
    let diffuse = abs(dot(normal, (*state).light));
    let specular = power(abs(dot(normal, (*state).half_vector)), frame.shininess);
    return color * (frame.ambient + frame.diffuse * diffuse) + vec3<f32>(frame.specular * specular * alpha);
}

// Composites one sample; returns false once the ray is opaque enough to stop.
fn composite(state: ptr<function, RayState>, value: f32, gradient: vec3<f32>, level: u32) -> bool {
    let entry = step_lookup(value, (*state).step);
    if entry.w <= 0.0 {
        return true;
    }
    var premultiplied = entry.xyz;
    if (frame.flags & RAY_FRAME_COLOUR_BY_LEVEL) != 0u {
        premultiplied = level_colour(level) * entry.w;
    }
    if (frame.flags & RAY_FRAME_PHONG) != 0u {
        let scale = vec3<f32>(frame.inverse_scale_x, frame.inverse_scale_y, frame.inverse_scale_z);
        premultiplied = shade(state, premultiplied, entry.w, gradient * scale);
    }
    (*state).color += (*state).transmittance * premultiplied;
    (*state).transmittance *= 1.0 - entry.w;
    return (*state).transmittance > frame.stop_below;
}

// A constant node over [from, to): one exp, unshaded (`EmissionAbsorption::constant`).
fn composite_constant(state: ptr<function, RayState>, start: f32, end: f32, value: f32, level: u32) -> bool {
    let p = table_position(value);
    let a = table[u32(p.x)];
    let b = table[u32(p.x) + 1u];
    let entry = mix(vec4<f32>(a.r, a.g, a.b, a.a), vec4<f32>(b.r, b.g, b.b, b.a), p.y);
    if entry.w <= 0.0 {
        return true;
    }
    let alpha = opacity(entry.w * (end - start));
    var color = entry.xyz;
    if (frame.flags & RAY_FRAME_COLOUR_BY_LEVEL) != 0u {
        color = level_colour(level);
    }
    (*state).color += (*state).transmittance * alpha * color;
    (*state).transmittance *= 1.0 - alpha;
    return (*state).transmittance > frame.stop_below;
}

fn footprint(t: f32) -> f32 {
    return max(t * frame.pixel_spread / frame.world_per_volume, 1e-30);
}

// The continuous level of detail at distance t (`Traversal::level_at`).
fn level_at(t: f32) -> f32 {
    let n = f32(tree.n);
    let level = -log(f32(tree.brick_size) * footprint(t)) / log(n) + frame.lod_bias;
    return clamp(level, 0.0, f32(tree.max_level));
}

// N^d, by multiplication (exact for powers of two; `pow` need not be).
fn level_scale(d: u32) -> f32 {
    var s = 1.0;
    for (var i = 0u; i < d; i++) {
        s *= f32(tree.n);
    }
    return s;
}

// Voxel edge (unit cube) of level d: N^(−d) / M.
fn level_voxel(d: u32) -> f32 {
    return 1.0 / (level_scale(d) * f32(tree.brick_size));
}

// Slab test against [lower, upper]: (t_enter, t_exit), t_enter > t_exit when missed.
fn intersect_box(origin: vec3<f32>, direction: vec3<f32>, lower: vec3<f32>, upper: vec3<f32>) -> vec2<f32> {
    var t0 = -3.0e38;
    var t1 = 3.0e38;
    for (var a = 0u; a < 3u; a++) {
        let o = origin[a];
        let d = direction[a];
        if d == 0.0 {
            if o < lower[a] || o > upper[a] {
                return vec2<f32>(1.0, 0.0);
            }
            continue;
        }
        var near = (lower[a] - o) / d;
        var far = (upper[a] - o) / d;
        if near > far {
            let swap = near;
            near = far;
            far = swap;
        }
        t0 = max(t0, near);
        t1 = min(t1, far);
    }
    if t1 < max(t0, 0.0) {
        return vec2<f32>(1.0, 0.0);
    }
    return vec2<f32>(t0, t1);
}

// One node on the descent: its index, its record, its level, its integer coordinates at that level (down to the
// anchor level), and its lower corner and edge in the anchor frame.
struct PathNode {
    id: u32,
    node: Node,
    level: u32,
    ijk: vec3<u32>,
    corner: vec3<f32>,
    size: f32,
}

// N^d as an integer (d ≤ the anchor level, so below 2³¹).
fn integer_power(d: u32) -> u32 {
    var s = 1u;
    for (var i = 0u; i < d; i++) {
        s *= tree.n;
    }
    return s;
}

// Child `offset` (0‥N−1 per axis) of `parent`: node coordinates in integers while they fit (down to the anchor
// level), then corners by halving (N = 2) or thirding in the anchor frame.
fn child_of(parent: PathNode, offset: vec3<u32>, id: u32, node: Node) -> PathNode {
    let level = parent.level + 1u;
    let n = tree.n;
    let ijk = parent.ijk * n + offset;
    if level <= frame.anchor_level {
        let edge = integer_power(frame.anchor_level - level);
        let anchor = vec3<i32>(vec3<u32>(frame.anchor_x, frame.anchor_y, frame.anchor_z));
        let corner = vec3<f32>(vec3<i32>(ijk * edge) - anchor);
        return PathNode(id, node, level, ijk, corner, f32(edge));
    }
    let size = parent.size / f32(n);
    return PathNode(id, node, level, ijk, parent.corner + vec3<f32>(offset) * size, size);
}

fn has_brick(node: Node) -> bool {
    return (node.child_word & NODE_CONSTANT_BIT) == 0u && node.data_word != 0u;
}

// Continuous voxel index in the brick of `entry` at the ray's point at distance t (`Traversal::brick_line`).
fn brick_coordinates(state: ptr<function, RayState>, entry: PathNode, t: f32) -> vec3<f32> {
    let m = f32(tree.brick_size);
    let origin = ((*state).origin - entry.corner) / entry.size * m + 0.5;
    return origin + brick_rate(state, entry) * t;
}

// Voxels of the brick of `entry` per world unit along the ray.
fn brick_rate(state: ptr<function, RayState>, entry: PathNode) -> vec3<f32> {
    return (*state).direction * (f32(tree.brick_size) / entry.size);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let pixel = id.y * frame.width + id.x;
    if pixel_flags[pixel] == 0u || (id.x % frame.pixel_stride) != 0u || (id.y % frame.pixel_stride) != 0u {
        pixel_flags[pixel] = 0u;
        return;
    }

    // The ray through the pixel's centre (`CameraFrame::direction`), in volume space with t in world units.
    let sx = 2.0 * (f32(id.x) + 0.5) / f32(frame.width) - 1.0;
    let sy = 1.0 - 2.0 * (f32(id.y) + 0.5) / f32(frame.height);
    let forward = vec3<f32>(frame.forward_x, frame.forward_y, frame.forward_z);
    let right = vec3<f32>(frame.right_x, frame.right_y, frame.right_z);
    let up = vec3<f32>(frame.up_x, frame.up_y, frame.up_z);
    let world_direction = normalize(forward + right * sx + up * sy);
    let inverse_scale = vec3<f32>(frame.inverse_scale_x, frame.inverse_scale_y, frame.inverse_scale_z);

    var state: RayState;
    state.origin = vec3<f32>(frame.eye_x, frame.eye_y, frame.eye_z);
    let volume_direction = world_direction * inverse_scale;
    state.direction = volume_direction * frame.anchor_scale;
    state.inverse_direction = 1.0 / state.direction;
    state.speed = length(volume_direction);
    state.color = vec3<f32>(0.0);
    state.transmittance = 1.0;
    state.requests_left = frame.max_requests_per_ray;
    state.requested = false;
    state.samples = 0u;
    state.has_step = false;
    state.step = 0.0;
    let view = -world_direction;
    var light = vec3<f32>(frame.light_x, frame.light_y, frame.light_z);
    if dot(light, light) == 0.0 {
        light = view;
    }
    state.light = light;
    let half_sum = light + view;
    state.half_vector = select(vec3<f32>(0.0), normalize(half_sum), dot(half_sum, half_sum) > 0.0);

    var descents = 0u;
    let lower = vec3<f32>(frame.clip_lower_x, frame.clip_lower_y, frame.clip_lower_z);
    let upper = vec3<f32>(frame.clip_upper_x, frame.clip_upper_y, frame.clip_upper_z);
    let hit = intersect_box(state.origin, state.direction, lower, upper);
    if hit.x <= hit.y {
        var t = max(hit.x, 0.0);
        let t_leave = hit.y;
        var covered = t;
        let root = Node(nodes[0].child_word, nodes[0].data_word);
        if has_brick(root) {
            mark_brick(root.data_word - 1u);
        }
        var segments = 0u;
        var running = true;
        let n = tree.n;
        while running && t < t_leave && segments < frame.max_segments {
            segments += 1u;
            descents += 1u;
            let p = state.origin + state.direction * t;
            // The cone's footprint voxel and the level to descend to (`Traversal::footprint_at`).
            let footprint_voxel = clamp(footprint(t) * frame.bias_scale, level_voxel(tree.max_level), level_voxel(0u));
            var target_level = 0u;
            var target_voxel = 1.0 / f32(tree.brick_size);
            while target_level < tree.max_level && target_voxel > footprint_voxel {
                target_level += 1u;
                target_voxel /= f32(tree.n);
            }

            // Descend from the root (`Traversal::descend`), keeping the last three nodes of the path.
            let root_corner = -vec3<f32>(vec3<i32>(vec3<u32>(frame.anchor_x, frame.anchor_y, frame.anchor_z)));
            var current = PathNode(0u, root, 0u, vec3<u32>(0u), root_corner, frame.anchor_scale);
            var parent = current;
            var grandparent = current;
            var depth = 0u;
            var constant = false;
            loop {
                let node = current.node;
                if (node.child_word & NODE_CONSTANT_BIT) != 0u {
                    constant = true;
                    break;
                }
                if node.data_word == 0u {
                    request(&state, current.id, REQUEST_PRODUCE);
                    break;
                }
                if current.level >= target_level || (node.child_word & NODE_TERMINAL_BIT) != 0u {
                    break;
                }
                let tile = node.child_word & NODE_CHILD_MASK;
                if tile == 0u {
                    request(&state, current.id, REQUEST_SUBDIVIDE);
                    break;
                }
                mark_tile(tile);
                let local = max((p - current.corner) / current.size * f32(n), vec3<f32>(0.0));
                let offset = min(vec3<u32>(local), vec3<u32>(n - 1u));
                let child_index = (offset.z * n + offset.y) * n + offset.x;
                let child_id = tile * tree.nodes_per_tile + child_index;
                let child = Node(nodes[child_id].child_word, nodes[child_id].data_word);
                if has_brick(child) {
                    mark_brick(child.data_word - 1u);
                }
                grandparent = parent;
                parent = current;
                current = child_of(current, offset, child_id, child);
                depth += 1u;
            }

            // The node's box is one segment.
            let node_size = current.size;
            let box_lower = current.corner;
            var t_exit = t_leave;
            for (var a = 0u; a < 3u; a++) {
                let inv = state.inverse_direction[a];
                if state.direction[a] != 0.0 {
                    let bound = select(box_lower[a], box_lower[a] + node_size, inv > 0.0);
                    t_exit = min(t_exit, (bound - state.origin[a]) * inv);
                }
            }
            // Never stall on a boundary: move at least a sliver of the node (f32: coarser than the CPU's sliver).
            t_exit = max(t_exit, t + (node_size * 1e-5 + 2e-7 * max(max(abs(p.x), abs(p.y)), abs(p.z)))
                / (state.speed * frame.anchor_scale) + 2e-7 * t);
            let t_start = t;
            t = t_exit;

            if constant {
                let segment_start = covered;
                covered = max(covered, t_exit);
                if segment_start < t_exit {
                    state.samples += 1u;
                    running = composite_constant(&state, segment_start, t_exit, bitcast<f32>(current.node.data_word),
                        current.level);
                }
                continue;
            }
            // The finest brick on the path and its parent: every node above the last holds a brick.
            var fine = current;
            var coarse = parent;
            var has_coarse = depth >= 1u;
            if !has_brick(current.node) {
                if depth == 0u {
                    // Nothing resident at all: the segment is skipped.
                    covered = max(covered, t_exit);
                    continue;
                }
                fine = parent;
                coarse = grandparent;
                has_coarse = depth >= 2u;
            }
            let is_final = fine.level == current.level
                && (current.level >= target_level || (current.node.child_word & NODE_TERMINAL_BIT) != 0u);
            let stand_in = !is_final;

            // The step: the footprint voxel, or the sampled level's voxel where only coarser data exists, rounded
            // down to the ladder of `StepLength` (kept while it still is the rung for the desired step).
            var sampled_level = fine.level;
            if stand_in && (frame.flags & RAY_FRAME_STEPS_IGNORE_STAND_INS) != 0u {
                sampled_level = min(fine.level + frame.stand_in_levels, tree.max_level);
            }
            let desired = max(level_voxel(sampled_level), footprint_voxel) * frame.step_factor / state.speed;
            if !(state.has_step && state.step <= desired && desired < state.step * RUNG_RATIO) {
                let index = clamp(ceil(-4.0 * log2(desired)), -512.0, 511.0);
                state.step = exp2(-index / 4.0);
                state.has_step = true;
            }
            let dt = state.step;
            let first = covered + 0.5 * dt;
            var count = 0u;
            if first < t_exit {
                // Bounded, so that no placement, however extreme, can keep a ray busy for ever.
                count = u32(clamp(ceil((t_exit - first) / dt), 1.0, 16777216.0));
            }
            covered += f32(count) * dt;
            if count == 0u {
                continue;
            }
            // Quadrilinear: blend with the parent by the cone's level where the finest data is the wanted level.
            var weight = 1.0;
            if has_coarse && fine.level == target_level {
                weight = clamp(level_at(0.5 * (t_start + t_exit)) - f32(coarse.level), 0.0, 1.0);
            }
            let blend = has_coarse && weight < 1.0;
            let fine_slot = fine.node.data_word - 1u;
            let coarse_slot = coarse.node.data_word - 1u;
            // Empty-space skipping: nothing in the bricks (fine, and coarse if blended) can contribute. The samples
            // were placed above, so skipping moves none.
            if (frame.flags & RAY_FRAME_SKIP_EMPTY_SPACE) != 0u {
                var range = brick_range(fine_slot);
                if blend {
                    let coarse_range = brick_range(coarse_slot);
                    range = vec2<f32>(min(range.x, coarse_range.x), max(range.y, coarse_range.y));
                }
                if !visible_in(range.x, range.y) {
                    continue;
                }
            }
            let fine_start = brick_coordinates(&state, fine, first);
            let fine_delta = brick_rate(&state, fine) * dt;
            let coarse_start = brick_coordinates(&state, coarse, first);
            let coarse_delta = brick_rate(&state, coarse) * dt;
            // Within the bricks, samples in occupancy blocks that hold nothing visible are skipped (the CPU skips
            // them in runs; here each sample checks its blocks, once per block change).
            let check_blocks = (frame.flags & RAY_FRAME_SKIP_EMPTY_SPACE) != 0u;
            var last_blocks = vec4<u32>(0xffffffffu);
            var blocks_visible = true;
            for (var k = 0u; k < count; k++) {
                let kf = f32(k);
                let fine_x = fine_start + kf * fine_delta;
                let coarse_x = coarse_start + kf * coarse_delta;
                if check_blocks {
                    let fine_block = block_of(fine_x);
                    var coarse_block = vec3<u32>(0u);
                    if blend {
                        coarse_block = block_of(coarse_x);
                    }
                    let blocks = vec4<u32>(
                        (fine_block.z * tree.blocks_per_axis + fine_block.y) * tree.blocks_per_axis + fine_block.x,
                        (coarse_block.z * tree.blocks_per_axis + coarse_block.y) * tree.blocks_per_axis + coarse_block.x,
                        0u, 0u);
                    if any(blocks != last_blocks) {
                        last_blocks = blocks;
                        // A blended value lies between the two bricks' values: their ranges' hull bounds it.
                        var range = block_range(fine_slot, fine_block);
                        if blend {
                            let coarse_range = block_range(coarse_slot, coarse_block);
                            range = vec2<f32>(min(range.x, coarse_range.x), max(range.y, coarse_range.y));
                        }
                        blocks_visible = visible_in(range.x, range.y);
                    }
                    if !blocks_visible {
                        continue;
                    }
                }
                var s = sample_brick(fine_slot, fine_x);
                if blend {
                    let c = sample_brick(coarse_slot, coarse_x);
                    s.x = c.x + (s.x - c.x) * weight;
                }
                state.samples += 1u;
                if !composite(&state, s.x, s.yzw, fine.level) {
                    running = false;
                    break;
                }
            }
        }
    }

    let background = vec3<f32>(frame.background_r, frame.background_g, frame.background_b);
    pixels[pixel] = vec4<f32>(state.color + state.transmittance * background, 1.0 - state.transmittance);
    pixel_flags[pixel] = select(PIXEL_DONE, PIXEL_MISSED, state.requested);
    atomicAdd(&feedback.rays.rays, 1u);
    atomicAdd(&feedback.rays.samples, state.samples);
    atomicAdd(&feedback.rays.descents, descents);
}
