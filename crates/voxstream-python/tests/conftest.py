"""Shared fixtures: the CLI binary to compare with, and a small store imported from a numpy array."""

import os
import pathlib
import subprocess

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def cli() -> pathlib.Path:
    """The `voxstream` binary (VOXSTREAM_BIN, else target/release/voxstream, built by `cargo build --release`)."""
    path = pathlib.Path(os.environ.get("VOXSTREAM_BIN", REPO / "target" / "release" / "voxstream"))
    assert path.is_file(), f"{path} is missing: run `cargo build --release` first (or set VOXSTREAM_BIN)"
    return path


def ball(n: int = 48) -> np.ndarray:
    """A radial ramp, bright at the centre: uint8, indexed [z, y, x], slightly anisotropic so axes matter."""
    z, y, x = np.meshgrid(np.arange(n - 8), np.arange(n), np.arange(n + 8), indexing="ij")
    c = [(n - 9) / 2, (n - 1) / 2, (n + 7) / 2]
    r = np.sqrt((z - c[0]) ** 2 + (y - c[1]) ** 2 + (x - c[2]) ** 2)
    return np.clip(255 - r * 10, 0, 255).astype(np.uint8)


@pytest.fixture(scope="session")
def ball_store(tmp_path_factory) -> pathlib.Path:
    """`ball()` imported into a voxstream store through Python."""
    import voxstream as vs

    out = tmp_path_factory.mktemp("stores") / "ball.vxs"
    vs.import_volume(ball(), out, spacing=(1.0, 1.0, 1.5))
    return out


def run_cli(cli: pathlib.Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(cli), *args], capture_output=True, text=True, timeout=300)
