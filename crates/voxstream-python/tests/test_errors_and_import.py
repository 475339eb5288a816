"""Bad arguments raise Python's exceptions with the CLI's one-line messages; imports from numpy and files."""

import numpy as np
import pytest

import voxstream as vs
from conftest import REPO, ball, run_cli


def cli_error(cli, *args):
    result = run_cli(cli, *args)
    assert result.returncode != 0
    line = result.stderr.strip().splitlines()[-1]
    assert line.startswith("error: "), result.stderr
    return line[len("error: "):]


def test_a_missing_store_is_file_not_found_with_the_clis_message(cli, tmp_path):
    missing = str(tmp_path / "nothing.zarr")
    message = cli_error(cli, "render", missing, "--quiet", "--out", str(tmp_path / "x.png"))
    with pytest.raises(OSError) as raised:
        vs.open(missing)
    assert str(raised.value) == message


def test_an_isovalue_outside_the_data_is_a_value_error_with_the_clis_message(cli, tmp_path, ball_store):
    message = cli_error(cli, "render", str(ball_store), "--iso", "300", "--quiet", "--out", str(tmp_path / "x.png"))
    with pytest.raises(ValueError) as raised:
        vs.open(ball_store).render(iso=[300])
    assert str(raised.value) == message


def test_bad_sizes_budgets_modes_and_backends_are_value_errors(ball_store):
    volume = vs.open(ball_store)
    with pytest.raises(ValueError, match="image size must be positive"):
        volume.render(size=(0, 10))
    with pytest.raises(ValueError, match="budget"):
        volume.render(budget_mb=0)
    with pytest.raises(ValueError, match="mode 'fast'"):
        volume.render(mode="fast")
    with pytest.raises(ValueError, match="backend 'tpu'"):
        volume.render(backend="tpu")
    with pytest.raises(ValueError, match="lies outside the data's values"):
        vs.open("sponge").render(iso=[2.0])
    with pytest.raises(ValueError, match="value-range applies to stores"):
        vs.open("sponge", value_range=(0, 1))


def test_info_describes_an_imported_array(ball_store):
    info = vs.open(ball_store).info
    assert info["kind"] == "store" and info["native"] and not info["remote"]
    assert tuple(info["dims"]) == (56, 48, 40)
    assert info["dtype"] == "u8"
    assert tuple(info["spacing"]) == (1.0, 1.0, 1.5)
    data = ball()
    assert tuple(info["value_range"]) == (float(data.min()), float(data.max()))
    assert info["levels"] >= 2
    assert vs.open("sponge").info["kind"] == "scene"
    assert "sponge" in vs.scenes()


def test_import_reports_progress_and_an_exception_in_it_removes_the_partial_store(tmp_path):
    calls = []
    out = tmp_path / "a.zarr"
    report = vs.import_volume(ball(32), out, progress=lambda done, total: calls.append((done, total)))
    assert tuple(report["dims"]) == (40, 32, 24)
    # Input bytes: 40 x 32 x 24 samples of one byte.
    assert calls[-1] == (30720, 30720) and all(a[0] <= b[0] for a, b in zip(calls, calls[1:]))
    # A second import over it is refused without overwrite, and allowed with it.
    with pytest.raises(Exception, match="overwrite"):
        vs.import_volume(ball(32), out)

    def stop(done, total):
        if done > 0:
            raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        vs.import_volume(ball(32), tmp_path / "b.zarr", progress=stop)
    assert not (tmp_path / "b.zarr").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.zarr"]


