"""Opens a voxstream store with zarr-python (a standard Zarr v3 reader) and checks it against a reference array.

Usage: check_store_with_zarr_python.py STORE REFERENCE.npy
Checks: the OME-Zarr 0.5 multiscales metadata lists every level, level 0 equals the reference exactly, each level
halves the previous (rounding up), and level 1 is the 2x2x2 mean of level 0 where blocks are complete.
"""
import sys

import numpy as np
import zarr


def main(store: str, reference: str) -> None:
    group = zarr.open_group(store, mode="r")
    ome = group.attrs["ome"]
    assert ome["version"] == "0.5", ome["version"]
    datasets = ome["multiscales"][0]["datasets"]
    paths = [d["path"] for d in datasets]
    assert sorted(paths) == sorted(group.array_keys()), (paths, list(group.array_keys()))
    expected = np.load(reference)
    level0 = group["0"][:]
    assert level0.dtype == expected.dtype, (level0.dtype, expected.dtype)
    assert np.array_equal(level0, expected), "level 0 differs from the reference"
    previous = level0
    for path in paths[1:]:
        level = group[path][:]
        assert level.shape == tuple((s + 1) // 2 for s in previous.shape), (path, level.shape, previous.shape)
        previous = level
    z, y, x = (s // 2 * 2 for s in level0.shape)
    blocks = level0[:z, :y, :x].astype(np.float64).reshape(z // 2, 2, y // 2, 2, x // 2, 2).mean(axis=(1, 3, 5))
    level1 = group["1"][: z // 2, : y // 2, : x // 2].astype(np.float64)
    tolerance = 0.5 if np.issubdtype(level0.dtype, np.integer) else 1e-3
    assert np.abs(level1 - blocks).max() <= tolerance, np.abs(level1 - blocks).max()
    print(f"zarr-python {zarr.__version__} read {store}: {len(paths)} levels, level 0 exact, level 1 = 2x2x2 mean")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
