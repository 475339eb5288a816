"""Running voxstream's long jobs on a Dask cluster (issue 50): an import spread over workers, one task per shard, and
a camera path's frames rendered by many workers. voxstream brings no cluster protocol of its own: the work goes to
the active ``dask.distributed.Client`` (``Client(LocalCluster(...))`` on one machine, ``Client("tcp://host:8786")``
for a scheduler elsewhere), or, without one, to Dask's local scheduler.

The import's tasks own whole shards (two writers of one shard would corrupt it) and run level by level: a coarser
shard is made from the 2×2×2 averages its (up to 8) child shards' tasks return, so the store is byte for byte what
the single-process ``import_volume`` writes. The store's folder must be visible to every worker (a shared
filesystem); the client holds the store's import lock from the first task to the last.
"""

from __future__ import annotations

import itertools
import os
import threading
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence

import numpy as np

from . import _native

_DTYPES = {"uint8", "uint16", "int16", "float32"}


def is_dask_array(source) -> bool:
    """Whether ``source`` is a dask array (without importing dask when it is not)."""
    module = type(source).__module__ or ""
    return module.startswith("dask.") and hasattr(source, "dask") and hasattr(source, "chunks")


def _client():
    """The active distributed client, or None."""
    try:
        from distributed import get_client
    except ImportError:
        return None
    try:
        return get_client()
    except ValueError:
        return None


def _run(tasks: List[Any], progress: Optional[Callable[[int, int], Any]], on_result=None) -> List[Any]:
    """Computes delayed ``tasks`` on the active client (progress per finished task) or Dask's local scheduler;
    ``on_result(index, value)`` sees each result as it arrives. Returns the results in order."""
    client = _client()
    total = len(tasks)
    if client is None:
        import dask
        results = list(dask.compute(*tasks))
        for index, value in enumerate(results):
            if on_result is not None:
                on_result(index, value)
        if progress is not None:
            progress(total, total)
        return results
    from distributed import as_completed
    futures = client.compute(tasks)
    index_of = {future.key: index for index, future in enumerate(futures)}
    results: List[Any] = [None] * total
    try:
        for done, (future, value) in enumerate(as_completed(futures, with_results=True), start=1):
            index = index_of[future.key]
            results[index] = value
            if on_result is not None:
                on_result(index, value)
            if progress is not None:
                progress(done, total)
    except BaseException:
        client.cancel(futures)
        raise
    return results


# Shards this process wrote (the tests check that every worker took part).
_SHARDS_WRITTEN = 0


def _write_shard(spec: str, level: int, shard, samples, pieces):
    """One shard's task (runs on a worker)."""
    global _SHARDS_WRITTEN
    _SHARDS_WRITTEN += 1
    if pieces is not None:
        # Arrays that crossed the network may sit unaligned in their message's buffer: aligned copies where so.
        pieces = [(tuple(child), np.require(halves, np.float32, "CA")) for child, halves in pieces]
    return _native.write_shard(spec, level, tuple(shard), samples=samples, pieces=pieces)


def import_dask(array, out, *, spacing=None, origin=None, brick_size: int = 32, overwrite: bool = False,
                nan_as: Optional[float] = None,
                progress: Optional[Callable[[int, int], Any]] = None) -> Dict[str, Any]:
    """Imports a 3-D dask array indexed ``[z, y, x]`` into the store ``out`` on the active Dask cluster (see the
    module's documentation); ``progress(done, total)`` counts finished shard tasks."""
    from dask import delayed

    if array.ndim != 3:
        raise ValueError(f"the array has shape {tuple(array.shape)}: a volume is a 3-D array indexed [z, y, x]")
    dtype = np.dtype(array.dtype).name
    if dtype not in _DTYPES:
        raise ValueError(f"arrays of {dtype} cannot be imported: convert to uint8, uint16, int16 or float32 "
                         "(e.g. array.astype(numpy.float32))")
    z, y, x = (int(v) for v in array.shape)
    job = _native.ShardImport(
        os.fspath(out), (x, y, z), dtype, spacing=None if spacing is None else tuple(float(v) for v in spacing),
        origin=None if origin is None else tuple(float(v) for v in origin), brick_size=int(brick_size),
        overwrite=bool(overwrite), nan_as=nan_as)
    try:
        spec = job.spec()
        task = delayed(_write_shard, nout=2, pure=True)
        halves: Dict[Any, Any] = {}
        summaries = []
        for level in range(job.levels()):
            gx, gy, gz = job.shards(level)
            for sz, sy, sx in itertools.product(range(gz), range(gy), range(gx)):
                shard = (sx, sy, sz)
                name = f"voxstream-shard-{level}-{sx}-{sy}-{sz}-{abs(hash(spec)):x}"
                if level == 0:
                    (ox, oy, oz), (ex, ey, ez) = job.region(0, shard)
                    block = array[oz:oz + ez, oy:oy + ey, ox:ox + ex]
                    coarse, summary = task(spec, 0, shard, block, None, dask_key_name=name)
                else:
                    pieces = [(child, halves.pop((level - 1, tuple(child)))) for child in job.children(level, shard)]
                    coarse, summary = task(spec, level, shard, None, pieces, dask_key_name=name)
                halves[(level, shard)] = coarse
                summaries.append(summary)
        results = _run(summaries, progress)
        aligned = [{k: np.require(v, requirements="CA") if isinstance(v, np.ndarray) else v for k, v in r.items()}
                   for r in results]
        return dict(job.finish(aligned))
    except BaseException:
        job.abort()
        raise


