"""A store's pyramid levels as lazy arrays for napari: each read fetches only the bricks under the slice."""

from __future__ import annotations

from typing import List, Tuple

import numpy as np


class LevelArray:
    """One level of a store, indexed ``[z, y, x]`` like a numpy array, read on demand (float32 data values)."""

    ndim = 3
    dtype = np.dtype(np.float32)

    def __init__(self, native, level: int, dims_xyz: Tuple[int, int, int]):
        self._native = native
        self.level = level
        self.shape = (int(dims_xyz[2]), int(dims_xyz[1]), int(dims_xyz[0]))

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, key):
        if not isinstance(key, tuple):
            key = (key,)
        if any(k is Ellipsis for k in key):
            at = next(i for i, k in enumerate(key) if k is Ellipsis)
            key = key[:at] + (slice(None),) * (3 - (len(key) - 1)) + key[at + 1:]
        key = key + (slice(None),) * (3 - len(key))
        if len(key) != 3:
            raise IndexError(f"too many indices for a 3-D level: {key!r}")
        lower, size, post = [], [], []
        for axis, k in enumerate(key):
            n = self.shape[axis]
            if isinstance(k, (int, np.integer)):
                i = int(k) + (n if k < 0 else 0)
                if not 0 <= i < n:
                    raise IndexError(f"index {k} is out of bounds for axis {axis} with size {n}")
                lower.append(i)
                size.append(1)
                post.append(0)
            elif isinstance(k, slice):
                span = range(*k.indices(n))
                if len(span) == 0:
                    return np.zeros(self._empty_shape(key), np.float32)
                lo, hi = min(span), max(span) + 1
                lower.append(lo)
                size.append(hi - lo)
                # Within the region read (lo..hi), the span starts at its first element and walks by its step.
                post.append(slice(span.start - lo, None, span.step))
            else:
                return np.asarray(self)[key]
        # The native reader takes (x, y, z).
        region = self._native.read_region(self.level, tuple(reversed(lower)), tuple(reversed(size)))
        return region[tuple(post)]

    def _empty_shape(self, key) -> List[int]:
        shape = []
        for axis, k in enumerate(key):
            if isinstance(k, slice):
                shape.append(len(range(*k.indices(self.shape[axis]))))
        return shape

    def __array__(self, dtype=None, copy=None):
        data = self[:, :, :]
        return data if dtype is None else data.astype(dtype)

    def __repr__(self) -> str:
        return f"LevelArray(level={self.level}, shape={self.shape})"
