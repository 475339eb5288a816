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


def dicom_element(group, element, vr, value):
    if isinstance(value, str):
        value = value.encode()
    if len(value) % 2:
        value += b"\0" if vr == "UI" else b" "
    tag = struct.pack("<HH", group, element) + vr.encode()
    if vr in ("OB", "OW", "OF", "SQ", "UT", "UN"):
        return tag + b"\0\0" + struct.pack("<I", len(value)) + value
    return tag + struct.pack("<H", len(value)) + value


def dicom(frames):
    """A CT slice (or an RT-dose-like grid of `frames` frames) of 4x3 u16 samples, explicit VR little endian."""
    us = lambda v: struct.pack("<H", v)
    syntax = "1.2.840.10008.1.2.1"
    meta = dicom_element(0x0002, 0x0001, "OB", b"\0\1") + dicom_element(0x0002, 0x0002, "UI", "1.2.840.10008.5.1.4.1.1.2") \
        + dicom_element(0x0002, 0x0003, "UI", "2.25.1") + dicom_element(0x0002, 0x0010, "UI", syntax)
    meta = dicom_element(0x0002, 0x0000, "UL", struct.pack("<I", len(meta))) + meta
    body = [dicom_element(0x0008, 0x0016, "UI", "1.2.840.10008.5.1.4.1.1.2"), dicom_element(0x0008, 0x0060, "CS", "CT"),
            dicom_element(0x0020, 0x000E, "UI", "2.25.2"), dicom_element(0x0020, 0x0032, "DS", "0\\0\\0"),
            dicom_element(0x0020, 0x0037, "DS", "1\\0\\0\\0\\1\\0"), dicom_element(0x0028, 0x0002, "US", us(1)),
            dicom_element(0x0028, 0x0004, "CS", "MONOCHROME2")]
    if frames > 1:
        body.append(dicom_element(0x0028, 0x0008, "IS", str(frames)))
    body += [dicom_element(0x0028, 0x0010, "US", us(3)), dicom_element(0x0028, 0x0011, "US", us(4)),
             dicom_element(0x0028, 0x0030, "DS", "0.5\\0.5"), dicom_element(0x0028, 0x0100, "US", us(16)),
             dicom_element(0x0028, 0x0101, "US", us(12)), dicom_element(0x0028, 0x0102, "US", us(11)),
             dicom_element(0x0028, 0x0103, "US", us(0)), dicom_element(0x0028, 0x1052, "DS", "-1024"),
             dicom_element(0x0028, 0x1053, "DS", "1")]
    if frames > 1:
        body.append(dicom_element(0x3004, 0x000C, "DS", "\\".join(str(2 * i) for i in range(frames))))
    body.append(dicom_element(0x7FE0, 0x0010, "OW", struct.pack("<%dH" % (12 * frames), *range(12 * frames))))
    return b"\0" * 128 + b"DICM" + meta + b"".join(body)


put("import_dicom", "ct-slice", dicom(1))
put("import_dicom", "dose-grid", dicom(3))
put("import_raw", "u8", struct.pack("<3HBB", *DIMS, 0, 0) + U8)
put("import_raw", "f32-big", struct.pack("<3HBB", *DIMS, 7, 4) + b"skip" + struct.pack(">%df" % N, *range(N)))
put("vdb_converter_header", "fog", json.dumps({"name": "density", "class": "fog volume", "dims": [4, 3, 2],
                                               "spacing": [0.5, 0.5, 0.5], "origin": [0, 0, 0], "background": 0.0}))
attributes = {"format_version": 1, "dims": [40, 30, 20], "dtype": "u8", "spacing": [1, 1, 2], "origin": [0, 0, 0],
              "brick_size": 32, "levels": 2, "value_range": [0, 255], "complete": True}
