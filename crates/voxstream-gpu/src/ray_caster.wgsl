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
// The records (Node, TreeHeader, RayFrame, SurfaceRecord, TransferTableEntry, FeedbackCounters, RayCounters,
// RequestRecord) come from crates/voxstream-layout/src/layout.wgsl, which is prepended to this file.
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

// The sample at continuous voxel index x of the brick in `slot`: with its analytic gradient when `gradient`
// (`sample_brick`), else the value alone (`filtered_value`: the texture unit's filtering where the atlas has it).
fn sample_at(slot: u32, x: vec3<f32>, gradient: bool) -> vec4<f32> {
    if gradient {
        return sample_brick(slot, x);
    }
    return vec4<f32>(filtered_value(slot, x), 0.0, 0.0, 0.0);
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

// The level passed for samples that `RAY_FRAME_COLOUR_BY_LEVEL` leaves untinted (the volume around isosurfaces:
// colour by level is volume rendering's, as on the CPU).
const NO_LEVEL: u32 = 0xffffffffu;

// Composites one sample; returns false once the ray is opaque enough to stop.
fn composite(state: ptr<function, RayState>, value: f32, gradient: vec3<f32>, level: u32) -> bool {
    let entry = step_lookup(value, (*state).step);
    if entry.w <= 0.0 {
        return true;
    }
    var premultiplied = entry.xyz;
    if (frame.flags & RAY_FRAME_COLOUR_BY_LEVEL) != 0u && level != NO_LEVEL {
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
    if (frame.flags & RAY_FRAME_COLOUR_BY_LEVEL) != 0u && level != NO_LEVEL {
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

// A shadow ray's cone at the surface is this many times the primary ray's (`SurfaceCaster`).
const SHADOW_CONE: f32 = 2.0;
// A shadow ray starts this many of its footprints off the surface (no self-shadowing by the crossing itself).
const SHADOW_OFFSET: f32 = 1.5;

// ---- Isosurfaces: the `Isosurfaces` integrand of voxstream-render (Knoll et al., seed 002) ----
// The ray carries, per surface (bit i), whether it is inside (f ≥ iso); a crossing is any change of that state:
// inside a trilinear cell (a root of the cell's cubic along the ray) or between pieces of the ray whose fields
// differ (a level seam, a constant node).

// The surfaces a stored value (0‥65535) is inside of.
fn iso_inside_of(stored: f32) -> u32 {
    var bits = 0u;
    for (var i = 0u; i < frame.surface_count; i++) {
        bits |= select(0u, 1u << i, stored >= surfaces[i].iso);
    }
    return bits;
}

// Whether some value in [lower, upper] (normalised) can change the ray's state (`Isosurfaces::can_contribute`).
fn iso_can_contribute(state: ptr<function, RayState>, lower: f32, upper: f32) -> bool {
    if !(*state).known {
        return true;
    }
    for (var i = 0u; i < frame.surface_count; i++) {
        let s = surfaces[i];
        let may_straddle = lower <= s.upper && upper >= s.lower;
        let all_inside = lower > s.upper;
        let inside = ((*state).inside & (1u << i)) != 0u;
        if may_straddle || all_inside != inside {
            return true;
        }
    }
    return false;
}

// A crossing of surface i at t with the field's gradient there (world axes; zero where unknown); returns false
// once the ray is done (`Isosurfaces::hit`).
fn iso_hit(state: ptr<function, RayState>, i: u32, t: f32, gradient: vec3<f32>) -> bool {
    if (*state).any_hit {
        (*state).has_hit = true;
        (*state).first_hit = t;
        (*state).transmittance = 0.0;
        return false;
    }
    let s = surfaces[i];
    let color = vec3<f32>(s.r, s.g, s.b);
    let phong = (frame.flags & RAY_FRAME_PHONG) != 0u;
    var shaded = color;
    if phong {
        shaded = shade(state, color, s.opacity, gradient);
    }
    if !(*state).has_hit {
        (*state).has_hit = true;
        (*state).first_hit = t;
        if phong {
            (*state).first_lit = (*state).transmittance * (shaded - color * frame.ambient);
        }
    }
    (*state).color += (*state).transmittance * shaded;
    (*state).transmittance *= 1.0 - s.opacity;
    return (*state).transmittance > frame.stop_below;
}

// The surfaces whose state changes where the ray's state becomes `entry` (none for the first data met): the
// state is updated, the changed bits returned (`Isosurfaces::enter` without the hits).
fn iso_changes(state: ptr<function, RayState>, entry: u32) -> u32 {
    if !(*state).known {
        (*state).known = true;
        (*state).inside = entry;
        return 0u;
    }
    let changed = entry ^ (*state).inside;
    (*state).inside = entry;
    return changed;
}

// The state is `entry` from t on: a crossing at t for every surface that changed.
fn iso_enter(state: ptr<function, RayState>, entry: u32, t: f32, gradient: vec3<f32>) -> bool {
    return iso_enter_changed(state, iso_changes(state, entry), t, gradient);
}

// Whether this ray draws the volume around its surfaces (never a shadow ray).
fn fog_on(state: ptr<function, RayState>) -> bool {
    return (frame.flags & RAY_FRAME_SURFACES_IN_VOLUME) != 0u && !(*state).any_hit;
}

// The volume's step for a segment where the volume renderer wants steps of `desired` at most: the ladder of
// `StepLength`, kept while it still is the rung for the desired step (as the volume renderer's segments); the
// segment's samples start where the last one's step ended (`VolumeSamples::begin`).
fn fog_begin(state: ptr<function, RayState>, desired: f32) {
    choose_step(state, desired);
    (*state).fog_first = (*state).fog_covered + 0.5 * (*state).step;
    (*state).fog_next = 0u;
}

// The step for a segment that wants `desired` at most: the rung of the ladder of `StepLength`, kept while it still
// is the rung for the desired step (`StepLength::keep_or_at_most`).
fn choose_step(state: ptr<function, RayState>, desired: f32) {
    if !((*state).has_step && (*state).step <= desired && desired < (*state).step * RUNG_RATIO) {
        let index = clamp(ceil(-4.0 * log2(desired)), -512.0, 511.0);
        (*state).step = exp2(-index / 4.0);
        (*state).has_step = true;
    }
}

// The samples whose centres lie before the segment's start t_start (where the step shrank, the first one or two),
// taken from the segment's brick as the volume renderer does (`VolumeSamples::take_before`). Returns false once
// the ray is done.
fn fog_before(state: ptr<function, RayState>, entry: PathNode, t_start: f32) -> bool {
    let slot = entry.node.data_word - 1u;
    let gradients = (frame.flags & RAY_FRAME_PHONG) != 0u;
    for (var guard = 0u; guard < 64u; guard++) {
        let centre = (*state).fog_first + f32((*state).fog_next) * (*state).step;
        if centre >= t_start {
            break;
        }
        (*state).fog_next += 1u;
        let s = sample_at(slot, brick_coordinates(state, entry, centre), gradients);
        if !composite(state, s.x, s.yzw, NO_LEVEL) {
            return false;
        }
    }
    return true;
}

// Passes over the samples whose centres lie before t (where nothing is visible): the next sample is the first at
// or after t, as if they had been taken one by one (`VolumeSamples::pass_until`).
fn fog_pass(state: ptr<function, RayState>, t: f32) {
    let dt = (*state).step;
    let first = (*state).fog_first;
    if first + f32((*state).fog_next) * dt >= t {
        return;
    }
    var k = max(u32(clamp(ceil((t - first) / dt), 0.0, 16777216.0)), (*state).fog_next);
    for (var guard = 0u; guard < 4u && k > (*state).fog_next && first + f32(k - 1u) * dt >= t; guard++) {
        k -= 1u;
    }
    for (var guard = 0u; guard < 4u && first + f32(k) * dt < t; guard++) {
        k += 1u;
    }
    (*state).fog_next = k;
}

// Ends the segment at t: every sample whose centre lies before it is accounted for (`VolumeSamples::end`).
fn fog_end(state: ptr<function, RayState>, t: f32) {
    fog_pass(state, t);
    (*state).fog_covered += f32((*state).fog_next) * (*state).step;
    (*state).fog_next = 0u;
}

// The trilinear interpolant of a cell's corners (x fastest) at cell-local p.
fn cell_value(v: array<f32, 8>, p: vec3<f32>) -> f32 {
    let front = mix(mix(v[0], v[1], p.x), mix(v[2], v[3], p.x), p.y);
    let back = mix(mix(v[4], v[5], p.x), mix(v[6], v[7], p.x), p.y);
    return mix(front, back, p.z);
}

// Composites the volume's samples in the cell `cell` (corners `v`, stored units) whose centres lie before `limit`;
// the cell's brick has the ray at x0 + (t − t_from)·rate (`VolumeSamples::take_until`). Returns false once the
// ray is done.
fn fog_until(state: ptr<function, RayState>, v: array<f32, 8>, x0: vec3<f32>, t_from: f32, rate: vec3<f32>,
    cell: vec3<i32>, t_in: f32, limit: f32) -> bool {
    if !fog_on(state) {
        return true;
    }
    // Samples before the cell lie in blocks the walk passed over.
    fog_pass(state, t_in);
    let dt = (*state).step;
    var centre = (*state).fog_first + f32((*state).fog_next) * dt;
    for (var guard = 0u; centre < limit && guard < 16777216u; guard++) {
        let p = x0 + (centre - t_from) * rate - vec3<f32>(cell);
        let value = cell_value(v, p) * (1.0 / 65535.0);
        let gradient = cell_gradient(v, p) * (1.0 / 65535.0);
        (*state).fog_next += 1u;
        centre = (*state).fog_first + f32((*state).fog_next) * dt;
        if !composite(state, value, gradient, NO_LEVEL) {
            return false;
        }
    }
    return true;
}

// The cubic f(u) = c.x + u·(c.y + u·(c.z + u·c.w)) of the trilinear interpolant of `v` along start + u·rate
// (cell-local coordinates): `CellCubic::new`.
fn cell_cubic(v: array<f32, 8>, start: vec3<f32>, rate: vec3<f32>) -> vec4<f32> {
    var e: array<vec2<f32>, 4>;
    for (var i = 0u; i < 4u; i++) {
        let a = v[i];
        let b = v[i + 4u];
        e[i] = vec2<f32>(a + (b - a) * start.z, (b - a) * rate.z);
    }
    let w0 = 1.0 - start.y;
    let w0u = -rate.y;
    let w1 = start.y;
    let w1u = rate.y;
    // Along y: e00·(1 − y) + e01·y with x = 0 (edges 0, 2), the same with x = 1 (edges 1, 3).
    let q0 = vec3<f32>(e[0].x * w0 + e[2].x * w1, e[0].x * w0u + e[0].y * w0 + e[2].x * w1u + e[2].y * w1,
        e[0].y * w0u + e[2].y * w1u);
    let q1 = vec3<f32>(e[1].x * w0 + e[3].x * w1, e[1].x * w0u + e[1].y * w0 + e[3].x * w1u + e[3].y * w1,
        e[1].y * w0u + e[3].y * w1u);
    let x0 = 1.0 - start.x;
    let x0u = -rate.x;
    let x1 = start.x;
    let x1u = rate.x;
    return vec4<f32>(q0.x * x0 + q1.x * x1, q0.x * x0u + q0.y * x0 + q1.x * x1u + q1.y * x1,
        q0.y * x0u + q0.z * x0 + q1.y * x1u + q1.z * x1, q0.z * x0u + q1.z * x1u);
}

fn cubic_at(c: vec4<f32>, u: f32) -> f32 {
    return c.x + u * (c.y + u * (c.z + u * c.w));
}

// The crossing in [a, b] where fa = f(a) − iso and fb = f(b) − iso lie on different sides: Illinois-modified
// regula falsi (`CellCubic::refine`).
fn cubic_refine(c: vec4<f32>, iso: f32, a_in: f32, fa_in: f32, b_in: f32, fb_in: f32) -> f32 {
    var a = a_in;
    var fa = fa_in;
    var b = b_in;
    var fb = fb_in;
    let inside_a = fa >= 0.0;
    var side = 0;
    for (var k = 0u; k < 16u; k++) {
        let denominator = fb - fa;
        var m = 0.5 * (a + b);
        if denominator != 0.0 {
            m = a - fa * (b - a) / denominator;
        }
        if !(m > a && m < b) {
            m = 0.5 * (a + b);
            if !(m > a && m < b) {
                break;
            }
        }
        let fm = cubic_at(c, m) - iso;
        if (fm >= 0.0) == inside_a {
            a = m;
            fa = fm;
            if side == -1 {
                fb *= 0.5;
            }
            side = -1;
        } else {
            b = m;
            fb = fm;
            if side == 1 {
                fa *= 0.5;
            }
            side = 1;
        }
        if fm == 0.0 {
            break;
        }
    }
    return select(b, a, fa == 0.0);
}

// The analytic gradient of the trilinear cell at cell-local p (`cell_gradient`).
fn cell_gradient(v: array<f32, 8>, p_in: vec3<f32>) -> vec3<f32> {
    let p = clamp(p_in, vec3<f32>(0.0), vec3<f32>(1.0));
    let gx = mix(mix(v[1] - v[0], v[3] - v[2], p.y), mix(v[5] - v[4], v[7] - v[6], p.y), p.z);
    let gy = mix(mix(v[2] - v[0], v[3] - v[1], p.x), mix(v[6] - v[4], v[7] - v[5], p.x), p.z);
    let gz = mix(mix(v[4] - v[0], v[5] - v[1], p.x), mix(v[6] - v[2], v[7] - v[3], p.x), p.y);
    return vec3<f32>(gx, gy, gz);
}

// Central differences at the cell's corners, interpolated trilinearly at cell-local p; one-sided at the brick's
// outer voxels (`CellVisit::central_gradient`).
fn central_gradient(origin: vec3<u32>, cell: vec3<i32>, p_in: vec3<f32>) -> vec3<f32> {
    let p = clamp(p_in, vec3<f32>(0.0), vec3<f32>(1.0));
    let last = i32(tree.stored_brick_size) - 1;
    var g = vec3<f32>(0.0);
    for (var corner = 0u; corner < 8u; corner++) {
        let side = vec3<u32>(corner & 1u, (corner >> 1u) & 1u, corner >> 2u);
        let ijk = cell + vec3<i32>(side);
        let f = select(vec3<f32>(1.0) - p, p, side == vec3<u32>(1u));
        let w = f.x * f.y * f.z;
        for (var a = 0u; a < 3u; a++) {
            var lo = ijk;
            var hi = ijk;
            lo[a] = max(ijk[a] - 1, 0);
            hi[a] = min(ijk[a] + 1, last);
            let span = f32(hi[a] - lo[a]);
            g[a] += w * (voxel(origin + vec3<u32>(hi)) - voxel(origin + vec3<u32>(lo))) / span;
        }
    }
    return g;
}

// The normal at cell-local p, world axes (`Isosurfaces::cell`'s `gradient_at`).
fn surface_gradient(v: array<f32, 8>, origin: vec3<u32>, cell: vec3<i32>, p: vec3<f32>) -> vec3<f32> {
    var g = cell_gradient(v, p);
    if (frame.flags & RAY_FRAME_CENTRAL_NORMALS) != 0u {
        g = central_gradient(origin, cell, p);
    }
    return g * vec3<f32>(frame.inverse_scale_x, frame.inverse_scale_y, frame.inverse_scale_z);
}

// One trilinear cell entered at t_in and crossed over `span_length` (world t): the seams at its entry, then its exact
// crossings in ray order (`Isosurfaces::cell`, `CellCubic::crossings`). `start` is the ray's cell-local position
// at t_in, `rate` its cell-local units per world unit.
fn iso_cell(state: ptr<function, RayState>, v: array<f32, 8>, t_in: f32, span_length: f32, start: vec3<f32>,
    rate: vec3<f32>, origin: vec3<u32>, cell: vec3<i32>, x0: vec3<f32>, t_from: f32, t_out: f32) -> bool {
    // With the volume around the surfaces, its samples before each crossing are composited first, and the rest of
    // the cell's, up to t_out (the next cell's t_in, the same f32), after the last (`Isosurfaces::cell_with`).
    var lo = v[0];
    var hi = v[0];
    for (var k = 1u; k < 8u; k++) {
        lo = min(lo, v[k]);
        hi = max(hi, v[k]);
    }
    var above = 0u;
    var straddle = 0u;
    for (var i = 0u; i < frame.surface_count; i++) {
        let iso = surfaces[i].iso;
        if lo >= iso {
            above |= 1u << i;
        } else if hi >= iso {
            straddle |= 1u << i;
        }
    }
    if straddle == 0u && (*state).known && above == (*state).inside {
        return fog_until(state, v, x0, t_from, rate, cell, t_in, t_out);
    }
    if straddle == 0u {
        let changed = iso_changes(state, above);
        if changed != 0u && !iso_enter_changed(state, changed, t_in, surface_gradient(v, origin, cell, start)) {
            return false;
        }
        return fog_until(state, v, x0, t_from, rate, cell, t_in, t_out);
    }
    let c = cell_cubic(v, start, rate);
    let f0 = cubic_at(c, 0.0);
    var entry = above;
    for (var i = 0u; i < frame.surface_count; i++) {
        if (straddle & (1u << i)) != 0u && f0 >= surfaces[i].iso {
            entry |= 1u << i;
        }
    }
    let changed = iso_changes(state, entry);
    if changed != 0u && !iso_enter_changed(state, changed, t_in, surface_gradient(v, origin, cell, start)) {
        return false;
    }
    // The cubic's extrema inside (0, span_length) split it into monotone pieces (`CellCubic::extrema`).
    let qa = 3.0 * c.w;
    let qb = 2.0 * c.z;
    let qc = c.y;
    var ends = array<f32, 3>(span_length, span_length, span_length);
    var pieces = 0u;
    let scale = max(max(abs(qa), abs(qb)), abs(qc));
    if scale != 0.0 {
        var r = vec2<f32>(-1.0, -1.0);
        if abs(qa) <= 1e-6 * scale {
            if qb != 0.0 {
                r.x = -qc / qb;
            }
        } else {
            let discriminant = qb * qb - 4.0 * qa * qc;
            if discriminant > 0.0 {
                let q = -0.5 * (qb + select(-sqrt(discriminant), sqrt(discriminant), qb >= 0.0));
                let r0 = q / qa;
                let r1 = select(0.0, qc / q, q != 0.0);
                r = vec2<f32>(min(r0, r1), max(r0, r1));
                if r.y == r.x {
                    r.y = -1.0;
                }
            }
        }
        if r.x > 0.0 && r.x < span_length {
            ends[pieces] = r.x;
            pieces += 1u;
        }
        if r.y > 0.0 && r.y < span_length {
            ends[pieces] = r.y;
            pieces += 1u;
        }
    }
    ends[pieces] = span_length;
    // Every straddled surface's crossings, merged in ray order by insertion.
    var cross_u: array<f32, 24>;
    var cross_i: array<u32, 24>;
    var count = 0u;
    for (var i = 0u; i < frame.surface_count; i++) {
        if (straddle & (1u << i)) == 0u {
            continue;
        }
        let iso = surfaces[i].iso;
        var a = 0.0;
        var fa = f0 - iso;
        for (var k = 0u; k <= pieces; k++) {
            let b = ends[k];
            let fb = cubic_at(c, b) - iso;
            if (fa >= 0.0) != (fb >= 0.0) {
                let u = cubic_refine(c, iso, a, fa, b, fb);
                var j = count;
                while j > 0u && cross_u[j - 1u] > u {
                    cross_u[j] = cross_u[j - 1u];
                    cross_i[j] = cross_i[j - 1u];
                    j -= 1u;
                }
                cross_u[j] = u;
                cross_i[j] = i;
                count += 1u;
            }
            a = b;
            fa = fb;
        }
    }
    for (var k = 0u; k < count; k++) {
        let i = cross_i[k];
        let u = cross_u[k];
        if !fog_until(state, v, x0, t_from, rate, cell, t_in, t_in + u) {
            return false;
        }
        (*state).inside ^= 1u << i;
        if !iso_hit(state, i, t_in + u, surface_gradient(v, origin, cell, start + u * rate)) {
            return false;
        }
    }
    return fog_until(state, v, x0, t_from, rate, cell, t_in, t_out);
}

// Hits at t for the surfaces in `changed`, in order.
fn iso_enter_changed(state: ptr<function, RayState>, changed: u32, t: f32, gradient: vec3<f32>) -> bool {
    for (var i = 0u; i < frame.surface_count; i++) {
        if (changed & (1u << i)) != 0u && !iso_hit(state, i, t, gradient) {
            return false;
        }
    }
    return true;
}

// The DDA's next lattice plane per axis, as distances from the span's start (`Lattice::at`); 3e38 where the ray
// does not move along an axis.
fn lattice_next(cell: vec3<i32>, x0: vec3<f32>, rate: vec3<f32>) -> vec3<f32> {
    var next = vec3<f32>(3.0e38);
    for (var a = 0u; a < 3u; a++) {
        if rate[a] != 0.0 {
            let plane = f32(cell[a]) + select(0.0, 1.0, rate[a] > 0.0);
            next[a] = (plane - x0[a]) / rate[a];
        }
    }
    return next;
}

// The trilinear cells the ray crosses in the brick of `entry` over [from, to), in order, each handed to
// `iso_cell`; occupancy blocks that cannot change the ray's state are crossed without visiting their cells
// (`walk_cells`: Amanatides & Woo). Returns false once the ray is done.
fn walk_cells(state: ptr<function, RayState>, entry: PathNode, t_from: f32, t_to: f32) -> bool {
    let b = tree.stored_brick_size;
    let last_cell = i32(b) - 2;
    let slot = entry.node.data_word - 1u;
    let origin = brick_origin(slot);
    let x0 = brick_coordinates(state, entry, t_from);
    let rate = brick_rate(state, entry);
    let span_length = t_to - t_from;
    let direction_sign = vec3<i32>(select(vec3<i32>(0), vec3<i32>(1), rate > vec3<f32>(0.0)))
        - vec3<i32>(select(vec3<i32>(0), vec3<i32>(1), rate < vec3<f32>(0.0)));
    let delta = select(vec3<f32>(0.0), abs(vec3<f32>(1.0) / rate), rate != vec3<f32>(0.0));
    var cell = clamp(vec3<i32>(x0), vec3<i32>(0), vec3<i32>(last_cell));
    var next = lattice_next(cell, x0, rate);
    var u = 0.0;
    let cull = (frame.flags & RAY_FRAME_SKIP_EMPTY_SPACE) != 0u;
    let block_cells = i32(tree.block_cells);
    var checked = vec3<i32>(-1);
    for (var visits = 0u; visits < 3u * b + 3u; visits++) {
        if cull {
            let block = cell / block_cells;
            if any(block != checked) {
                checked = block;
                let range = block_range(slot, vec3<u32>(block));
                if !iso_can_contribute(state, range.x, range.y) && !(fog_on(state) && visible_in(range.x, range.y)) {
                    // Leave the block: the nearest of its exit planes.
                    var exit_u = 3.0e38;
                    var exit_axis = 0u;
                    var exit_across = 0;
                    for (var a = 0u; a < 3u; a++) {
                        if direction_sign[a] == 0 {
                            continue;
                        }
                        var across = block[a] * block_cells - 1;
                        var plane = across + 1;
                        if direction_sign[a] > 0 {
                            across = min((block[a] + 1) * block_cells, last_cell + 1);
                            plane = across;
                        }
                        let u_plane = (f32(plane) - x0[a]) / rate[a];
                        if u_plane < exit_u {
                            exit_u = u_plane;
                            exit_axis = a;
                            exit_across = across;
                        }
                    }
                    if exit_u >= span_length || exit_across < 0 || exit_across > last_cell {
                        break;
                    }
                    u = max(exit_u, u);
                    // Into the block across the plane, the other coordinates kept inside it (the CPU's
                    // `Lattice::at`): rounding near a block's edge could otherwise land in a rejected neighbour whose
                    // exit leads back.
                    var entered = block;
                    entered[exit_axis] = exit_across / block_cells;
                    let first = entered * block_cells;
                    cell = clamp(vec3<i32>(x0 + u * rate), first, min(first + vec3<i32>(block_cells - 1), vec3<i32>(last_cell)));
                    cell[exit_axis] = exit_across;
                    next = lattice_next(cell, x0, rate);
                    continue;
                }
            }
        }
        var axis = 2u;
        if next.x <= next.y && next.x <= next.z {
            axis = 0u;
        } else if next.y <= next.z {
            axis = 1u;
        }
        let u_out = max(min(next[axis], span_length), u);
        let base = origin + vec3<u32>(cell);
        var v: array<f32, 8>;
        for (var k = 0u; k < 8u; k++) {
            v[k] = voxel(base + vec3<u32>(k & 1u, (k >> 1u) & 1u, k >> 2u));
        }
        (*state).samples += 1u;
        let start = x0 + u * rate - vec3<f32>(cell);
        if !iso_cell(state, v, t_from + u, u_out - u, start, rate, origin, cell, x0, t_from, t_from + u_out) {
            return false;
        }
        if next[axis] >= span_length {
            break;
        }
        cell[axis] += direction_sign[axis];
        if cell[axis] < 0 || cell[axis] > last_cell {
            break;
        }
        u = u_out;
        next[axis] += delta[axis];
    }
    return true;
}

// Whether the brick in `slot` has faded in completely (its descendants may be drawn): `BrickBlend::is_in`.
fn blend_is_in(slot: u32) -> bool {
    return !has_blend(slot) || blends[slot].fade >= 1.0;
}

// Whether the brick in `slot` has a blend record this pass (as the CPU's `brick_blends.get(slot)`): none without
// blending, or past the records uploaded (which cover every slot today).
fn has_blend(slot: u32) -> bool {
    return (frame.flags & RAY_FRAME_BLENDING) != 0u && slot < arrayLength(&blends);
}

// Whether the brick in `slot` stands in fully for its parent everywhere: `BrickBlend::is_full`.
fn blend_is_full(slot: u32) -> bool {
    if !has_blend(slot) {
        return true;
    }
    let b = blends[slot];
    return min(min(min(b.corner0, b.corner1), min(b.corner2, b.corner3)),
        min(min(b.corner4, b.corner5), min(b.corner6, b.corner7))) >= 1.0;
}

// The cap of the brick of `entry` where the ray is at t, trilinear between its corners (`Traversal::cap_at`,
// `BrickBlend::at`); only called where `has_blend` holds (through `blend_is_full`).
fn cap_at(state: ptr<function, RayState>, entry: PathNode, t: f32) -> f32 {
    let b = blends[entry.node.data_word - 1u];
    let p = clamp(((*state).origin + (*state).direction * t - entry.corner) / entry.size, vec3<f32>(0.0),
        vec3<f32>(1.0));
    let y0 = mix(mix(b.corner0, b.corner1, p.x), mix(b.corner2, b.corner3, p.x), p.y);
    let y1 = mix(mix(b.corner4, b.corner5, p.x), mix(b.corner6, b.corner7, p.x), p.y);
    return mix(y0, y1, p.z);
}

// Walks one ray through the tree from distance `(*state).start` (`Traversal::trace`), handing its segments to the
// frame's integrand: emission–absorption, or the isosurfaces when the frame has any.
fn march(state: ptr<function, RayState>) {
    let lower = vec3<f32>(frame.clip_lower_x, frame.clip_lower_y, frame.clip_lower_z);
    let upper = vec3<f32>(frame.clip_upper_x, frame.clip_upper_y, frame.clip_upper_z);
    let surfaces_on = ISOSURFACES;
    let skip_empty = (frame.flags & RAY_FRAME_SKIP_EMPTY_SPACE) != 0u;
    let hit = intersect_box((*state).origin, (*state).direction, lower, upper);
    if hit.x <= hit.y {
        var t = max(hit.x, (*state).start);
        let t_leave = hit.y;
        var covered = t;
        (*state).fog_covered = t;
        (*state).fog_first = t;
        (*state).fog_next = 0u;
        let root = Node(nodes[0].child_word, nodes[0].data_word);
        if has_brick(root) {
            mark_brick(root.data_word - 1u);
        }
        var segments = 0u;
        var running = true;
        let n = tree.n;
        // Edge of the finest level's nodes, anchor units (for the descent's look-ahead below).
        let finest_node = frame.anchor_scale / level_scale(tree.max_level);
        while running && t < t_leave && segments < frame.max_segments {
            segments += 1u;
            (*state).descents += 1u;
            let p = (*state).origin + (*state).direction * t;
            // The node a hair ahead of t (`Traversal::next_march`'s probe): on a face the last segment ended at,
            // the node the ray enters, not the one it leaves (one descent fewer per such face).
            let probe = (*state).origin + (*state).direction * (t + sliver(finest_node, p, t, (*state).speed));
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
            // Level blending: the shallowest node on the path whose brick has not faded in, and its parent
            // (`first_fading`): it is drawn, blended with its parent, instead of anything below it.
            var fading = current;
            var fading_parent = current;
            var has_fading = false;
            loop {
                let node = current.node;
                if !has_fading && has_brick(node) && !blend_is_in(node.data_word - 1u) {
                    fading = current;
                    fading_parent = parent;
                    has_fading = true;
                }
                if (node.child_word & NODE_CONSTANT_BIT) != 0u {
                    constant = true;
                    break;
                }
                if node.data_word == 0u {
                    // The parent stands in: drawn one level above this node (the deficit, as the CPU's).
                    request(state, current.id, REQUEST_PRODUCE | (min(target_level + 1u - current.level, 255u) << REQUEST_DEFICIT_SHIFT));
                    break;
                }
                if current.level >= target_level || (node.child_word & NODE_TERMINAL_BIT) != 0u {
                    break;
                }
                // Isosurfaces: a subtree whose values cannot change the ray's state is one segment, skipped whole
                // and never loaded deeper (Knoll et al.'s min/max culling; the CPU's span integrands).
                if surfaces_on && skip_empty && has_brick(node) && !fog_on(state) {
                    let range = brick_range(node.data_word - 1u);
                    if !iso_can_contribute(state, range.x, range.y) {
                        break;
                    }
                }
                let tile = node.child_word & NODE_CHILD_MASK;
                if tile == 0u {
                    request(state, current.id, REQUEST_SUBDIVIDE | (min(target_level - current.level, 255u) << REQUEST_DEFICIT_SHIFT));
                    break;
                }
                mark_tile(tile);
                let local = max((probe - current.corner) / current.size * f32(n), vec3<f32>(0.0));
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
                let inv = (*state).inverse_direction[a];
                if (*state).direction[a] != 0.0 {
                    let bound = select(box_lower[a], box_lower[a] + node_size, inv > 0.0);
                    t_exit = min(t_exit, (bound - (*state).origin[a]) * inv);
                }
            }
            // Never stall on a boundary: move at least a sliver of the node (f32: coarser than the CPU's sliver).
            t_exit = max(t_exit, t + sliver(node_size, p, t, (*state).speed));
            let t_start = t;
            t = t_exit;

            // Under a brick still fading in, that brick stands in for a constant node too.
            if constant && !(has_fading && fading.level < current.level) {
                let segment_start = covered;
                covered = max(covered, t_exit);
                if segment_start < t_exit {
                    (*state).samples += 1u;
                    let value = bitcast<f32>(current.node.data_word);
                    if surfaces_on {
                        running = iso_enter(state, iso_inside_of(value * 65535.0), segment_start, vec3<f32>(0.0));
                        if running && fog_on(state) {
                            // The volume over the distance not yet accounted for (`SurfacesInVolume::constant`).
                            // From the end of the last sample's step, a little before or after the node's entry.
                            let fog_from = (*state).fog_covered;
                            (*state).fog_covered = max((*state).fog_covered, t_exit);
                            if fog_from < t_exit {
                                running = composite_constant(state, fog_from, t_exit, value, NO_LEVEL);
                            }
                        }
                    } else {
                        running = composite_constant(state, segment_start, t_exit, value, current.level);
                    }
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
            if has_fading && fading.level < fine.level {
                fine = fading;
                coarse = fading_parent;
                has_coarse = fading.level >= 1u;
            }
            let is_final = fine.level == current.level
                && (current.level >= target_level || (current.node.child_word & NODE_TERMINAL_BIT) != 0u);
            let stand_in = !is_final;
            // The level whose voxel sets the step (`Traversal::sampled_level`): the fine brick's, or with
            // RAY_FRAME_STEPS_IGNORE_STAND_INS, for a stand-in, the level it stands in for.
            var sampled_level = fine.level;
            if stand_in && (frame.flags & RAY_FRAME_STEPS_IGNORE_STAND_INS) != 0u {
                sampled_level = min(fine.level + frame.stand_in_levels, tree.max_level);
            }
            if surfaces_on {
                // The whole segment at the fine brick's level, cell by cell: no level blending (the crossings of
                // the state close the seams where the level changes).
                covered = max(covered, t_exit);
                let fog = fog_on(state);
                if fog {
                    // The step the volume renderer takes in this segment (`BrickSpan::step`).
                    fog_begin(state, max(level_voxel(sampled_level), footprint_voxel) * frame.step_factor / (*state).speed);
                }
                if skip_empty {
                    let range = brick_range(fine.node.data_word - 1u);
                    if !iso_can_contribute(state, range.x, range.y) && !(fog && visible_in(range.x, range.y)) {
                        if fog {
                            fog_end(state, t_exit);
                        }
                        continue;
                    }
                }
                // The samples before the segment's start come before its first cell's seam crossing.
                running = !fog || fog_before(state, fine, t_start);
                if running {
                    running = walk_cells(state, fine, t_start, t_exit);
                }
                if running && fog {
                    fog_end(state, t_exit);
                }
                continue;
            }

            // The step: the footprint voxel, or the sampled level's voxel where only coarser data exists, rounded
            // down to the ladder of `StepLength` (kept while it still is the rung for the desired step).
            choose_step(state, max(level_voxel(sampled_level), footprint_voxel) * frame.step_factor / (*state).speed);
            let dt = (*state).step;
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
            let fine_slot = fine.node.data_word - 1u;
            let coarse_slot = coarse.node.data_word - 1u;
            // Thiele et al.: the cone's weight capped by the fine brick's caps (fade-in, coarser neighbours) at the
            // first and the last sample, ramped linearly between them; normals blend by the caps alone.
            let capped = has_coarse && !blend_is_full(fine_slot);
            var weight_first = weight;
            var weight_step = 0.0;
            var normal_first = 1.0;
            var normal_step = 0.0;
            if capped {
                let cap_first = cap_at(state, fine, first);
                let cap_last = cap_at(state, fine, first + f32(count - 1u) * dt);
                weight_first = min(weight, cap_first);
                normal_first = cap_first;
                if count > 1u {
                    weight_step = (min(weight, cap_last) - weight_first) / f32(count - 1u);
                    normal_step = (cap_last - cap_first) / f32(count - 1u);
                }
            }
            let blend = has_coarse && (!(weight_first >= 1.0 && weight_first + weight_step >= 1.0) || capped);
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
            let fine_start = brick_coordinates(state, fine, first);
            let fine_delta = brick_rate(state, fine) * dt;
            let coarse_start = brick_coordinates(state, coarse, first);
            let coarse_delta = brick_rate(state, coarse) * dt;
            // Within the bricks, samples in occupancy blocks that hold nothing visible are skipped (the CPU skips
            // them in runs; here each sample checks its blocks, once per block change).
            let check_blocks = (frame.flags & RAY_FRAME_SKIP_EMPTY_SPACE) != 0u;
            // Gradients only where Phong shades with them (unshaded samples are one filtered fetch).
            let gradients = (frame.flags & RAY_FRAME_PHONG) != 0u;
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
                var s = sample_at(fine_slot, fine_x, gradients);
                if blend {
                    let c = sample_at(coarse_slot, coarse_x, gradients);
                    s.x = c.x + (s.x - c.x) * (weight_first + kf * weight_step);
                    if capped {
                        // A coarse gradient per coarse voxel, in fine voxels.
                        let coarse_gradient = c.yzw / f32(tree.n);
                        s = vec4<f32>(s.x, coarse_gradient + (s.yzw - coarse_gradient) * (normal_first + kf * normal_step));
                    }
                }
                (*state).samples += 1u;
                if !composite(state, s.x, s.yzw, fine.level) {
                    running = false;
                    break;
                }
            }
        }
    }

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

    state.start = 0.0;
    state.descents = 0u;
    state.inside = 0u;
    state.known = false;
    state.has_hit = false;
    state.first_hit = 0.0;
    state.first_lit = vec3<f32>(0.0);
    state.any_hit = false;
    march(&state);

    // Hard shadows (`SurfaceCaster`, Knoll et al. §5): from the first crossing, a ray towards the light through the
    // same tree, its cone twice as wide as the primary ray's at the surface; a blocked light leaves the crossing
    // its ambient term. Its misses are reported like the primary ray's.
    if ISOSURFACES && (frame.flags & RAY_FRAME_SHADOWS) != 0u && state.has_hit {
        let t_hit = state.first_hit;
        let point = state.origin + state.direction * t_hit;
        let toward_light = light * inverse_scale;
        let back = t_hit * SHADOW_CONE;
        let shadow_footprint = max(t_hit * frame.pixel_spread * SHADOW_CONE, frame.finest_voxel);
        let color = state.color;
        let transmittance = state.transmittance;
        let first_lit = state.first_lit;
        state.direction = toward_light * frame.anchor_scale;
        state.origin = point - state.direction * back;
        state.inverse_direction = 1.0 / state.direction;
        state.speed = length(toward_light);
        state.start = back + SHADOW_OFFSET * shadow_footprint;
        state.requests_left = frame.max_requests_per_ray;
        state.color = vec3<f32>(0.0);
        state.transmittance = 1.0;
        state.inside = 0u;
        state.known = false;
        state.has_hit = false;
        state.any_hit = true;
        march(&state);
        // A shadow ray counts as a ray, as on the CPU.
        atomicAdd(&feedback.rays.rays, 1u);
        let blocked = state.has_hit;
        state.color = color;
        state.transmittance = transmittance;
        if blocked {
            state.color -= first_lit;
        }
    }

    let background = vec3<f32>(frame.background_r, frame.background_g, frame.background_b);
    pixels[pixel] = vec4<f32>(state.color + state.transmittance * background, 1.0 - state.transmittance);
    pixel_flags[pixel] = select(PIXEL_DONE, PIXEL_MISSED, state.requested);
    atomicAdd(&feedback.rays.rays, 1u);
    atomicAdd(&feedback.rays.samples, state.samples);
    atomicAdd(&feedback.rays.descents, state.descents);
}
