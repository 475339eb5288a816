"""Ablation of voxstream builds on the peers' scenes: warm-frame time, CPU per frame, samples, ns per sample.

    python3 bench/ablation/ablation.py --builds BIN1,BIN2,... --scenes mni-soft,dragon,frog [--size 512] [--rounds 2]

Each build is a `voxstream` binary (e.g. built from older commits). Uses the stores and scene definitions of
`bench/peers/run.sh` (run it first: target/peers/data, target/peers/out/stores). For every scene and build, in turn,
it renders the scene's camera once (cold) and 1 + N times (a --path of N+1 copies); CPU per warm frame (both cores)
= (CPU(1+N frames) − CPU(1 frame)) / N from GNU time, samples per frame likewise from --stats, wall = median of the
N warm frames. The machine drifts, so builds alternate and the best of --rounds rounds is kept. Prints a Markdown
table.
"""
import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench/peers"))
import scenes as scene_list  # noqa: E402

N = 4


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--builds", required=True, help="comma-separated voxstream binaries")
    parser.add_argument("--scenes", default="mni-soft,dragon,frog")
    parser.add_argument("--size", default="512")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--data", type=Path, default=ROOT / "target/peers/data")
    parser.add_argument("--stores", type=Path, default=ROOT / "target/peers/out/stores")
    parser.add_argument("--work", type=Path, default=ROOT / "target/ablation")
    args = parser.parse_args()
    builds = args.builds.split(",")
    by_name = {s["name"]: s for s in scene_list.scenes(args.data)}
    best = {}
    for name in args.scenes.split(","):
        scene = by_name[name]
        work = args.work / name
        work.mkdir(parents=True, exist_ok=True)
        (work / "tf.json").write_text(json.dumps(scene["tf"]))
        (work / "path1.json").write_text(json.dumps([scene["camera"]]))
        (work / "path.json").write_text(json.dumps([scene["camera"]] * (N + 1)))
        light = ",".join(map(str, scene_list.headlight(scene["camera"])))
        store = args.stores / scene["volume"]

        def render(build, path):
            command = ["/usr/bin/time", "-f", "%U %S", "-o", work / "time.txt", build, "render", store, "--width",
                       args.size, "--height", args.size, "--tf", work / "tf.json", "--shading", scene["shading"],
                       "--light", light, "--path", path, "--stats", work / "stats.json", "--out",
                       work / "frame.png", "--budget-mb", "512", "--step", "0.5", "--quiet"]
            subprocess.run([str(c) for c in command], check=True, stdout=subprocess.DEVNULL)
            user, system = (work / "time.txt").read_text().split()[-2:]
            stats = json.loads((work / "stats.json").read_text())
            return float(user) + float(system), stats["samples"], stats["frame_ms"]

        for round_index in range(args.rounds):
            for build in builds:
                cpu1, samples1, _ = render(build, work / "path1.json")
                cpu, samples, frame_ms = render(build, work / "path.json")
                row = ((cpu - cpu1) / N, (samples - samples1) / N, statistics.median(frame_ms[1:]), frame_ms[0])
                print(f"{name} {build} round {round_index}: {row[0]:.3f} CPU s/frame, {row[1] / 1e6:.2f} M samples, "
                      f"{row[2]:.0f} ms wall, first {row[3]:.0f} ms", flush=True)
                key = (name, build)
                if key not in best or row[0] < best[key][0]:
                    best[key] = row
    print("\n| scene | build | warm frame (wall) | CPU per frame (2 cores) | samples per frame | ns CPU per sample "
          "| first frame |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for (name, build), (cpu, samples, wall, first) in best.items():
        print(f"| {name} | {Path(build).name} | {wall:.0f} ms | {cpu:.3f} s | {samples / 1e6:.2f} M "
              f"| {cpu * 1e9 / samples:.1f} | {first / 1000:.2f} s |")


if __name__ == "__main__":
    main()
