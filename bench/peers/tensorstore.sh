#!/usr/bin/env bash
# voxstream against tensorstore over the same emulated link (issue 43; not part of CI): STORE served by nginx
# (byte ranges), a proxy adding RTT ms to every exchange (bench/lib/http_store.sh). voxstream renders the URL converged at
# 512² (wall clock, opening and rendering included); tensorstore (pip, into target/peers/ts-venv) then reads exactly
# the bricks that render fetched (bench/peers/tensorstore_fetch.py), without and with a cache pool. Prints one line
# per RTT: voxstream's seconds and requests, tensorstore's seconds and requests (as nginx logged them).
# Usage: bench/peers/tensorstore.sh STORE [RTT_MS ...]   (default RTTs: 0 50 150)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
store=$(realpath "$1"); shift
rtts=("$@"); [ ${#rtts[@]} -gt 0 ] || rtts=(0 50 150)
bin=${VOXSTREAM_BIN:-$(pwd)/target/release/voxstream}
[ -x "$bin" ] || cargo build --release --quiet
venv=target/peers/ts-venv
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet --disable-pip-version-check tensorstore==0.1.86 numpy==2.4.6
fi
work=$(mktemp -d /tmp/voxstream-ts-bench.XXXXXX)
pids=()
cleanup() { for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done; rm -rf "$work"; }
trap cleanup EXIT
source bench/lib/http_store.sh
serve_folder "$(dirname "$store")"
name=$(basename "$store")
printf '%6s %14s %10s %16s %10s %18s %10s %7s\n' "RTT ms" "voxstream s" requests "tensorstore s" requests "ts + cache s" requests chunks
for rtt in "${rtts[@]}"; do
    start_proxy "$rtt"
    url="http://127.0.0.1:$proxy_port/$name"
    : > "$work/nginx/access.log"
    start=$(date +%s.%N)
    "$bin" render "$url" --out "$work/remote.png" --quiet --width 512 --height 512
    end=$(date +%s.%N); vs=$(echo "$end - $start" | bc)
    cp "$work/nginx/access.log" "$work/voxstream.log"
    vs_requests=$(wc -l < "$work/voxstream.log")
    : > "$work/nginx/access.log"
    plain=$("$venv/bin/python" bench/peers/tensorstore_fetch.py "$store" "$url" "$work/voxstream.log")
    plain_requests=$(wc -l < "$work/nginx/access.log")
    : > "$work/nginx/access.log"
    cached=$("$venv/bin/python" bench/peers/tensorstore_fetch.py "$store" "$url" "$work/voxstream.log" --cache-mb 256)
    cached_requests=$(wc -l < "$work/nginx/access.log")
    read -r chunks ts_plain < <(python3 -c 'import json,sys; r=json.loads(sys.argv[1]); print(r["chunks"], r["seconds"])' "$plain")
    ts_cached=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["seconds"])' "$cached")
    printf '%6s %14.2f %10s %16s %10s %18s %10s %7s\n' "$rtt" "$vs" "$vs_requests" "$ts_plain" "$plain_requests" "$ts_cached" "$cached_requests" "$chunks"
    kill "${pids[-1]}" 2>/dev/null || true
done