# fusion_chunks: a chunk file of chunk (-1, 0, 2) (crates/voxstream-fusion/src/spill.rs): one brick with a colour
# block and a surface offset block, and an empty chunk; the CRC-32 is zlib's (the same polynomial as crc32fast).
def fusion_chunk(bricks):
    body = b"VXFC" + struct.pack("<I3iI", 2, -1, 0, 2, len(bricks))
    for key, colours, offsets in bricks:
        body += struct.pack("<3ifB", *key, 0.004, 1) + struct.pack("<16Q", *([0x0F0F] * 8 + [0x0F0F] * 8))
        body += bytes([len(colours)]) + b"".join(bytes([b]) + struct.pack("<32H", *([0xF800] * 32)) for b in colours)
        body += bytes([len(offsets)]) + b"".join(bytes([b]) + struct.pack("<32b", *range(-16, 16)) + bytes([7] * 32)
                                                for b in offsets)
    return body + struct.pack("<I", zlib.crc32(body))


put("fusion_chunks", "one_brick", fusion_chunk([((-32, 5, 64), [3], [3, 9])]))
put("fusion_chunks", "empty", fusion_chunk([]))

# wavelet_brick: a first byte choosing decoding (even) or a round trip (odd), then bytes; the round trips' seeds are a
# smooth ramp and noise (the codec's own encodings are reached through the round trip and libFuzzer's mutations).
put("wavelet_brick", "decode_zeros", bytes(64))
put("wavelet_brick", "round_trip_ramp", bytes([1, 0x3f]) + bytes(range(256)) * 8)
put("wavelet_brick", "round_trip_noise_lossy", bytes([0x71, 0x2a]) + bytes((i * 151 + 7) % 256 for i in range(2048)))

# remote_inputs: store locations as users type them, and a disk-cache entry (magic, key, length, bytes, CRC-32).
for name, url in [("https", b"https://example.org/data/brain.zarr/"), ("s3", b"s3://bucket/scans/ct.zarr"),
                  ("credentials", b"https://alice:s3cr%40t@example.org:8443/s.zarr?sig=abc#x"),
                  ("gs", b"gs://bucket/x"), ("az", b"az://container/a/b"), ("no_bucket", b"s3:///x")]:
    put("remote_inputs", name, url)
entry_key = b"s3://b/x/0/c/0/0/0#None"
entry_body = struct.pack("<I", len(entry_key)) + entry_key + struct.pack("<Q", 5) + b"brick"
put("remote_inputs", "cache_entry", b"VXC1" + entry_body + struct.pack("<I", zlib.crc32(entry_body)))

# store_shards: the first byte picks what the rest replaces in the template store's shard (0: the file, 1: the
# index's (offset, nbytes) pairs, 2: brick 0's bytes, a zstd frame); here a small index and an empty zstd frame.
put("store_shards", "index", b"\x01" + struct.pack("<QQ", 0, 64))
put("store_shards", "brick", b"\x02" + bytes.fromhex("28b52ffd2000010000"))
put("store_metadata", "voxstream", json.dumps({"zarr_format": 3, "node_type": "group",
                                               "attributes": {"voxstream": attributes}}))
put("store_metadata", "foreign-ome", json.dumps({"zarr_format": 3, "node_type": "group", "attributes": {"ome": {
    "version": "0.5", "multiscales": [{"axes": [{"name": a, "type": "space"} for a in "zyx"], "datasets": [
        {"path": "0", "coordinateTransformations": [{"type": "scale", "scale": [1, 1, 1]}]}]}]}}}))
# foreign_metadata: a selector byte (bit 0: Zarr v2), then the group's document, dataset 0's and dataset 1's,
# separated by NUL bytes (voxstream_fuzz::foreign_files).
OME_AXES = [{"name": a, "type": "space"} for a in "zyx"]
OME_DATASETS = [{"path": str(i), "coordinateTransformations": [{"type": "scale", "scale": [2 ** i] * 3}]}
                for i in range(2)]
V3_ARRAY = lambda edge: json.dumps({"zarr_format": 3, "node_type": "array", "shape": [edge] * 3,
                                    "data_type": "uint8", "chunk_grid": {"name": "regular", "configuration": {
                                        "chunk_shape": [16] * 3}},
                                    "chunk_key_encoding": {"name": "default", "configuration": {"separator": "/"}},
                                    "fill_value": 0, "codecs": [{"name": "bytes"}]})
