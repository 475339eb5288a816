#!/usr/bin/env bash
# Meshes and particles rendered directly (BENCHMARKS.md, "Meshes and particles"): voxstream's on-demand producers
# against what a user would run instead, on this machine, in one run.
#
#   bench/peers/geometry.sh            # writes target/peers/geometry/results.md
#
# Inputs: the Stanford dragon (871,414 triangles, scripts/fetch-real-data.sh), a million-particle clustered cloud
# (made here with numpy, fixed seed: 256 Gaussian clumps), and adenylate kinase in water (47,681 atoms, GRO).
# Peers: OpenVDB's vdb_tool (-mesh2ls, -points2ls: voxelise first) + vdb_render (Debian libopenvdb-tools); for
# particles also VTK's Gaussian splatter + fixed-point ray caster (bench/peers/splat.py, VTK 9.7.2 from PyPI in
# target/peers/venv, which bench/peers/run.sh makes).
# For each: time to the first 512x512 image (from the file, cold), a second frame of the same view (warm, voxstream
# only: the peers have no cache to reuse), and peak memory (GNU time).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
out=target/peers/geometry
mkdir -p "$out"
python=target/peers/venv/bin/python
[ -x "$python" ] || python=/usr/bin/python3
cargo build --release --quiet
vs=target/release/voxstream
scripts/fetch-real-data.sh >/dev/null

[ -f "$out/dragon.ply" ] || gzip -dc data/real/dragon_vrip.ply.gz > "$out/dragon.ply"
if [ ! -f "$out/cloud1m.ply" ]; then
    "$python" - "$out" <<'PY'
import sys, numpy as np
out = sys.argv[1]
rng = np.random.default_rng(2026)
centres = rng.uniform(-1, 1, (256, 3))
sigmas = rng.uniform(0.01, 0.08, 256)
which = rng.integers(0, 256, 1_000_000)
p = (centres[which] + rng.normal(size=(1_000_000, 3)) * sigmas[which, None]).astype(np.float32)
with open(f"{out}/cloud1m.ply", "wb") as f:
    f.write(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000\nproperty float x\nproperty float y\n"
            b"property float z\nend_header\n")
    f.write(p.tobytes())
PY
fi

timed() { # label command... -> prints "seconds peak_MiB"
    /usr/bin/time -f "%e %M" -o "$out/time.txt" "$@" >"$out/last.log" 2>&1 || { cat "$out/last.log"; exit 1; }
    awk '{ printf "%.2f %.0f\n", $1, $2 / 1024 }' "$out/time.txt"
}

{
echo "| input | tool | first image (s) | peak memory (MiB) | warm frame (ms) | note |"
echo "|---|---|---|---|---|---|"
for input in dragon.ply cloud1m.ply adk_oplsaa.gro; do
    path="$out/$input"
    [ "$input" = adk_oplsaa.gro ] && path=data/real/adk_oplsaa.gro
    # The default view, twice: frame 0 cold (reading, indexing, producing), frame 1 warm (all resident).
    "$vs" render "$path" --width 512 --height 512 --stats "$out/probe.json" --out "$out/probe.png" --quiet \
        --resolution 16 2>/dev/null || "$vs" render "$path" --width 16 --height 16 --stats "$out/probe.json" \
        --out "$out/probe.png" --quiet
    "$python" -c "import json; c = json.load(open('$out/probe.json'))['camera']; json.dump([c, c], open('$out/path.json', 'w'))"
    read -r first_s peak < <(timed "$vs" render "$path" --width 512 --height 512 --path "$out/path.json" \
        --stats "$out/vs.json" --out "$out/${input%%.*}-voxstream.png" --quiet)
    read -r cold warm bricks < <("$python" -c "
import json; d = json.load(open('$out/vs.json')); print('%.0f %.0f %d' % (d['frame_ms'][0], d['frame_ms'][1], d['bricks_produced']))")
    echo "| $input | voxstream | $first_s | $peak | $warm | first frame ${cold} ms after opening; $bricks bricks produced |"
    if [ "$input" = dragon.ply ]; then
        for d in 512 1024; do
            read -r t1 m1 < <(timed vdb_tool -read "$path" -mesh2ls d=$d -write "$out/dragon$d.vdb")
            read -r t2 m2 < <(timed vdb_render "$out/dragon$d.vdb" "$out/dragon-vdb$d.png" -res 512x512 -shader diffuse)
            echo "| $input | vdb_tool -mesh2ls d=$d + vdb_render | $(echo "$t1 + $t2" | bc) | $((m1 > m2 ? m1 : m2)) | | voxelise ${t1} s, render ${t2} s |"
        done
    fi
    if [ "$input" != dragon.ply ] && [ -x target/peers/venv/bin/python ]; then
        # A particle splatter: VTK's Gaussian splatter (ParaView's "Gaussian Resampling") + its CPU ray caster.
        for d in 256 512; do
            read -r t1 m1 < <(timed target/peers/venv/bin/python bench/peers/splat.py "$path" $d "$out/${input%%.*}-splat$d.png")
            echo "| $input | VTK vtkGaussianSplatter ${d}³ + fixed-point ray caster | $t1 | $m1 | | splat, then one 512² frame (python + VTK: ~300 MiB before any data) |"
        done
    fi
    if [ "$input" = cloud1m.ply ]; then
        for d in 512 1024; do
            read -r t1 m1 < <(timed vdb_tool -read "$path" -points2ls d=$d r=2.0 -write "$out/cloud$d.vdb")
            read -r t2 m2 < <(timed vdb_render "$out/cloud$d.vdb" "$out/cloud-vdb$d.png" -res 512x512 -shader diffuse)
            echo "| $input | vdb_tool -points2ls d=$d + vdb_render | $(echo "$t1 + $t2" | bc) | $((m1 > m2 ? m1 : m2)) | | voxelise ${t1} s, render ${t2} s |"
        done
    fi
done
} | tee "$out/results.md"
