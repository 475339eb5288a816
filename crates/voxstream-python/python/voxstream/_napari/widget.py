"""napari dock widget: renders napari's current 3D view of a store layer with voxstream, at full resolution within
a memory budget, progressively (coarse first) on a worker thread, again whenever the camera or the layer's colours
change. napari's event loop never waits: frames arrive as Qt signals, and a new camera abandons the old frames."""

from __future__ import annotations

from typing import Optional

import numpy as np
from qtpy.QtCore import QEvent, QObject, QTimer
from qtpy.QtGui import QImage, QPixmap
from qtpy.QtWidgets import QLabel, QSpinBox, QFormLayout, QVBoxLayout, QWidget

from .._volume import Session, open as open_volume
from .camera import mirrored, transfer_function, voxstream_camera

#: The longest side of the rendered image, pixels (the canvas' aspect is kept).
MAX_SIDE = 512


class VoxstreamWidget(QWidget):
    """Renders the active store layer (one opened by voxstream's reader) as napari's 3D camera sees it."""

    def __init__(self, napari_viewer, budget_mb: int = 1024):
        super().__init__()
        self.viewer = napari_viewer
        self.picture = QLabel("open a store with voxstream and switch to 3D")
        self.status = QLabel("")
        self.budget = QSpinBox()
        self.budget.setRange(64, 1 << 20)
        self.budget.setValue(budget_mb)
        self.budget.setSuffix(" MiB")
        form = QFormLayout()
        form.addRow("budget", self.budget)
        layout = QVBoxLayout(self)
        layout.addLayout(form)
        layout.addWidget(self.picture)
        layout.addWidget(self.status)
        #: The last image shown (H, W, 4 uint8), its stats, and whether it is the converged view.
        self.last_image: Optional[np.ndarray] = None
        self.last_stats: dict = {}
        self.converged = False
        #: The camera, transfer function and size of the frames in flight.
        self.camera = None
        self.tf = None
        self.size = None
        #: Whether voxstream's images are flipped left to right to show napari's view (see ``camera.mirrored``).
        self.mirrored = True
        self._volumes = {}
        self._worker = None
        self._generation = 0
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(30)
        self._timer.timeout.connect(self.start)
        scene_camera(napari_viewer).events.connect(self._schedule)
        napari_viewer.dims.events.ndisplay.connect(self._schedule)
        napari_viewer.layers.selection.events.active.connect(self._schedule)
        napari_viewer.layers.events.inserted.connect(self._schedule)
        self.budget.valueChanged.connect(self._schedule)
        # A resized canvas changes the image's size and aspect: render again.
        self._resize_watcher = _ResizeWatcher(self._schedule)
        try:
            self.viewer.window._qt_viewer.canvas.native.installEventFilter(self._resize_watcher)
        except Exception:  # a viewer without a window
            pass
        self._schedule()

    def layer(self):
        """The layer rendered: the active one if voxstream opened it, else the topmost such layer."""
        active = self.viewer.layers.selection.active
        if active is not None and "voxstream_source" in getattr(active, "metadata", {}):
            return active
        for layer in reversed(self.viewer.layers):
            if "voxstream_source" in getattr(layer, "metadata", {}):
                return layer
        return None

    def render_size(self):
        """(width, height): napari's canvas' aspect, the longest side at most ``MAX_SIDE``."""
        try:
            height, width = self.viewer.window._qt_viewer.canvas.size
        except Exception:  # a viewer without a window (napari's own tests make such)
            height, width = MAX_SIDE, MAX_SIDE
        scale = min(1.0, MAX_SIDE / max(width, height, 1))
        return max(1, round(width * scale)), max(1, round(height * scale)), height

    def _schedule(self, *_):
        self._timer.start()

    def _watch(self, layer):
        for event in ("colormap", "contrast_limits", "opacity"):
            emitter = getattr(layer.events, event, None)
            if emitter is not None:
                emitter.connect(self._schedule)

    def start(self):
        """Starts rendering the current view (abandoning frames of an older one)."""
        from napari.qt.threading import create_worker

        layer = self.layer()
        if layer is None or self.viewer.dims.ndisplay != 3:
            self.status.setText("voxstream renders a store layer in napari's 3D view")
            return
        self._watch(layer)
        width, height, canvas_height = self.render_size()
        if min(width, height) < 8:
            self.status.setText("napari's canvas is too small to render")
            return
        cam = scene_camera(self.viewer)
        self.mirrored = mirrored(cam)
        self.camera = voxstream_camera(cam.center, cam.view_direction, cam.up_direction, cam.zoom,
                                       cam.perspective, canvas_height)
        self.tf = transfer_function(layer.colormap, layer.contrast_limits, layer.opacity)
        self.size = (width, height)
        budget = self.budget.value()
        key = (layer.metadata["voxstream_source"], self.size, budget)
        if key not in self._volumes:
            self._volumes = {key: open_volume(key[0], size=self.size, budget_mb=budget)}
        volume = self._volumes[key]
        if self._worker is not None:
            self._worker.quit()
        self._generation += 1
        self.converged = False
        generation = self._generation
        worker = create_worker(_frames, volume, self.camera, self.tf, self.size, budget, self.mirrored)
        worker.yielded.connect(lambda frame, g=generation: self._show(frame, g))
        self._worker = worker
        worker.start()

    def _show(self, frame, generation):
        if generation != self._generation:
            return  # a frame of a view the camera has left
        image, stats, final = frame
        self.last_image, self.last_stats, self.converged = image, stats, final
        rgb = np.ascontiguousarray(image[..., :3])
        height, width = rgb.shape[:2]
        qimage = QImage(rgb.data, width, height, 3 * width, QImage.Format_RGB888).copy()
        self.picture.setPixmap(QPixmap.fromImage(qimage))
        state = "complete" if final else f"{int(stats.get('pending', 0))} bricks on their way"
        self.status.setText(f"{width}x{height}, {state}, {stats.get('elapsed_ms', 0):.0f} ms")


class _ResizeWatcher(QObject):
    """Calls back when the widget it watches is resized."""

    def __init__(self, callback):
        super().__init__()
        self._callback = callback

    def eventFilter(self, watched, event):  # noqa: N802 (Qt's name)
        if event.type() == QEvent.Resize:
            self._callback()
        return False


def scene_camera(viewer):
    """napari's camera (``viewer.scene.camera`` since 0.9, ``viewer.camera`` before)."""
    scene = getattr(viewer, "scene", None)
    return scene.camera if scene is not None and hasattr(scene, "camera") else viewer.camera


def _frames(volume, camera, tf, size, budget_mb, flip):
    """Interactive frames until the view is loaded, then the converged image (``volume.render``'s, flipped left to
    right when napari's axes are right-handed in their own order)."""
    session = Session(volume, camera=camera, tf=tf, size=size, budget_mb=budget_mb, blending=False)
    for _ in range(10_000):
        image, stats = session.frame()
        if stats["converged"]:
            break
        yield (image[:, ::-1] if flip else image), stats, False
    image = session.converge()
    yield (image[:, ::-1] if flip else image), session.last_stats, True
