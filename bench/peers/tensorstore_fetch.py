"""Reads, with tensorstore (the reader behind Neuroglancer), exactly the bricks a voxstream render fetched: issue 43's
peer comparison ("voxstream's time to a complete view, rendering included, no longer than tensorstore's time to only
read them").

The bricks are recovered from the HTTP server's access log of the voxstream run: every bounded range GET of a shard
is matched, through the shard's index in the local copy of the store, to the inner chunks it holds (one, or several
that abut where voxstream merged their ranges). tensorstore
then opens each level's array over the same URL (through the same latency proxy) and reads those chunks' boxes, all
issued at once, with its default HTTP concurrency (32 requests) and either no cache (its default) or a 256 MiB cache
pool (so that each shard index is fetched once, as voxstream does). Prints the chunks, the time from open to the
last byte, and tensorstore's requests as the server logged them.

Usage: tensorstore_fetch.py STORE_DIR URL ACCESS_LOG [--cache-mb N]
"""
import json
import os
import re
import struct
import sys
import time

import tensorstore as ts


def shard_chunks(store, level):
    meta = json.load(open(os.path.join(store, level, "zarr.json")))
    shard = meta["chunk_grid"]["configuration"]["chunk_shape"]
    sharding = meta["codecs"][0]["configuration"]
    inner = sharding["chunk_shape"]
    return meta["shape"], shard, inner


def chunks_from_log(store, name, log):
    """(level, inner chunk box) for each bounded shard range voxstream fetched."""
    pattern = re.compile(r'^GET /%s/(\d+)/c/(\d+)/(\d+)/(\d+) HTTP/[\d.]+ "bytes=(\d+)-(\d+)"' % re.escape(name))
    wanted = set()
    indexes = {}
    for line in open(log):
        m = pattern.match(line)
        if not m:
            continue
        level, sz, sy, sx, start, end = m.groups()
        shape, shard, inner = shard_chunks(store, level)
        path = os.path.join(store, level, "c", sz, sy, sx)
        if path not in indexes:
            per = [s // i for s, i in zip(shard, inner)]
            n = per[0] * per[1] * per[2]
            data = open(path, "rb").read()
            index = data[-(n * 16 + 4):-4]
            entries = [struct.unpack_from("<QQ", index, 16 * k) + (k,) for k in range(n)]
            indexes[path] = (entries, per)
        entries, per = indexes[path]
        held = [k for offset, length, k in entries
                if offset != 2**64 - 1 and offset >= int(start) and offset + length <= int(end) + 1]
        for k in held:
            cz, cy, cx = k // (per[1] * per[2]), k // per[2] % per[1], k % per[2]
            origin = [int(s) * sh + c * i for s, sh, c, i in zip((sz, sy, sx), shard, (cz, cy, cx), inner)]
            box = tuple((o, min(o + i, d)) for o, i, d in zip(origin, inner, shape))
            wanted.add((level, box))
    return sorted(wanted)


def main():
    store, url, log = sys.argv[1:4]
    cache_mb = int(sys.argv[sys.argv.index("--cache-mb") + 1]) if "--cache-mb" in sys.argv else 0
    name = os.path.basename(os.path.normpath(store))
    chunks = chunks_from_log(store, name, log)
    levels = sorted({level for level, _ in chunks})
    context = {"cache_pool": {"total_bytes_limit": cache_mb << 20}} if cache_mb else {}
    started = time.perf_counter()
    arrays = {
        level: ts.open({"driver": "zarr3", "kvstore": {"driver": "http", "base_url": url.rstrip("/") + "/" + level + "/"},
                        "context": context}, read=True).result()
        for level in levels
    }
    futures = [arrays[level][tuple(slice(a, b) for a, b in box)].read() for level, box in chunks]
    samples = sum(f.result().size for f in futures)
    elapsed = time.perf_counter() - started
    print(json.dumps({"chunks": len(chunks), "levels": levels, "samples": int(samples), "seconds": round(elapsed, 3),
                      "cache_mb": cache_mb}))


if __name__ == "__main__":
    main()
