#!/usr/bin/env python3
"""Distance between a reconstructed surface and the true scene mesh.

Accuracy: for every reconstructed point (point-cloud PLY, or a mesh PLY's vertices) the
unsigned distance to the true mesh (Open3D RaycastingScene.compute_distance).
Completeness: sample the true mesh uniformly, distance from each sample to the nearest
reconstructed point. By default this includes parts of the true mesh no camera saw;
with --dataset the samples are also filtered to those visible in at least one depth
frame (projected into the frame with its ground-truth pose, inside the image and
within --visible-tol of the measured depth, not beyond --depth-max).

    python surface_error.py --truth scene.ply --points SURFACE.ply [--json OUT.json]
        [--voxel 0.01] [--samples 200000] [--dataset DIR]
"""
import argparse
import json
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tum_io import (TUM_DEPTH_SCALE, TUM_INTRINSICS, DatasetError, fail,  # noqa: E402
                    load_sequence)


def dist_stats(d, thresholds):
    d = np.asarray(d, np.float64)
    if len(d) == 0:
        return dict(count=0)
    out = dict(count=int(len(d)), mean=float(d.mean()), median=float(np.median(d)),
               p95=float(np.percentile(d, 95)), max=float(d.max()),
               rms=float(np.sqrt(np.mean(d ** 2))))
    for name, t in thresholds.items():
        out[f"fraction_within_{name}"] = float(np.mean(d <= t))
    return out


def read_surface_points(path, o3d):
    """Vertices of a PLY (point cloud or mesh) as float64 (N,3)."""
    with open(path, "rb") as f:
        header = f.read(4096)
    if not header.startswith(b"ply"):
        fail(f"{path}: not a PLY file")
    if re.search(rb"element face [1-9]", header):
        mesh = o3d.io.read_triangle_mesh(path)
        return np.asarray(mesh.vertices, np.float64), "mesh_vertices"
    pcd = o3d.io.read_point_cloud(path)
    return np.asarray(pcd.points, np.float64), "points"


