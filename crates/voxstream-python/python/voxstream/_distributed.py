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


def _write_band(spec: str, level: int, shards, origin, block, predecessors):
    """One task (runs on a worker): writes ``shards`` (``(shard, region, children)`` of ``level``, a band of one z
    row) from ``block`` (level 0: the band's region of the source, whose corner is ``origin``) or from the halves
    the ``predecessors`` (the child bands' tasks) returned as their first value. Returns ``({shard: halves}, [summary, …])``."""
    global _SHARDS_WRITTEN
    halves_by_child: Dict[Any, Any] = {}
    for returned in predecessors or ():
        halves_by_child.update(returned)
    halves, summaries = {}, []
    for shard, region, children in shards:
        if level == 0:
            (ox, oy, oz), (ex, ey, ez) = region
            x0, y0, z0 = ox - origin[0], oy - origin[1], oz - origin[2]
            coarse, summary = _native.write_shard(spec, 0, shard, samples=block[z0:z0 + ez, y0:y0 + ey, x0:x0 + ex])
        else:
            # Arrays that crossed the network may sit unaligned in their message's buffer: aligned copies where so.
            pieces = [(child, np.require(halves_by_child.pop(child), np.float32, "CA")) for child in children]
            coarse, summary = _native.write_shard(spec, level, shard, pieces=pieces)
        _SHARDS_WRITTEN += 1
        halves[shard] = coarse
        summaries.append(summary)
    return halves, summaries


# Samples (as float32) a task of the import takes at most, when its level's shards allow: big enough that Dask's
# per-task cost (about a millisecond) is small beside it, small enough for many workers' memory.
_TASK_BYTES = 64 << 20


