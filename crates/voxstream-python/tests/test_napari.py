"""napari (0.9, under Xvfb): the plugin opens a store as a multiscale layer read brick by brick, and the dock
widget's image for a 3D camera is `vs.open(…).render(…)` at the same camera, arriving without blocking napari."""

import time

import numpy as np
import pytest

import voxstream as vs
from voxstream._napari.camera import voxstream_camera
from voxstream._napari.widget import scene_camera
from voxstream._napari.levels import LevelArray

import napari  # installed by scripts/python-tests.sh


class _Fake:
    """A native volume whose regions come from an array (x, y, z arguments, [z, y, x] results)."""

    def __init__(self, array):
        self.array = array

    def read_region(self, level, lower, size):
        (x, y, z), (sx, sy, sz) = lower, size
        return self.array[z:z + sz, y:y + sy, x:x + sx].copy()


def test_levels_index_like_numpy_arrays():
    array = np.random.default_rng(1).random((7, 9, 11), dtype=np.float32)
    level = LevelArray(_Fake(array), 0, (11, 9, 7))
    keys = [(3,), (slice(None), 2), (Ellipsis, 4), (slice(1, 6, 2), slice(None, None, -1), -1),
            (slice(5, 0, -2),), (slice(None, None, -3), slice(2, 3), slice(8, 2, -1)), (slice(4, 4),),
            (Ellipsis,)]
    for key in keys:
        assert np.array_equal(np.asarray(level[key]), array[key]), key
        assert level[key].shape == array[key].shape, key
    # Views of views, and nothing read until asked.
    reads = []
    fake = _Fake(array)
    fake_read = fake.read_region
    fake.read_region = lambda *args: reads.append(args) or fake_read(*args)
    lazy = LevelArray(fake, 0, (11, 9, 7))
    view = lazy[:, 2:8][::2, :, 3]
    assert not reads and view.shape == array[:, 2:8][::2, :, 3].shape
    assert np.array_equal(np.asarray(view), array[:, 2:8][::2, :, 3])
    # One read, of the view's bounding box only: z 0..6, y 2..7, x 3.
    assert reads == [(0, (3, 2, 0), (1, 6, 7))]
    assert np.array_equal(np.asarray(level), array)
    with pytest.raises(IndexError):
        level[7]


def test_the_reader_opens_a_store_as_a_multiscale_layer(ball_store):
    from voxstream._napari.reader import get_reader

    assert get_reader(str(ball_store)) is not None
    assert get_reader("not-a-store.txt") is None
    viewer = napari.Viewer(show=False)
    try:
        layers = viewer.open(str(ball_store), plugin="voxstream")
        layer = layers[0]
        assert layer.multiscale
        assert layer.data[0].shape == (40, 48, 56)
        assert tuple(layer.scale) == (1.5, 1.0, 1.0)
        # Level 0's samples are the imported array's.
        from conftest import ball

        assert layer.data[0].dtype == np.uint8
        assert np.array_equal(np.asarray(layer.data[0][20]), ball()[20])
    finally:
        viewer.close()


def test_the_widget_renders_napari_s_3d_view_as_voxstream_does(ball_store, qapp_events):
    viewer = napari.Viewer(show=True)
    try:
        viewer.open(str(ball_store), plugin="voxstream")
        viewer.dims.ndisplay = 3
        scene_camera(viewer).angles = (10.0, -30.0, 60.0)
        widget = docked_widget(viewer, qapp_events)
        qapp_events(lambda: widget.converged, timeout=60)
        assert widget.converged, f"the widget did not converge: {widget.status.text()}"
        width, height = widget.size
        camera = widget.camera
        # The camera looks along napari's view direction at its centre.
        cam = scene_camera(viewer)
        forward = np.subtract(camera.target, camera.eye)
        assert np.allclose(forward / np.linalg.norm(forward), np.array(cam.view_direction[::-1]), atol=1e-9)
        assert np.allclose(camera.target, cam.center[::-1])
        expected = vs.open(ball_store, size=(width, height), budget_mb=128).render(camera, widget.tf)
        # napari's axes are right-handed in its (z, y, x) order: the widget shows voxstream's image mirrored.
        assert widget.mirrored
        assert np.array_equal(widget.last_image, expected[:, ::-1])
        assert expected[..., :3].std() > 1, "an empty picture proves nothing"
        # A new camera starts new frames, which converge to the new view.
        first = widget.last_image
        scene_camera(viewer).angles = (0.0, 45.0, 30.0)
        qapp_events(lambda: widget.converged and widget.camera != camera, timeout=60)
        assert widget.converged and not np.array_equal(widget.last_image, first)
    finally:
        viewer.close()