def visible_mask(samples, dataset, a):
    """True for samples seen by at least one depth frame (ground-truth poses)."""
    frames, _ = load_sequence(dataset, a.max_dt, need_gt=True)
    from o3d_import import o3d
    step = max(1, a.visible_stride)
    frames = frames[::step]
    vis = np.zeros(len(samples), bool)
    P = np.concatenate([samples, np.ones((len(samples), 1))], 1)
    for fr in frames:
        depth = np.asarray(o3d.io.read_image(fr["depth"])).astype(np.float64) / a.depth_scale
        H, W = depth.shape
        Tcw = np.linalg.inv(fr["pose"])
        pc = P @ Tcw[:3].T
        z = pc[:, 2]
        ok = (z > 1e-6) & (z <= a.depth_max) & ~vis
        u = np.rint(a.fx * pc[ok, 0] / z[ok] + a.cx).astype(np.int64)
        v = np.rint(a.fy * pc[ok, 1] / z[ok] + a.cy).astype(np.int64)
        inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
        idx = np.flatnonzero(ok)[inside]
        dm = depth[v[inside], u[inside]]
        seen = (dm > 0) & (np.abs(dm - z[idx]) <= a.visible_tol)
        vis[idx[seen]] = True
    return vis, len(frames)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--truth", required=True, help="true scene mesh (PLY), same world frame")
    ap.add_argument("--points", required=True, help="reconstructed surface: point-cloud PLY or mesh PLY")
    ap.add_argument("--json", help="output JSON file")
    ap.add_argument("--voxel", type=float, default=0.01,
                    help="voxel size (m); thresholds 1 and 2 voxels are reported (default 0.01)")
    ap.add_argument("--samples", type=int, default=200000, help="uniform samples on the true mesh")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--dataset", help="TUM-layout folder: also report completeness of visible samples only")
    ap.add_argument("--visible-tol", type=float, default=0.03,
                    help="sample counts as seen if |measured depth - sample depth| <= this (m)")
    ap.add_argument("--visible-stride", type=int, default=1, help="use every k-th frame for visibility")
    ap.add_argument("--depth-max", type=float, default=3.0, help="as in the fusion run (m)")
    ap.add_argument("--depth-scale", type=float, default=TUM_DEPTH_SCALE)
    ap.add_argument("--fx", type=float, default=TUM_INTRINSICS["fx"])
    ap.add_argument("--fy", type=float, default=TUM_INTRINSICS["fy"])
    ap.add_argument("--cx", type=float, default=TUM_INTRINSICS["cx"])
    ap.add_argument("--cy", type=float, default=TUM_INTRINSICS["cy"])
    ap.add_argument("--max-dt", type=float, default=0.02)
    a = ap.parse_args()

    for p, what in ((a.truth, "--truth"), (a.points, "--points")):
        if not os.path.isfile(p):
            fail(f"{what} file not found: {p}")
    if a.dataset and not os.path.isdir(a.dataset):
        fail(f"--dataset folder not found: {a.dataset}")
    if a.json and not os.path.isdir(os.path.dirname(os.path.abspath(a.json))):
        fail(f"output folder does not exist: {os.path.dirname(os.path.abspath(a.json))}")

    from o3d_import import o3c, o3d

    truth = o3d.io.read_triangle_mesh(a.truth)
    if len(truth.triangles) == 0:
        fail(f"{a.truth}: no triangles (is it a mesh PLY?)")
    rec, kind = read_surface_points(a.points, o3d)
    if len(rec) == 0:
        fail(f"{a.points}: no points")
    if not np.all(np.isfinite(rec)):
        print("warning: dropping non-finite reconstructed points", file=sys.stderr)
        rec = rec[np.all(np.isfinite(rec), 1)]

    th = {"1_voxel": a.voxel, "2_voxels": 2 * a.voxel}

    # accuracy: reconstructed point -> true mesh (exact point-to-triangle distance)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(truth))
    acc = scene.compute_distance(o3c.Tensor(rec.astype(np.float32))).numpy()

    # completeness: uniform true-mesh samples -> nearest reconstructed point
    o3d.utility.random.seed(a.seed)
    samples = np.asarray(truth.sample_points_uniformly(a.samples).points, np.float64)
    nns = o3c.nns.NearestNeighborSearch(o3c.Tensor(rec.astype(np.float32)))
    nns.knn_index()
    _, d2 = nns.knn_search(o3c.Tensor(samples.astype(np.float32)), 1)
    comp = np.sqrt(d2.numpy()[:, 0].astype(np.float64))

    out = dict(
        truth=os.path.abspath(a.truth),
        surface=os.path.abspath(a.points),
        surface_kind=kind,
        voxel_m=a.voxel,
        accuracy=dict(
            description="unsigned distance (m) from each reconstructed point to the true mesh",
            **dist_stats(acc, th)),
        completeness_all=dict(
            description=f"distance (m) from {a.samples} uniform true-mesh samples to the nearest "
                        "reconstructed point; INCLUDES parts of the true mesh that no camera saw",
            **dist_stats(comp, th)),
    )
    if a.dataset:
        try:
            vis, nfr = visible_mask(samples, a.dataset, a)
        except DatasetError as e:
            fail(str(e))
        out["completeness_visible"] = dict(
            description="as completeness_all, restricted to true-mesh samples observed in at least "
                        f"one of {nfr} depth frames (|depth - z| <= {a.visible_tol} m, "
                        f"z <= {a.depth_max} m)",
            visible_fraction_of_samples=float(vis.mean()),
            **dist_stats(comp[vis], th))
    # F-score at 2 voxels (precision = accuracy fraction, recall = completeness fraction)
    rec_key = "completeness_visible" if a.dataset else "completeness_all"
    p = out["accuracy"]["fraction_within_2_voxels"]
    r = out[rec_key]["fraction_within_2_voxels"] if out[rec_key]["count"] else 0.0
    out["fscore_2_voxels"] = dict(precision=p, recall=r, recall_from=rec_key,
                                  f=float(2 * p * r / (p + r)) if p + r > 0 else 0.0)

    txt = json.dumps(out, indent=2)
    if a.json:
        with open(a.json, "w") as f:
            f.write(txt)
    print(txt)


if __name__ == "__main__":
    main()
