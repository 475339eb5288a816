"""napari reader: a voxstream store or another tool's OME-Zarr image (a folder, or an http(s)/s3/gs/az URL) as a
multiscale image layer whose levels are read brick by brick as napari slices them."""

from __future__ import annotations

import os

from .. import _native
from .levels import LevelArray

_URL_SCHEMES = ("http://", "https://", "s3://", "gs://", "az://")


def is_store(path) -> bool:
    """Whether ``path`` looks like a Zarr store voxstream can open (without opening it)."""
    if not isinstance(path, (str, os.PathLike)):
        return False
    path = os.fspath(path)
    if path.startswith(_URL_SCHEMES):
        return path.rstrip("/").endswith((".zarr", ".vxs"))
    return os.path.isdir(path) and any(
        os.path.exists(os.path.join(path, marker)) for marker in ("zarr.json", ".zattrs", ".zgroup"))


def get_reader(path):
    """npe2 reader hook: a reader for stores, None for anything else."""
    if isinstance(path, list):
        if len(path) != 1:
            return None
        path = path[0]
    return read_store if is_store(path) else None


def read_store(path):
    """The store at ``path`` as napari layer data: its levels, finest first, in world units (its spacing)."""
    if isinstance(path, list):
        path = path[0]
    path = os.fspath(path)
    native = _native.Volume(path)
    info = native.info
    dtype = {"u8": "uint8", "u16": "uint16", "i16": "int16", "f32": "float32"}[native.dtype]
    levels = [LevelArray(native, level, dims, dtype) for level, dims in enumerate(native.level_dims)]
    lo, hi = info["typical_range"]
    if not hi > lo:
        lo, hi = info["value_range"]
    metadata = {"voxstream_source": path}
    attributes = {
        "name": os.path.basename(path.rstrip("/")) or path,
        "multiscale": len(levels) > 1,
        "contrast_limits": [float(lo), float(hi)],
        "scale": tuple(reversed(info["spacing"])),
        "translate": tuple(reversed(info["origin"])),
        "metadata": metadata,
        "rendering": "translucent",
    }
    data = levels if len(levels) > 1 else levels[0]
    return [(data, attributes, "image")]
