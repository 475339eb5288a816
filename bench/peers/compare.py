"""Renders every scene of scenes.py with voxstream and its peers, scores each image against the brute-force
reference, and writes the table (results.md, results.json) and one side-by-side PNG per scene and size.

Run through bench/peers/run.sh, which installs the peers and prepares the data. Times are medians of RUNS timed
frames after one warm-up frame, all tools on both cores; peak memory is each tool process's peak RSS (GNU time).
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

sys.path.insert(0, str(Path(__file__).parent))
import metrics  # noqa: E402
import scenes as scene_list  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
# Another build can be measured with the same harness: VOXSTREAM_BIN=/path/to/voxstream.
VOXSTREAM = Path(os.environ.get("VOXSTREAM_BIN", ROOT / "target/release/voxstream"))
REFERENCE = ROOT / "target/release/peers-reference"
BUDGET_MB = 512
# A tool whose first frame takes longer than this is timed on that frame alone.
SLOW_FRAME_S = 60.0


def run(command, **kwargs):
    """Runs a command; returns (stdout, stderr, wall seconds, peak RSS bytes of the command).

    The peak comes from GNU time (`%M`): a child forked from this Python process would inherit its resident set as
    the starting high-water mark of `ru_maxrss` (it survives exec), so wait4's figure has this process's size as a
    floor; GNU time is small, so the floor it passes on is negligible. Fails loudly."""
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err, \
            tempfile.NamedTemporaryFile("r") as peak_file:
        start = time.perf_counter()
        process = subprocess.run(["/usr/bin/time", "-f", "%M", "-o", peak_file.name] + [str(c) for c in command],
                                 stdout=out, stderr=err, **kwargs)
        wall = time.perf_counter() - start
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(), err.read().decode()
        peak_text = peak_file.read().strip().splitlines()
    if process.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, command))} failed ({process.returncode}):\n{stderr[-2000:]}")
    return stdout, stderr, wall, int(peak_text[-1]) * 1024


def volume_meta(data: Path, name: str):
    """The raw volume's description as the reference and the VTK runner read it."""
    meta = json.loads((data / f"{name}.json").read_text())
    meta.pop("density_scale", None)
    meta["path"] = str(data / f"{name}.raw")
    return meta


def reference(scene, size, data: Path, out: Path):
    """The supersampled brute-force image of the scene's own volume (cached): 3x3 rays per pixel at 512², 2x2 above,
    steps of 1/8 (512²) or 1/4 (larger) of a base voxel."""
    png = out / "reference" / f"{scene['name']}-{size}.png"
    if png.exists():
        return png
    png.parent.mkdir(parents=True, exist_ok=True)
    step = (0.125 if size <= 512 else 0.25) * scene["reference_step_scale"]
    spec = {"volume": volume_meta(data, scene["volume"]), "camera": scene["camera"], "width": size,
            "height": size, "mode": scene["mode"], "shading": scene["shading"], "phong": scene_list.PHONG,
            "light": scene_list.headlight(scene["camera"]), "background": [0, 0, 0],
            "supersample": 3 if size <= 512 else 2, "step_voxels": step}
    if scene["mode"] == "volume":
        spec["tf"] = scene["tf"]
    else:
        spec["iso"] = scene["iso"]
    spec_path = png.with_suffix(".json")
    spec_path.write_text(json.dumps(spec))
    stdout, _, wall, _ = run([REFERENCE, "--scene", spec_path, "--out", png])
    print(f"    reference {scene['name']} {size}²: {wall:.1f} s", flush=True)
    return png


def voxstream_variant(tool: str):
    """The flags of a voxstream tool name: `voxstream` (the default: since 2026-12-06 the adaptive step at 0.05 for
    volumes), or `voxstream-` followed by dash-separated parts `stepX` (--step X), `pre` (--preintegrate), `adapt` or
    `adaptX` (--adaptive-step [X]), `faithful` (--faithful: fixed steps, the default before); e.g.
    `voxstream-step1-pre-adapt0.05`, `voxstream-faithful`. None if the name is not a voxstream tool."""
    if tool == "voxstream":
        return []
    if not tool.startswith("voxstream-"):
        return None
    flags = []
    for part in tool.removeprefix("voxstream-").split("-"):
        if m := re.fullmatch(r"step(\d+(?:\.\d+)?)", part):
            flags += ["--step", m.group(1)]
        elif part == "pre":
            flags.append("--preintegrate")
        elif m := re.fullmatch(r"adapt(\d+(?:\.\d+)?)?", part):
            flags += ["--adaptive-step"] + ([m.group(1)] if m.group(1) else [])
        elif part == "faithful":
            flags.append("--faithful")
        else:
            raise ValueError(f"unknown part '{part}' of voxstream tool '{tool}'")
    return flags


