#!/usr/bin/env bash
# Builds the Python package (crates/voxstream-python) as a wheel with maturin, installs it into the project's
# virtual environment (.venv, created here; never your Python) and runs its tests with pytest. The tests compare
# with the `voxstream` binary: build it first (`cargo build --release`), or set VOXSTREAM_BIN.
#
# crates/voxstream/tests/python_package.rs runs this script, so `cargo test --release --workspace` (the README's
# test command) runs the Python tests too. Run by hand: bash scripts/python-tests.sh [pytest arguments]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

venv="${VOXSTREAM_VENV:-.venv}"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv" || { echo "cannot create $venv: install python3-venv (sudo apt-get install python3-venv)" >&2; exit 1; }
fi
# Pinned: the build tool and what the tests use.
"$venv/bin/pip" install --quiet --disable-pip-version-check \
    maturin==1.16.0 numpy==2.4.6 pytest==9.2.0 pillow==13.0.0 "napari[pyqt5]==0.9.2" nbclient==0.11.0 nbformat==5.11.1 ipykernel==7.4.0 \
    dask==2026.8.0 distributed==2026.8.0 imageio-ffmpeg==0.8.1 pydicom==3.0.1
# The wheel, built against this checkout in release mode (sharing target/ with cargo), then installed.
rm -rf target/wheels
"$venv/bin/maturin" build --release --quiet -m crates/voxstream-python/Cargo.toml --out target/wheels
"$venv/bin/pip" install --quiet --disable-pip-version-check --force-reinstall --no-deps target/wheels/voxstream-*.whl
# From outside the source folder, so that the installed package is what is tested. napari's tests need a display:
# without one, a virtual X server (xvfb-run, Debian's xvfb) with Mesa's software OpenGL.
cd crates/voxstream-python/tests
pytest=("../../../$venv/bin/python" -m pytest -q -p no:cacheprovider "$@")
if [ -z "${DISPLAY:-}" ]; then
    command -v xvfb-run >/dev/null || { echo "no display and no xvfb-run: sudo apt-get install xvfb xauth" >&2; exit 1; }
    exec xvfb-run -a -s "-screen 0 1280x1024x24" "${pytest[@]}"
fi
exec "${pytest[@]}"
