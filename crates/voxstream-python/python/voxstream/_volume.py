"""Volumes and sessions: what the native module renders, with Python's conveniences around it."""

from __future__ import annotations

import os
import struct
import zlib
from typing import Any, Dict, Optional, Sequence, Tuple

import numpy as np

from . import _native
from ._camera import Camera
from ._transfer import TransferFunction


def scenes():
    """The names of the built-in scenes (``"sponge"``, ``"hypertexture"``, ``"shell"``)."""
    return list(_native.scene_names())


def open(source, *, size: Tuple[int, int] = (512, 512), budget_mb: int = 256, value_range=None,
         in_memory: bool = False, cache_dir=None, cache_mb: Optional[int] = None,
         request_timeout: Optional[float] = None, retries: Optional[int] = None,
         concurrent_requests: Optional[int] = None) -> "Volume":
    """Opens ``source``: a built-in scene's name, a mesh or particle file, or a store's folder or URL
    (``http(s)://``, ``s3://bucket/prefix``, ``gs://``, ``az://``; S3 credentials from the standard AWS variables and
    profiles, public buckets without). ``size`` and ``budget_mb`` are the defaults of later renders.

    ``value_range`` (low, high) normalises another tool's integer OME-Zarr image (as ``--value-range``);
    ``cache_dir`` keeps fetched bytes of a remote store on disk (at most ``cache_mb`` MiB) for the next run.
    Raises ``FileNotFoundError``, ``OSError`` or ``ValueError`` with the CLI's one-line message."""
    width, height = _size(size)
    native = _native.Volume(
        os.fspath(source), width=width, height=height, budget_mb=int(budget_mb),
        value_range=None if value_range is None else tuple(float(v) for v in value_range),
        in_memory=bool(in_memory), cache_dir=None if cache_dir is None else os.fspath(cache_dir),
        cache_mb=cache_mb, request_timeout=request_timeout, retries=retries,
        concurrent_requests=concurrent_requests)
    return Volume(native, (width, height), int(budget_mb))


def _size(size) -> Tuple[int, int]:
    try:
        width, height = (int(v) for v in size)
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height), got {size!r}") from None
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    return width, height


