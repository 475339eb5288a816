"""Decodes the real volumes with tools independent of voxstream (nibabel, numpy, pydicom) into reference arrays.

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
import pydicom


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

    dicom_references(out)


def dicom_volume(files):
    """A DICOM series as pydicom decodes it: slices sorted along the normal, the modality's values (rescaled) as
    float32, spacing (columns, rows, between slices), the first slice's position. A multi-frame RT dose grid's frames
    lie at GridFrameOffsetVector along the normal, its values scaled by DoseGridScaling."""
    datasets = [pydicom.dcmread(f) for f in files]
    slices = []
    for ds in datasets:
        row, column = np.array(ds.ImageOrientationPatient[:3], float), np.array(ds.ImageOrientationPatient[3:], float)
        normal = np.cross(row, column)
        position = np.array(ds.ImagePositionPatient, float)
        pixels = ds.pixel_array.astype(np.float64)
        if "GridFrameOffsetVector" in ds:
            scale = float(ds.DoseGridScaling)
            for offset, frame in zip(ds.GridFrameOffsetVector, pixels):
                slices.append((position + float(offset) * normal, frame * scale))
        else:
            slope, intercept = float(ds.get("RescaleSlope", 1)), float(ds.get("RescaleIntercept", 0))
            slices.append((position, pixels * slope + intercept))
    slices.sort(key=lambda s: float(np.dot(s[0], normal)))
    depths = [float(np.dot(p, normal)) for p, _ in slices]
    dz = (depths[-1] - depths[0]) / (len(depths) - 1) if len(depths) > 1 else float(
        datasets[0].get("SpacingBetweenSlices", datasets[0].get("SliceThickness", 1)))
    spacing = [float(datasets[0].PixelSpacing[1]), float(datasets[0].PixelSpacing[0]), dz]
    array = np.stack([values for _, values in slices]).astype(np.float32)
    return array, spacing, list(map(float, slices[0][0]))


def dicom_references(out: Path):
    dicom = out / "dicom"
    for name, files in [("dicom_ct5n", sorted((dicom / "CT5N").iterdir())), ("dicom_ct_small", [dicom / "CT_small.dcm"]),
                        ("dicom_mr_small", [dicom / "MR_small.dcm"]), ("dicom_rtdose", [dicom / "rtdose.dcm"])]:
        array, spacing, origin = dicom_volume(files)
        save(out, name, array, spacing, origin)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
