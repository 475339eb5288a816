// The emission–absorption integrand (`EmissionAbsorption` in voxstream-render): the transfer table corrected per
// step, two-sided Phong, front-to-back compositing of samples and of constant nodes, colour by level.

fn level_colour(level: u32) -> vec3<f32> {
    var palette = array<vec3<f32>, 8>(
        vec3<f32>(0.85, 0.2, 0.2), vec3<f32>(0.95, 0.6, 0.1), vec3<f32>(0.9, 0.9, 0.2), vec3<f32>(0.3, 0.8, 0.2),
        vec3<f32>(0.1, 0.75, 0.75), vec3<f32>(0.2, 0.4, 0.95), vec3<f32>(0.6, 0.3, 0.9), vec3<f32>(0.95, 0.4, 0.75),
    );
    return palette[level % 8u];
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

// The error-bounded adaptive step (`StepVariation::step`, voxstream-render's adaptive_step.rs): `tolerance / TV`
// within [base, MAX_STEP_GROWTH·base], TV the transfer function's variation over [lower, upper] from the prefix sums
// that end the range list (RAY_FRAME_ADAPTIVE_STEP).
const MAX_STEP_GROWTH: f32 = 4.0;
fn adaptive_step(lower: f32, upper: f32, base: f32) -> f32 {
    let entries = arrayLength(&table);
    let last = f32(entries - 1u);
    let a = u32(clamp(floor(lower * last), 0.0, last));
    let b = u32(clamp(ceil(upper * last), 0.0, last));
    let sums = arrayLength(&ranges) - entries;
    let variation = bitcast<f32>(ranges[sums + max(a, b)]) - bitcast<f32>(ranges[sums + min(a, b)]);
    let longest = MAX_STEP_GROWTH * base;
    if variation * longest <= frame.adaptive_tolerance {
        return longest;
    }
    return max(frame.adaptive_tolerance / variation, base);
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