class Volume:
    """A source opened for rendering (see :func:`open`). Renders reuse one session, so a second render of the same
    store starts with its bricks in memory."""

    def __init__(self, native: "_native.Volume", size: Tuple[int, int], budget_mb: int):
        self._native = native
        self._size = size
        self._budget_mb = budget_mb
        self.last_stats: Dict[str, Any] = {}

    @property
    def name(self) -> str:
        """The name it was opened by (a URL without its credentials)."""
        return self._native.name

    @property
    def info(self) -> Dict[str, Any]:
        """Kind (scene, store, geometry), and for stores: dims (x, y, z), dtype, spacing, origin, unit, orientation
        (``"RAS"``, ``"LPS"``, …, or None), levels, brick_size, value_range, typical_range (0.5th to 99.5th
        percentile), percentiles, native, remote."""
        return dict(self._native.info)

    @property
    def camera(self) -> Camera:
        """The default camera for the size the volume was opened with."""
        return Camera.from_value(self._native.default_camera)

    def render(self, camera=None, tf=None, iso: Optional[Sequence[float]] = None, *,
               size: Optional[Tuple[int, int]] = None, budget_mb: Optional[int] = None, backend: str = "cpu",
               mode: str = "converged", dtype=np.uint8, iso_colors=None, iso_opacities=None,
               shadows: bool = False, light=None, background=(0.0, 0.0, 0.0), step: float = 0.5,
               lod_bias: float = 0.0, shading: Optional[str] = None, blending: bool = True,
               preintegrate: bool = False, adaptive_step: Optional[float] = None,
               faithful: bool = False, region=None, projection: str = "composite", clip_planes=(),
               view: Optional[str] = None, azimuth: Optional[float] = None, elevation: Optional[float] = None,
               zoom: Optional[float] = None, slice: Optional[str] = None, slice_with_volume: bool = False,
               color_bar: bool = False, scale_bar: bool = False) -> np.ndarray:
        """Renders the volume; returns an (height, width, 4) array, RGBA: ``uint8`` (the CLI's PNG, plus alpha) or
        ``float32`` (linear, unclamped). The array's memory is Rust's buffer, handed over without a copy.

        - ``camera``: a :class:`Camera`, a dict (eye, target, up, fov) or None for the default view;
        - ``tf``: a :class:`TransferFunction`, control points, a transfer-function file (voxstream JSON or a
          ParaView preset), a matplotlib colour map's name (over the data's typical range), or None;
        - ``iso``: isovalues in data values (with ``iso_colors``, ``iso_opacities``, ``shadows``, ``light``);
        - ``mode``: ``"converged"`` (every brick the view needs; the default) or ``"interactive"`` (one
          progressive frame: what is loaded, coarser data standing in);
        - ``backend``: ``"cpu"`` or ``"gpu"``; ``budget_mb``: the whole memory budget;
        - ``step``: the ray-march step in voxels of the sampled level; ``preintegrate``: integrate the transfer
          function between samples (the CLI's ``--preintegrate``); ``adaptive_step``: the error-bounded adaptive
          step's tolerance (``--adaptive-step``; None: the default, 0.05, for volumes); ``faithful``: fixed steps
          of ``step`` everywhere (``--faithful``) (pre-integration: CPU only);
        - ``region``: ``((x0, y0, z0), (x1, y1, z1))``, only the store's level-0 samples in ``[x0, x1) × …``; the rest
          is transparent (what :func:`voxstream.render_sort_last` gives each worker);
        - ``projection``: ``"composite"`` (volume rendering), ``"max"`` (MIP), ``"min"`` (MinIP) or ``"mean"``
          (``--projection``; CPU backend);
        - ``clip_planes``: ``[((x, y, z), (nx, ny, nz)), ...]``, each keeping the side of the plane through the
          point that the normal points to (world units; ``--clip-plane``; CPU backend);
        - ``view``: ``"+x"``, ``"-x"``, ``"+y"``, ``"-y"``, ``"+z"``, ``"-z"`` or ``"iso"``, framing the volume
          looking along that axis in place of ``camera``, or ``"anterior"``, ``"posterior"``, ``"left"``,
          ``"right"``, ``"superior"``, ``"inferior"`` looking at that side of the patient where the store says its
          anatomical orientation (``info()["orientation"]``; ``--view``); ``azimuth``, ``elevation`` (degrees) and
          ``zoom`` (a factor) turn and move the camera around its target (``--azimuth``, ``--elevation``,
          ``--zoom``);
        - ``slice``: ``"z=100"`` (``x``, ``y``, ``z``, or ``sagittal``, ``coronal``, ``axial``), one plane of the
          store's level-0 samples alone and face-on (``--slice``; CPU backend); with ``slice_with_volume=True``
          drawn inside the volume rendering from the default view, over the volume beyond it (what lies between
          the eye and the plane cut away; ``--with-volume``);
        - ``color_bar``, ``scale_bar``: the transfer function's colour bar at the right edge, a scale bar in the
          data's units at the bottom left (``--color-bar``, ``--scale-bar``).

        The GIL is released while rendering; Ctrl-C raises ``KeyboardInterrupt`` at once. Statistics of the frame
        are in ``last_stats``. A converged render whose bricks could not all be read raises ``RuntimeError``."""
        width, height = _size(self._size if size is None else size)
        if np.dtype(dtype) not in (np.dtype(np.uint8), np.dtype(np.float32)):
            raise ValueError(f"dtype must be uint8 or float32, got {np.dtype(dtype)}")
        tf_points, tf_file = self._transfer(tf)
        pixels, stats = self._native.render(
            width=width, height=height, budget_mb=int(self._budget_mb if budget_mb is None else budget_mb), backend=backend, mode=mode,
            camera=None if camera is None else Camera.from_value(camera).as_tuple(),
            tf_points=tf_points, tf_file=tf_file, iso=[float(v) for v in (iso or [])],
            iso_colors=[tuple(c) for c in (iso_colors or [])],
            iso_opacities=[float(a) for a in (iso_opacities or [])], shadows=bool(shadows),
            light=None if light is None else tuple(light), background=tuple(background), step=float(step),
            lod_bias=float(lod_bias), shading=shading, blending=bool(blending),
            preintegrate=bool(preintegrate),
            adaptive_step=None if adaptive_step is None else float(adaptive_step),
            faithful=bool(faithful),
            float32=np.dtype(dtype) == np.dtype(np.float32),
            region=None if region is None else tuple(tuple(int(v) for v in corner) for corner in region),
            projection=str(projection),
            clip_planes=[(tuple(float(v) for v in p), tuple(float(v) for v in n)) for p, n in clip_planes],
            view=view, azimuth=None if azimuth is None else float(azimuth),
            elevation=None if elevation is None else float(elevation), zoom=None if zoom is None else float(zoom),
            slice=None if slice is None else str(slice), slice_with_volume=bool(slice_with_volume),
            color_bar=bool(color_bar), scale_bar=bool(scale_bar))
        self.last_stats = dict(stats)
        return pixels

    def _transfer(self, tf):
        if tf is None:
            return None, None
        if isinstance(tf, (str, os.PathLike)):
            if isinstance(tf, str) and not os.path.exists(tf) and not tf.lower().endswith(".json"):
                lo, hi = self.info["typical_range"]
                if not hi > lo:
                    hi = lo + 1.0
                tf = TransferFunction.from_colormap(tf, (lo, hi))
            else:
                return None, os.fspath(tf)
        tf = TransferFunction.from_value(tf)
        return [list(p) for p in tf.points], None

    def _repr_png_(self) -> bytes:
        """The default view, 256 pixels wide, for Jupyter."""
        width, height = self._size
        scale = 256 / max(width, height)
        image = self.render(size=(max(1, round(width * scale)), max(1, round(height * scale))))
        return png_bytes(image)

    def __repr__(self) -> str:
        return f"voxstream.Volume({self.name!r})"


