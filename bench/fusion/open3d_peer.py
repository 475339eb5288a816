#!/usr/bin/env python3
"""Open3D peer for voxstream's depth-camera fusion benchmark.

Integrates a TUM-layout RGB-D sequence with ground-truth poses into Open3D's tensor
VoxelBlockGrid (attributes tsdf, weight, color; CPU device), timing integration per
frame (all frames are read into memory first; reading is timed separately), reports
memory (grid bytes and process peak RSS), extracts the surface and optionally runs
Open3D's dense frame-to-model tracking (t.pipelines.slam) to report ATE.

    python open3d_peer.py DATASET --voxel 0.01 [--trunc-voxels 4] [--block 16]
        [--frames N] [--odometry] --json OUT.json [--points OUT.ply] [--mesh OUT.ply]
"""
import argparse
import json
import os
import platform
import resource
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tum_io import (TUM_DEPTH_SCALE, TUM_INTRINSICS, DatasetError, ate, fail,  # noqa: E402
                    intrinsic_matrix, load_sequence, write_tum_trajectory)

MiB = 1024.0 * 1024.0


def peak_rss_bytes():
    # ru_maxrss is in KiB on Linux (bytes on macOS)
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r if sys.platform == "darwin" else r * 1024


def current_rss_bytes():
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def stats(x):
    x = np.asarray(x, float)
    if len(x) == 0:
        return None
    return dict(mean=float(x.mean()), median=float(np.median(x)), min=float(x.min()),
                max=float(x.max()), p95=float(np.percentile(x, 95)), total=float(x.sum()))


