"""Depth-camera fusion from Python (issue 49): a synthetic sequence of the CGAL bunny fused into a store that opens
and renders, with its surface points, progress and stopping, and bad arguments as the CLI refuses them (the
surface's distance to the true scene is checked by crates/voxstream/tests/fuse.rs)."""

import pathlib
import struct

import numpy as np
import pytest

import voxstream as vs

REPO = pathlib.Path(__file__).resolve().parents[3]
BUNNY = REPO / "data" / "real" / "bunny00.off"


@pytest.fixture(scope="module")
def sequence(tmp_path_factory) -> pathlib.Path:
    assert BUNNY.is_file(), f"{BUNNY} is missing: run scripts/fetch-real-data.sh"
    out = tmp_path_factory.mktemp("rgbd") / "bunny"
    assert vs.synthesize_rgbd(BUNNY, out, frames=24, sweep=60.0) == 24
    return out


def read_points(path: pathlib.Path) -> np.ndarray:
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    count = int(next(line for line in data[:end].decode().splitlines() if line.startswith("element vertex")).split()[2])
    record = struct.Struct("<6f3B")
    return np.array([record.unpack_from(data, end + i * record.size)[:3] for i in range(count)])


def test_a_fused_sequence_reports_its_work_and_opens_as_a_store(sequence, tmp_path):
    calls = []
    report = vs.fuse(sequence, tmp_path / "bunny.vxs", points=tmp_path / "surface.ply",
                     progress=lambda done, total: calls.append((done, total)))
    assert report["frames"] == 24 and report["frames_lost"] == 0 and report["windows"] >= 2
    assert calls[-1] == (24, 24) and len(calls) == 24
    assert 0 < report["peak_brick_bytes"] < 4 << 20
    points = read_points(tmp_path / "surface.ply")
    assert len(points) == report["surface_points"] > 2000
    image = vs.open(tmp_path / "bunny.vxs").render(iso=[128], size=(96, 96))
    assert (image[..., 3] > 0).mean() > 0.05, "the fused surface is drawn"


def test_sign_only_keeps_the_thesis_two_bits_in_less_memory(sequence, tmp_path):
    with_offsets = vs.fuse(sequence, points=tmp_path / "offsets.ply")
    sign_only = vs.fuse(sequence, points=tmp_path / "sign.ply", sign_only=True)
    assert sign_only["frames"] == with_offsets["frames"] == 24
    assert 0 < sign_only["peak_brick_bytes"] < with_offsets["peak_brick_bytes"]
    assert len(read_points(tmp_path / "sign.ply")) == sign_only["surface_points"] > 2000


def test_an_exception_in_progress_stops_the_fusion_and_saves_nothing(sequence, tmp_path):
    def stop(done, total):
        if done == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        vs.fuse(sequence, tmp_path / "stopped.vxs", progress=stop)
    assert not (tmp_path / "stopped.vxs").exists()


def test_bad_arguments_are_value_errors_naming_them(sequence, tmp_path):
    with pytest.raises(ValueError, match="poses"):
        vs.fuse(sequence, tmp_path / "a.vxs", poses="gps")
    with pytest.raises(ValueError, match="window"):
        vs.fuse(sequence, tmp_path / "a.vxs", window=3)
    with pytest.raises(ValueError, match="nothing would be saved"):
        vs.fuse(sequence)
    with pytest.raises(FileNotFoundError):
        vs.fuse(tmp_path / "missing", tmp_path / "a.vxs")
    assert not (tmp_path / "a.vxs").exists()