V2_ARRAY = lambda edge: json.dumps({"zarr_format": 2, "shape": [edge] * 3, "chunks": [16] * 3, "dtype": "|u1",
                                    "compressor": None, "fill_value": 0, "order": "C", "filters": None})
put("foreign_metadata", "v3", b"\x00" + b"\x00".join(s.encode() for s in [
    json.dumps({"zarr_format": 3, "node_type": "group", "attributes": {"ome": {"version": "0.5", "multiscales": [
        {"axes": OME_AXES, "datasets": OME_DATASETS}]}}}), V3_ARRAY(64), V3_ARRAY(32)]))
put("foreign_metadata", "v2", b"\x01" + b"\x00".join(s.encode() for s in [
    json.dumps({"multiscales": [{"version": "0.4", "axes": OME_AXES, "datasets": OME_DATASETS}]}), V2_ARRAY(64),
    V2_ARRAY(32)]))
with open(os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "frog-tf.json"), "rb") as f:
    put("transfer_function", "frog", f.read())
put("transfer_function", "paraview", json.dumps([{"Name": "Cool to Warm", "ColorSpace": "Diverging",
                                                 "RGBPoints": [0, 0.23, 0.3, 0.75, 0.5, 0.87, 0.87, 0.87,
                                                               1, 0.71, 0.02, 0.15],
                                                 "Points": [0, 0, 0.5, 0, 1, 0.3, 0.5, 0]}]))
put("camera_path", "list", json.dumps([{"eye": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 40},
                                       {"eye": [3, 0, 0], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 35}]))
put("camera_path", "object", json.dumps({"cameras": [{"eye": [1, 2, 3], "target": [0, 0, 0], "up": [0, 0, 1],
                                                      "fov": 60}]}))


# geometry_files: the first byte picks the file-name ending (its index in GEOMETRY_FILE_ENDINGS of
# crates/voxstream-geometry/src/formats/mod.rs, modulo their number), the rest is the file.
GEOMETRY_ENDINGS = [".ply", ".obj", ".off", ".stl", ".xyz", ".csv", ".txt", ".gro", ".pdb", ".vtk", ".vtp", ".vtu"]


def geometry(name, ending, data):
    put("geometry_files", name, bytes([GEOMETRY_ENDINGS.index(ending)]) + (data if isinstance(data, bytes)
                                                                          else data.encode()))


TETRA = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
TETRA_FACES = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
PLY_MESH_HEAD = ("ply\nformat %s 1.0\ncomment a tetrahedron\nelement vertex 4\nproperty float x\nproperty float y\n"
                 "property float z\nproperty uchar red\nelement edge 1\nproperty list uchar int vertex_pair\n"
                 "element face 4\nproperty list uchar int vertex_indices\nend_header\n")
geometry("ply-ascii-mesh", ".ply", PLY_MESH_HEAD % "ascii" + "".join("%g %g %g 255\n" % p for p in TETRA)
         + "2 0 1\n" + "".join("3 %d %d %d\n" % f for f in TETRA_FACES))
for fmt, order in (("binary_little_endian", "<"), ("binary_big_endian", ">")):
    body = b"".join(struct.pack(order + "3fB", *p, 255) for p in TETRA) + struct.pack(order + "B2i", 2, 0, 1)
    body += b"".join(struct.pack(order + "B3i", 3, *f) for f in TETRA_FACES)
    geometry("ply-binary-%s-mesh" % ("le" if order == "<" else "be"), ".ply", (PLY_MESH_HEAD % fmt).encode() + body)
PLY_POINTS_HEAD = ("ply\nformat %s 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\n"
                   "property float nx\nproperty float hsml\nproperty float mass\nproperty float temperature\n"
                   "end_header\n")
POINTS = [(0, 0, 0, 1, 0.5, 1, 300), (1, 0, 0, 1, 0.25, 2, 310), (0, 1, 0.5, 1, 0.75, 3, 320)]
geometry("ply-ascii-points", ".ply", PLY_POINTS_HEAD % "ascii" + "".join("%g %g %g %g %g %g %g\n" % p for p in POINTS))
geometry("ply-binary-points", ".ply", (PLY_POINTS_HEAD % "binary_little_endian").encode()
         + b"".join(struct.pack("<3d4f", *p) for p in POINTS))