def render_voxstream(scene, size, runs, data: Path, out: Path, tool="voxstream"):
    meta = volume_meta(data, scene["volume"])
    store = out / "stores" / scene["volume"]
    import_s = None
    if not store.exists():
        store.parent.mkdir(parents=True, exist_ok=True)
        _, _, import_s, _ = run([VOXSTREAM, "import", meta["path"], "--dims", ",".join(map(str, meta["dims"])),
                                 "--dtype", meta["dtype"], "--spacing", ",".join(map(str, meta["spacing"])),
                                 "--out", store, "--quiet"])
    flags = voxstream_variant(tool)
    if "--step" not in flags:
        flags = ["--step", "0.5"] + flags
    work = out / tool / f"{scene['name']}-{size}"
    work.mkdir(parents=True, exist_ok=True)
    if scene["mode"] == "volume":
        (work / "tf.json").write_text(json.dumps(scene["tf"]))
        look = ["--tf", work / "tf.json"]
    else:
        iso = scene["iso"]
        look = ["--iso", iso["value"], "--iso-color", ",".join(map(str, iso["color"]))]
    (work / "path.json").write_text(json.dumps([scene["camera"]] * (runs + 1)))
    _, _, wall, peak = run([VOXSTREAM, "render", store, "--width", size, "--height", size, *look,
                            "--shading", scene["shading"], "--light",
                            ",".join(map(str, scene_list.headlight(scene["camera"]))),
                            "--path", work / "path.json", "--stats", work / "stats.json", "--out", work / "frame.png",
                            "--budget-mb", BUDGET_MB, *flags])
    stats = json.loads((work / "stats.json").read_text())
    frames = [ms / 1000 for ms in stats["frame_ms"]]
    image = work / f"frame_{runs:04d}.png"
    return {"first_s": frames[0], "frame_s": frames[1:], "peak_rss_bytes": peak, "image": image,
            "import_s": import_s, "note": f"{stats['bricks_resident']} bricks resident"}


def render_vtk(kind, scene, size, runs, data: Path, out: Path):
    work = out / f"vtk-{kind}" / f"{scene['name']}-{size}"
    work.mkdir(parents=True, exist_ok=True)
    spec = dict(scene, phong=scene_list.PHONG)
    (work / "scene.json").write_text(json.dumps(spec))
    (work / "volume.json").write_text(json.dumps(volume_meta(data, scene["volume"])))
    stdout, _, _, peak = run([sys.executable, Path(__file__).parent / "vtk_render.py", kind, work / "volume.json",
                              work / "scene.json", size, size, runs, work / "frame.png"])
    result = json.loads(stdout.strip().splitlines()[-1])
    note = f"{result['triangles']:,} triangles, extraction+first frame {result['prepare_s']:.2f} s" \
        if result["triangles"] else ""
    return {"first_s": result["prepare_s"], "frame_s": result["frame_s"], "peak_rss_bytes": peak,
            "image": work / "frame.png", "load_s": result["load_s"], "note": note}


def render_vdb(scene, size, runs, data: Path, out: Path):
    meta = volume_meta(data, scene["volume"])
    work = out / "vdb_render" / f"{scene['name']}-{size}"
    work.mkdir(parents=True, exist_ok=True)
    cam, fog = scene["camera"], scene["fog"]
    voxel = meta["spacing"][0]
    extinction = fog["k"] * voxel
    scatter = [c * extinction for c in fog["colour"]]
    absorb = [(1 - c) * extinction for c in fog["colour"]]
    vec = lambda v: ",".join(f"{x:.9g}" for x in v)  # noqa: E731
    command = ["vdb_render", data / f"{scene['volume']}.vdb", work / "frame.png", "-res", f"{size}x{size}",
               "-translate", vec(cam["eye"]), "-lookat", vec(cam["target"]), "-up", vec(cam["up"]),
               "-fov", cam["fov"], "-step", "0.5", "-shadowstep", "1e9", "-scatter", vec(scatter),
               "-absorb", vec(absorb), "-light", vec(scene_list.headlight(cam) + [1, 1, 1]), "-cpus", "0", "-v"]
    frames, peak, first = [], 0, None
    for i in range(runs + 1):
        if i == 1 and first > SLOW_FRAME_S:
            frames.append(first_render)  # one frame took minutes: report it rather than repeat it
            break
        stdout, stderr, wall, rss = run(command)
        log = stdout + stderr
        match = re.search(r"ray-tracing.*?\n.*?completed in ([0-9.e+-]+) sec", log, re.S)
        if not match:
            raise RuntimeError(f"no timing in vdb_render output:\n{log[-1000:]}")
        seconds = float(match.group(1))
        read = re.search(r"reading.*?\n.*?completed in ([0-9.e+-]+) sec", log, re.S)
        peak = max(peak, rss)
        if i == 0:
            first = seconds + (float(read.group(1)) if read else 0)
            first_render = seconds
        else:
            frames.append(seconds)
    return {"first_s": first, "frame_s": frames, "peak_rss_bytes": peak, "image": work / "frame.png",
            "note": "file read + render per process"}


