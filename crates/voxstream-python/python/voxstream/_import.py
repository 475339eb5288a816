"""Importing volumes into voxstream stores from Python."""

from __future__ import annotations

import os
from typing import Any, Callable, Dict, Optional, Sequence

from . import _native
from ._distributed import import_dask, is_dask_array


def import_volume(source, out, *, spacing: Optional[Sequence[float]] = None,
                  origin: Optional[Sequence[float]] = None, brick_size: int = 32, overwrite: bool = False,
                  nan_as: Optional[float] = None, resolution: Optional[int] = None,
                  amplify: Optional[float] = None,
                  progress: Optional[Callable[[int, int], Any]] = None, codec: str = "zstd",
                  max_error: Optional[float] = None, series: Optional[str] = None,
                  orientation: Optional[str] = None) -> Dict[str, Any]:
    """Writes ``source`` as a voxstream store at ``out``: a file's or folder's path (any format ``voxstream import``
    reads: NumPy, NIfTI, NRRD, MetaImage, VTK, TIFF stacks, a DICOM series' folder, …; meshes and particle files are
    baked into a grid of ``resolution`` voxels per axis, meshes with noise of ``amplify``) or a 3-D numpy
    array indexed ``[z, y, x]`` of uint8, uint16, int16 or float32 (stored as they are), or int8, int32, uint32 or
    float64 (converted as ``voxstream import`` converts them; the report's ``conversion`` says what it did).
    ``progress(done, total)`` is called with input bytes read (tqdm-friendly:
    ``lambda done, total: bar.update(done - bar.n)``). An existing store is replaced only with ``overwrite=True``,
    and only once the new one is complete; Ctrl-C or an exception raised by ``progress`` stops the import and
    removes what was written. Returns dims, dtype, levels, bricks written and empty, and the value range.

    ``codec="wavelet"`` compresses bricks with voxstream's wavelet codec (a Zarr extension only voxstream reads):
    lossless, or with ``max_error=E`` every stored sample within E of its value; ``"zstd"`` (the default) writes a
    store every Zarr v3 reader opens.

    ``series`` chooses among the series of a DICOM folder that holds several: its number in the list the error
    without it gives (``"1"``, ``"2"``, …) or its Series Instance UID (``voxstream import --series``).

    ``orientation`` names the anatomical direction each axis (x, y, z; an array's last, middle and first index)
    points to, as three letters: ``"RAS"`` (NIfTI's MNI space), ``"LPS"`` (DICOM's), … It replaces the file's and is
    written to the store's OME-Zarr axes; the default view then looks at the front, head up
    (``voxstream import --orientation``).

    A dask array is imported on the active Dask cluster (``distributed.Client``; without one, Dask's local
    scheduler), one task per shard, into the same store byte for byte; ``out`` must then be on a filesystem every
    worker sees, and ``progress(done, total)`` counts finished shards."""
    if is_dask_array(source):
        if series is not None:
            raise ValueError("series chooses among the series of a DICOM folder, not of an array")
        if orientation is not None:
            raise ValueError("orientation is not taken by a dask import yet: import the array with numpy, or "
                             "write the store and import a NIfTI or NRRD file that says its orientation")
        if resolution is not None or amplify is not None:
            raise ValueError("resolution and amplify apply to meshes and particle files, not to arrays")
        return import_dask(source, out, spacing=spacing, origin=origin, brick_size=brick_size, overwrite=overwrite,
                           nan_as=nan_as, codec=codec, max_error=max_error, progress=progress)
    if not isinstance(source, (str, os.PathLike)) and not hasattr(source, "__array_interface__"):
        raise ValueError("source must be a file's path or a 3-D numpy or dask array")
    if isinstance(source, (str, os.PathLike)):
        source = os.fspath(source)
    return dict(_native.import_volume(
        source, os.fspath(out), spacing=None if spacing is None else tuple(float(v) for v in spacing),
        origin=None if origin is None else tuple(float(v) for v in origin), brick_size=int(brick_size),
        overwrite=bool(overwrite), nan_as=nan_as, resolution=resolution, amplify=amplify, progress=progress,
        codec=str(codec), max_error=None if max_error is None else float(max_error),
        series=None if series is None else str(series),
        orientation=None if orientation is None else str(orientation)))