geometry("obj", ".obj", "# a tetrahedron\nmtllib none.mtl\no tetra\n" + "".join("v %g %g %g\n" % p for p in TETRA)
         + "vn 0 0 1\nvt 0 0\nf 1/1/1 3/1/1 2/1/1\nf 1//1 2//1 4//1\nf -4 -1 -2\nf 2 3 4\n")
geometry("off", ".off", "OFF\n# a tetrahedron\n4 4 6\n" + "".join("%g %g %g\n" % p for p in TETRA)
         + "".join("3 %d %d %d\n" % f for f in TETRA_FACES[:3]) + "3 1 2 3 255 0 0\n")


def stl_facets():
    return [[TETRA[i] for i in f] for f in TETRA_FACES]


geometry("stl-ascii", ".stl", "solid tetra\n" + "".join(
    "facet normal 0 0 0\n outer loop\n" + "".join("  vertex %g %g %g\n" % v for v in f) + " endloop\nendfacet\n"
    for f in stl_facets()) + "endsolid tetra\n")
geometry("stl-binary", ".stl", b"solid binary header".ljust(80, b" ") + struct.pack("<I", 4) + b"".join(
    struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *v) for v in f) + b"\0\0" for f in stl_facets()))
geometry("xyz-header", ".xyz", "# particles\nx y z h density\n0 0 0 0.5 1\n1 0 0 0.25 2\n0 1 0.5 0.75 3\n")
geometry("csv-header", ".csv", "\"x\",\"y\",\"z\",\"mass\",\"T\"\n0,0,0,1,300\n1,0,0,2,310\n0,1,0.5,3,320\n")
geometry("txt-plain", ".txt", "0 0 0\n1 0 0 \n0 1 0.5\n")
geometry("gro", ".gro", "Two atoms, t= 0.0\n    2\n"
         "    1ALA     CA    1   1.000   2.000  -3.500  0.1000  0.2000  0.3000\n"
         "    2CL-     CL    2  10.125   0.000   0.001\n   5.00000   5.00000   5.00000\n")
geometry("pdb", ".pdb", "HEADER    TEST\nMODEL        1\n"
         "ATOM      1  N   ALA A   1      -8.901   4.127  -0.555  1.00  0.00           N\n"
         "ATOM      2  CA  ALA A   1      -8.608   3.135  -1.618  1.00  0.00           C\n"
         "ATOM      3  HB1AALA A   1       1.000   1.000   1.000  0.50  0.00           H\n"
         "ATOM      4  HB1BALA A   1       1.100   1.000   1.000  0.50  0.00           H\n"
         "HETATM    5 CA    CA A   4       0.000   3.000   0.000  1.00 00.00\n"
         "ENDMDL\nMODEL        2\n"
         "ATOM      1  N   ALA A   1      -9.901   4.127  -0.555  1.00  0.00           N\nENDMDL\nEND\n")
geometry("vtk-ascii", ".vtk", "# vtk DataFile Version 3.0\nthree particles\nASCII\nDATASET POLYDATA\n"
         "POINTS 3 float\n0 0 0 1 0 0\n0 1 0.5\nVERTICES 3 6\n1 0 1 1 1 2\nPOINT_DATA 3\n"
         "SCALARS density double\nLOOKUP_TABLE default\n1.5 2.5 3.5\nVECTORS velocity float\n0 0 0 1 1 1 2 2 2\n"
         "FIELD FieldData 2\nhsml 1 3 float\n0.1 0.2 0.3\nmass 1 3 int\n4 5 6\n")
