#!/usr/bin/env bash
# A volume far larger than the memory budget, end to end (not part of CI; needs ~20 GB of free disk):
#   1. builds a 2048^3 u8 raw volume (8 GiB) by tiling the real MNI152 T1 scan, slab by slab, as GigaVoxels copied
#      its bone scan 8x per axis;
#   2. imports it (peak RSS, time, throughput) and measures a plain sequential read of the same file;
#   3. renders it under --budget-mb 512: converged from a cold cache (time, peak RSS, bytes read vs bytes used), and
#      an interactive sequence (time to the first image, frames until complete).
# Usage: bench/large-volume.sh [WORK_DIR] [EDGE]    (defaults: /tmp/voxstream-large 2048)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
work=${1:-/tmp/voxstream-large}
edge=${2:-2048}
mkdir -p "$work"
bash scripts/fetch-real-data.sh >/dev/null
cargo build --release --quiet
bin=./target/release/voxstream

if [ ! -f "$work/tiled_$edge.raw" ]; then
    python3 - "$work/tiled_$edge.raw" "$edge" <<'PY'
import sys
import numpy as np
out, edge = sys.argv[1], int(sys.argv[2])
scan = np.load("data/real/mni152_t1.reference.npy")  # (z, y, x) u8
zs, ys, xs = scan.shape
with open(out, "wb") as f:
    for z in range(edge):
        plane = scan[z % zs]
        tiled = np.tile(plane, (edge // ys + 1, edge // xs + 1))[:edge, :edge]
        f.write(np.ascontiguousarray(tiled).tobytes())
PY
fi
raw="$work/tiled_$edge.raw"
size=$(stat -c %s "$raw")
echo "volume: ${edge}^3 u8, $((size / 1048576)) MiB"

echo "--- sequential read of the raw file (dd, 16 MiB blocks)"
dd if="$raw" of=/dev/null bs=16M 2>&1 | tail -1

echo "--- import"
rm -rf "$work/tiled.zarr"
/usr/bin/time -f "import: %e s wall, %M KiB peak RSS" $bin import "$raw" --dims "$edge,$edge,$edge" --dtype u8 \
    --out "$work/tiled.zarr" --quiet
$bin info "$work/tiled.zarr" | tail -n +7

echo "--- converged render, cold store, --budget-mb 512"
/usr/bin/time -f "render: %e s wall, %M KiB peak RSS" $bin render "$work/tiled.zarr" --budget-mb 512 \
    --out "$work/converged.png" --stats "$work/converged.json"
python3 -c "
import json; s = json.load(open('$work/converged.json'))
print('converged:', s['converged'], 'passes:', s['passes'], 'time ms:', round(s['frame_ms'][0]))
print('bricks used:', s['bricks_resident'], 'brick bytes used MiB:', round(s['brick_bytes_used'] / 2**20, 1),
      'file bytes read MiB:', round(s['file_bytes_read'] / 2**20, 1))
print('pools peak MiB:', round(s['resident_bytes_peak'] / 2**20, 1), 'process peak RSS MiB:', round(s['peak_rss_bytes'] / 2**20, 1))
"

echo "--- interactive from a cold store: frames until complete"
/usr/bin/time -f "interactive: %e s wall, %M KiB peak RSS" $bin render "$work/tiled.zarr" --budget-mb 512 \
    --mode interactive --frames 200 --out "$work/interactive.png" --stats "$work/interactive.json"
python3 -c "
import json; s = json.load(open('$work/interactive.json'))
ms = s['frame_ms']
print('first image ms:', round(ms[0]), 'frames until complete:', len(ms), 'complete:', s['converged'],
      'total ms:', round(sum(ms)))
print('median frame ms:', round(sorted(ms)[len(ms) // 2]))
"
