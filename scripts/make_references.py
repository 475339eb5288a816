"""Decodes the real volumes with tools independent of voxstream (nibabel, numpy) into reference arrays.

For each volume NAME it writes NAME.reference.npy (C order, shape (z, y, x): x fastest, as voxstream stores) and
NAME.reference.json (dims x,y,z, dtype, spacing, origin).
"""
import base64
import gzip
import json
import re
import zlib
import sys
from pathlib import Path

import nibabel
import numpy as np


def save(out: Path, name: str, array_zyx: np.ndarray, spacing, origin):
    np.save(out / f"{name}.reference.npy", np.ascontiguousarray(array_zyx))
    z, y, x = array_zyx.shape
    meta = {"dims": [x, y, z], "dtype": str(array_zyx.dtype), "spacing": list(map(float, spacing)),
            "origin": list(map(float, origin))}
    (out / f"{name}.reference.json").write_text(json.dumps(meta))


def inr(path: Path):
    raw = gzip.open(path).read() if path.suffix == ".gz" else path.read_bytes()
    end = raw.index(b"##}\n") + 4
    header_len = (end + 255) // 256 * 256
    fields = dict(line.split("=", 1) for line in raw[:end].decode().splitlines() if "=" in line)
    dims = [int(fields[k]) for k in ("XDIM", "YDIM", "ZDIM")]
    kind, bits = fields["TYPE"], int(fields["PIXSIZE"].split()[0])
    dtype = {("unsigned fixed", 8): "u1", ("unsigned fixed", 16): "<u2", ("signed fixed", 16): "<i2",
             ("float", 32): "<f4"}[(kind, bits)]
    data = np.frombuffer(raw[header_len:], dtype=dtype, count=dims[0] * dims[1] * dims[2])
    spacing = [float(fields.get(k, 1)) for k in ("VX", "VY", "VZ")]
    return data.reshape(dims[2], dims[1], dims[0]), spacing


def vti_inline_zlib_uint32(path: Path):
    """The frog file's layout: one UInt8 array, inline base64, zlib blocks, UInt32 headers."""
    text = path.read_text()
    extent = [int(v) for v in re.search(r'WholeExtent="([^"]+)"', text).group(1).split()]
    spacing = [float(v) for v in re.search(r'Spacing="([^"]+)"', text).group(1).split()]
    payload = re.search(r"<DataArray[^>]*>\s*([^<]+?)\s*</DataArray>", text).group(1).strip()
    blocks = int(np.frombuffer(base64.b64decode(payload[:8])[:4], "<u4")[0])
    header_chars = 4 * -(-(3 + blocks) * 4 // 3)
    header = np.frombuffer(base64.b64decode(payload[:header_chars])[:(3 + blocks) * 4], "<u4")
    data = base64.b64decode(payload[header_chars:])
    raw, at = b"", 0
    for size in header[3:3 + blocks]:
        raw += zlib.decompress(data[at:at + size])
        at += size
    dims = [extent[1] - extent[0] + 1, extent[3] - extent[2] + 1, extent[5] - extent[4] + 1]
    return np.frombuffer(raw, "u1").reshape(dims[2], dims[1], dims[0]), spacing


def main(out: Path):
    image = nibabel.load(out / "mni152_t1.nii.gz")
    data = np.asarray(image.dataobj)  # stored values, no scaling: (x, y, z)
    header = image.header
    origin = [float(header["qoffset_x"]), float(header["qoffset_y"]), float(header["qoffset_z"])]
    save(out, "mni152_t1", data.transpose(2, 1, 0), header.get_zooms()[:3], origin)

    for name in ("liver.inr.gz", "skull_2.9.inr"):
        array, spacing = inr(out / name)
        save(out, name.split(".")[0], array, spacing, [0, 0, 0])

    frog, spacing = vti_inline_zlib_uint32(out / "frog_tissues.vti")
    save(out, "frog_tissues", frog, spacing, [0, 0, 0])

    den = (out / "brainsmall.den").read_bytes()
    save(out, "brainsmall", np.frombuffer(den[62:], dtype="u1").reshape(84, 128, 128), [1, 1, 1], [0, 0, 0])


if __name__ == "__main__":
    main(Path(sys.argv[1]))