def test_the_widget_shows_what_napari_itself_draws(tmp_path, qapp_events):
    """An asymmetric volume (blobs along +x, +y, +z, bright to dim): each blob sits where napari's own 3D rendering
    (maximum intensity, its coarser level) draws it, so the view is neither mirrored nor shifted nor scaled."""
    n = 64
    array = np.zeros((n, n, n), np.uint8)
    array[28:36, 28:36, 50:60] = 250
    array[28:36, 50:60, 28:36] = 160
    array[50:60, 28:36, 28:36] = 90
    vs.import_volume(array, tmp_path / "blobs.zarr")
    viewer = napari.Viewer(show=True)
    try:
        layer = viewer.open(str(tmp_path / "blobs.zarr"), plugin="voxstream")[0]
        layer.colormap = "gray"
        layer.contrast_limits = (0, 255)
        viewer.dims.ndisplay = 3
        scene_camera(viewer).angles = (20.0, -40.0, 70.0)
        widget = docked_widget(viewer, qapp_events)
        qapp_events(lambda: widget.converged, timeout=60)
        assert widget.converged, widget.status.text()
        layer.rendering = "mip"
        qapp_events(lambda: False, timeout=1)
        shot = viewer.screenshot(canvas_only=True)[..., :3].astype(float).mean(axis=2)
        ours = widget.last_image[..., :3].astype(float).mean(axis=2)
        assert shot.shape[0] / shot.shape[1] == pytest.approx(ours.shape[0] / ours.shape[1], rel=0.02)
        for image in (shot, ours):
            assert image.max() > 20, "a blank picture"
        # Blobs by brightness rank: the brightest pixels of each picture, then the next band.
        for band in ((0.75, 1.01), (0.45, 0.7)):
            centres = []
            for image in (shot, ours):
                lo, hi = (f * image.max() for f in band)
                ys, xs = np.nonzero((image >= lo) & (image < hi))
                centres.append((xs.mean() / image.shape[1], ys.mean() / image.shape[0]))
            assert np.allclose(centres[0], centres[1], atol=0.05), (band, centres)
    finally:
        viewer.close()


def test_camera_conversion_keeps_napari_s_scale_at_the_centre():
    camera = voxstream_camera((10, 20, 30), (1, 0, 0), (0, -1, 0), zoom=2.0, perspective=0, canvas_height=400)
    assert camera.target == (30.0, 20.0, 10.0)
    # 400 px at 2 px per unit: 200 units of height at the target, seen at 30 degrees.
    assert np.isclose(camera.distance, 100 / np.tan(np.radians(15)))
    assert np.allclose(np.subtract(camera.target, camera.eye) / camera.distance, (0, 0, 1))
    assert camera.up == (0.0, -1.0, 0.0)


def docked_widget(viewer, qapp_events):
    """voxstream's widget docked in a 1400x900 window (its canvas sized first), budget 128 MiB."""
    from voxstream._napari.widget import VoxstreamWidget

    viewer.window._qt_window.resize(1400, 900)
    qapp_events(lambda: False, timeout=0.3)
    widget = VoxstreamWidget(viewer, budget_mb=128)
    viewer.window.add_dock_widget(widget)
    return widget


@pytest.fixture
def qapp_events():
    """Runs Qt's event loop until `done()` or `timeout` seconds (what napari does between user inputs)."""
    from qtpy.QtWidgets import QApplication

    def run(done, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end and not done():
            QApplication.processEvents()
            time.sleep(0.01)

    return run