def import_dask(array, out, *, spacing=None, origin=None, brick_size: int = 32, overwrite: bool = False,
                nan_as: Optional[float] = None, codec: str = "zstd", max_error: Optional[float] = None,
                progress: Optional[Callable[[int, int], Any]] = None) -> Dict[str, Any]:
    """Imports a 3-D dask array indexed ``[z, y, x]`` into the store ``out`` on the active Dask cluster (see the
    module's documentation); ``progress(done, total)`` counts finished tasks (each a band of whole shards)."""
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
        overwrite=bool(overwrite), nan_as=nan_as, codec=str(codec),
        max_error=None if max_error is None else float(max_error))
    try:
        spec = job.spec()
        task = delayed(_write_band, nout=2, pure=True)
        tag = f"{abs(hash(spec)):x}"
        # Tasks own bands of whole shards: one z row, `band` rows of shards along y (the same at every level, so a
        # band's children are two bands of each of two z rows of the level below).
        gx, gy, _ = job.shards(0)
        _, (sx, sy, sz) = job.region(0, (0, 0, 0))
        band = max(1, min(gy, _TASK_BYTES // max(1, sx * sy * sz * 4 * gx)))
        # The array in chunks of one band each (a no-op where they are already): each level-0 task takes one chunk.
        # (Slicing bands out of other chunks in the graph cost Dask 4× the import itself.)
        blocks = array.rechunk((sz, band * sy, x)).to_delayed()
        previous: Dict[Any, Any] = {}
        summaries = []
        for level in range(job.levels()):
            gx, gy, gz = job.shards(level)
            current: Dict[Any, Any] = {}
            for z, first in itertools.product(range(gz), range(0, gy, band)):
                shards = []
                for y, x in itertools.product(range(first, min(gy, first + band)), range(gx)):
                    children = [tuple(c) for c in job.children(level, (x, y, z))] if level > 0 else []
                    shards.append(((x, y, z), job.region(level, (x, y, z)), children))
                name = f"voxstream-band-{level}-{z}-{first}-{tag}"
                if level == 0:
                    origin = (0, first * sy, z * sz)
                    block = blocks[z, first // band, 0]
                    halves, summary = task(spec, 0, shards, origin, block, None, dask_key_name=name)
                else:
                    keys = sorted({(2 * z + dz, 2 * (first // band) + k) for dz in (0, 1) for k in (0, 1)})
                    inputs = [previous.pop(key) for key in keys if key in previous]
                    halves, summary = task(spec, level, shards, None, None, inputs, dask_key_name=name)
                current[(z, first // band)] = halves
                summaries.append(summary)
            previous = current
        results = [summary for band_summaries in _run(summaries, progress) for summary in band_summaries]
        aligned = [{k: np.require(v, requirements="CA") if isinstance(v, np.ndarray) else v for k, v in r.items()}
                   for r in results]
        return dict(job.finish(aligned))
    except BaseException:
        job.abort()
        raise


# Volumes opened by this worker process, kept for its next frames: (source, size, budget, options) -> (volume, lock).
_OPENED: Dict[Any, Any] = {}
_OPENED_LOCK = threading.Lock()


def _opened(source: str, open_options: Dict[str, Any], region=None):
    """This worker's opened copy of ``source`` (one for each region it renders) and its lock (opened on first
    use)."""
    from ._volume import open as open_volume

    key = (source, repr(sorted(open_options.items())), repr(region))
    with _OPENED_LOCK:
        if key not in _OPENED:
            _OPENED[key] = (open_volume(source, **open_options), threading.Lock())
        return _OPENED[key]


def _render_frame(source: str, open_options: Dict[str, Any], camera, options: Dict[str, Any], keep_pixels: bool):
    """One frame's task (runs on a worker): the PNG's bytes, and the pixels when a video is made."""
    from ._volume import png_bytes

    volume, lock = _opened(source, open_options)
    with lock:
        image = volume.render(camera, **options)
    return png_bytes(image), (np.array(image[:, :, :3]) if keep_pixels else None)


def _render_piece(source: str, open_options: Dict[str, Any], camera, options: Dict[str, Any], region):
    """One piece's task (runs on a worker): its premultiplied linear RGBA over nothing, float32."""
    volume, lock = _opened(source, open_options, region)
    with lock:
        return volume.render(camera, region=region, dtype=np.float32, background=(0.0, 0.0, 0.0), **options)


def kd_pieces(info: Dict[str, Any], pieces: int):
    """The k-d tree of ``pieces`` (a power of two) boxes of a store's level-0 samples: the tree's cube halved along
    x, y, z in turn, so every cut is a face of the nodes of all but the coarsest levels (rays sample there as a
    render of the whole volume does). Returns nested ``(axis, plane, lower, upper)`` splits with ``(lower, upper)``
    boxes at the leaves; boxes outside the volume are None."""
    if pieces < 1 or pieces & (pieces - 1):
        raise ValueError(f"pieces must be a power of two, got {pieces}")
    dims = [int(v) for v in info["dims"]]
    span = int(info["brick_size"]) << (int(info["levels"]) - 1)
    depth = pieces.bit_length() - 1

    def split(lower, upper, level):
        if level == depth:
            lo = [max(0, v) for v in lower]
            hi = [min(d, v) for d, v in zip(dims, upper)]
            return (tuple(lo), tuple(hi)) if all(a < b for a, b in zip(lo, hi)) else None
        axis = level % 3
        plane = (lower[axis] + upper[axis]) // 2
        below, above = list(upper), list(lower)
        below[axis], above[axis] = plane, plane
        return (axis, plane, split(lower, below, level + 1), split(above, upper, level + 1))

    return split([0, 0, 0], [span] * 3, 0)


def _view_order(tree, eye_voxel) -> List[Any]:
    """The leaves of ``tree`` front to back as seen from ``eye_voxel`` (in level-0 sample units)."""
    if tree is None:
        return []
    if len(tree) == 2:
        return [tree]
    axis, plane, lower, upper = tree
    near, far = (lower, upper) if eye_voxel[axis] < plane else (upper, lower)
    return _view_order(near, eye_voxel) + _view_order(far, eye_voxel)


def render_sort_last(source, camera=None, *, pieces: int = 4, size=(512, 512), budget_mb: int = 256,
                     background=(0.0, 0.0, 0.0), dtype=np.uint8, open_options: Optional[Dict[str, Any]] = None,
                     **render_options) -> np.ndarray:
    """Renders one frame of a store split into ``pieces`` boxes (:func:`kd_pieces`) on the active Dask cluster:
    each worker renders its box alone (premultiplied RGBA, float32, within its own ``budget_mb``), and the client
    composites them front to back with "over" in the camera's view order, then the background. Returns what
    :meth:`voxstream.Volume.render` returns (``dtype`` uint8 or float32). Rays sample where one render of the whole
    volume samples except at the cut planes; ``faithful=True`` (fixed steps) keeps the samples the same."""
    from ._camera import Camera
    from ._volume import _size, open as open_volume
    from dask import delayed

    taken = {"region", "dtype", "background", "camera"} & set(render_options)
    if taken:
        raise ValueError(f"render_sort_last sets {', '.join(sorted(taken))} itself: give background= and dtype= "
                         "as its own arguments")
    width, height = _size(size)
    opened = dict(open_options or {})
    opened.update(size=(width, height), budget_mb=int(budget_mb))
    local = open_volume(source, **opened)
    info = local.info
    if info.get("kind") != "store":
        raise ValueError(f"{local.name}: sort-last rendering splits a store; scenes, meshes and particles are "
                         "rendered whole (Volume.render)")
    camera = local.camera if camera is None else Camera.from_value(camera)
    eye = [(camera.eye[a] - info["origin"][a]) / info["spacing"][a] + 0.5 for a in range(3)]
    order = _view_order(kd_pieces(info, pieces), eye)
    task = delayed(_render_piece, pure=True)
    name = os.fspath(source)
    tasks = [task(name, opened, camera, dict(render_options), box,
                  dask_key_name=f"voxstream-piece-{i}-{abs(hash((name, repr(camera), repr(box), repr(render_options)))):x}")
             for i, box in enumerate(order)]
    layers = _run(tasks, None)
    colour = np.zeros((height, width, 3), np.float32)
    transmittance = np.ones((height, width, 1), np.float32)
    for layer in layers:
        colour += transmittance * layer[:, :, :3]
        transmittance *= 1.0 - layer[:, :, 3:4]
    image = np.concatenate([colour + transmittance * np.asarray(background, np.float32), 1.0 - transmittance], axis=2)
    if np.dtype(dtype) == np.dtype(np.float32):
        return image
    return (np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


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
