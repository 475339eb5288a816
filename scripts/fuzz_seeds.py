#!/usr/bin/env python3
"""Writes a small seed corpus for every fuzz target into fuzz/seeds/<target>/: one valid file per format variant, so
that short fuzzing runs start past the magic numbers. Standard library only; the seeds are generated, not committed."""
import base64
import gzip
import io
import json
import os
import struct
import sys
import zipfile
import zlib

root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "fuzz", "seeds")
DIMS = (4, 3, 2)
N = DIMS[0] * DIMS[1] * DIMS[2]
U8 = bytes(range(N))
F32 = struct.pack("<%df" % N, *[i * 0.5 for i in range(N)])


def put(target, name, data):
    folder = os.path.join(root, target)
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, name), "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())


def nrrd(kind, encoding, data):
    head = "NRRD0004\ntype: %s\ndimension: 3\nsizes: 4 3 2\nspacings: 1 1 2\nencoding: %s\nendian: little\n\n"
    return (head % (kind, encoding)).encode() + data


put("import_nrrd", "raw-u8", nrrd("uchar", "raw", U8))
put("import_nrrd", "gzip-f32", nrrd("float", "gzip", gzip.compress(F32)))


def nifti(code, bitpix, data, slope=1.0):
    h = bytearray(352)
    struct.pack_into("<i", h, 0, 348)
    struct.pack_into("<8h", h, 40, 3, *DIMS, 1, 1, 1, 1)
    struct.pack_into("<hh", h, 70, code, bitpix)
    struct.pack_into("<4f", h, 76, 1, 1, 1, 2)
    struct.pack_into("<fff", h, 108, 352, slope, 0)
    struct.pack_into("<h", h, 252, 1)
    h[344:348] = b"n+1\0"
    return bytes(h) + data


put("import_nifti", "plain-u8", b"\0" + nifti(2, 8, U8))
put("import_nifti", "gzip-f32-scaled", b"\1" + gzip.compress(nifti(16, 32, F32, 2.0)))


def mha(compressed, data):
    head = ("ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\nCompressedData = %s\n"
            "DimSize = 4 3 2\nElementSpacing = 1 1 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n")
    return (head % ("True" if compressed else "False")).encode() + data


put("import_metaimage", "raw", mha(False, U8))
put("import_metaimage", "zlib", mha(True, zlib.compress(U8)))


def inr(data):
    text = "#INRIMAGE-4#{\nXDIM=4\nYDIM=3\nZDIM=2\nVDIM=1\nTYPE=unsigned fixed\nPIXSIZE=8 bits\nCPU=decm\nVX=1\nVY=1\nVZ=2\n"
    text += "\n" * (252 - len(text)) + "##}\n"
    return text.encode() + data


put("import_inr", "plain", b"\0" + inr(U8))
put("import_inr", "gzip", b"\1" + gzip.compress(inr(U8)))


def npy(descr, data):
    header = "{'descr': '%s', 'fortran_order': False, 'shape': (2, 3, 4), }" % descr
    header += " " * (63 - (10 + len(header)) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + data


def npz(method):
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", method) as z:
        z.writestr("volume.npy", npy("<f4", F32))
    return out.getvalue()


put("import_npy", "npy", b"\0" + npy("|u1", U8))
put("import_npy", "npz-stored", b"\1" + npz(zipfile.ZIP_STORED))
put("import_npy", "npz-deflated", b"\1" + npz(zipfile.ZIP_DEFLATED))


def vti(array, appended=b"", compressor=""):
    comp = ' compressor="vtkZLibDataCompressor"' if compressor else ""
    text = ('<?xml version="1.0"?>\n<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian"%s>\n'
            '<ImageData WholeExtent="0 3 0 2 0 1" Origin="0 0 0" Spacing="1 1 2">\n<Piece Extent="0 3 0 2 0 1">\n'
            '<PointData Scalars="v">\n%s\n</PointData>\n</Piece>\n</ImageData>\n' % (comp, array))
    if appended:
        return text.encode() + b'<AppendedData encoding="raw">\n_' + appended + b"\n</AppendedData>\n</VTKFile>\n"
    return (text + "</VTKFile>\n").encode()


put("import_vti", "ascii", vti('<DataArray type="UInt8" Name="v" format="ascii">%s</DataArray>'
                               % " ".join(str(v) for v in U8)))
put("import_vti", "binary", vti('<DataArray type="Float32" Name="v" format="binary">%s</DataArray>'
                                % base64.b64encode(struct.pack("<I", len(F32)) + F32).decode()))
block = zlib.compress(F32)
put("import_vti", "appended-zlib",
    vti('<DataArray type="Float32" Name="v" format="appended" offset="0"/>',
        struct.pack("<4I", 1, len(F32), len(F32), len(block)) + block, compressor=True))


def tiff(pages):
    """A little-endian TIFF of `pages` 4x3 8-bit greyscale uncompressed pages."""
    out = bytearray(b"II*\0" + struct.pack("<I", 8))
    for page in range(pages):
        data_at = len(out)
        out += bytes((v + page) % 256 for v in range(12))
        ifd_at = len(out)
        tags = [(256, 3, 1, 4), (257, 3, 1, 3), (258, 3, 1, 8), (259, 3, 1, 1), (262, 3, 1, 1), (273, 4, 1, data_at),
                (277, 3, 1, 1), (278, 3, 1, 3), (279, 4, 1, 12)]
        out += struct.pack("<H", len(tags))
        for tag, kind, count, value in tags:
            out += struct.pack("<HHII", tag, kind, count, value)
        next_at = len(out)
        out += struct.pack("<I", 0)
        if page == 0:
            struct.pack_into("<I", out, 4, ifd_at)
        else:
            struct.pack_into("<I", out, previous_next, ifd_at)
        previous_next = next_at
    return bytes(out)


put("import_tiff", "two-pages", tiff(2))
put("import_raw", "u8", struct.pack("<3HBB", *DIMS, 0, 0) + U8)
put("import_raw", "f32-big", struct.pack("<3HBB", *DIMS, 7, 4) + b"skip" + struct.pack(">%df" % N, *range(N)))
put("vdb_converter_header", "fog", json.dumps({"name": "density", "class": "fog volume", "dims": [4, 3, 2],
                                               "spacing": [0.5, 0.5, 0.5], "origin": [0, 0, 0], "background": 0.0}))
attributes = {"format_version": 1, "dims": [40, 30, 20], "dtype": "u8", "spacing": [1, 1, 2], "origin": [0, 0, 0],
              "brick_size": 32, "levels": 2, "value_range": [0, 255], "complete": True}
put("store_metadata", "voxstream", json.dumps({"zarr_format": 3, "node_type": "group",
                                               "attributes": {"voxstream": attributes}}))
put("store_metadata", "foreign-ome", json.dumps({"zarr_format": 3, "node_type": "group", "attributes": {"ome": {
    "version": "0.5", "multiscales": [{"axes": [{"name": a, "type": "space"} for a in "zyx"], "datasets": [
        {"path": "0", "coordinateTransformations": [{"type": "scale", "scale": [1, 1, 1]}]}]}]}}}))
with open(os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "frog-tf.json"), "rb") as f:
    put("transfer_function", "frog", f.read())
put("camera_path", "list", json.dumps([{"eye": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 40},
                                       {"eye": [3, 0, 0], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 35}]))
put("camera_path", "object", json.dumps({"cameras": [{"eye": [1, 2, 3], "target": [0, 0, 0], "up": [0, 0, 1],
                                                      "fov": 60}]}))
