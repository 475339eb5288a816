// Thiele et al.'s level blending (`BrickBlend`): whether a brick has faded in, and its cap at a point.

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
