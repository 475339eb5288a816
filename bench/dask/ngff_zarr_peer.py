"""The peer of bench/dask/import_scaling.py: ngff-zarr (`to_multiscales` + `to_ngff_zarr`, OME-Zarr 0.5) building a
pyramid of the same procedural volume on LocalClusters of 1 and 2 worker processes, with the settings nearest to
voxstream's import: 2×2×2 means (`DASK_BIN_SHRINK`, or `ITKWASM_BIN_SHRINK` before ngff-zarr had it), 32³ chunks in shards of 1×8×8 chunks, down to one chunk.

    python3 -m venv /tmp/ngff && /tmp/ngff/bin/pip install -r bench/dask/requirements-peer.txt
    /tmp/ngff/bin/python bench/dask/ngff_zarr_peer.py --edge 1024
"""

import argparse
import pathlib
import resource
import shutil
import sys
import time

from distributed import Client, LocalCluster
from ngff_zarr import Methods, to_multiscales, to_ngff_image, to_ngff_zarr

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from procedural import volume  # noqa: E402  (the same array as import_scaling.py)


def peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--edge", type=int, default=1024)
    parser.add_argument("--out", default="/tmp/vs-ngff-peer")
    args = parser.parse_args()
    root = pathlib.Path(args.out)
    shutil.rmtree(root, ignore_errors=True)
    root.mkdir(parents=True)
    levels = 1
    while args.edge >> levels >= 32:
        levels += 1
    factors = [2 ** k for k in range(1, levels)]
    print(f"ngff-zarr, volume {args.edge}³ u8, scale factors {factors}, 32³ chunks, shards of 1×8×8 chunks")
    times = {}
    for workers in (1, 2):
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                          memory_limit=None) as cluster, Client(cluster) as client:
            start = time.perf_counter()
            image = to_ngff_image(volume(args.edge), dims=("z", "y", "x"))
            method = getattr(Methods, "DASK_BIN_SHRINK", None) or Methods.ITKWASM_BIN_SHRINK
            multiscales = to_multiscales(image, scale_factors=factors, method=method, chunks=32)
            to_ngff_zarr(str(root / f"ngff{workers}.ome.zarr"), multiscales, version="0.5",
                         chunks_per_shard={"z": 1, "y": 8, "x": 8})
            times[workers] = time.perf_counter() - start
            peaks = client.run(peak_rss_mib)
        print(f"{workers} worker(s): {times[workers]:.1f} s (making the array included), peak RSS per worker "
              f"{', '.join(f'{v:.0f}' for v in peaks.values())} MiB")
    print(f"2 workers against 1: {times[1] / times[2]:.2f}×")
    shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
