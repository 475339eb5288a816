#!/usr/bin/env python3
"""An HTTP/1.1 proxy in front of one server that adds round-trip latency and faults, for voxstream's remote-store
tests and benchmarks (issue 43): a fixed delay before every answer (an emulated round trip), answers of 503, bodies
cut short (the Content-Length of the whole body, half of it sent, then the connection closed), and stalls (from the
Nth request on, or for paths matching a regular expression, nothing is answered).

    python3 scripts/fault_proxy.py --listen 18090 --upstream 127.0.0.1:18080 --latency-ms 50 \
        --fail-rate 0.2 --truncate-rate 0.05 --seed 1 --log requests.log

Each request gets its own upstream connection and `Connection: close` (a client keeps many connections open at
once, as it would to a real server). Faults are drawn from a seeded generator; metadata (`zarr.json`, `.zattrs`,
`.zarray`, `.zgroup`) is faulted like everything else. `--log` writes one line per request: method, path, range,
what was done, when it was answered (seconds, monotonic). Standard library only.
"""

import argparse
import asyncio
import random
import re
import sys


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--listen", type=int, required=True, help="port to listen on (127.0.0.1)")
    parser.add_argument("--upstream", required=True, help="HOST:PORT of the real server")
    parser.add_argument("--latency-ms", type=float, default=0.0, help="delay before each answer")
    parser.add_argument("--fail-rate", type=float, default=0.0, help="share of requests answered 503")
    parser.add_argument("--truncate-rate", type=float, default=0.0, help="share of bodies cut to half")
    parser.add_argument("--stall-after", type=int, default=None, help="answer nothing from this request on")
    parser.add_argument("--stall-match", default=None, help="never answer requests whose path matches this regex")
    parser.add_argument("--stall-match-after", type=int, default=0, help="...except the first N of them")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--log", default=None, help="file to log requests to")
    return parser.parse_args()


async def read_head(reader):
    head = await reader.readuntil(b"\r\n\r\n")
    if len(head) > 65536:
        raise ValueError("request head too long")
    return head


def with_connection_close(head: bytes) -> bytes:
    lines = head.decode("latin-1").split("\r\n")
    kept = [line for line in lines if line and not line.lower().startswith(("connection:", "keep-alive:"))]
    return ("\r\n".join(kept) + "\r\nConnection: close\r\n\r\n").encode("latin-1")


def header(head: bytes, name: str):
    for line in head.decode("latin-1").split("\r\n")[1:]:
        key, _, value = line.partition(":")
        if key.strip().lower() == name:
            return value.strip()
    return None


class Proxy:
    def __init__(self, args):
        self.args = args
        self.random = random.Random(args.seed)
        self.count = 0
        self.upstream_host, port = args.upstream.rsplit(":", 1)
        self.upstream_port = int(port)
        self.log = open(args.log, "a", buffering=1) if args.log else None

    def note(self, head: bytes, action: str):
        if self.log:
            request_line = head.split(b"\r\n", 1)[0].decode("latin-1")
            now = asyncio.get_running_loop().time()
            self.log.write(f"{request_line}\t{header(head, 'range') or '-'}\t{action}\t{now:.4f}\n")

    async def handle(self, client_reader, client_writer):
        try:
            head = await read_head(client_reader)
            length = int(header(head, "content-length") or 0)
            body = await client_reader.readexactly(length) if length else b""
            self.count += 1
            path = head.split(b"\r\n", 1)[0].decode("latin-1").split(" ")[1:2]
            stall_path = False
            if self.args.stall_match and path and re.search(self.args.stall_match, path[0]):
                self.matched = getattr(self, "matched", 0) + 1
                stall_path = self.matched > self.args.stall_match_after
            if stall_path or (self.args.stall_after is not None and self.count >= self.args.stall_after):
                self.note(head, "stall")
                await asyncio.sleep(3600)
                return
            if self.args.latency_ms:
                await asyncio.sleep(self.args.latency_ms / 1000.0)
            draw = self.random.random()
            if draw < self.args.fail_rate:
                self.note(head, "503")
                client_writer.write(b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
                await client_writer.drain()
                return
            truncate = draw < self.args.fail_rate + self.args.truncate_rate
            up_reader, up_writer = await asyncio.open_connection(self.upstream_host, self.upstream_port)
            up_writer.write(with_connection_close(head) + body)
            await up_writer.drain()
            response = await up_reader.read()
            up_writer.close()
            split = response.find(b"\r\n\r\n")
            answer_head, answer_body = response[: split + 4], response[split + 4 :]
            if truncate and len(answer_body) > 1:
                self.note(head, f"truncated {len(answer_body) // 2} of {len(answer_body)}")
                client_writer.write(answer_head + answer_body[: len(answer_body) // 2])
            else:
                self.note(head, "passed")
                client_writer.write(response)
            await client_writer.drain()
        except (asyncio.IncompleteReadError, ConnectionError, ValueError):
            pass
        finally:
            try:
                client_writer.close()
            except Exception:
                pass

    async def serve(self):
        server = await asyncio.start_server(self.handle, "127.0.0.1", self.args.listen, backlog=512)
        print(f"listening on 127.0.0.1:{self.args.listen}", flush=True)
        async with server:
            await server.serve_forever()


def main():
    args = parse_args()
    try:
        asyncio.run(Proxy(args).serve())
    except KeyboardInterrupt:
        pass
    except OSError as error:
        print(f"fault_proxy: {error}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
