"""Prints compare.sh's results as the markdown table of BENCHMARKS.md "Depth fusion"."""
import json
import sys
from pathlib import Path

MiB = 1 << 20


def load(path):
    return json.loads(Path(path).read_text())


def row(label, err, fps, scene_mib, total_mib, rss_mib, ate):
    a = err["accuracy"]
    c = err.get("completeness_visible", err["completeness_all"])
    return (f"| {label} | {a['mean'] * 1e3:.2f} | {a['p95'] * 1e3:.2f} | {c['fraction_within_2_voxels'] * 100:.1f} | "
            f"{fps:.1f} | {scene_mib:.2f} | {total_mib:.1f} | {rss_mib:.0f} | {ate} |")


def main(work):
    work = Path(work)
    print("| sequence, fusion | accuracy mean mm | p95 mm | visible surface within 2 voxels % | frames/s | "
          "scene MiB | scene + frame cache MiB | peak RSS MiB | ATE RMSE mm (tracked) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ("bunny", "dragon", "bunny-room", "dragon-room"):
        if not (work / f"{name}-vx.json").exists():
            continue
        vx = load(work / f"{name}-vx.json")
        vt = load(work / f"{name}-vx-track.json")
        o3 = load(work / f"{name}-o3d.json")
        scene = vx["peak_brick_bytes"] / MiB
        print(row(f"{name}, voxstream (ground truth)", load(work / f"{name}-vx-err.json"), vx["frames_per_second"],
                  scene, scene + vx["ring_bytes"] / MiB, vx["peak_rss_bytes"] / MiB, "–"))
        if (work / f"{name}-vx-sign.json").exists():
            vs = load(work / f"{name}-vx-sign.json")
            sign = vs["peak_brick_bytes"] / MiB
            print(row(f"{name}, voxstream --sign-only (ground truth)", load(work / f"{name}-vx-sign-err.json"),
                      vs["frames_per_second"], sign, sign + vs["ring_bytes"] / MiB, vs["peak_rss_bytes"] / MiB, "–"))
        print(row(f"{name}, voxstream (tracked)", load(work / f"{name}-vx-track-err.json"),
                  vt["frames_per_second"], vt["peak_brick_bytes"] / MiB,
                  (vt["peak_brick_bytes"] + vt["ring_bytes"]) / MiB, vt["peak_rss_bytes"] / MiB,
                  f"{vt['ate_rmse'] * 1e3:.1f}"))
        g = o3["memory"]["grid"]
        odo = o3.get("odometry", {})
        ate = odo.get("ate", {}).get("rmse_m")
        odo_fps = odo.get("fps")
        print(row(f"{name}, Open3D VoxelBlockGrid", load(work / f"{name}-o3d-err.json"), o3["integration"]["fps"],
                  g["active_with_hash_estimate_bytes"] / MiB, g["allocated_buffer_bytes"] / MiB,
                  o3["memory"]["peak_rss_after_integration_bytes"] / MiB,
                  f"{ate * 1e3:.1f} at {odo_fps:.1f} frames/s" if ate is not None and odo_fps else "?"))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "/tmp/voxstream-fusion-bench")
