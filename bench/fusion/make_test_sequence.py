#!/usr/bin/env python3
"""Generate a small synthetic RGB-D sequence in the TUM layout (for testing the peer).

Scene: floor plane (z = 0, z up), a box, a sphere and a torus. The camera orbits the
objects looking at them. Depth is rendered exactly with Open3D's RaycastingScene
(z-depth, pixel centres at integer coordinates, TUM intrinsics), optionally with
Kinect-like noise. Writes rgb/, depth/, rgb.txt, depth.txt, groundtruth.txt, scene.ply.

    python make_test_sequence.py OUT_DIR [--frames 30] [--arc-deg 120] [--noise 0]
"""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from o3d_import import o3d  # noqa: E402
from tum_io import TUM_DEPTH_SCALE, TUM_INTRINSICS, rot_to_quat  # noqa: E402


def build_scene():
    floor = o3d.geometry.TriangleMesh()
    s = 3.0
    floor.vertices = o3d.utility.Vector3dVector(
        np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]], float))
    floor.triangles = o3d.utility.Vector3iVector(np.array([[0, 1, 2], [0, 2, 3]]))
    box = o3d.geometry.TriangleMesh.create_box(0.4, 0.3, 0.5)
    box.rotate(o3d.geometry.get_rotation_matrix_from_xyz((0, 0, 0.5)), center=(0, 0, 0))
    box.translate((-0.45, -0.1, 0.0))
    sphere = o3d.geometry.TriangleMesh.create_sphere(0.22, resolution=60)
    sphere.translate((0.35, 0.1, 0.22))
    torus = o3d.geometry.TriangleMesh.create_torus(0.18, 0.06, 60, 30)
    torus.rotate(o3d.geometry.get_rotation_matrix_from_xyz((np.pi / 2, 0, 0.3)), center=(0, 0, 0))
    torus.translate((0.0, 0.45, 0.24))
    parts = [floor, box, sphere, torus]
    colors = [None, (0.85, 0.3, 0.2), (0.2, 0.5, 0.9), (0.3, 0.8, 0.3)]
    return parts, colors


def look_at(eye, target, up=(0, 0, 1)):
    """Camera-to-world pose: camera z forward, x right, y down."""
    eye, target, up = (np.asarray(v, float) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", help="output dataset folder (created)")
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--arc-deg", type=float, default=120.0, help="orbit arc covered by the sequence")
    ap.add_argument("--radius", type=float, default=1.6)
    ap.add_argument("--height", type=float, default=0.9)
    ap.add_argument("--noise", type=float, default=0.0,
                    help="depth noise scale; std = noise * (0.0012 + 0.0019*(z-0.4)^2) metres (1 = Kinect-like)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    if a.frames < 1:
        sys.exit("error: --frames must be >= 1")

    W, H = TUM_INTRINSICS["width"], TUM_INTRINSICS["height"]
    fx, fy, cx, cy = (TUM_INTRINSICS[k] for k in ("fx", "fy", "cx", "cy"))
    rng = np.random.default_rng(a.seed)

    parts, colors = build_scene()
    scene = o3d.t.geometry.RaycastingScene()
    for p in parts:
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(p))
    mesh = o3d.geometry.TriangleMesh()
    for p in parts:
        mesh += p
    os.makedirs(os.path.join(a.out, "rgb"), exist_ok=True)
    os.makedirs(os.path.join(a.out, "depth"), exist_ok=True)
    o3d.io.write_triangle_mesh(os.path.join(a.out, "scene.ply"), mesh)

    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    dirs_cam = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], -1).reshape(-1, 3)
    light = np.array([0.3, -0.5, 1.0])
    light /= np.linalg.norm(light)

    f_rgb = open(os.path.join(a.out, "rgb.txt"), "w")
    f_dep = open(os.path.join(a.out, "depth.txt"), "w")
    f_gt = open(os.path.join(a.out, "groundtruth.txt"), "w")
    for f in (f_rgb, f_dep):
        f.write("# synthetic sequence (make_test_sequence.py)\n# timestamp filename\n")
    f_gt.write("# timestamp tx ty tz qx qy qz qw\n")

    target = np.array([0.0, 0.1, 0.2])
    for i in range(a.frames):
        ts = 1000.0 + i / 30.0
        ang = np.deg2rad(-90 + a.arc_deg * (i / max(1, a.frames - 1) - 0.5))
        eye = target + np.array([a.radius * np.cos(ang), a.radius * np.sin(ang),
                                 a.height + 0.15 * np.sin(2 * np.pi * i / max(2, a.frames))])
        T = look_at(eye, target)
        d_world = dirs_cam @ T[:3, :3].T  # camera-frame z component stays 1 -> t_hit is z-depth
        rays = np.concatenate([np.broadcast_to(T[:3, 3], d_world.shape), d_world], 1).astype(np.float32)
        ans = scene.cast_rays(o3d.core.Tensor(rays))
        z = ans["t_hit"].numpy().astype(np.float64)
        gid = ans["geometry_ids"].numpy()
        n = ans["primitive_normals"].numpy()
        hit = np.isfinite(z)
        if a.noise > 0:
            std = a.noise * (0.0012 + 0.0019 * (z[hit] - 0.4) ** 2)
            z[hit] += rng.normal(0, 1, hit.sum()) * std
        depth = np.zeros(H * W, np.uint16)
        depth[hit] = np.clip(np.round(z[hit] * TUM_DEPTH_SCALE), 1, 65535).astype(np.uint16)

        # colour: albedo x (ambient + diffuse); checkerboard on the floor
        p = T[:3, 3] + d_world * np.where(hit, z, 0)[:, None]
        albedo = np.zeros((H * W, 3))
        for g, c in enumerate(colors):
            m = hit & (gid == g)
            if c is None:
                chk = (np.floor(p[m, 0] / 0.25) + np.floor(p[m, 1] / 0.25)) % 2
                albedo[m] = np.where(chk[:, None] > 0, 0.85, 0.35)
            else:
                albedo[m] = c
        shade = 0.35 + 0.65 * np.clip(np.abs(n @ light), 0, 1)
        rgb = np.where(hit[:, None], albedo * shade[:, None], 0.05)
        rgb8 = np.clip(rgb * 255 + 0.5, 0, 255).astype(np.uint8).reshape(H, W, 3)

        name = "%.6f.png" % ts
        o3d.io.write_image(os.path.join(a.out, "rgb", name), o3d.geometry.Image(rgb8))
        o3d.io.write_image(os.path.join(a.out, "depth", name), o3d.geometry.Image(depth.reshape(H, W)))
        f_rgb.write("%.6f rgb/%s\n" % (ts, name))
        f_dep.write("%.6f depth/%s\n" % (ts, name))
        q = rot_to_quat(T[:3, :3])
        f_gt.write("%.6f %.6f %.6f %.6f %.6f %.6f %.6f %.6f\n" % (ts, *T[:3, 3], *q))
    for f in (f_rgb, f_dep, f_gt):
        f.close()
    print(f"wrote {a.frames} frames to {a.out}")


if __name__ == "__main__":
    main()
