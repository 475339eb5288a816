"""A camera path's frames on Dask, and sort-last compositing's cost (issue 50): a procedural volume imported once,
then `voxstream.render_frames` over a 120-frame orbit on LocalClusters of 1 and 2 worker processes (one thread
each, each with its own budget), and `voxstream.render_sort_last` of one frame in 2 and 4 pieces, its compositing
timed apart from its rendering.

    .venv/bin/python bench/dask/path_scaling.py --edge 512 --frames 120 --size 256
"""

import argparse
import pathlib
import shutil
import time

import numpy as np
from distributed import Client, LocalCluster

import voxstream as vs


def volume(edge: int) -> np.ndarray:
    z, y, x = np.meshgrid(*(np.arange(edge, dtype=np.float32),) * 3, indexing="ij")
    v = 128 + 60 * np.sin(x / 37.0) * np.cos(y / 23.0) + 50 * np.sin(z / 17.0 + x / 91.0)
    r = np.sqrt((x - edge / 2) ** 2 + (y - edge / 2) ** 2 + (z - edge / 2) ** 2)
    return np.where(r < edge * 0.45, np.clip(v, 0, 255), 0).astype(np.uint8)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--edge", type=int, default=512)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--out", default="/tmp/vs-dask-path")
    args = parser.parse_args()
    root = pathlib.Path(args.out)
    shutil.rmtree(root, ignore_errors=True)
    root.mkdir(parents=True)
    store = root / "store"
    vs.import_volume(volume(args.edge), store)
    size = (args.size, args.size)
    cameras = vs.orbit(store, args.frames, elevation=20, size=size)
    print(f"{args.edge}³ u8 store, {args.frames} frames of {args.size}², budget 256 MiB a worker")
    times = {}
    for workers in (1, 2):
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                          memory_limit=None) as cluster, Client(cluster):
            start = time.perf_counter()
            vs.render_frames(store, cameras, root / f"frames{workers}", size=size)
            times[workers] = time.perf_counter() - start
            print(f"{workers} worker(s): {times[workers]:.1f} s, {times[workers] / args.frames * 1000:.0f} ms a frame")
            if workers == 2:
                camera = cameras[args.frames // 8]
                start = time.perf_counter()
                whole = vs.open(store, size=size).render(camera, dtype=np.float32)
                single = time.perf_counter() - start
                for pieces in (2, 4):
                    start = time.perf_counter()
                    vs.render_sort_last(store, camera, pieces=pieces, size=size, dtype=np.float32)
                    total = time.perf_counter() - start
                    layers = [np.random.default_rng(i).random((args.size, args.size, 4), dtype=np.float32)
                              for i in range(pieces)]
                    start = time.perf_counter()
                    for _ in range(10):
                        colour = np.zeros((args.size, args.size, 3), np.float32)
                        t = np.ones((args.size, args.size, 1), np.float32)
                        for layer in layers:
                            colour += t * layer[:, :, :3]
                            t *= 1.0 - layer[:, :, 3:4]
                    composite = (time.perf_counter() - start) / 10
                    print(f"sort-last, {pieces} pieces on 2 workers: {total * 1000:.0f} ms a frame (first, bricks "
                          f"read), compositing {composite * 1000:.1f} ms; one process renders it in "
                          f"{single * 1000:.0f} ms (first)")
    print(f"2 workers against 1: {times[1] / times[2]:.2f}×")
    shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
