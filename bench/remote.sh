#!/usr/bin/env bash
# Remote stores over emulated round trips (issue 43; not part of CI): one store served by nginx (byte ranges, ETags),
# a proxy delaying every byte by half the round trip each way (bench/lib/http_store.sh), and voxstream rendering it:
#   - the converged image must be the local folder's, byte for byte;
#   - time to the first image with data (`--mode interactive --frames 2`: the root brick arrives after the first frame) and to the complete view (`--mode converged`),
#     wall clock, opening included;
#   - requests and bytes fetched (`--stats`'s remote) against the store's bytes on disk, and how many (chunk, range)
#     pairs were fetched more than once.
# Usage: bench/remote.sh STORE [RTT_MS ...] [-- RENDER_FLAGS...]   (default RTTs: 0 50 150; VOXSTREAM_BIN names
# another build than target/release/voxstream)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
store=$(realpath "$1"); shift
rtts=()
while [ $# -gt 0 ] && [ "$1" != "--" ]; do rtts+=("$1"); shift; done
[ $# -gt 0 ] && shift
flags=("$@")
[ ${#rtts[@]} -gt 0 ] || rtts=(0 50 150)
bin=${VOXSTREAM_BIN:-$(pwd)/target/release/voxstream}
[ -x "$bin" ] || cargo build --release --quiet
work=$(mktemp -d /tmp/voxstream-remote-bench.XXXXXX)
pids=()
cleanup() { for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done; rm -rf "$work"; }
trap cleanup EXIT
source bench/lib/http_store.sh
serve_folder "$(dirname "$store")"
name=$(basename "$store")
disk=$(du -sb "$store" | cut -f1)
"$bin" render "$store" --out "$work/local.png" --quiet "${flags[@]}"
start=$(date +%s.%N); "$bin" render "$store" --out "$work/local.png" --quiet "${flags[@]}"; end=$(date +%s.%N)
printf 'store %s: %s bytes on disk; local converged render %.2f s\n' "$name" "$disk" "$(echo "$end - $start" | bc)"
printf '%8s %12s %12s %9s %12s %10s %s\n' "RTT ms" "first img s" "complete s" requests "bytes" "repeated" "image"
for rtt in "${rtts[@]}"; do
    start_proxy "$rtt"
    url="http://127.0.0.1:$proxy_port/$name"
    start=$(date +%s.%N)
    "$bin" render "$url" --out "$work/first.png" --quiet --mode interactive --frames 2 "${flags[@]}"
    end=$(date +%s.%N); first=$(echo "$end - $start" | bc)
    : > "$work/nginx/access.log"
    start=$(date +%s.%N)
    "$bin" render "$url" --out "$work/remote.png" --quiet --stats "$work/stats.json" "${flags[@]}"
    end=$(date +%s.%N); complete=$(echo "$end - $start" | bc)
    read -r requests bytes < <(python3 -c 'import json,sys; r=json.load(open(sys.argv[1]))["remote"]; print(r["requests"], r["bytes"])' "$work/stats.json")
    repeated=$(grep '/c/' "$work/nginx/access.log" | cut -d' ' -f1-5 | sort | uniq -d | wc -l)
    same=$(cmp -s "$work/local.png" "$work/remote.png" && echo identical || echo DIFFERENT)
    printf '%8s %12.2f %12.2f %9s %12s %10s %s\n' "$rtt" "$first" "$complete" "$requests" "$bytes" "$repeated" "$same"
done
