// The ray's feedback (GigaVoxels [P09] §5): the node tiles and bricks it used, and the nodes it missed, as
// requests within the ray's allowance (`RequestSink` on the CPU).

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