def grid_memory(vbg, o3c, hash_entry_bytes_estimate=48):
    """Bytes of a VoxelBlockGrid.

    Open3D's HashMap preallocates its key/value buffers for `capacity` blocks, so the
    bytes actually allocated follow the capacity, not the number of active blocks.
    Both are reported. The backend hash table itself (CPU: TBB concurrent map,
    key -> buffer index) is not exposed; it is estimated per active entry.
    """
    hm = vbg.hashmap()
    cap, n = int(hm.capacity()), int(hm.size())
    attrs = {}
    per_block_values = 0
    for name in ("tsdf", "weight", "color"):
        t = vbg.attribute(name)  # (capacity, R, R, R, C) view of the value buffer
        shape = tuple(int(s) for s in t.shape)
        voxels_per_block = int(np.prod(shape[1:4]))
        ch = int(shape[4]) if len(shape) > 4 else 1
        bsz = int(t.dtype.byte_size())
        attrs[name] = dict(dtype=str(t.dtype), channels=ch, bytes_per_voxel=bsz * ch)
        per_block_values += voxels_per_block * bsz * ch
    key = hm.key_tensor()
    key_bytes_per_block = int(np.prod([int(s) for s in key.shape[1:]])) * int(key.dtype.byte_size())
    bytes_per_voxel = sum(a["bytes_per_voxel"] for a in attrs.values())
    active_values = n * per_block_values
    return dict(
        attributes=attrs,
        bytes_per_voxel=bytes_per_voxel,
        block_resolution=int(round(voxels_per_block ** (1 / 3))),
        active_blocks=n,
        hashmap_capacity_blocks=cap,
        active_voxels=n * voxels_per_block,
        # (a) active blocks x voxels/block x bytes/voxel
        active_voxel_bytes=active_values,
        active_voxel_mib=active_values / MiB,
        # plus keys (int32 x 3 per block) and estimated hash-table entries
        active_with_hash_estimate_bytes=active_values + n * (key_bytes_per_block + hash_entry_bytes_estimate),
        active_with_hash_estimate_mib=(active_values + n * (key_bytes_per_block + hash_entry_bytes_estimate)) / MiB,
        # what the hash map has actually allocated (buffers sized by capacity)
        allocated_buffer_bytes=cap * (per_block_values + key_bytes_per_block + 4),
        allocated_buffer_mib=cap * (per_block_values + key_bytes_per_block + 4) / MiB,
        hash_entry_bytes_estimate=hash_entry_bytes_estimate,
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset", help="TUM-layout folder (rgb/, depth/, rgb.txt, depth.txt, groundtruth.txt)")
    ap.add_argument("--voxel", type=float, default=0.01, help="voxel size in metres (default 0.01)")
    ap.add_argument("--trunc-voxels", type=float, default=4.0,
                    help="truncation distance in voxels (Open3D trunc_voxel_multiplier; default 4)")
    ap.add_argument("--block", type=int, default=16, help="voxels per block edge (default 16)")
    ap.add_argument("--block-count", type=int, default=10000,
                    help="initial hash map capacity in blocks; Open3D preallocates the voxel buffers for this many blocks and grows (rehashes) on demand on CPU (default 10000, as Open3D)")
    ap.add_argument("--frames", type=int, default=0, help="use only the first N frames (0 = all)")
    ap.add_argument("--depth-max", type=float, default=3.0, help="ignore depth beyond this (m; default 3.0)")
    ap.add_argument("--depth-min", type=float, default=0.1, help="ray-casting min depth for odometry (m)")
    ap.add_argument("--depth-scale", type=float, default=TUM_DEPTH_SCALE, help="depth PNG units per metre (5000)")
    ap.add_argument("--fx", type=float, default=TUM_INTRINSICS["fx"])
    ap.add_argument("--fy", type=float, default=TUM_INTRINSICS["fy"])
    ap.add_argument("--cx", type=float, default=TUM_INTRINSICS["cx"])
    ap.add_argument("--cy", type=float, default=TUM_INTRINSICS["cy"])
    ap.add_argument("--half-pixel-fix", action="store_true",
                    help="pass cx+0.5, cy+0.5 to VoxelBlockGrid integration. Open3D's integrate kernel "
                         "truncates the projected pixel coordinate (static_cast<int>(u)), i.e. treats "
                         "pixel i as [i, i+1); with TUM intrinsics (pixel centres at integers) that "
                         "samples the depth half a pixel off. The shift makes it pick the nearest pixel. "
                         "Off by default (stock Open3D behaviour); does not affect --odometry.")
    ap.add_argument("--max-dt", type=float, default=0.02, help="max timestamp difference for association (s)")
    ap.add_argument("--weights", choices=["float32", "compact"], default="float32",
                    help="attribute dtypes: float32 = tsdf f32, weight f32, color 3xf32 (default); "
                         "compact = Open3D's SLAM layout tsdf f32, weight u16, color 3xu16")
    ap.add_argument("--weight-threshold", type=float, default=3.0,
                    help="min voxel weight for surface extraction (Open3D default 3.0)")
    ap.add_argument("--no-color", action="store_true", help="integrate depth only (color attribute stays allocated)")
    ap.add_argument("--odometry", action="store_true",
                    help="also run Open3D frame-to-model tracking (t.pipelines.slam) and report ATE")
    ap.add_argument("--odometry-depth-diff", type=float, default=0.07,
                    help="max correspondence depth difference for tracking (m; Open3D default 0.07)")
    ap.add_argument("--odometry-iters", default="6,3,1",
                    help="ICP iterations per pyramid level, in the order of Open3D's criteria list "
                         "(default 6,3,1 = Open3D's default criteria)")
    ap.add_argument("--trajectory", help="write the odometry trajectory (TUM format) here")
    ap.add_argument("--threads", type=int, default=0, help="informational; set OMP_NUM_THREADS in the env")
    ap.add_argument("--json", required=True, help="output JSON file")
    ap.add_argument("--points", help="write the extracted surface point cloud (PLY) here")
    ap.add_argument("--mesh", help="write the extracted triangle mesh (PLY) here")
    a = ap.parse_args()

    if a.voxel <= 0 or a.trunc_voxels <= 0 or a.block <= 0:
        fail("--voxel, --trunc-voxels and --block must be positive")
    for p in (a.json, a.points, a.mesh, a.trajectory):
        if p and os.path.dirname(os.path.abspath(p)) and not os.path.isdir(os.path.dirname(os.path.abspath(p))):
            fail(f"output folder does not exist: {os.path.dirname(os.path.abspath(p))}")
    try:
        frames, dropped = load_sequence(a.dataset, a.max_dt, need_gt=True)
    except DatasetError as e:
        fail(str(e))
    if a.frames > 0:
        frames = frames[:a.frames]

    from o3d_import import LIBUSB_SOURCE, o3c, o3d  # heavy import after argument checks
    dev = o3c.Device("CPU:0")
    K = intrinsic_matrix(a.fx, a.fy, a.cx, a.cy)
    K_t = o3c.Tensor(K, o3c.float64)
    K_int = K.copy()
    if a.half_pixel_fix:
        K_int[0, 2] += 0.5
        K_int[1, 2] += 0.5
    K_int_t = o3c.Tensor(K_int, o3c.float64)
    rss_start = current_rss_bytes()

    # ------------------------------------------------------------ read all frames
    t0 = time.perf_counter()
    depths, colors = [], []
    for fr in frames:
        d = o3d.t.io.read_image(fr["depth"])
        c = o3d.t.io.read_image(fr["rgb"])
        if d.is_empty() or c.is_empty():
            fail(f"cannot read {fr['depth']} / {fr['rgb']}")
        if d.dtype != o3c.uint16 or d.channels != 1:
            fail(f"{fr['depth']}: expected 16-bit single-channel PNG, got {d.dtype} x{d.channels}")
        if c.channels == 4:
            c = o3d.t.geometry.Image(c.as_tensor()[:, :, :3].contiguous())
        if (c.rows, c.columns) != (d.rows, d.columns):
            fail(f"rgb {c.columns}x{c.rows} and depth {d.columns}x{d.rows} sizes differ ({fr['rgb']})")
        depths.append(d.to(dev))
        colors.append(c.to(dev))
    read_s = time.perf_counter() - t0
    H, W = depths[0].rows, depths[0].columns
    rss_after_read = current_rss_bytes()
    peak_after_read = peak_rss_bytes()
    print(f"read {len(frames)} frames ({W}x{H}) in {read_s:.2f} s", file=sys.stderr)

    # ------------------------------------------------------------ integration (GT poses)
    if a.weights == "float32":
        dtypes = (o3c.float32, o3c.float32, o3c.float32)
    else:
        dtypes = (o3c.float32, o3c.uint16, o3c.uint16)
    vbg = o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight", "color"), attr_dtypes=dtypes,
        attr_channels=((1), (1), (3)), voxel_size=a.voxel,
        block_resolution=a.block, block_count=a.block_count, device=dev)
    per_frame = []
    block_s = []
    for i, fr in enumerate(frames):
        extr = o3c.Tensor(np.linalg.inv(fr["pose"]), o3c.float64)  # world-to-camera
        t1 = time.perf_counter()
        blocks = vbg.compute_unique_block_coordinates(
            depths[i], K_int_t, extr, a.depth_scale, a.depth_max, a.trunc_voxels)
        t2 = time.perf_counter()
        if a.no_color:
            vbg.integrate(blocks, depths[i], K_int_t, extr, a.depth_scale, a.depth_max, a.trunc_voxels)
        else:
            vbg.integrate(blocks, depths[i], colors[i], K_int_t, K_int_t, extr,
                          a.depth_scale, a.depth_max, a.trunc_voxels)
        t3 = time.perf_counter()
        per_frame.append(t3 - t1)
        block_s.append(t2 - t1)
    integ_total = float(np.sum(per_frame))
    mem = grid_memory(vbg, o3c)
    rss_after_integrate = current_rss_bytes()
    peak_after_integrate = peak_rss_bytes()
    print(f"integrated {len(frames)} frames in {integ_total:.2f} s "
          f"({len(frames) / integ_total:.1f} fps); {mem['active_blocks']} blocks", file=sys.stderr)

    # ------------------------------------------------------------ surface extraction
    t0 = time.perf_counter()
    pcd = vbg.extract_point_cloud(a.weight_threshold)
    pcd_s = time.perf_counter() - t0
    n_points = int(pcd.point.positions.shape[0]) if "positions" in pcd.point else 0
    if a.points:
        if n_points == 0:
            print("warning: extracted point cloud is empty", file=sys.stderr)
        if "colors" in pcd.point and pcd.point.colors.dtype != o3c.uint8:
            # scale float colours to 0..1 for portable PLY output
            c = pcd.point.colors.numpy().astype(np.float32)
            cmax = float(c.max()) if c.size else 1.0
            if cmax > 1.0:
                pcd.point.colors = o3c.Tensor(c / (255.0 if cmax <= 255.0 else 65535.0))
        if not o3d.t.io.write_point_cloud(a.points, pcd):
            fail(f"cannot write {a.points}")
    mesh_info = None
    if a.mesh:
        t0 = time.perf_counter()
        mesh = vbg.extract_triangle_mesh(a.weight_threshold)
        mesh_s = time.perf_counter() - t0
        leg = mesh.to_legacy()
        if not o3d.io.write_triangle_mesh(a.mesh, leg):
            fail(f"cannot write {a.mesh}")
        mesh_info = dict(path=os.path.abspath(a.mesh), vertices=len(leg.vertices),
                         triangles=len(leg.triangles), extract_s=mesh_s)

    out = dict(
        tool="open3d_peer",
        open3d_version=o3d.__version__,
        numpy_version=np.__version__,
        python=platform.python_version(),
        machine=dict(platform=platform.platform(), cpu_count=os.cpu_count(),
                     omp_num_threads=os.environ.get("OMP_NUM_THREADS"),
                     loadavg_1_5_15_at_end=list(os.getloadavg())),
        libusb=LIBUSB_SOURCE,
        dataset=os.path.abspath(a.dataset),
        frames=len(frames),
        frames_dropped_no_pose=dropped,
        image_size=[W, H],
        intrinsics=dict(fx=a.fx, fy=a.fy, cx=a.cx, cy=a.cy),
        params=dict(voxel_m=a.voxel, trunc_voxels=a.trunc_voxels, trunc_m=a.trunc_voxels * a.voxel,
                    block_resolution=a.block, initial_block_count=a.block_count,
                    depth_scale=a.depth_scale, depth_max_m=a.depth_max, weights=a.weights,
                    color=not a.no_color, half_pixel_fix=a.half_pixel_fix,
                    weight_threshold=a.weight_threshold, device=str(dev)),
        read=dict(total_s=read_s, per_frame_ms=1000 * read_s / len(frames)),
        integration=dict(
            total_s=integ_total,
            fps=len(frames) / integ_total,
            per_frame_ms=stats(1000 * np.asarray(per_frame)),
            block_coords_per_frame_ms=stats(1000 * np.asarray(block_s)),
            note="per frame: compute_unique_block_coordinates + integrate; excludes file reading",
        ),
        memory=dict(
            grid=mem,
            rss_start_bytes=rss_start,
            rss_after_read_bytes=rss_after_read,
            rss_after_integration_bytes=rss_after_integrate,
            peak_rss_after_read_bytes=peak_after_read,
            peak_rss_after_integration_bytes=peak_after_integrate,
            peak_rss_after_integration_mib=peak_after_integrate / MiB,
            integration_rss_increase_mib=(peak_after_integrate - peak_after_read) / MiB,
        ),
        surface=dict(points=n_points, extract_point_cloud_s=pcd_s,
                     points_path=os.path.abspath(a.points) if a.points else None, mesh=mesh_info),
    )

    # ------------------------------------------------------------ odometry (optional)
    if a.odometry:
        out["odometry"] = run_odometry(a, frames, depths, colors, K_t, dev, o3d, o3c)
        out["memory"]["peak_rss_final_bytes"] = peak_rss_bytes()
        out["memory"]["peak_rss_final_mib"] = peak_rss_bytes() / MiB

    with open(a.json, "w") as f:
        json.dump(out, f, indent=2)
    print(json.dumps(dict(fps=out["integration"]["fps"],
                          grid_active_mib=mem["active_voxel_mib"],
                          grid_allocated_mib=mem["allocated_buffer_mib"],
                          peak_rss_mib=out["memory"]["peak_rss_after_integration_mib"],
                          points=n_points,
                          ate_rmse_m=out.get("odometry", {}).get("ate", {}).get("rmse_m"))))


