#!/usr/bin/env bash
# Renders a fixed set of images with two voxstream binaries and compares them byte for byte: the check that a
# refactoring (issue 45's splits) changed no pixel. Covers the built-in scenes, volumes and isosurfaces (shadows,
# both normal modes, several surfaces inside a volume), level blending over an interactive camera path, the
# level-colour diagnostic, a finer step and LOD bias, stores (imported real data, 8- and 16-bit bricks, in memory),
# a mesh, and particle files (density and attribute).
#
#   bash bench/same-images.sh BEFORE_BINARY AFTER_BINARY [WORK_DIR]
#
# Prints one line per case (same / DIFFERENT) and exits non-zero if any image differs. Needs data/real (fetched by
# scripts/fetch-real-data.sh).
set -euo pipefail
before=$(realpath "$1"); after=$(realpath "$2")
work=${3:-$(mktemp -d)}
cd "$(dirname "${BASH_SOURCE[0]}")/.."
real=$PWD/data/real
mkdir -p "$work"
# One store imported once (with the BEFORE binary), read by both.
if [ ! -d "$work/skull.vxs" ]; then
    "$before" import "$real/skull_2.9.inr" --out "$work/skull.vxs" --quiet >/dev/null
fi
# A binary PLY of 600,000 points (a deterministic cloud: a shell and a cluster), for the out-of-core particle path.
if [ ! -f "$work/cloud.ply" ]; then
    python3 - "$work/cloud.ply" <<'PY'
import math, random, struct, sys
random.seed(45)
points = []
for i in range(600_000):
    if i % 3:
        u, v = random.random() * 2 * math.pi, math.acos(2 * random.random() - 1)
        r = 1.0 + 0.05 * random.gauss(0, 1)
        points.append((r * math.sin(v) * math.cos(u), r * math.sin(v) * math.sin(u), r * math.cos(v)))
    else:
        points.append(tuple(0.3 * random.gauss(0, 1) for _ in range(3)))
with open(sys.argv[1], "wb") as f:
    f.write(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\nend_header\n" % len(points))
    f.write(b"".join(struct.pack("<3f", *p) for p in points))
PY
fi
echo '{"points": [[0, 0, 0, 0, 0], [0.4, 0.2, 0.4, 0.9, 0.05], [1, 1, 0.9, 0.6, 0.8]]}' >"$work/tf.json"
cases=(
    "sponge|sponge"
    "hypertexture|hypertexture"
    "shell|shell"
    "sponge-iso|sponge --iso 0.5 --shadows --light 1,1,0.5"
    "sponge-iso-central|sponge --iso 0.3,0.6 --iso-opacity 0.5,1 --normals central"
    "shell-iso-in-volume|shell --iso 0.5 --tf $work/tf.json"
    "sponge-interactive|sponge --mode interactive --path orbit:6 --requests-per-frame 64"
    "sponge-levels|sponge --colour-by-level"
    "sponge-fine|sponge --step 0.25 --lod-bias 1 --shading phong"
    "hypertexture-small-budget|hypertexture --budget-mb 8"
    "skull|$work/skull.vxs"
    "skull-16|$work/skull.vxs --brick-bits 16"
    "skull-in-memory|$work/skull.vxs --in-memory"
    "skull-iso|$work/skull.vxs --iso 2.5 --shadows --light 0,1,1"
    "skull-interactive|$work/skull.vxs --mode interactive --frames 6 --requests-per-frame 32"
    "bunny-mesh|$real/bunny00.off --resolution 96"
    "bunny-amplified|$real/bunny00.off --resolution 96 --amplify 0.02"
    "protein|$real/1hvr.pdb --resolution 64"
    "dam-break|$real/dam_break_3d_fluid.vtu --resolution 64"
    "dam-break-attribute|$real/dam_break_3d_fluid.vtu --resolution 64 --attribute"
    "cloud-in-memory|$work/cloud.ply --resolution 64"
    "cloud-out-of-core|$work/cloud.ply --resolution 64 --particle-memory 8"
    "sponge-gpu|sponge --backend gpu --gpu-filter exact"
    "skull-iso-gpu|$work/skull.vxs --iso 2.5 --backend gpu --gpu-filter exact"
)
status=0
for entry in "${cases[@]}"; do
    name=${entry%%|*}; args=${entry#*|}
    for which in before after; do
        binary=$before; [ $which = after ] && binary=$after
        mkdir -p "$work/$which/$name"
        # shellcheck disable=SC2086
        "$binary" render $args --width 192 --height 160 --quiet --out "$work/$which/$name/frame.png" \
            >"$work/$which/$name/log" 2>&1 || { echo "$name: $which failed (see $work/$which/$name/log)"; status=1; }
    done
    if cmp -s <(cd "$work/before/$name" && cat $(ls *.png | sort)) <(cd "$work/after/$name" && cat $(ls *.png | sort)) \
        && [ "$(ls "$work/before/$name" | grep -c png)" = "$(ls "$work/after/$name" | grep -c png)" ]; then
        echo "$name: same ($(ls "$work/after/$name" | grep -c png) images)"
    else
        echo "$name: DIFFERENT"; status=1
    fi
done
exit $status
