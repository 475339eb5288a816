"""Dense reference arrays of the bunny VDBs, from OpenVDB's Python binding (system python3, Debian python3-openvdb).

Writes NAME.reference.npy (C order (z, y, x), float32) and NAME.reference.json for bunny_ls and bunny_fog: the
active bounding box of the first float grid, as voxstream imports it.
"""
import json
import sys
from pathlib import Path

import numpy as np
import pyopenvdb as vdb

out = Path(sys.argv[1])
for name in ("bunny_ls", "bunny_fog"):
    grid = [g for g in vdb.readAll(str(out / f"{name}.vdb"))[0] if isinstance(g, vdb.FloatGrid)][0]
    lo, hi = grid.evalActiveVoxelBoundingBox()
    dims = [hi[a] - lo[a] + 1 for a in range(3)]
    dense = np.empty(dims, dtype=np.float32)
    grid.copyToArray(dense, ijk=lo)
    np.save(out / f"{name}.reference.npy", np.ascontiguousarray(dense.transpose(2, 1, 0)))
    meta = {"dims": dims, "dtype": "float32", "spacing": list(grid.transform.voxelSize()),
            "origin": list(grid.transform.indexToWorld(lo))}
    (out / f"{name}.reference.json").write_text(json.dumps(meta))
