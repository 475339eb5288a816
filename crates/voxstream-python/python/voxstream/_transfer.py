"""Transfer functions: colour and opacity as functions of the data value, as control points in data values."""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

Point = Tuple[float, float, float, float, float]


@dataclass(frozen=True)
class TransferFunction:
    """Control points ``(value, r, g, b, opacity)`` in data values, linear RGB in [0, 1]; opacity is per unit
    distance (one finest voxel). Between points the colours and opacities are interpolated linearly."""

    points: Tuple[Point, ...]

    @staticmethod
    def from_points(points: Sequence[Sequence[float]]) -> "TransferFunction":
        """Control points ``[(value, r, g, b, opacity), ...]``, values increasing."""
        checked: List[Point] = []
        for point in points:
            if len(point) != 5:
                raise ValueError(f"a transfer function's point is (value, r, g, b, opacity), got {tuple(point)!r}")
            checked.append(tuple(float(v) for v in point))  # type: ignore[arg-type]
        if not checked:
            raise ValueError("a transfer function needs at least one point")
        return TransferFunction(tuple(checked))

    @staticmethod
    def from_colormap(name, value_range: Sequence[float], opacity: Sequence[float] = (0.0, 0.1),
                      samples: int = 32) -> "TransferFunction":
        """A matplotlib colour map (by name, e.g. ``"viridis"``, or a ``Colormap``) over ``value_range``, opacity
        ramping linearly from ``opacity[0]`` to ``opacity[1]``. Needs matplotlib (``pip install
        voxstream[colormaps]``)."""
        if isinstance(name, str):
            try:
                from matplotlib import colormaps
            except ImportError:
                raise ImportError("a colour map by name needs matplotlib: pip install matplotlib") from None
            if name not in colormaps:
                raise ValueError(f"{name!r} is neither a file nor one of matplotlib's colour maps")
            cmap = colormaps[name]
        else:
            cmap = name
        lo, hi = (float(v) for v in value_range)
        if not hi > lo:
            raise ValueError(f"value_range must be (low, high) with low < high, got {tuple(value_range)!r}")
        if samples < 2:
            raise ValueError("samples must be at least 2")
        a0, a1 = (float(v) for v in opacity)
        points = []
        for i in range(samples):
            f = i / (samples - 1)
            r, g, b, _ = cmap(f)
            points.append((lo + (hi - lo) * f, r, g, b, a0 + (a1 - a0) * f))
        return TransferFunction(tuple(points))

    @staticmethod
    def from_value(value) -> Optional["TransferFunction"]:
        """A transfer function from a TransferFunction, a list of points, or None (the source's default)."""
        if value is None or isinstance(value, TransferFunction):
            return value
        return TransferFunction.from_points(value)
