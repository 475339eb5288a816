#!/usr/bin/env bash
# A camera path that revisits places, rendered under a budget that cannot hold two places' bricks (issue 47's
# compressed host cache): close views of three places of the volume, A B C A B C A B, each frame converged, from a
# cold start. Prints per binary the bytes read from files, the compressed cache's hits, the time and peak memory.
#
#   bash bench/revisit.sh STORE BINARY [BINARY...]      (e.g. a build before a change and one after it)
#
# Uses --budget-mb 512 at 512x512 (BUDGET_MB and SIZE override). Not part of CI: the measurement of BENCHMARKS.md
# used the 2048^3 store of bench/large-volume.sh.
set -euo pipefail
store=$1; shift
budget=${BUDGET_MB:-512}; size=${SIZE:-512}
work=$(mktemp -d)
first=$1
"$first" render "$store" --width 32 --height 32 --out "$work/probe.png" --stats "$work/probe.json" >/dev/null 2>&1
"$first" info "$store" --json > "$work/info.json"
python3 - "$work" <<'PY'
import json, sys
work = sys.argv[1]
camera = json.load(open(f"{work}/probe.json"))["camera"]
info = json.load(open(f"{work}/info.json"))
extent = [d * s for d, s in zip(info["dims"], info["spacing"])]
origin = info["origin"]
away = [e - t for e, t in zip(camera["eye"], camera["target"])]
def view(fx, fy, fz):
    target = [o + f * e for o, f, e in zip(origin, (fx, fy, fz), extent)]
    return {"eye": [t + 0.3 * a for t, a in zip(target, away)], "target": target, "up": camera["up"],
            "fov": camera["fov"]}
a, b, c = view(0.25, 0.25, 0.5), view(0.75, 0.75, 0.5), view(0.25, 0.75, 0.5)
json.dump([a, b, c, a, b, c, a, b], open(f"{work}/revisit.json", "w"))
PY
for bin in "$@"; do
    "$bin" render "$store" --path "$work/revisit.json" --budget-mb "$budget" --width "$size" --height "$size" \
        --out "$work/frame.png" --stats "$work/stats.json" >/dev/null 2>&1
    python3 - "$work/stats.json" "$bin" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
hits = ((s.get("host_caches") or {}).get("compressed") or {}).get("hits", "-")
print(f"{sys.argv[2]}: read {s['file_bytes_read'] / 1e6:.0f} MB, compressed-cache hits {hits}, "
      f"{sum(s['frame_ms']) / 1000:.1f} s for {len(s['frame_ms'])} frames, peak RSS {s['peak_rss_bytes'] >> 20} MiB")
PY
done
rm -rf "$work"