# Volumes opened by this worker process, kept for its next frames: (source, size, budget, options) -> (volume, lock).
_OPENED: Dict[Any, Any] = {}
_OPENED_LOCK = threading.Lock()


def _render_frame(source: str, open_options: Dict[str, Any], camera, options: Dict[str, Any], keep_pixels: bool):
    """One frame's task (runs on a worker): the PNG's bytes, and the pixels when a video is made."""
    from ._volume import open as open_volume, png_bytes

    key = (source, repr(sorted(open_options.items())))
    with _OPENED_LOCK:
        if key not in _OPENED:
            _OPENED[key] = (open_volume(source, **open_options), threading.Lock())
        volume, lock = _OPENED[key]
    with lock:
        image = volume.render(camera, **options)
    return png_bytes(image), (np.array(image[:, :, :3]) if keep_pixels else None)


def orbit(source, frames: int, *, degrees: float = 360.0, elevation: float = 0.0, size=(512, 512)) -> List[Any]:
    """``frames`` cameras around ``source``'s default view (a :class:`~voxstream.Volume` or anything
    :func:`voxstream.open` opens), ``degrees`` in all, at ``elevation`` degrees above it."""
    from ._volume import Volume, open as open_volume

    if frames <= 0:
        raise ValueError(f"a path needs at least one frame, got {frames}")
    volume = source if isinstance(source, Volume) else open_volume(source, size=size)
    start = volume.camera.orbit(0.0, elevation)
    return [start.orbit(azimuth=degrees * i / frames) for i in range(frames)]


def render_frames(source, cameras: Sequence[Any], out_dir, *, size=(512, 512), budget_mb: int = 256,
                  video: Optional[str] = None, fps: int = 30, open_options: Optional[Dict[str, Any]] = None,
                  progress: Optional[Callable[[int, int], Any]] = None, **render_options) -> Dict[str, Any]:
    """Renders one frame per camera of ``cameras`` (see :func:`orbit`) on the active Dask cluster, each worker with
    its own ``budget_mb`` and its own opened copy of ``source`` (a store's folder or URL, or a scene), and writes
    ``out_dir/frame_00000.png``, … in order as they arrive; with ``video`` (a path ending in ``.mp4``), also an
    H.264 video through ``imageio-ffmpeg`` (``pip install imageio-ffmpeg``). ``render_options`` are
    :meth:`voxstream.Volume.render`'s (``tf``, ``iso``, ``step``, …). Returns the frames' paths and the video's."""
    from ._camera import Camera
    from ._volume import _size
    from dask import delayed

    cameras = [Camera.from_value(c) for c in cameras]
    if not cameras:
        raise ValueError("no cameras: give at least one (voxstream.orbit(source, frames) makes a path)")
    width, height = _size(size)
    writer = None
    if video is not None:
        try:
            import imageio_ffmpeg
        except ImportError:
            raise ValueError("a video needs imageio-ffmpeg (pip install imageio-ffmpeg); the frames alone need "
                             "nothing more") from None
        writer = imageio_ffmpeg.write_frames(os.fspath(video), (width, height), fps=int(fps), macro_block_size=1,
                                             quality=8)
        writer.send(None)
    os.makedirs(out_dir, exist_ok=True)
    opened = dict(open_options or {})
    opened.update(size=(width, height), budget_mb=int(budget_mb))
    options = dict(render_options)
    source_name = os.fspath(source)
    task = delayed(_render_frame, pure=True)
    tasks = [task(source_name, opened, camera, options, writer is not None,
                  dask_key_name=f"voxstream-frame-{i}-{abs(hash((source_name, repr(camera), repr(options)))):x}")
             for i, camera in enumerate(cameras)]
    paths = [os.path.join(os.fspath(out_dir), f"frame_{i:05d}.png") for i in range(len(cameras))]
    pending: Dict[int, Any] = {}
    next_frame = [0]

    def arrived(index, value):
        # Frames are written in order: one that arrives early waits for those before it.
        pending[index] = value
        while next_frame[0] in pending:
            png, pixels = pending.pop(next_frame[0])
            with open(paths[next_frame[0]], "wb") as f:
                f.write(png)
            if writer is not None:
                writer.send(np.ascontiguousarray(pixels))
            next_frame[0] += 1

    try:
        _run(tasks, progress, on_result=arrived)
    finally:
        if writer is not None:
            writer.close()
    return {"frames": paths, "video": None if video is None else os.fspath(video)}