geometry("vtk-ascii-v5", ".vtk", "# vtk DataFile Version 5.1\nvtk output\nASCII\nDATASET UNSTRUCTURED_GRID\n"
         "FIELD FieldData 1\nTIME 1 1 double\n0.5\nPOINTS 2 double\n1 2 3 4 5 6\nMETADATA\nINFORMATION 0\n\n"
         "CELLS 3 2\nOFFSETS vtktypeint64\n0 1 2\nCONNECTIVITY vtktypeint64\n0 1\nCELL_TYPES 2\n1\n1\n"
         "CELL_DATA 2\nSCALARS cell_id int 1\nLOOKUP_TABLE default\n7 8\nPOINT_DATA 2\n"
         "SCALARS radius float\nLOOKUP_TABLE default\n0.25 0.5\nSCALARS pressure%20kPa float 1\n"
         "LOOKUP_TABLE default\n10 20\n")
vtk = b"# vtk DataFile Version 3.0\nbinary\nBINARY\nDATASET POLYDATA\nPOINTS 2 float\n"
vtk += struct.pack(">6f", 1, 2, 3, -4, 5.5, 6) + b"\nVERTICES 1 3\n" + struct.pack(">3i", 2, 0, 1)
vtk += b"\nPOINT_DATA 2\nSCALARS temperature short\nLOOKUP_TABLE default\n" + struct.pack(">2h", -300, 10)
vtk += b"\nNORMALS n double\n" + struct.pack(">6d", 0, 0, 1, 0, 1, 0)
vtk += b"\nSCALARS h double\nLOOKUP_TABLE default\n" + struct.pack(">2d", 0.5, 0.75)
vtk += b"\nFIELD FieldData 1\nm 1 2 unsigned_char\n\x07\x08\n"
geometry("vtk-binary", ".vtk", vtk)
geometry("vtp-ascii", ".vtp", """<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">
  <PolyData>
    <Piece NumberOfPoints="3" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="0">
      <PointData Scalars="density">
        <DataArray type="Float32" Name="velocity" NumberOfComponents="3" format="ascii">0 0 0 1 1 1 2 2 2</DataArray>
        <DataArray type="Float64" Name="density" format="ascii">1.5 2.5 3.5</DataArray>
        <DataArray type="Float32" Name="Mass" format="ascii">1 2 3</DataArray>
        <DataArray type="Float32" Name="hsml" format="ascii">0.1 0.2 0.3</DataArray>
      </PointData>
      <Points>
        <DataArray type="Float32" Name="Points" NumberOfComponents="3" format="ascii">0 0 0 1 0 0 0 1 0.5</DataArray>
      </Points>
      <Verts><DataArray type="Int64" Name="connectivity" format="ascii">0 1 2</DataArray></Verts>
    </Piece>
  </PolyData>
</VTKFile>
""")


# An unstructured grid as PySPH's dump_vtk (pyvisfile) writes it: every array appended as its own base64 run of a
# UInt32 byte count and the values, one vertex cell per particle.
vtu_arrays = [("Float64", "rho", 1, struct.pack("<2d", 1000.5, 1001.5)), ("Float64", "m", 1, struct.pack("<2d", 0.064, 0.064)),
              ("Float64", "h", 1, struct.pack("<2d", 0.052, 0.052)),
              ("Float64", "velocity", 3, struct.pack("<6d", 0, 1, 2, 3, 4, 5)),
              ("Float64", "points", 3, struct.pack("<6d", 0.1, 0.2, 0.3, 1.1, 1.2, 1.3)),
              ("Int64", "connectivity", 1, struct.pack("<2q", 0, 1))]
vtu_runs = [base64.b64encode(struct.pack("<I", len(data)) + data).decode() for (_, _, _, data) in vtu_arrays]
vtu_offsets = [sum(len(r) for r in vtu_runs[:i]) for i in range(len(vtu_runs))]
vtu_elements = ['<DataArray type="%s" Name="%s" NumberOfComponents="%d" format="appended" offset="%d"/>'
                % (ty, name, components, offset) for (ty, name, components, _), offset in zip(vtu_arrays, vtu_offsets)]
geometry("vtu-pysph", ".vtu", '<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid" version="0.1" '
         'byte_order="LittleEndian">\n<UnstructuredGrid>\n<Piece NumberOfPoints="2" NumberOfCells="2">\n<PointData>\n'
         + "\n".join(vtu_elements[:4]) + "\n</PointData>\n<Points>\n" + vtu_elements[4] + "\n</Points>\n<Cells>\n"
         + vtu_elements[5] + '\n</Cells>\n</Piece>\n</UnstructuredGrid>\n<AppendedData encoding="base64">\n_'
         + "".join(vtu_runs) + "\n</AppendedData>\n</VTKFile>\n")