class Session:
    """Progressive frames for an interactive loop: set ``camera`` (or ``tf``), call :meth:`frame` again and again;
    each frame draws what is loaded (coarser data standing in), loads more, and never waits for all of it. Frames
    whose stats say ``converged`` are final."""

    def __init__(self, volume: Volume, *, camera=None, tf=None, iso=None, size: Optional[Tuple[int, int]] = None,
                 budget_mb: Optional[int] = None, backend: str = "cpu", blending: bool = True):
        self.volume = volume
        self.camera = volume.camera if camera is None else Camera.from_value(camera)
        self.tf = tf
        self.iso = iso
        self.size = size
        self.budget_mb = budget_mb
        self.backend = backend
        self.blending = blending
        self.last_stats: Dict[str, Any] = {}

    def frame(self) -> Tuple[np.ndarray, Dict[str, Any]]:
        """One interactive frame at the current camera: (image, stats)."""
        image = self.volume.render(self.camera, self.tf, self.iso, size=self.size, budget_mb=self.budget_mb,
                                   backend=self.backend, mode="interactive", blending=self.blending)
        self.last_stats = self.volume.last_stats
        return image, self.last_stats

    def converge(self) -> np.ndarray:
        """The final image at the current camera (waits for every brick the view needs)."""
        image = self.volume.render(self.camera, self.tf, self.iso, size=self.size, budget_mb=self.budget_mb,
                                   backend=self.backend, mode="converged", blending=self.blending)
        self.last_stats = self.volume.last_stats
        return image


def png_bytes(image: np.ndarray) -> bytes:
    """An (H, W, 3 or 4) uint8 array as PNG bytes (RGB or RGBA, no filtering)."""
    image = np.ascontiguousarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4):
        raise ValueError("png_bytes takes an (H, W, 3 or 4) uint8 array")
    height, width, channels = image.shape
    raw = b"".join(b"\x00" + image[y].tobytes() for y in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    colour_type = 6 if channels == 4 else 2
    header = struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")
