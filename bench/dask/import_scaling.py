"""Distributed import against the single-process one (issue 50): the same procedural volume imported by
`voxstream.import_volume` from a numpy array in this process, then from a dask array on LocalClusters of 1 and 2
worker processes (one thread each); times, the ratio, peak memory per worker, and whether the stores are the same
byte for byte.

    .venv/bin/python bench/dask/import_scaling.py --edge 1024 --out /tmp/vs-dask-bench

(.venv is what scripts/python-tests.sh makes: voxstream, dask and distributed installed.)
"""

import argparse
import filecmp
import pathlib
import resource
import shutil
import time

from distributed import Client, LocalCluster

import voxstream as vs
from procedural import volume
import voxstream._distributed as distributed_module


def same(a: pathlib.Path, b: pathlib.Path) -> bool:
    files = sorted(str(p.relative_to(a)) for p in a.rglob("*") if p.is_file())
    other = sorted(str(p.relative_to(b)) for p in b.rglob("*") if p.is_file())
    if files != other:
        return False
    _, mismatch, errors = filecmp.cmpfiles(a, b, files, shallow=False)
    return not mismatch and not errors


def peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--edge", type=int, default=1024)
    parser.add_argument("--out", default="/tmp/vs-dask-bench")
    parser.add_argument("--skip-single", action="store_true", help="no single-process import (needs the whole array)")
    args = parser.parse_args()
    root = pathlib.Path(args.out)
    shutil.rmtree(root, ignore_errors=True)
    root.mkdir(parents=True)
    array = volume(args.edge)
    gib = args.edge ** 3 / 2 ** 30
    print(f"volume {args.edge}³ u8 ({gib:.2f} GiB), bricks of 32, shards of 8×8 bricks")
    results = {}
    for workers in (1, 2):  # before the single-process run, whose memory forked workers would inherit
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                          memory_limit=None) as cluster, Client(cluster) as client:
            (root / f"dask{workers}").mkdir()
            start = time.perf_counter()
            vs.import_volume(array, root / f"dask{workers}" / "store")
            results[workers] = time.perf_counter() - start
            peaks = client.run(peak_rss_mib)
            tasks = sum(client.run(lambda: distributed_module._SHARDS_WRITTEN).values())
        identical = same(root / "dask1" / "store", root / f"dask{workers}" / "store")
        print(f"dask, {workers} worker(s): {results[workers]:.1f} s (making the array included; {tasks} shards), "
              f"peak RSS per "
              f"worker {', '.join(f'{v:.0f}' for v in peaks.values())} MiB, byte-identical: {identical}")
    if not args.skip_single:
        start = time.perf_counter()
        samples = array.compute(scheduler="threads")
        made = time.perf_counter() - start
        (root / "single").mkdir()
        start = time.perf_counter()
        vs.import_volume(samples, root / "single" / "store")
        results["single"] = time.perf_counter() - start
        del samples
        print(f"single process: {results['single']:.1f} s import (+{made:.1f} s to make the array), "
              f"peak RSS {peak_rss_mib():.0f} MiB")
    if not args.skip_single:
        print("single process against dask, 1 and 2 workers, byte-identical:",
              same(root / "single" / "store", root / "dask1" / "store"))
    print(f"2 workers against 1: {results[1] / results[2]:.2f}×")
    shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
