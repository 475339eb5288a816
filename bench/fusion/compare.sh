#!/usr/bin/env bash
# Depth-camera fusion against Open3D (issue 49, BENCHMARKS.md "Depth fusion"): synthetic Kinect-like sequences of
# the two real meshes (the CGAL bunny and the Stanford dragon, on a floor and in a room) fused by `voxstream fuse` and by Open3D's tensor TSDF
# (VoxelBlockGrid) on the same frames and voxel size, both with ground-truth poses and with tracking (voxstream also
# with --sign-only, the thesis' two bits without surface offsets); surfaces measured against the true scene by
# surface_error.py. SKIP_O3D=1 reuses Open3D's results already in $WORK. Prints a markdown table; everything else lands in $WORK.
#
#   bash bench/fusion/compare.sh [FRAMES]        (default 300: one orbit of 10 s at 30 Hz)
#
# Needs target/release/voxstream (cargo build --release), data/real (scripts/fetch-real-data.sh) and the Open3D
# venv of bench/fusion/README.md (O3D_PYTHON, default bench/fusion/venv/bin/python).
set -euo pipefail
cd "$(dirname "$0")/../.."
FRAMES=${1:-300}
VOXEL=${VOXEL:-0.01}
VOXSTREAM=${VOXSTREAM:-target/release/voxstream}
PY=${O3D_PYTHON:-bench/fusion/venv/bin/python}
WORK=${WORK:-/tmp/voxstream-fusion-bench}
mkdir -p "$WORK"
# Each mesh on a bare floor, and in a room (walls 1.5 m high around the 3 m floor), which gives tracking more to hold.
for case in bunny:data/real/bunny00.off:0 dragon:data/real/dragon_vrip.ply.gz:0 \
            bunny-room:data/real/bunny00.off:1.5 dragon-room:data/real/dragon_vrip.ply.gz:1.5; do
    name=${case%%:*}; rest=${case#*:}; file=${rest%%:*}; walls=${rest#*:}
    seq="$WORK/$name"
    echo "== $name: $FRAMES frames" >&2
    "$VOXSTREAM" synth-rgbd "$file" --out "$seq" --frames "$FRAMES" --walls "$walls" --overwrite --quiet
    "$VOXSTREAM" fuse "$seq" --voxel "$VOXEL" --points "$WORK/$name-vx.ply" --stats "$WORK/$name-vx.json" --quiet
    "$VOXSTREAM" fuse "$seq" --voxel "$VOXEL" --sign-only --points "$WORK/$name-vx-sign.ply" \
        --stats "$WORK/$name-vx-sign.json" --quiet
    "$VOXSTREAM" fuse "$seq" --voxel "$VOXEL" --poses track --points "$WORK/$name-vx-track.ply" \
        --trajectory "$WORK/$name-vx-track.txt" --stats "$WORK/$name-vx-track.json" --quiet
    [ "${SKIP_O3D:-0}" = 1 ] && [ -f "$WORK/$name-o3d-err.json" ] || "$PY" bench/fusion/open3d_peer.py "$seq" --voxel "$VOXEL" --depth-max 5 --half-pixel-fix --odometry \
        --json "$WORK/$name-o3d.json" --points "$WORK/$name-o3d.ply" --trajectory "$WORK/$name-o3d-track.txt" >/dev/null
    for run in vx vx-sign vx-track $([ "${SKIP_O3D:-0}" = 1 ] && [ -f "$WORK/$name-o3d-err.json" ] || echo o3d); do
        "$PY" bench/fusion/surface_error.py --truth "$seq/scene.ply" --points "$WORK/$name-$run.ply" \
            --dataset "$seq" --json "$WORK/$name-$run-err.json" >/dev/null
    done
done
"$PY" bench/fusion/summarise.py "$WORK"
