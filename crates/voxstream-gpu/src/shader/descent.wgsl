// Level of detail and the descent's geometry (`Traversal`'s footprint, levels, slivers and slab tests): the cone's
// level at a distance, nodes on the descent path in the anchor frame, and a brick's coordinates along the ray.

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

// `Traversal`'s `sliver`: a distance along the ray of 1e-5 of a node of edge `node_size` (anchor units), plus more
// than the rounding of the point `p` at `t` (f32: coarser than the CPU's 1e-7).
fn sliver(node_size: f32, p: vec3<f32>, t: f32, speed: f32) -> f32 {
    return (node_size * 1e-5 + 2e-7 * max(max(abs(p.x), abs(p.y)), abs(p.z))) / (speed * frame.anchor_scale) + 2e-7 * t;
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
