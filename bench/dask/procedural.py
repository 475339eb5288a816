"""The procedural volume the Dask benchmarks share (made from its coordinates, so no input I/O is timed)."""

import dask.array as da
import numpy as np


def block(block_info=None):
    """A smooth field with structure at several scales, u8, computed from its position (no input I/O)."""
    loc = block_info[None]["array-location"]
    z, y, x = np.meshgrid(*(np.arange(a, b, dtype=np.float32) for a, b in loc), indexing="ij")
    v = 128 + 60 * np.sin(x / 37.0) * np.cos(y / 23.0) + 50 * np.sin(z / 17.0 + x / 91.0) + 10 * np.sin(x * y / 997.0)
    return np.clip(v, 0, 255).astype(np.uint8)


def volume(edge: int):
    return da.map_blocks(block, chunks=((64,) * (edge // 64),) * 3, dtype=np.uint8)
