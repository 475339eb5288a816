"""Cameras: an eye looking at a target, with an up direction and a vertical field of view (degrees)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Sequence, Tuple

Vec3 = Tuple[float, float, float]


def _vec3(value: Sequence[float], name: str) -> Vec3:
    try:
        x, y, z = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be three numbers, got {value!r}") from None
    return (x, y, z)


@dataclass(frozen=True)
class Camera:
    """A pinhole camera in the volume's world coordinates (a store's are its spacing times sample indices)."""

    eye: Vec3
    target: Vec3
    up: Vec3 = (0.0, 0.0, 1.0)
    fov: float = 30.0

    @staticmethod
    def look_at(eye: Sequence[float], target: Sequence[float], up: Sequence[float] = (0.0, 0.0, 1.0),
                fov: float = 30.0) -> "Camera":
        """A camera at ``eye`` looking at ``target``."""
        return Camera(_vec3(eye, "eye"), _vec3(target, "target"), _vec3(up, "up"), float(fov))

    @property
    def distance(self) -> float:
        """Distance from the eye to the target."""
        return math.dist(self.eye, self.target)

    def orbit(self, azimuth: float = 0.0, elevation: float = 0.0) -> "Camera":
        """This camera turned about its target: ``azimuth`` degrees about the up axis, then ``elevation`` degrees
        towards it (clamped short of the pole). The distance stays."""
        up = _normalised(self.up)
        offset = _sub(self.eye, self.target)
        offset = _rotate(offset, up, math.radians(azimuth))
        side = _cross(offset, up)
        if _norm(side) > 1e-12:
            current = math.degrees(math.asin(max(-1.0, min(1.0, _dot(_normalised(offset), up)))))
            wanted = max(-89.0, min(89.0, current + elevation))
            offset = _rotate(offset, _normalised(side), math.radians(wanted - current))
        return replace(self, eye=_add(self.target, offset))

    def zoom(self, factor: float) -> "Camera":
        """This camera moved along its line of sight: ``factor`` > 1 comes closer."""
        if not factor > 0:
            raise ValueError(f"zoom factor must be positive, got {factor}")
        offset = _sub(self.eye, self.target)
        return replace(self, eye=_add(self.target, tuple(c / factor for c in offset)))

    def as_tuple(self):
        """(eye, target, up, fov), as the native module takes it."""
        return (tuple(self.eye), tuple(self.target), tuple(self.up), float(self.fov))

    @staticmethod
    def from_value(value) -> "Camera":
        """A camera from a Camera, a dict with eye/target/up/fov (voxstream's camera JSON), or an (eye, target,
        up, fov) tuple."""
        if isinstance(value, Camera):
            return value
        if isinstance(value, dict):
            return Camera.look_at(value["eye"], value["target"], value.get("up", (0.0, 0.0, 1.0)),
                                  value.get("fov", 30.0))
        try:
            eye, target, up, fov = value
        except (TypeError, ValueError):
            raise ValueError(f"a camera is a Camera, a dict or (eye, target, up, fov); got {value!r}") from None
        return Camera.look_at(eye, target, up, fov)


def _sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def _add(a, b):
    return tuple(x + y for x, y in zip(a, b))


def _dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _norm(a):
    return math.sqrt(_dot(a, a))


def _normalised(a):
    n = _norm(a)
    if n == 0:
        raise ValueError("the camera's up direction is zero")
    return tuple(x / n for x in a)


def _rotate(v, axis, angle):
    """Rodrigues' rotation of ``v`` about the unit ``axis``."""
    c, s = math.cos(angle), math.sin(angle)
    k_cross_v = _cross(axis, v)
    k_dot_v = _dot(axis, v)
    return tuple(v[i] * c + k_cross_v[i] * s + axis[i] * k_dot_v * (1 - c) for i in range(3))
