"""napari's 3D camera and layer appearance in voxstream's terms (no Qt here: testable on its own).

napari's scene coordinates are the displayed dimensions in order, (z, y, x) for a volume; voxstream's world is
(x, y, z). A store layer opened by this plugin has scale = spacing and translate = origin (reversed), so both
worlds are the same space with the axes listed in reverse.

Reversing the axes is a reflection: napari's default axes, (z, y, x), are right-handed in that order (napari's
``camera.handedness``), so (x, y, z) is left-handed in napari's picture, and voxstream's right-handed camera sees the
mirror image of napari's view. The widget flips voxstream's images left to right then ([`mirrored`]); checked against
napari's own rendering of an asymmetric volume (``tests/test_napari.py``).

napari draws 3D orthographically by default (``camera.perspective == 0``); voxstream is a pinhole camera. The
conversion keeps napari's view direction, up direction, centre and scale at the centre: the eye sits where a
``fov``-degree frustum (napari's perspective, else 30°) covers the canvas' height in world units (height / zoom) at
the centre's depth. Parts of the volume nearer or farther than the centre are therefore drawn slightly larger or
smaller than napari's orthographic view draws them.
"""

from __future__ import annotations

import math
from typing import Sequence, Tuple

import numpy as np

from .._camera import Camera
from .._transfer import TransferFunction

#: Field of view for napari's orthographic 3D view (``perspective == 0``).
DEFAULT_FOV = 30.0

#: Opacity per unit distance (one finest voxel) at the top of the contrast limits, before the layer's opacity.
MAX_OPACITY = 0.1


def voxstream_camera(center: Sequence[float], view_direction: Sequence[float], up_direction: Sequence[float],
                     zoom: float, perspective: float, canvas_height: int) -> Camera:
    """The voxstream camera for napari's camera (scene coordinates (z, y, x); ``canvas_height`` in pixels)."""
    target = np.array(center[::-1], dtype=float)
    forward = np.array(view_direction[::-1], dtype=float)
    up = np.array(up_direction[::-1], dtype=float)
    if not (np.linalg.norm(forward) > 0 and np.linalg.norm(up) > 0 and zoom > 0 and canvas_height > 0):
        raise ValueError("napari's camera has no 3D direction or scale yet (is the view 3D?)")
    forward /= np.linalg.norm(forward)
    fov = float(perspective) if perspective and perspective > 0 else DEFAULT_FOV
    visible_height = canvas_height / zoom
    distance = 0.5 * visible_height / math.tan(math.radians(fov) / 2)
    eye = target - forward * distance
    return Camera(tuple(eye.tolist()), tuple(target.tolist()), tuple(up.tolist()), fov)


def mirrored(napari_camera) -> bool:
    """Whether voxstream's image of napari's view must be flipped left to right: napari's axes are right-handed in
    napari's own order (its default), so reversed to (x, y, z) they are left-handed."""
    handedness = getattr(napari_camera, "handedness", "right")
    return str(getattr(handedness, "value", handedness)).lower() == "right"


def transfer_function(colormap, contrast_limits: Tuple[float, float], opacity: float = 1.0,
                      samples: int = 32) -> TransferFunction:
    """A transfer function from a napari colormap over its contrast limits: the map's colours, opacity rising
    linearly from 0 to ``MAX_OPACITY`` times the map's alpha and the layer's opacity."""
    lo, hi = (float(v) for v in contrast_limits)
    if not hi > lo:
        hi = lo + 1.0
    t = np.linspace(0.0, 1.0, samples)
    rgba = np.asarray(colormap.map(t), dtype=float)
    points = []
    for i, f in enumerate(t):
        r, g, b, a = rgba[i]
        points.append((lo + (hi - lo) * f, r, g, b, MAX_OPACITY * f * a * float(opacity)))
    return TransferFunction.from_points(points)