def vtp_zlib(data, block, u64=True):
    """A zlib-compressed array as VTK writes it: the block header and the blocks, two base64 runs."""
    blocks = [zlib.compress(data[i:i + block]) for i in range(0, len(data), block)]
    last = len(data) - (len(blocks) - 1) * block
    entries = [len(blocks), block, 0 if last == block else last] + [len(b) for b in blocks]
    header = struct.pack(("<%dQ" if u64 else "<%dI") % len(entries), *entries)
    return (base64.b64encode(header) + base64.b64encode(b"".join(blocks))).decode()


VTP_POINTS = struct.pack("<9d", 0, 0, 0, 1, 2, 3, -1, 0.5, 9)
VTP_HSML = struct.pack("<3f", 0.1, 0.2, 0.3)
geometry("vtp-base64-zlib", ".vtp", """<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" \
header_type="UInt64" compressor="vtkZLibDataCompressor">
<PolyData><Piece NumberOfPoints="3">
<PointData><DataArray type="Float32" Name="hsml" format="binary">
  %s
</DataArray></PointData>
<Points><DataArray type="Float64" NumberOfComponents="3" format="binary">%s</DataArray></Points>
</Piece></PolyData></VTKFile>
""" % (vtp_zlib(VTP_HSML, 8), vtp_zlib(VTP_POINTS, 32)))
geometry("vtp-base64-uncompressed-be", ".vtp", """<VTKFile type="PolyData" byte_order="BigEndian"><PolyData>
<Piece NumberOfPoints="1"><Points><DataArray type="Float32" NumberOfComponents="3" format="binary">%s</DataArray>
</Points></Piece></PolyData></VTKFile>
""" % base64.b64encode(struct.pack(">I3f", 12, 1, 2, 3)).decode())
vtp_arrays = [struct.pack("<6f", 0, 0, 0, 1, 1, 1), struct.pack("<2h", -5, 6), struct.pack("<3f", 2, 2, 2),
              struct.pack("<h", 7)]
vtp_offsets, vtp_data = [], b""
for array in vtp_arrays:
    vtp_offsets.append(len(vtp_data))
    vtp_data += struct.pack("<I", len(array)) + array
geometry("vtp-appended-raw", ".vtp", ("""<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">
<PolyData>
<Piece NumberOfPoints="2"><PointData><DataArray type="Int16" Name="T" format="appended" offset="%d"/></PointData>
<Points><DataArray type="Float32" NumberOfComponents="3" format="appended" offset="%d"/></Points></Piece>
<Piece NumberOfPoints="1"><PointData><DataArray type="Int16" Name="T" format="appended" offset="%d"/></PointData>
<Points><DataArray type="Float32" NumberOfComponents="3" format="appended" offset="%d"/></Points></Piece>
</PolyData>
<AppendedData encoding="raw">
_""" % (vtp_offsets[1], vtp_offsets[0], vtp_offsets[3], vtp_offsets[2])).encode() + vtp_data
         + b"\n</AppendedData>\n</VTKFile>\n")
vtp_mass = vtp_zlib(struct.pack("<d", 3.0), 8, u64=False)
geometry("vtp-appended-base64-zlib", ".vtp", """<VTKFile type="PolyData" compressor="vtkZLibDataCompressor">
<PolyData><Piece NumberOfPoints="1"><PointData><DataArray type="Float64" Name="m" format="appended" offset="0"/>
</PointData><Points><DataArray type="Float32" NumberOfComponents="3" format="appended" offset="%d"/></Points></Piece>
</PolyData>
<AppendedData encoding="base64">
_%s%s
</AppendedData></VTKFile>
""" % (len(vtp_mass), vtp_mass, vtp_zlib(struct.pack("<3f", 4, 5, 6), 12, u64=False)))
