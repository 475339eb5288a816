#!/usr/bin/env python3
"""A large synthetic splash for the fluid preview's scale runs (issue 48): a collapsing water column hitting a
wavy pool, a crown sheet thrown up where they meet, and ballistic droplets above it, as FLIP particles (a jittered
lattice inside the liquid, one particle per cell) written as a binary little-endian PLY of float32 x, y, z.

    python3 scripts/fluid_splash.py --particles 100000000 --out /tmp/splash.ply [--steps 1] [--seed 1]

With --steps K > 1 it writes K time steps (splash_0000.ply, …: the column lower and the droplets further out at
each step) for scrubbing tests. Written to /tmp (or where --out says), never committed; numpy only; the body is
generated a lattice slab at a time, so memory stays small whatever the count.
"""

import argparse
import os
import shutil
import sys

import numpy as np

# The domain: x in [0, 4], y (up) in [0, 2.6], z in [0, 2].
BOX = np.array([4.0, 2.6, 2.0])
DROPLET_SHARE = 0.04


def inside(x, y, z, phase):
    """Whether points are in the liquid at `phase` (0: column standing, 1: fully collapsed)."""
    pool = y < 0.55 + 0.06 * np.sin(3.1 * x + 2.0 * phase) * np.cos(2.3 * z)
    # The column: a wedge at x < 1.2 whose top falls with the phase.
    height = 2.4 * (1.0 - 0.7 * phase) * np.clip(1.0 - (x / (1.2 + 1.5 * phase)) ** 2, 0.0, 1.0)
    column = y < height
    # The crown: a thin curved sheet rising where the column's front meets the pool.
    front = 1.2 + 1.5 * phase
    r = np.abs(x - front - 0.15 * np.cos(4.0 * z))
    crown = (r < 0.05) & (y < 0.55 + 0.9 * np.exp(-((z - 1.0) ** 2) * 2.0) * (0.4 + phase))
    return pool | column | crown


def liquid_volume(phase, samples=400_000, seed=7):
    rng = np.random.default_rng(seed)
    p = rng.random((samples, 3)) * BOX
    return inside(p[:, 0], p[:, 1], p[:, 2], phase).mean() * BOX.prod()


def write_step(path, particles, phase, seed):
    liquid = particles * (1.0 - DROPLET_SHARE)
    spacing = (liquid_volume(phase) / liquid) ** (1.0 / 3.0)
    counts = np.ceil(BOX / spacing).astype(int)
    rng = np.random.default_rng(seed)
    body = path + ".body"
    written = 0
    with open(body, "wb") as out:
        gx, gy = np.meshgrid(np.arange(counts[0]), np.arange(counts[1]), indexing="ij")
        gx = gx.ravel().astype(np.float32)
        gy = gy.ravel().astype(np.float32)
        for k in range(counts[2]):
            jitter = (rng.random((gx.size, 3), dtype=np.float32) - 0.5) * 0.3
            x = (gx + 0.5 + jitter[:, 0]) * spacing
            y = (gy + 0.5 + jitter[:, 1]) * spacing
            z = np.full_like(x, (k + 0.5) * spacing) + jitter[:, 2] * spacing
            keep = inside(x, y, z, phase)
            xyz = np.stack([x[keep], y[keep], z[keep]], axis=1).astype("<f4")
            out.write(xyz.tobytes())
            written += len(xyz)
        # Droplets: ballistic, thrown from the crown, spread out with time; sparse enough to be spray.
        droplets = int(particles * DROPLET_SHARE)
        front = 1.2 + 1.5 * phase
        for start in range(0, droplets, 1 << 22):
            n = min(1 << 22, droplets - start)
            speed = rng.random(n) * 2.0 + 0.5
            angle = rng.random(n) * np.pi
            t = rng.random(n) * (0.3 + phase)
            x = front + np.cos(angle) * speed * t * 0.8
            z = 1.0 + (rng.random(n) - 0.5) * 1.6
            y = 0.6 + np.sin(angle) * speed * t * 1.4 - 4.9 * t * t * 0.5
            ok = (y > 0.6) & (x > 0) & (x < BOX[0]) & (z > 0) & (z < BOX[2])
            xyz = np.stack([x[ok], y[ok], z[ok]], axis=1).astype("<f4")
            out.write(xyz.tobytes())
            written += len(xyz)
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"comment voxstream synthetic splash, phase {phase:.3f}, spacing {spacing:.6g}\n"
        f"element vertex {written}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    )
    with open(path, "wb") as out:
        out.write(header.encode())
        with open(body, "rb") as src:
            shutil.copyfileobj(src, out, 16 << 20)
    os.remove(body)
    return written, spacing


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--particles", type=int, default=10_000_000)
    parser.add_argument("--out", default="/tmp/splash.ply")
    parser.add_argument("--steps", type=int, default=1)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    if args.particles < 1000:
        sys.exit("fluid_splash: give --particles of at least 1000")
    folder = os.path.dirname(os.path.abspath(args.out))
    os.makedirs(folder, exist_ok=True)
    for step in range(args.steps):
        phase = 0.5 if args.steps == 1 else step / (args.steps - 1)
        path = args.out if args.steps == 1 else args.out.replace(".ply", f"_{step:04d}.ply")
        n, spacing = write_step(path, args.particles, phase, args.seed + step)
        print(f"{path}: {n} particles, spacing {spacing:.5g}", file=sys.stderr)


if __name__ == "__main__":
    main()