def side_by_side(images, labels, path: Path):
    tiles = [np.asarray(Image.open(p).convert("RGB")) for p in images]
    h, w = tiles[0].shape[:2]
    canvas = Image.new("RGB", (w * len(tiles), h + 24), (32, 32, 32))
    draw = ImageDraw.Draw(canvas)
    for i, (tile, label) in enumerate(zip(tiles, labels)):
        canvas.paste(Image.fromarray(tile), (i * w, 24))
        draw.text((i * w + 6, 6), label, fill=(255, 255, 255))
    canvas.save(path)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, default=ROOT / "target/peers/data")
    parser.add_argument("--out", type=Path, default=ROOT / "target/peers/out")
    parser.add_argument("--runs", type=int, default=5, help="timed frames per tool after one warm-up")
    parser.add_argument("--sizes", default="512,1024")
    parser.add_argument("--scenes", default="", help="comma-separated scene names (default: all)")
    parser.add_argument("--tools", default="", help="comma-separated tools (default: all)")
    parser.add_argument("--extra-tools", default="",
                        help="voxstream variants to add to every volume scene, e.g. voxstream-step1-pre,voxstream-adapt")
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    wanted = set(filter(None, args.scenes.split(",")))
    tools_wanted = set(filter(None, args.tools.split(",")))
    args.out.mkdir(parents=True, exist_ok=True)
    results_path = args.out / "results.json"
    results = json.loads(results_path.read_text()) if results_path.exists() else {}

    for scene in scene_list.scenes(args.data):
        if wanted and scene["name"] not in wanted:
            continue
        for size in sizes:
            key = f"{scene['name']}-{size}"
            print(f"{key}", flush=True)
            ref_png = reference(scene, size, args.data, args.out)
            ref = np.asarray(Image.open(ref_png).convert("RGB"))
            row = results.get(key, {})
            tools = scene["tools"] + [t for t in args.extra_tools.split(",") if t and t not in scene["tools"]
                                      and (scene["mode"] == "volume" or not t.startswith("voxstream-"))]
            for tool in tools:
                if tools_wanted and tool not in tools_wanted:
                    continue
                if voxstream_variant(tool) is not None:
                    r = render_voxstream(scene, size, args.runs, args.data, args.out, tool)
                elif tool == "vdb_render":
                    r = render_vdb(scene, size, args.runs, args.data, args.out)
                else:
                    r = render_vtk(tool.removeprefix("vtk-"), scene, size, args.runs, args.data, args.out)
                img = np.asarray(Image.open(r["image"]).convert("RGB"))
                r["psnr"] = metrics.psnr(img, ref)
                r["ssim"] = metrics.ssim(img, ref)
                r["median_s"] = statistics.median(r["frame_s"])
                r["image"] = str(r["image"])
                print(f"    {tool:18} {r['median_s'] * 1000:9.1f} ms  first {r['first_s']:.2f} s  "
                      f"{r['peak_rss_bytes'] / 2**20:7.0f} MiB  {r['psnr']:.1f} dB  SSIM {r['ssim']:.3f}", flush=True)
                row[tool] = r
            results[key] = row
            results_path.write_text(json.dumps(results, indent=1))
            present = [t for t in tools if t in row]
            side_by_side([ref_png] + [row[t]["image"] for t in present],
                         ["reference"] + [f"{t} {row[t]['psnr']:.1f} dB" for t in present],
                         args.out / f"{key}.png")
    write_table(results, args.out / "results.md")


def write_table(results, path: Path):
    lines = ["| scene | size | tool | frame (median) | first frame | peak RSS | PSNR | SSIM | time ÷ voxstream's |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for key, row in results.items():
        name, size = key.rsplit("-", 1)
        base = row.get("voxstream", {}).get("median_s")
        for tool, r in row.items():
            ratio = f"{r['median_s'] / base:.2f}×" if base and tool != "voxstream" else ""
            lines.append(f"| {name} | {size}² | {tool} | {r['median_s'] * 1000:.0f} ms | {r['first_s']:.2f} s | "
                         f"{r['peak_rss_bytes'] / 2**20:.0f} MiB | {r['psnr']:.1f} dB | {r['ssim']:.3f} | {ratio} |")
    path.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
