"""Depth-camera fusion from Python (Reichl ch. 8): ``fuse`` an RGB-D sequence into a store, ``synthesize_rgbd`` a
sequence with ground truth from a mesh. The same work as ``voxstream fuse`` and ``voxstream synth-rgbd``."""

from __future__ import annotations

import os
from typing import Any, Callable, Dict, Optional

from . import _native


def fuse(dataset, out=None, *, points=None, trajectory=None, poses: str = "ground-truth", voxel: float = 0.01,
         window: int = 16, sub_cache: int = 2, confidence: float = 3.0, frames: Optional[int] = None,
         memory_mb: int = 1024, overwrite: bool = False, sign_only: bool = False,
         progress: Optional[Callable[[int, int], Any]] = None) -> Dict[str, Any]:
    """Fuses the TUM RGB-D folder ``dataset`` (``rgb/``, ``depth/``, ``rgb.txt``, ``depth.txt``, optional
    ``groundtruth.txt``) into binary bricks of ``voxel`` metres and saves them as the store ``out`` (open it with
    ``voxstream.open(out)`` and ``iso=[128]``), the surface as ``points`` (PLY) and the poses as ``trajectory``.
    ``poses="track"`` estimates each frame's pose by ICP against the surface fused so far. ``progress(done, total)``
    is called after every frame; Ctrl-C or an exception in it stops the fusion, saving nothing. ``sign_only=True``
    keeps the thesis' two bits a voxel, without the surface offsets that place the surface between voxel centres
    (less memory, the surface on voxel faces). Returns frames,
    windows, bricks, memory, time and (tracked, with ground truth) the ATE RMSE in metres."""
    path = lambda p: None if p is None else os.fspath(p)  # noqa: E731
    return dict(_native.fuse(os.fspath(dataset), path(out), points=path(points), trajectory=path(trajectory),
                             poses=poses, voxel=float(voxel), window=int(window), sub_cache=int(sub_cache),
                             confidence=float(confidence), frames=frames, memory_mb=int(memory_mb),
                             overwrite=bool(overwrite), sign_only=bool(sign_only), progress=progress))


def synthesize_rgbd(mesh, out, *, frames: int = 300, noise: bool = True, object_size: float = 0.5,
                    radius: float = 1.2, height: float = 0.5, sweep: float = 360.0, up: str = "y",
                    seed: int = 0x5EED, level: bool = False, overwrite: bool = False) -> int:
    """Renders ``frames`` RGB-D frames of the mesh file ``mesh`` standing on a floor, from an orbit, with Kinect v1
    noise (``noise=False``: exact depth), into the TUM RGB-D folder ``out`` with ``groundtruth.txt`` and the true
    scene as ``scene.ply``. The scene is tilted 7° and moved a few cm (``level=True``: floor at z = 0). Returns the
    number of frames written."""
    return int(_native.synthesize_rgbd(os.fspath(mesh), os.fspath(out), frames=int(frames), noise=bool(noise),
                                       object_size=float(object_size), radius=float(radius), height=float(height),
                                       sweep=float(sweep), up=up, seed=int(seed), level=bool(level),
                                       overwrite=bool(overwrite)))