def test_a_mesh_file_is_baked_into_a_store_as_the_cli_does(cli, tmp_path):
    mesh = tmp_path / "tetra.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    report = vs.import_volume(mesh, tmp_path / "py.zarr", resolution=32)
    result = run_cli(cli, "import", str(mesh), "--resolution", "32", "--out", str(tmp_path / "cli.zarr"), "--quiet")
    assert result.returncode == 0, result.stderr
    assert tuple(report["dims"]) == tuple(vs.open(tmp_path / "cli.zarr").info["dims"])
    assert max(report["dims"]) <= 32 and "description" in report
    ours = vs.open(tmp_path / "py.zarr", size=(64, 64)).render()
    theirs = vs.open(tmp_path / "cli.zarr", size=(64, 64)).render()
    assert np.array_equal(ours, theirs) and ours[..., :3].any()
    with pytest.raises(ValueError, match="--resolution and --amplify apply to mesh and particle files"):
        vs.import_volume(tmp_path / "x.npy", tmp_path / "q.zarr", resolution=32)


def test_a_dicom_series_folder_imports_from_python_as_its_array(cli, tmp_path):
    """A CT series written by pydicom (scripts/nifti_to_dicom.py's writer: file names in no order, two subfolders, 12
    bits stored with intercept -1024, some slices RLE-compressed) imports from Python as `voxstream import FOLDER`
    does (issue 42 item 6): in the modality's units, as int16, rendering as the array itself."""
    import sys

    sys.path.insert(0, str(REPO / "scripts"))
    from nifti_to_dicom import write_series

    volume = ball(24).astype(np.int16) * 3 - 200  # [z, y, x], Hounsfield-like values
    write_series(volume.transpose(2, 1, 0), (0.5, 0.75, 1.5), (0.0, 0.0, 0.0), tmp_path / "series")
    report = vs.import_volume(tmp_path / "series", tmp_path / "ct.zarr")
    assert report["dtype"] == "i16" and tuple(report["dims"]) == (32, 24, 16), report
    info = vs.open(tmp_path / "ct.zarr").info
    assert tuple(info["spacing"]) == (0.5, 0.75, 1.5) and info["unit"] == "millimeter", info
    result = run_cli(cli, "import", str(tmp_path / "series"), "--out", str(tmp_path / "cli.zarr"), "--quiet")
    assert result.returncode == 0, result.stderr
    vs.import_volume(volume, tmp_path / "array.zarr", spacing=(0.5, 0.75, 1.5))
    images = [vs.open(tmp_path / name, size=(48, 48)).render() for name in ("ct.zarr", "cli.zarr", "array.zarr")]
    assert np.array_equal(images[0], images[1]) and np.array_equal(images[0], images[2]) and images[0][..., :3].any()


def test_arrays_of_other_types_and_shapes_are_refused_with_the_fix(tmp_path):
    with pytest.raises(ValueError, match="astype"):
        vs.import_volume(np.zeros((4, 4, 4), dtype=np.int64), tmp_path / "x.zarr")
    with pytest.raises(ValueError, match="beyond float32's range"):
        vs.import_volume(np.full((4, 4, 4), 1e300), tmp_path / "y.zarr")
    assert not (tmp_path / "y.zarr").exists()
    with pytest.raises(ValueError, match="3-D array"):
        vs.import_volume(np.zeros((4, 4), dtype=np.uint8), tmp_path / "x.zarr")


def test_a_strided_array_imports_in_its_logical_order(tmp_path):
    volume = ball(32)
    flipped = volume[:, :, ::-1]
    vs.import_volume(np.ascontiguousarray(flipped), tmp_path / "c.zarr")
    vs.import_volume(flipped, tmp_path / "s.zarr")
    a = vs.open(tmp_path / "c.zarr", size=(64, 64)).render()
    b = vs.open(tmp_path / "s.zarr", size=(64, 64)).render()
    assert np.array_equal(a, b)


