// The entry point: one invocation per pending pixel, its primary ray (and shadow rays), its pixel and flags.

@compute @workgroup_size(WORKGROUP_EDGE, WORKGROUP_EDGE, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let pixel = id.y * frame.width + id.x;
    if pixel_flags[pixel] != PIXEL_PENDING || (id.x % frame.pixel_stride) != 0u || (id.y % frame.pixel_stride) != 0u {
        pixel_flags[pixel] = PIXEL_UNTRACED;
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
