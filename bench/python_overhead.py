"""Python's overhead per frame: the wall time of `Volume.render` against the frame time the engine itself measured
(`last_stats["elapsed_ms"]`, what `voxstream render` spends on the same frame before writing its PNG), for warm
converged frames (the view resident) and for an interactive orbit. Also the peak RSS of the process.

Usage: .venv/bin/python bench/python_overhead.py SOURCE [SIZE] [BUDGET_MB]   (after scripts/python-tests.sh)
"""

import resource
import statistics
import sys
import time

import voxstream as vs

source = sys.argv[1]
size = int(sys.argv[2]) if len(sys.argv) > 2 else 512
budget = int(sys.argv[3]) if len(sys.argv) > 3 else 512

start = time.perf_counter()
volume = vs.open(source, size=(size, size), budget_mb=budget)
image = volume.render()
cold = time.perf_counter() - start
print(f"{source}: {size}x{size}, budget {budget} MiB; cold open + converged render {cold:.2f} s "
      f"({volume.last_stats['passes']:.0f} passes, {volume.last_stats['bricks_produced']:.0f} bricks)")


def measure(label, frames):
    walls, engines, converts, calls = [], [], [], []
    for camera, mode in frames:
        t0 = time.perf_counter()
        volume.render(camera, mode=mode)
        walls.append((time.perf_counter() - t0) * 1000)
        engines.append(volume.last_stats["elapsed_ms"])
        converts.append(volume.last_stats["convert_ms"])
        calls.append(volume.last_stats["call_ms"])
    wall, engine = statistics.median(walls), statistics.median(engines)
    overheads = [w - e for w, e in zip(walls, engines)]
    print(f"{label}: median wall {wall:.2f} ms, engine {engine:.2f} ms, overhead median "
          f"{statistics.median(overheads):.3f} ms ({100 * statistics.median(overheads) / engine:.2f}% of the frame), "
          f"max {max(overheads):.3f} ms, {len(frames)} frames; of it: pixels to uint8 "
          f"{statistics.median(converts):.3f} ms, facade outside the frame "
          f"{statistics.median(calls) - engine - statistics.median(converts):.3f} ms, thread and Python "
          f"{wall - statistics.median(calls):.3f} ms")


camera = volume.camera
measure("warm converged, same view", [(camera, "converged")] * 30)
orbit = [camera.orbit(azimuth=3 * i) for i in range(60)]
measure("interactive orbit (3 deg per frame)", [(c, "interactive") for c in orbit])
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(f"peak RSS {peak:.0f} MiB (budget {budget} MiB + {peak - budget:.0f} MiB)")
