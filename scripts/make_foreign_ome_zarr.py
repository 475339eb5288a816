"""Writes a reference array as OME-Zarr images the way other tools do (zarr-python defaults, pyramid halving rounding
down, 64^3 chunks): Zarr v3 / OME-Zarr 0.5 and Zarr v2 (blosc) / OME-Zarr 0.4.

Usage: make_foreign_ome_zarr.py REFERENCE.npy OUT_V3 OUT_V2 [ORIGIN_X ORIGIN_Y ORIGIN_Z [ORIENTATION]]

ORIENTATION (e.g. RAS: the letter each axis x, y, z points to) is written as OME-NGFF RFC-4's anatomical orientation
of the axes, as ngff-zarr writes it.
"""
import sys

import numpy as np
import zarr


RFC4 = {"R": "left-to-right", "L": "right-to-left", "A": "posterior-to-anterior", "P": "anterior-to-posterior",
        "S": "inferior-to-superior", "I": "superior-to-inferior"}


def main(reference, out_v3, out_v2, origin, orientation=None):
    levels = [np.load(reference)]
    while max(levels[-1].shape) > 64:
        a = levels[-1].astype(np.float64)
        z, y, x = (s // 2 * 2 for s in a.shape)
        mean = a[:z, :y, :x].reshape(z // 2, 2, y // 2, 2, x // 2, 2).mean(axis=(1, 3, 5))
        levels.append(mean.round().astype(levels[0].dtype) if levels[0].dtype.kind in "ui" else mean.astype(levels[0].dtype))
    for fmt, path in ((3, out_v3), (2, out_v2)):
        group = zarr.open_group(path, mode="w", zarr_format=fmt)
        for i, a in enumerate(levels):
            array = group.create_array(str(i), shape=a.shape, chunks=(64, 64, 64), dtype=a.dtype)
            array[:] = a
        axes = [{"name": n, "type": "space", "unit": "millimeter"} for n in "zyx"]
        if orientation:
            for axis, letter in zip(axes, reversed(orientation.upper())):
                axis["orientation"] = {"type": "anatomical", "value": RFC4[letter]}
        multiscale = {
            "axes": axes,
            "datasets": [
                {"path": str(i), "coordinateTransformations": [
                    {"type": "scale", "scale": [2.0**i] * 3},
                    {"type": "translation", "translation": [origin[2], origin[1], origin[0]]}]}
                for i in range(len(levels))
            ],
        }
        if fmt == 3:
            group.attrs["ome"] = {"version": "0.5", "multiscales": [multiscale]}
        else:
            group.attrs["multiscales"] = [dict(multiscale, version="0.4")]


if __name__ == "__main__":
    origin = [float(v) for v in sys.argv[4:7]] if len(sys.argv) >= 7 else [0.0, 0.0, 0.0]
    main(sys.argv[1], sys.argv[2], sys.argv[3], origin, sys.argv[7] if len(sys.argv) >= 8 else None)
