"""Imports and camera paths on a Dask LocalCluster of two worker processes (issue 50): the distributed import writes
the single-process store byte for byte with both workers taking part; a path's frames are the frames one process
renders, written in order, and a video of them."""

import filecmp
import os
import pathlib

import dask.array as da
import numpy as np
import pytest
from distributed import Client, LocalCluster

import voxstream as vs
import voxstream._distributed as distributed_module


@pytest.fixture(scope="module")
def client():
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


def volume(shape=(45, 70, 83), dtype=np.uint16) -> np.ndarray:
    """Smooth structure, noise and an empty corner, so bricks are empty, uniform and varied; odd sizes."""
    rng = np.random.default_rng(7)
    z, y, x = np.meshgrid(*(np.arange(n) for n in shape), indexing="ij")
    values = 800 + 600 * np.sin(x / 9.0) * np.cos(y / 7.0) + 300 * np.sin(z / 5.0) + rng.normal(0, 40, shape)
    values[(x + y) < 20] = 0
    return values.astype(dtype)


def tree(root: pathlib.Path):
    return sorted(p.relative_to(root) for p in root.rglob("*") if p.is_file())


def assert_same_store(a: pathlib.Path, b: pathlib.Path):
    files = tree(a)
    assert files == tree(b)
    assert len(files) > 20
    _, mismatch, errors = filecmp.cmpfiles(a, b, [str(f) for f in files], shallow=False)
    assert mismatch == [] and errors == [], (mismatch, errors)


def shards_written(client) -> dict:
    return client.run(lambda: __import__("voxstream._distributed")._distributed._SHARDS_WRITTEN)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int16, np.float32])
def test_a_dask_array_imported_on_two_workers_is_the_single_process_store_byte_for_byte(client, tmp_path, dtype,
                                                                                         monkeypatch):
    samples = volume(dtype=dtype)
    if dtype in (np.int16, np.float32):
        # Tasks of one row of shards each (bands of one), so that bands gather halves from several tasks.
        monkeypatch.setattr(distributed_module, "_TASK_BYTES", 1)
    # Chunks that do not line up with the shards (8 × 64 × 64 samples with 8-sample bricks).
    array = da.from_array(samples, chunks=(20, 33, 40))
    (tmp_path / "one").mkdir()
    (tmp_path / "many").mkdir()
    single = vs.import_volume(samples, tmp_path / "one" / "store", brick_size=8, spacing=(1, 1, 2))
    before = shards_written(client)
    seen = []
    many = vs.import_volume(array, tmp_path / "many" / "store", brick_size=8, spacing=(1, 1, 2),
                            progress=lambda done, total: seen.append((done, total)))
    after = shards_written(client)
    assert {k: v for k, v in many.items() if k != "out"} == {k: v for k, v in single.items() if k != "out"}
    assert_same_store(tmp_path / "one" / "store", tmp_path / "many" / "store")
    assert len(after) == 2 and all(after[w] > before.get(w, 0) for w in after), (before, after)
    assert seen[-1][0] == seen[-1][1] and len(seen) == seen[-1][1] >= 10
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)


def test_non_finite_samples_are_replaced_or_refused_leaving_the_store_in_place(client, tmp_path):
    samples = volume(dtype=np.float32)
    samples[30, 41, 17] = np.nan
    array = da.from_array(samples, chunks=(16, 70, 83))
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    vs.import_volume(samples, tmp_path / "a" / "s", brick_size=8, nan_as=-5.0)
    vs.import_volume(array, tmp_path / "b" / "s", brick_size=8, nan_as=-5.0)
    assert_same_store(tmp_path / "a" / "s", tmp_path / "b" / "s")

    with pytest.raises(ValueError, match=r"\(17, 41, 30\)"):
        vs.import_volume(array, tmp_path / "b" / "s", brick_size=8, overwrite=True)
    assert_same_store(tmp_path / "a" / "s", tmp_path / "b" / "s")
    assert not (tmp_path / "b" / "s.partial").exists()
    with pytest.raises(ValueError, match="already exists"):
        vs.import_volume(array, tmp_path / "b" / "s", brick_size=8, nan_as=-5.0)
    with pytest.raises(ValueError, match="convert to uint8"):
        vs.import_volume(array.astype(np.float64), tmp_path / "c", brick_size=8)


def test_an_object_store_url_is_refused_for_a_distributed_import(tmp_path, monkeypatch):
    # Workers write shard files into the store's folder: "s3://…" would be a local folder named "s3:".
    monkeypatch.chdir(tmp_path)
    array = da.from_array(volume(dtype=np.uint8), chunks=(16, 70, 83))
    with pytest.raises(ValueError, match="folder every worker sees"):
        vs.import_volume(array, "s3://scans/volume.zarr", brick_size=8)
    assert list(tmp_path.iterdir()) == []


