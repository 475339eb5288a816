"""Rendering from Python: the CLI's images byte for byte, Rust-owned arrays, the GIL released, Ctrl-C."""

import json
import os
import signal
import threading
import time

import numpy as np
import pytest
from PIL import Image

import voxstream as vs
from conftest import run_cli


def cli_png(cli, tmp_path, *args):
    out = tmp_path / "cli.png"
    result = run_cli(cli, "render", *args, "--quiet", "--out", str(out))
    assert result.returncode == 0, result.stderr
    return np.asarray(Image.open(out).convert("RGB"))


def test_a_scene_renders_as_the_cli_does(cli, tmp_path):
    expected = cli_png(cli, tmp_path, "sponge", "--width", "160", "--height", "120")
    volume = vs.open("sponge", size=(160, 120))
    image = volume.render()
    assert image.shape == (120, 160, 4) and image.dtype == np.uint8
    assert np.array_equal(image[..., :3], expected)
    assert volume.last_stats["converged"] is True
    # Not an empty picture: the comparison means something.
    assert image[..., :3].std() > 10


def test_the_step_options_render_as_the_clis(cli, tmp_path):
    # The default is the adaptive step (as the CLI's); faithful=True is --faithful, adaptive_step=T is
    # --adaptive-step T, and they differ from one another on the translucent shell.
    volume = vs.open("shell", size=(96, 96))
    images = {}
    for name, kwargs, flags in [("default", {}, []), ("faithful", {"faithful": True}, ["--faithful"]),
                                ("loose", {"adaptive_step": 0.5}, ["--adaptive-step", "0.5"])]:
        expected = cli_png(cli, tmp_path, "shell", "--width", "96", "--height", "96", *flags)
        images[name] = volume.render(**kwargs)[..., :3]
        assert np.array_equal(images[name], expected), name
    assert not np.array_equal(images["default"], images["faithful"])
    assert not np.array_equal(images["default"], images["loose"])
    with pytest.raises(ValueError, match="give one of the two"):
        volume.render(faithful=True, adaptive_step=0.1)


def test_a_store_with_camera_tf_and_isosurfaces_renders_as_the_cli_does(cli, tmp_path, ball_store):
    camera = {"eye": [150.0, -90.0, 80.0], "target": [28.0, 24.0, 30.0], "up": [0.0, 0.0, 1.0], "fov": 35.0}
    (tmp_path / "camera.json").write_text(json.dumps(camera))
    points = [[0, 0, 0, 0, 0], [100, 0.2, 0.4, 0.9, 0.0], [255, 1.0, 0.9, 0.6, 0.3]]
    (tmp_path / "tf.json").write_text(json.dumps({"points": points}))
    volume = vs.open(ball_store)
    # The volume, a given transfer function, a camera file's view.
    expected = cli_png(cli, tmp_path, str(ball_store), "--width", "128", "--height", "128", "--camera",
                       str(tmp_path / "camera.json"), "--tf", str(tmp_path / "tf.json"))
    image = volume.render(camera, vs.TransferFunction.from_points(points), size=(128, 128))
    assert np.array_equal(image[..., :3], expected)
    # The same with the file's path as the transfer function.
    assert np.array_equal(volume.render(camera, str(tmp_path / "tf.json"), size=(128, 128)), image)
    # Two isosurfaces with colours, the default camera, a budget of its own.
    expected = cli_png(cli, tmp_path, str(ball_store), "--width", "96", "--height", "80", "--iso", "100,200",
                       "--iso-color", "1,0,0;0,0.5,1", "--iso-opacity", "0.5,1", "--budget-mb", "64")
    image = volume.render(iso=[100, 200], iso_colors=[(1, 0, 0), (0, 0.5, 1)], iso_opacities=[0.5, 1],
                          size=(96, 80), budget_mb=64)
    assert np.array_equal(image[..., :3], expected)
    assert (image[..., :3].reshape(-1, 3) != 0).any(axis=1).mean() > 0.05


def test_viewing_tools_render_as_the_clis(cli, tmp_path, ball_store):
    """Presets, turns, projections, crops and clipping planes: the same pixels as the CLI's flags."""
    volume = vs.open(ball_store)
    for kwargs, flags in [
        (dict(view="-z", azimuth=30.0, elevation=20.0, zoom=1.5),
         ["--view", "-z", "--azimuth", "30", "--elevation", "20", "--zoom", "1.5"]),
        (dict(view="+x", projection="max"), ["--view", "+x", "--projection", "max"]),
        (dict(view="iso", projection="min", region=((0, 0, 0), (30, 48, 40))),
         ["--view", "iso", "--projection", "min", "--crop", "0,0,0,30,48,40"]),
        (dict(clip_planes=[((28.0, 24.0, 30.0), (0.0, -1.0, 1.0))], projection="mean"),
         ["--clip-plane", "28,24,30,0,-1,1", "--projection", "mean"]),
        (dict(slice="z=20"), ["--slice", "z=20"]),
        (dict(color_bar=True, scale_bar=True), ["--color-bar", "--scale-bar"]),
    ]:
        expected = cli_png(cli, tmp_path, str(ball_store), "--width", "96", "--height", "80", *flags)
        image = volume.render(size=(96, 80), **kwargs)
        assert np.array_equal(image[..., :3], expected), flags
        if kwargs.get("projection") in (None, "max") and "slice" not in kwargs:
            # Not empty pictures: the comparison means something (a minimum or a mean may well be dark).
            assert image[..., :3].std() > 5, flags
    with pytest.raises(ValueError, match="projection 'loudest'"):
        volume.render(projection="loudest")
    with pytest.raises(ValueError, match="-z, iso"):
        volume.render(view="top")


