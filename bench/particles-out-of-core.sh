#!/usr/bin/env bash
# Particle sets read out of core (--particle-memory) against the in-memory read, end to end (not part of CI):
#   makes a clustered cloud of COUNT particles (256 Gaussian clumps, numpy seed 2026, as bench/peers/geometry.sh's
#   million-particle cloud) as a binary PLY, then renders its density surface (--iso 1e5) at 512x512 in memory
#   (default budget, and --budget-mb 1024) and out of core with 64, 256 and 512 MiB for particles; prints a table of
#   the time from the file to the PNG, the opening (read + index) time, the peak resident set and whether the image
#   is complete.
# Usage: bench/particles-out-of-core.sh [WORK_DIR] [COUNT]    (defaults: target/particles-ooc 8000000)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
work=${1:-target/particles-ooc}
count=${2:-8000000}
mkdir -p "$work"
cargo build --release --quiet
bin=./target/release/voxstream
python=data/venv/bin/python
[ -x "$python" ] || python=target/peers/venv/bin/python
[ -x "$python" ] || { echo "needs numpy: run scripts/fetch-real-data.sh (data/venv) first" >&2; exit 1; }
cloud="$work/cloud_$count.ply"
if [ ! -f "$cloud" ]; then
    "$python" - "$cloud" "$count" <<'PY'
import sys, numpy as np
out, n = sys.argv[1], int(sys.argv[2])
rng = np.random.default_rng(2026)
centres = rng.uniform(-1, 1, (256, 3))
sigmas = rng.uniform(0.01, 0.08, 256)
which = rng.integers(0, 256, n)
p = (centres[which] + rng.normal(size=(n, 3)) * sigmas[which, None]).astype(np.float32)
with open(out, "wb") as f:
    f.write(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
            b"property float z\nend_header\n" % n)
    f.write(p.tobytes())
PY
fi

echo "| read | flags | file to PNG (s) | opening (s) | peak memory (MiB) | image |"
echo "|---|---|---|---|---|---|"
run() { # label flags...
    local label=$1; shift
    /usr/bin/time -f "%e %M" -o "$work/time.txt" "$bin" render "$cloud" --iso 1e5 --width 512 --height 512 \
        --out "$work/out.png" "$@" >"$work/last.log" 2>&1 || { cat "$work/last.log"; exit 1; }
    local opening complete
    opening=$(grep -oE '(built|binned) in [0-9.]+ s' "$work/last.log" | grep -oE '[0-9.]+' | head -1 || true)
    complete=$(grep -oE '512x512, (complete|incomplete)' "$work/last.log" | grep -oE '[a-z]+$' || true)
    awk -v l="$label" -v f="$*" -v o="$opening" -v c="$complete" \
        '{ printf "| %s | `%s` | %.1f | %s | %.0f | %s |\n", l, f, $1, o, $2 / 1024, c }' "$work/time.txt"
}
run "in memory" --budget-mb 256
run "in memory" --budget-mb 1024
for mib in 64 256 512; do
    run "out of core" --budget-mb 256 --particle-memory "$mib"
done
