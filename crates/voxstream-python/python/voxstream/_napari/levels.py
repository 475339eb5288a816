"""A store's pyramid levels as lazy arrays for napari: indexing returns another lazy view, and only
``numpy.asarray`` reads, fetching just the bricks under the view.

napari's multiscale slicing indexes a level with ``slice(None)`` along the axes it does not display and picks the
plane afterwards (it expects dask-like laziness): an eager array would read the whole depth of the visible window
first (2048 × 391 × 557 samples of a 2048³ store for one 2D slice).
"""

from __future__ import annotations

from typing import List, Tuple, Union

import numpy as np

# Per source axis: an int (the axis was indexed away) or a range of source indices (start, stop, step).
_Axis = Union[int, range]


class LevelArray:
    """A view of one level of a store, indexed ``[z, y, x]`` like a numpy array (the store's sample type)."""

    def __init__(self, native, level: int, dims_xyz: Tuple[int, int, int], dtype="float32", axes=None):
        self._native = native
        self.level = level
        self._dims_xyz = tuple(int(v) for v in dims_xyz)
        self.dtype = np.dtype(dtype)
        full = (self._dims_xyz[2], self._dims_xyz[1], self._dims_xyz[0])
        self._axes: List[_Axis] = list(axes) if axes is not None else [range(n) for n in full]

    @property
    def shape(self) -> Tuple[int, ...]:
        return tuple(len(a) for a in self._axes if isinstance(a, range))

    @property
    def ndim(self) -> int:
        return len(self.shape)

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, key) -> "LevelArray":
        if not isinstance(key, tuple):
            key = (key,)
        ndim = self.ndim
        if any(k is Ellipsis for k in key):
            at = next(i for i, k in enumerate(key) if k is Ellipsis)
            key = key[:at] + (slice(None),) * (ndim - (len(key) - 1)) + key[at + 1:]
        if len(key) > ndim:
            raise IndexError(f"too many indices for a {ndim}-D array: {key!r}")
        key = key + (slice(None),) * (ndim - len(key))
        if not all(isinstance(k, (int, np.integer, slice)) for k in key):
            return np.asarray(self)[key]
        axes: List[_Axis] = []
        remaining = iter(key)
        for axis in self._axes:
            if not isinstance(axis, range):
                axes.append(axis)
                continue
            k = next(remaining)
            if isinstance(k, slice):
                axes.append(axis[k])
            else:
                i = int(k)
                if not -len(axis) <= i < len(axis):
                    raise IndexError(f"index {i} is out of bounds for an axis of size {len(axis)}")
                axes.append(axis[i])
        return LevelArray(self._native, self.level, self._dims_xyz, self.dtype, axes)

    def __array__(self, dtype=None, copy=None):
        if any(isinstance(a, range) and len(a) == 0 for a in self._axes):
            data = np.zeros(self.shape, self.dtype)
        else:
            lower, size, post = [], [], []
            for axis in self._axes:
                if isinstance(axis, range):
                    lo, hi = min(axis), max(axis) + 1
                    lower.append(lo)
                    size.append(hi - lo)
                    # Within the box read (lo..hi), the view starts at its first index and walks by its step.
                    post.append(slice(axis.start - lo, None, axis.step))
                else:
                    lower.append(axis)
                    size.append(1)
                    post.append(0)
            # The native reader takes (x, y, z).
            box = self._native.read_region(self.level, tuple(reversed(lower)), tuple(reversed(size)))
            data = box[tuple(post)]
        return data if dtype is None else data.astype(dtype)

    def __repr__(self) -> str:
        return f"LevelArray(level={self.level}, shape={self.shape}, dtype={self.dtype})"
