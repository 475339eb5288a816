// The segment walk (`Traversal::trace`'s `begin`/`next_march` and the brick marching after it): one ray from its
// start to its end, each segment handed to the frame's integrand.

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
                    request(state, current.id, REQUEST_PRODUCE | (min(target_level + 1u - current.level, REQUEST_MAX_DEFICIT) << REQUEST_DEFICIT_SHIFT));
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
                    request(state, current.id, REQUEST_SUBDIVIDE | (min(target_level - current.level, REQUEST_MAX_DEFICIT) << REQUEST_DEFICIT_SHIFT));
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
                        running = iso_enter(state, iso_inside_of(value * VOXEL_MAX), segment_start, vec3<f32>(0.0));
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

            // Quadrilinear: blend with the parent by the cone's level where the finest data is the wanted level.
            var weight = 1.0;
            if has_coarse && fine.level == target_level {
                weight = clamp(level_at(0.5 * (t_start + t_exit)) - f32(coarse.level), 0.0, 1.0);
            }
            let fine_slot = fine.node.data_word - 1u;
            let coarse_slot = coarse.node.data_word - 1u;
            let capped = has_coarse && !blend_is_full(fine_slot);
            // The step: the footprint voxel, or the sampled level's voxel where only coarser data exists, rounded
            // down to the ladder of `StepLength` (kept while it still is the rung for the desired step); with
            // RAY_FRAME_ADAPTIVE_STEP, longer where the transfer function varies little over the bricks' values
            // (the coarse brick's too where it is blended in).
            var desired = max(level_voxel(sampled_level), footprint_voxel) * frame.step_factor / (*state).speed;
            if (frame.flags & RAY_FRAME_ADAPTIVE_STEP) != 0u {
                var values = brick_range(fine_slot);
                if has_coarse && (weight < 1.0 || capped) {
                    let coarse_values = brick_range(coarse_slot);
                    values = vec2<f32>(min(values.x, coarse_values.x), max(values.y, coarse_values.y));
                }
                desired = adaptive_step(values.x, values.y, desired);
            }
            choose_step(state, desired);
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
            // Thiele et al.: the cone's weight capped by the fine brick's caps (fade-in, coarser neighbours) at the
            // first and the last sample, ramped linearly between them; normals blend by the caps alone.
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
