// The isosurfaces integrand (`Isosurfaces` and `SurfacesInVolume` in voxstream-render; Knoll et al., seed 002):
// crossings per surface, the volume composited between them, the surfaces' normals, and the cell walk through a
// brick segment. One cell's cubic and its crossings are cell_cubic.wgsl's.

// Surfaces one frame draws at most (`MAX_SURFACES`: a bit each in `RayState::inside`), and the crossings one cell
// can hold, three per surface.
const MAX_SURFACES: u32 = 8u;
const MAX_CROSSINGS: u32 = 3u * MAX_SURFACES;
// A shadow ray's cone at the surface is this many times the primary ray's (`SurfaceCaster`).
const SHADOW_CONE: f32 = 2.0;
// A shadow ray starts this many of its footprints off the surface (no self-shadowing by the crossing itself).
const SHADOW_OFFSET: f32 = 1.5;

// ---- Isosurfaces: the `Isosurfaces` integrand of voxstream-render (Knoll et al., seed 002) ----
// The ray carries, per surface (bit i), whether it is inside (f ≥ iso); a crossing is any change of that state:
// inside a trilinear cell (a root of the cell's cubic along the ray) or between pieces of the ray whose fields
// differ (a level seam, a constant node).

// The surfaces a stored value (0‥VOXEL_MAX) is inside of.
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
        let index = clamp(ceil(-STEPS_PER_OCTAVE * log2(desired)), -LADDER_HALF, LADDER_HALF - 1.0);
        (*state).step = exp2(-index / STEPS_PER_OCTAVE);
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
        let value = cell_value(v, p) * (1.0 / VOXEL_MAX);
        let gradient = cell_gradient(v, p) * (1.0 / VOXEL_MAX);
        (*state).fog_next += 1u;
        centre = (*state).fog_first + f32((*state).fog_next) * dt;
        if !composite(state, value, gradient, NO_LEVEL) {
            return false;
        }
    }
    return true;
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
    // The cubic's extrema inside (0, span_length) split it into monotone pieces, shared by every surface.
    let pieces = cubic_pieces(c, span_length);
    // Every straddled surface's crossings, merged in ray order by insertion.
    var cross_u: array<f32, MAX_CROSSINGS>;
    var cross_i: array<u32, MAX_CROSSINGS>;
    var count = 0u;
    for (var i = 0u; i < frame.surface_count; i++) {
        if (straddle & (1u << i)) == 0u {
            continue;
        }
        let found = cubic_crossings(c, surfaces[i].iso, pieces);
        for (var r = 0u; r < found.count; r++) {
            let u = found.u[r];
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
