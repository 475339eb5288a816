#!/usr/bin/env bash
# The GPU renderer's figures on whatever adapter this machine has, next to the CPU renderer's in the same run:
# the adapter, converged and warm frame times, frames along an interactive path, and the bytes uploaded to the GPU
# per frame (cold, warm, path). Not part of CI (CI's adapter is lavapipe, a CPU emulation: see BENCHMARKS.md).
#
#   bash bench/gpu.sh [SIZE] [SCENES]      e.g. bash bench/gpu.sh 1024 sponge,hypertexture
#   WARM_FRAMES=5 PATH_FRAMES=20 bash bench/gpu.sh 256      (fewer frames, e.g. on lavapipe)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
size="${1:-1024}"
scenes="${2:-sponge,hypertexture,shell}"
warm="${WARM_FRAMES:-20}"
path_frames="${PATH_FRAMES:-60}"
cargo build --release -q -p voxstream
bin=./target/release/voxstream
out=target/gpu-bench
mkdir -p "$out"
# The GPU twice: bricks filtered as the adapter can best (auto: by the texture units where it can filter 16-bit
# textures) and exactly in the shader (the CPU's arithmetic).
for run in gpu:auto gpu:exact cpu:auto; do
    backend="${run%%:*}"
    filter="${run##*:}"
    echo "## --backend $backend --gpu-filter $filter, ${size}², scenes $scenes"
    "$bin" bench --backend "$backend" --gpu-filter "$filter" --size "$size" --scenes "$scenes" --blending off \
        --warm-frames "$warm" --path-frames "$path_frames" --json "$out/$backend-$filter.json"
    echo
done
python3 - "$out/gpu-auto.json" "$out/gpu-exact.json" "$out/cpu-auto.json" <<'PY'
import json, sys
gpu, exact, cpu = (json.load(open(p)) for p in sys.argv[1:4])
print("| scene | warm frame GPU (auto) / GPU (exact) / CPU | path median GPU (auto) / CPU | uploaded per path frame |")
print("|---|---|---|---|")
for g, e, c in zip(gpu, exact, cpu):
    print(f"| {g['scene']} | {g['warm_frame_ms']:.1f} / {e['warm_frame_ms']:.1f} / {c['warm_frame_ms']:.1f} ms "
          f"({c['warm_frame_ms'] / g['warm_frame_ms']:.2f}x) "
          f"| {g['path_median_ms']:.1f} / {c['path_median_ms']:.1f} ms | {g['path_bytes_uploaded_per_frame'] / 1e3:.1f} kB |")
print(f"\nadapter (auto): {gpu[0]['backend']}")
PY