def test_float32_pixels_are_the_linear_colours(ball_store):
    volume = vs.open(ball_store, size=(64, 64))
    bytes_ = volume.render()
    floats = volume.render(dtype=np.float32)
    assert floats.dtype == np.float32 and floats.shape == (64, 64, 4)
    assert np.array_equal((np.clip(floats, 0, 1) * 255 + 0.5).astype(np.uint8), bytes_)


def test_the_array_owns_rusts_buffer_without_a_copy():
    image = vs.open("shell", size=(64, 48)).render()
    assert not image.flags.owndata
    base = image
    while isinstance(base, np.ndarray):
        base = base.base
    # numpy's own copies end in an ndarray that owns its data; Rust's buffer ends in the numpy crate's container.
    assert base is not None and "SliceContainer" in type(base).__name__
    assert image.flags.c_contiguous and image.shape == (48, 64, 4)


def test_a_python_thread_runs_while_rust_renders():
    volume = vs.open("hypertexture", size=(384, 384))
    ticks = []
    running = threading.Event()
    running.set()

    def tick():
        while running.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    thread = threading.Thread(target=tick)
    thread.start()
    start = time.perf_counter()
    volume.render(budget_mb=512)
    end = time.perf_counter()
    running.clear()
    thread.join()
    during = [t for t in ticks if start < t < end]
    # With the GIL held the ticker would stop for the whole render; released, it ticks about once a millisecond.
    assert end - start > 0.05, "the render was too short to tell"
    assert len(during) > 0.2 * (end - start) * 1000, (len(during), end - start)


def test_ctrl_c_interrupts_a_long_render_at_once_and_the_volume_stays_usable():
    volume = vs.open("hypertexture", size=(1024, 1024))
    sent = []

    def interrupt():
        time.sleep(0.4)
        sent.append(time.perf_counter())
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=interrupt).start()
    start = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        volume.render(budget_mb=1024, lod_bias=1.0)
    raised = time.perf_counter()
    assert sent, "the render ended before the interrupt was sent: make it longer"
    assert raised - sent[0] < 0.5, f"KeyboardInterrupt came {raised - sent[0]:.3f} s after Ctrl-C"
    assert raised - start < 5
    small = vs.open("hypertexture", size=(32, 32)).render()
    assert small.shape == (32, 32, 4)
    again = volume.render(size=(64, 64))
    assert again.shape == (64, 64, 4) and volume.last_stats["converged"]


def test_interactive_frames_refine_towards_the_converged_image(ball_store):
    volume = vs.open(ball_store, size=(96, 96))
    converged = volume.render(size=(96, 96))
    session = vs.Session(vs.open(ball_store, size=(96, 96)), blending=False)
    for _ in range(200):
        image, stats = session.frame()
        if stats["converged"]:
            break
    assert stats["converged"], "200 interactive frames did not load the view"
    assert np.array_equal(image, converged)
    assert np.array_equal(session.converge(), converged)


def test_cameras_orbit_and_zoom_about_their_target():
    camera = vs.Camera.look_at((10, 0, 0), (0, 0, 0))
    turned = camera.orbit(azimuth=90)
    assert np.allclose(turned.eye, (0, 10, 0), atol=1e-9)
    raised = camera.orbit(elevation=30)
    assert np.isclose(raised.distance, 10) and raised.eye[2] > 4.9
    assert np.isclose(camera.zoom(2).distance, 5)
    with pytest.raises(ValueError):
        vs.Camera.look_at((1, 2), (0, 0, 0))


def test_transfer_functions_from_colour_maps_and_points():
    ramp = vs.TransferFunction.from_colormap(lambda f: (f, 0.0, 1.0 - f, 1.0), (0, 200), opacity=(0, 0.2),
                                             samples=5)
    assert ramp.points[0] == (0.0, 0.0, 0.0, 1.0, 0.0)
    assert ramp.points[-1] == (200.0, 1.0, 0.0, 0.0, 0.2)
    with pytest.raises(ValueError, match="value, r, g, b, opacity"):
        vs.TransferFunction.from_points([(0, 1, 1, 1)])


def test_jupyter_shows_the_default_view_as_png(ball_store):
    data = vs.open(ball_store, size=(512, 256))._repr_png_()
    assert data.startswith(b"\x89PNG\r\n\x1a\n")
    import io

    shown = Image.open(io.BytesIO(data))
    assert shown.size == (256, 128)


def test_the_gpu_backend_renders_as_the_clis_gpu_backend(cli, tmp_path, ball_store):
    """`backend="gpu"` (wgpu; Mesa's lavapipe where there is no GPU) gives the CLI's `--backend gpu` image."""
    expected = cli_png(cli, tmp_path, str(ball_store), "--width", "96", "--height", "72", "--backend", "gpu",
                       "--iso", "100")
    volume = vs.open(ball_store)
    image = volume.render(size=(96, 72), backend="gpu", iso=[100])
    assert np.array_equal(image[..., :3], expected)
    assert volume.last_stats["renderer"].startswith("gpu")
    assert (image[..., :3].reshape(-1, 3) != 0).any(axis=1).mean() > 0.03
