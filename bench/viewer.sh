#!/usr/bin/env bash
# Measures what a user of `voxstream view` feels, in a virtual X server (Xvfb, Mesa's software OpenGL): the first
# image, the first final image, frames while the view moves (a scripted drag: 60 turns of 1.5°, 50 ms apart), and the
# time from the last input to the final image. Usage:
#   bench/viewer.sh SOURCE [SIZE] [OUT.json] [VIEW FLAGS…]   e.g. bench/viewer.sh hypertexture 512 out.json --refine blended
# SIZE is an edge (512) or WIDTHxHEIGHT (1024x768).
# Needs xvfb-run (Debian: xvfb xauth libgl1-mesa-dri) and a release build (cargo build --release).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source="${1:?usage: bench/viewer.sh SOURCE [SIZE] [OUT.json]}"
size="${2:-512}"
width="${size%%x*}"
height="${size##*x}"
out="${3:-target/viewer-bench.json}"
shift $(( $# < 3 ? $# : 3 ))
command -v xvfb-run >/dev/null || { echo "xvfb-run is needed (Debian: apt-get install xvfb xauth libgl1-mesa-dri)" >&2; exit 1; }
script="$(mktemp --suffix=.txt)"
trap 'rm -f "$script"' EXIT
{
    echo "wait-final 900"
    for _ in $(seq 60); do echo "orbit 1.5 0"; echo "wait 0.05"; done
    echo "wait-final 900"
    echo "quit"
} > "$script"
xvfb-run -a -s "-screen 0 1600x1200x24" ./target/release/voxstream view "$source" --width "$width" --height "$height" \
    --script "$script" --stats "$out" "$@"
python3 - "$out" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
moving = [f for f in s["frames"] if [f["width"], f["height"]] != s["render_size"]]
sizes = sorted({(f["width"], f["height"]) for f in moving})
print(f"render size {s['render_size'][0]}x{s['render_size'][1]}")
print(f"first image: {s['first_image_ms']:.0f} ms; first final image: {s['first_final_ms']:.0f} ms")
if moving:
    print(f"moving frames: {len(moving)}, median {s['moving_frame_ms_median']:.0f} ms, sizes {sizes}")
print("last input to final image: " + ", ".join(f"{t:.0f} ms" for t in s["input_to_final_ms"]))
PY
