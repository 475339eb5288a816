"""Prepares the volumes of the peer comparison (run with Debian's /usr/bin/python3: numpy + pyopenvdb).

Reads the arrays decoded by scripts/make_references.py (data/real/*.reference.npy, shape (z, y, x)) and the
Stanford dragon fog made by vdb_tool, and writes to OUT:

  NAME.raw + NAME.json      dense samples, x fastest, little-endian (u8 or f32), spacing, origin 0
  NAME_x4.raw + .json       the same field upsampled 4x per axis by trilinear interpolation: sample i' of the
                            fine grid lies at coarse coordinate i'/4, so dims become 4(n-1)+1 and spacing/4. The
                            trilinear interpolant of the fine grid equals the coarse one (up to rounding to u8),
                            so one reference image serves both.
  NAME.vdb / NAME_x4.vdb    (fog scenes) an OpenVDB FloatGrid "density" = value * density_scale, voxel size =
                            spacing (isotropic), sample (i,j,k) at spacing*(i,j,k), zeros inactive: what vdb_render
                            reads.

Usage: prepare_data.py REAL_DATA_DIR DRAGON_FOG_VDB OUT
"""
import json
import sys
from pathlib import Path

import numpy as np
import pyopenvdb as vdb

SLAB = 8  # coarse z-slices per block of the upsampler


def write_meta(out: Path, name: str, dims, dtype: str, spacing, density_scale=None):
    meta = {"dims": [int(d) for d in dims], "dtype": dtype, "spacing": [float(s) for s in spacing],
            "origin": [0.0, 0.0, 0.0]}
    if density_scale is not None:
        meta["density_scale"] = density_scale
    (out / f"{name}.json").write_text(json.dumps(meta))


def upsample_axis(a: np.ndarray, axis: int, factor: int) -> np.ndarray:
    """Linear interpolation along one axis at coordinates i/factor, i in 0..factor*(n-1)."""
    n = a.shape[axis]
    x = np.arange(factor * (n - 1) + 1) / factor
    i0 = np.minimum(np.floor(x).astype(np.int64), n - 2)
    f = (x - i0).astype(np.float32)
    shape = [1] * a.ndim
    shape[axis] = -1
    f = f.reshape(shape)
    lo = np.take(a, i0, axis=axis).astype(np.float32)
    hi = np.take(a, i0 + 1, axis=axis).astype(np.float32)
    return lo + (hi - lo) * f


def upsampled_slabs(zyx: np.ndarray, factor: int):
    """Yields (z0, block) of the upsampled volume, block shape (z, y, x), float32, bounded memory."""
    nz = zyx.shape[0]
    fine_nz = factor * (nz - 1) + 1
    z0 = 0
    while z0 < fine_nz:
        z1 = min(z0 + SLAB * factor, fine_nz)
        coarse_lo = z0 // factor
        coarse_hi = min((z1 - 1) // factor + 2, nz)
        part = zyx[coarse_lo:coarse_hi].astype(np.float32)
        if part.shape[0] == 1:
            block = part
        else:
            block = upsample_axis(part, 0, factor)
            offset = z0 - coarse_lo * factor
            block = block[offset:offset + (z1 - z0)]
        block = upsample_axis(upsample_axis(block, 1, factor), 2, factor)
        yield z0, block
        z0 = z1


def new_fog_grid(spacing):
    if max(spacing) - min(spacing) > 1e-9 * max(spacing):
        raise SystemExit(f"vdb_render needs isotropic voxels, got spacing {spacing}")
    grid = vdb.FloatGrid(0.0)
    grid.name = "density"
    grid.gridClass = vdb.GridClass.FOG_VOLUME
    grid.transform = vdb.createLinearTransform(voxelSize=float(spacing[0]))
    return grid


def add_slab(grid, z0: int, block_zyx: np.ndarray, scale: float):
    xyz = np.ascontiguousarray(block_zyx.transpose(2, 1, 0), dtype=np.float32) * np.float32(scale)
    grid.copyFromArray(xyz, ijk=(0, 0, z0), tolerance=0.0)


def prepare(out: Path, name: str, zyx: np.ndarray, spacing, fog_scale):
    """Writes NAME and NAME_x4 (raw + json, and VDBs when fog_scale is not None)."""
    dtype = {"uint8": "u8", "float32": "f32"}[str(zyx.dtype)]
    nz, ny, nx = zyx.shape
    if not (out / f"{name}.raw").exists():
        zyx.tofile(out / f"{name}.raw")
        write_meta(out, name, (nx, ny, nz), dtype, spacing, fog_scale)
        print(f"  {name}: {nx}x{ny}x{nz} {dtype}", flush=True)
    if fog_scale is not None and not (out / f"{name}.vdb").exists():
        grid = new_fog_grid(spacing)
        for z0 in range(0, nz, 64):
            add_slab(grid, z0, zyx[z0:z0 + 64], fog_scale)
        vdb.write(str(out / f"{name}.vdb"), grids=[grid])
        print(f"  {name}.vdb: {grid.activeVoxelCount()} active voxels", flush=True)

    fine = f"{name}_x4"
    if (out / f"{fine}.raw").exists() and (fog_scale is None or (out / f"{fine}.vdb").exists()):
        return
    fine_dims = (4 * (nx - 1) + 1, 4 * (ny - 1) + 1, 4 * (nz - 1) + 1)
    fine_spacing = [s / 4 for s in spacing]
    grid = new_fog_grid(fine_spacing) if fog_scale is not None else None
    partial = out / f"{fine}.raw.partial"
    with open(partial, "wb") as raw:
        for z0, block in upsampled_slabs(zyx, 4):
            if dtype == "u8":
                block = np.rint(block).astype(np.uint8)
            raw.write(np.ascontiguousarray(block).tobytes())
            if grid is not None:
                add_slab(grid, z0, block, fog_scale)
    partial.rename(out / f"{fine}.raw")
    write_meta(out, fine, fine_dims, dtype, fine_spacing, fog_scale)
    print(f"  {fine}: {fine_dims[0]}x{fine_dims[1]}x{fine_dims[2]} {dtype}", flush=True)
    if grid is not None:
        vdb.write(str(out / f"{fine}.vdb"), grids=[grid])
        print(f"  {fine}.vdb: {grid.activeVoxelCount()} active voxels", flush=True)


def dragon_dense(fog_path: Path) -> np.ndarray:
    """The vdb_tool fog as a dense (z, y, x) float32 array with one zero voxel of padding on every side."""
    grid = vdb.read(str(fog_path), vdb.readAllGridMetadata(str(fog_path))[0].name)
    lo, hi = grid.evalActiveVoxelBoundingBox()
    lo = [v - 1 for v in lo]
    dims = [hi[a] - lo[a] + 2 for a in range(3)]
    xyz = np.zeros(dims, dtype=np.float32)
    grid.copyToArray(xyz, ijk=tuple(lo))
    return np.ascontiguousarray(xyz.transpose(2, 1, 0))


def main(real: Path, dragon_fog: Path, out: Path):
    out.mkdir(parents=True, exist_ok=True)
    mni = np.load(real / "mni152_t1.reference.npy")
    prepare(out, "mni", mni, [1.0, 1.0, 1.0], 1.0 / 255.0)
    frog = np.load(real / "frog_tissues.reference.npy")
    prepare(out, "frog", frog, [1.0, 1.0, 1.5], None)
    prepare(out, "dragon", dragon_dense(dragon_fog), [1.0, 1.0, 1.0], 1.0)


if __name__ == "__main__":
    if len(sys.argv) != 4:
        raise SystemExit(__doc__)
    main(Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3]))