def test_a_camera_path_rendered_on_two_workers_gives_one_process_frames_in_order_and_a_video(client, tmp_path):
    store = tmp_path / "store"
    vs.import_volume(volume(dtype=np.uint8), store, brick_size=8)
    cameras = vs.orbit(store, 6, degrees=90, elevation=20, size=(96, 64))
    assert len(cameras) == 6 and cameras[0].eye != cameras[1].eye
    result = vs.render_frames(store, cameras, tmp_path / "frames", size=(96, 64), budget_mb=64,
                              video=str(tmp_path / "path.mp4"), fps=6, step=1.0)
    frames = [pathlib.Path(p) for p in result["frames"]]
    assert [p.name for p in frames] == [f"frame_{i:05d}.png" for i in range(6)]
    reference = vs.open(store, size=(96, 64), budget_mb=64)
    from voxstream._volume import png_bytes
    for camera, frame in zip(cameras, frames):
        assert frame.read_bytes() == png_bytes(reference.render(camera, step=1.0))
    import imageio_ffmpeg
    count, _ = imageio_ffmpeg.count_frames_and_secs(result["video"])
    assert count == 6
    # Both workers opened the store (each with its own budget) and rendered.
    opened = client.run(lambda: len(__import__("voxstream._distributed")._distributed._OPENED))
    assert sorted(opened.values()) == [1, 1], opened


def test_a_path_needs_cameras_and_a_video_names_its_encoder(tmp_path):
    with pytest.raises(ValueError, match="at least one"):
        vs.render_frames("sponge", [], tmp_path)
    with pytest.raises(ValueError, match="at least one frame"):
        vs.orbit("sponge", 0)
    assert distributed_module.is_dask_array(da.zeros((2, 2, 2))) and not distributed_module.is_dask_array(np.zeros(3))


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(1.0 / mse)


def test_one_frame_split_over_two_workers_composites_to_the_render_of_the_whole(client, tmp_path):
    store = tmp_path / "store"
    vs.import_volume(volume(dtype=np.uint8), store, brick_size=8)
    size = (128, 96)
    whole = vs.open(store, size=size, budget_mb=64)
    camera = whole.camera.orbit(25, 15)
    for faithful in (True, False):
        reference = whole.render(camera, faithful=faithful, dtype=np.float32)
        assert reference[:, :, 3].max() > 0.5, "the view shows the volume"
        for pieces in (2, 4, 8):
            split = vs.render_sort_last(store, camera, pieces=pieces, size=size, budget_mb=64, faithful=faithful,
                                        dtype=np.float32)
            quality = psnr(split[:, :, :3], reference[:, :, :3])
            print(f"faithful={faithful} pieces={pieces}: PSNR {quality:.1f} dB, "
                  f"max difference {np.abs(split - reference).max():.2e}")
            assert quality > 55, (faithful, pieces, quality)
    # The pieces in the wrong order composite to another image: the order is what makes it right.
    info = whole.info
    tree = distributed_module.kd_pieces(info, 2)
    assert tree[0] == 0 and tree[1] == (8 << (info["levels"] - 1)) // 2
    with pytest.raises(ValueError, match="holds none of"):
        whole.render(camera, region=((500, 0, 0), (600, 10, 10)))
    with pytest.raises(ValueError, match="power of two"):
        vs.render_sort_last(store, camera, pieces=3, size=size)
    with pytest.raises(ValueError, match="sets region itself"):
        vs.render_sort_last(store, camera, pieces=2, size=size, region=((0, 0, 0), (8, 8, 8)))
    with pytest.raises(ValueError, match="splits a store"):
        vs.render_sort_last("sponge", None, pieces=2, size=size)


def test_a_scheduler_and_workers_started_apart_import_over_tcp(tmp_path):
    """What a cluster of several machines runs: `dask scheduler` and `dask worker` as their own processes, the client
    connecting by the scheduler's tcp:// address (here all on this machine, as the test must start them itself)."""
    import subprocess
    import sys
    import time

    bin_dir = pathlib.Path(sys.executable).parent
    scheduler_file = tmp_path / "scheduler.json"
    started = [subprocess.Popen([str(bin_dir / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                                 "--no-dashboard", "--scheduler-file", str(scheduler_file)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not scheduler_file.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert scheduler_file.exists(), "the scheduler did not start within 60 s"
        for _ in range(2):
            started.append(subprocess.Popen([str(bin_dir / "dask"), "worker", "--scheduler-file", str(scheduler_file),
                                             "--nworkers", "1", "--nthreads", "1", "--no-dashboard"],
                                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        import json
        address = json.loads(scheduler_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        with Client(address) as remote:
            remote.wait_for_workers(2, timeout=60)
            samples = volume(dtype=np.uint16)
            (tmp_path / "one").mkdir()
            (tmp_path / "tcp").mkdir()
            vs.import_volume(samples, tmp_path / "one" / "store", brick_size=8)
            vs.import_volume(da.from_array(samples, chunks=(16, 70, 83)), tmp_path / "tcp" / "store", brick_size=8)
            assert_same_store(tmp_path / "one" / "store", tmp_path / "tcp" / "store")
            written = shards_written(remote)
            assert len(written) == 2 and sum(written.values()) > 0, written
    finally:
        for process in reversed(started):
            process.terminate()
        for process in reversed(started):
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