def run_odometry(a, frames, depths, colors, K_t, dev, o3d, o3c):
    """Dense frame-to-model tracking as in Open3D's t_reconstruction_system/dense_slam.py,
    started from the first ground-truth pose."""
    H, W = depths[0].rows, depths[0].columns
    T = o3c.Tensor(frames[0]["pose"], o3c.float64)
    model = o3d.t.pipelines.slam.Model(a.voxel, a.block, a.block_count, T, dev)
    input_frame = o3d.t.pipelines.slam.Frame(H, W, K_t, dev)
    raycast_frame = o3d.t.pipelines.slam.Frame(H, W, K_t, dev)
    try:
        iters = [int(x) for x in a.odometry_iters.split(",") if x.strip()]
        assert iters and all(i > 0 for i in iters)
    except (ValueError, AssertionError):
        fail(f"--odometry-iters: expected comma-separated positive integers, got {a.odometry_iters!r}")
    criteria = [o3d.t.pipelines.odometry.OdometryConvergenceCriteria(i) for i in iters]
    method = o3d.t.pipelines.odometry.Method.PointToPlane
    poses, per_frame, track_s, failures = [], [], [], 0
    for i in range(len(frames)):
        t0 = time.perf_counter()
        input_frame.set_data_from_image("depth", depths[i])
        input_frame.set_data_from_image("color", colors[i])
        if i > 0:
            t1 = time.perf_counter()
            try:
                res = model.track_frame_to_model(input_frame, raycast_frame, a.depth_scale,
                                                 a.depth_max, a.odometry_depth_diff,
                                                 method, criteria)
                T = T @ res.transformation
            except RuntimeError as e:  # e.g. too few correspondences
                failures += 1
                print(f"warning: tracking failed at frame {i}: {e}", file=sys.stderr)
            track_s.append(time.perf_counter() - t1)
        poses.append(T.cpu().numpy().copy())
        model.update_frame_pose(i, T)
        model.integrate(input_frame, a.depth_scale, a.depth_max, a.trunc_voxels)
        model.synthesize_model_frame(raycast_frame, a.depth_scale, a.depth_min, a.depth_max,
                                     a.trunc_voxels, False)
        per_frame.append(time.perf_counter() - t0)
    total = float(np.sum(per_frame))
    est = np.array([p[:3, 3] for p in poses])
    gt = np.array([fr["pose"][:3, 3] for fr in frames])
    if a.trajectory:
        write_tum_trajectory(a.trajectory, [fr["timestamp"] for fr in frames], poses)
    vg = model.voxel_grid
    res = dict(
        method="o3d.t.pipelines.slam.Model: track_frame_to_model (PointToPlane, depth) + "
               "integrate + synthesize_model_frame, start at first GT pose",
        frames=len(frames),
        total_s=total,
        fps=len(frames) / total,
        per_frame_ms=stats(1000 * np.asarray(per_frame)),
        tracking_per_frame_ms=stats(1000 * np.asarray(track_s)),
        tracking_failures=failures,
        icp_iterations_per_level=iters,
        ate=ate(est, gt) if len(frames) >= 3 else None,
        final_translation_error_m=float(np.linalg.norm(est[-1] - gt[-1])),
        model_grid=grid_memory(vg, o3c),
        trajectory_path=os.path.abspath(a.trajectory) if a.trajectory else None,
    )
    print(f"odometry: {res['fps']:.1f} fps, ATE RMSE "
          f"{res['ate']['rmse_m'] if res['ate'] else float('nan'):.4f} m", file=sys.stderr)
    return res


if __name__ == "__main__":
    main()