def test_int8_int32_uint32_and_float64_arrays_are_converted_and_said(tmp_path):
    """As `voxstream import` converts such .npy files (issue 42 item 6): int8 to int16 exactly, the others to float32,
    the rounding counted; the store holds what the float32 (or int16) array would."""
    base = ball(24)
    cases = [
        (base.astype(np.int8) - 60, "i16", "every int8 value is an int16: exact"),
        (base.astype(np.int32) * 1000, "f32", "exact"),
        (base.astype(np.uint32) + (1 << 25) + 1, "f32", "rounded to the nearest float32"),
        (base.astype(np.float64) / 3.0, "f32", "rounded to float32's 24-bit precision"),
    ]
    for i, (array, stored, note) in enumerate(cases):
        report = vs.import_volume(array, tmp_path / f"c{i}.zarr")
        assert report["dtype"] == stored and note in report["conversion"], report
        expected = array.astype(np.int16 if stored == "i16" else np.float32)
        vs.import_volume(expected, tmp_path / f"e{i}.zarr")
        a = vs.open(tmp_path / f"c{i}.zarr", size=(48, 48)).render()
        b = vs.open(tmp_path / f"e{i}.zarr", size=(48, 48)).render()
        assert np.array_equal(a, b), (i, array.dtype)
    assert "conversion" not in vs.import_volume(base, tmp_path / "plain.zarr")


def test_the_wavelet_codec_stores_within_its_bound_and_says_so(tmp_path):
    """`codec="wavelet"` as `voxstream import --codec wavelet` (issue 47): lossless renders as the zstd store does,
    a bound is kept and shown in `info`, and a bad choice is a ValueError naming it."""
    data = ball(40)
    vs.import_volume(data, tmp_path / "z.zarr")
    vs.import_volume(data, tmp_path / "w.zarr", codec="wavelet")
    vs.import_volume(data, tmp_path / "l.zarr", codec="wavelet", max_error=3)
    zstd, exact, lossy = (vs.open(tmp_path / n, size=(48, 48)) for n in ("z.zarr", "w.zarr", "l.zarr"))
    assert (zstd.info["codec"], zstd.info["max_error"]) == ("zstd", 0.0)
    assert (exact.info["codec"], exact.info["max_error"]) == ("wavelet", 0.0)
    assert (lossy.info["codec"], lossy.info["max_error"]) == ("wavelet", 3.0)
    assert np.array_equal(zstd.render(), exact.render())
    with pytest.raises(ValueError, match="unknown brick codec 'jpeg'"):
        vs.import_volume(data, tmp_path / "x.zarr", codec="jpeg")
    with pytest.raises(ValueError, match="zstd is lossless"):
        vs.import_volume(data, tmp_path / "x.zarr", max_error=1.0)
    assert not (tmp_path / "x.zarr").exists()


def test_an_arrays_anatomical_orientation_is_kept_and_turns_the_default_view(tmp_path):
    """``import_volume(..., orientation=)`` (issue 42 item 7): the store says it (``info["orientation"]``), the
    anatomical presets need it, and an array stored with x and y reversed and said to be LPS is seen as the RAS
    array is (the same head from the same side)."""
    volume = ball(32).astype(np.uint8)
    volume[20:26, 26:30, 14:18] = 255  # a "nose" towards +y (anterior in RAS), off-centre in x
    vs.import_volume(volume, tmp_path / "ras.zarr", orientation="RAS")
    vs.import_volume(np.ascontiguousarray(volume[:, ::-1, ::-1]), tmp_path / "lps.zarr", orientation="lps")
    vs.import_volume(volume, tmp_path / "plain.zarr")
    ras, lps, plain = (vs.open(tmp_path / f"{n}.zarr", size=(48, 48)) for n in ("ras", "lps", "plain"))
    assert (ras.info["orientation"], lps.info["orientation"], plain.info["orientation"]) == ("RAS", "LPS", None)
    a, b = ras.render().astype(int), lps.render().astype(int)
    assert np.abs(a - b).mean() < 0.05, np.abs(a - b).mean()
    assert np.abs(a - plain.render().astype(int)).mean() > 0.5, "without an orientation: the index axes' view"
    front = ras.render(view="anterior")
    assert np.abs(front.astype(int) - lps.render(view="anterior").astype(int)).max() <= 3
    with pytest.raises(ValueError, match="does not say its anatomical orientation"):
        plain.render(view="anterior")
    with pytest.raises(ValueError, match="names one body axis twice"):
        vs.import_volume(volume, tmp_path / "bad.zarr", orientation="RLS")
    assert not (tmp_path / "bad.zarr").exists()
