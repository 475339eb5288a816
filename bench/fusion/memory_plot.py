"""Plots the memory of `voxstream fuse` over a sequence (its --stats JSON: the bricks after every window, and the
fixed frame ring) against Open3D's VoxelBlockGrid on the same frames (open3d_peer.py's JSON: active voxel blocks
and what its hash map allocated), as BENCHMARKS.md "Depth fusion" shows it.

    python memory_plot.py FUSE_STATS.json [--open3d O3D.json] --out PLOT.png
"""
import argparse
import json
import sys
from pathlib import Path

MiB = float(1 << 20)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stats", help="voxstream fuse --stats JSON")
    ap.add_argument("--open3d", help="open3d_peer.py --json output for the same frames")
    ap.add_argument("--window", type=int, help="frames per window, for the caption (default: from the stats)")
    ap.add_argument("--out", required=True, help="PNG to write")
    a = ap.parse_args()
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        sys.exit("memory_plot.py needs matplotlib: pip install matplotlib==3.10.3 into the bench venv")
    stats = json.loads(Path(a.stats).read_text())
    trace = stats["memory_trace"]
    frames = [f for f, _ in trace]
    bricks = [b / MiB for _, b in trace]
    ring = stats["ring_bytes"] / MiB
    fig, ax = plt.subplots(figsize=(7, 3.6), dpi=110)
    ax.plot(frames, [b + ring for b in bricks], label="voxstream: bits + frame ring", color="tab:blue")
    ax.plot(frames, bricks, label="voxstream: bits (bricks, colours, index)", color="tab:blue", linestyle="--")
    if a.open3d:
        grid = json.loads(Path(a.open3d).read_text())["memory"]["grid"]
        ax.axhline(grid["allocated_buffer_bytes"] / MiB, color="tab:red", label="Open3D: allocated grid")
        ax.axhline(grid["active_with_hash_estimate_bytes"] / MiB, color="tab:red", linestyle="--",
                   label="Open3D: active blocks (20 B/voxel)")
    ax.set_yscale("log")
    ax.set_xlabel(f"frames fused (window {a.window or stats['window']} frames)")
    ax.set_ylabel("MiB (log scale)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="center right")
    ax.set_title(f"memory over {stats['frames']} frames at {stats['voxel'] * 1000:g} mm voxels", fontsize=10)
    fig.tight_layout()
    fig.savefig(a.out)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
