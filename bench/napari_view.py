"""napari's own 3D view of a store against voxstream's dock widget at the same camera: the level napari draws, the
process's memory after each, and both pictures.

Usage: xvfb-run -a -s "-screen 0 1600x1200x24" .venv/bin/python bench/napari_view.py STORE OUT_DIR [BUDGET_MB]
(after scripts/python-tests.sh, which installs napari into .venv)
"""

import pathlib
import resource
import sys
import time

import numpy as np
import napari
from PIL import Image
from qtpy.QtWidgets import QApplication

from voxstream._napari.widget import VoxstreamWidget, scene_camera

store, out = sys.argv[1], pathlib.Path(sys.argv[2])
budget = int(sys.argv[3]) if len(sys.argv) > 3 else 512
out.mkdir(parents=True, exist_ok=True)


def rss_mib():
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def pump(seconds, done=lambda: False):
    end = time.monotonic() + seconds
    while time.monotonic() < end and not done():
        QApplication.processEvents()
        time.sleep(0.01)


viewer = napari.Viewer(show=True)
viewer.window._qt_window.resize(1400, 900)
pump(0.5)
base = rss_mib()
t0 = time.perf_counter()
layer = viewer.open(store, plugin="voxstream")[0]
layer.colormap = "gray"
viewer.dims.ndisplay = 3
scene_camera(viewer).angles = (0.0, -35.0, 60.0)
pump(2.0)
napari_s = time.perf_counter() - t0
level = layer.data_level
shape = layer.data[level].shape
print(f"napari: 3D view of {store}: level {level} of {len(layer.data)}, {shape[2]}x{shape[1]}x{shape[0]} samples "
      f"(level 0: {layer.data[0].shape[2]}x{layer.data[0].shape[1]}x{layer.data[0].shape[0]}); "
      f"{napari_s:.1f} s to open and draw; RSS {rss_mib():.0f} MiB (viewer alone {base:.0f} MiB)")
widget = VoxstreamWidget(viewer, budget_mb=budget)
viewer.window.add_dock_widget(widget)
pump(0.5)
shot = viewer.screenshot(canvas_only=True)
t1 = time.perf_counter()
first = []
pump(600, lambda: (first.append(time.perf_counter()) if widget.last_image is not None and not first else None)
     or widget.converged)
done = time.perf_counter()
print(f"voxstream widget: {widget.size[0]}x{widget.size[1]}, budget {budget} MiB: first image "
      f"{(first[0] - t1) if first else float('nan'):.2f} s, complete {done - t1:.1f} s; RSS {rss_mib():.0f} MiB; "
      f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
width = widget.size[0]
napari_picture = Image.fromarray(shot[..., :3]).resize((width, widget.size[1]))
napari_picture.save(out / "napari-3d-native.png")
Image.fromarray(np.ascontiguousarray(widget.last_image[..., :3])).save(out / "napari-3d-voxstream.png")
print(f"pictures: {out / 'napari-3d-native.png'}, {out / 'napari-3d-voxstream.png'}")
viewer.close()
