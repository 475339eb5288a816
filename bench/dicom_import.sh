#!/usr/bin/env bash
# DICOM series import against the readers people use (issue 42 item 6): a synthetic CT series of SLICES files of
# 512x512 (12 bits stored, intercept -1024, every tenth slice RLE-compressed, names in no order, two subfolders;
# written by scripts/nifti_to_dicom.py's writer with pydicom) read by
#   - voxstream import SERIES --out STORE (sorting, decoding, the whole pyramid and the store written),
#   - SimpleITK's ImageSeriesReader (GDCM's series sorting, then the volume as a numpy array; no store),
#   - pydicom: every file read, sorted by position, stacked into a numpy array (no store).
# Wall time and peak RSS (GNU time) of each, in one run so the ratios hold on a drifting machine.
#
#   bash bench/dicom_import.sh [SLICES]      (default 300; needs a release build and a venv, below)
#
# VOXSTREAM_BIN (default target/release/voxstream); DICOM_PYTHON: a Python with pydicom==3.0.1, numpy and
# SimpleITK==2.5.3 (python3 -m venv v && v/bin/pip install pydicom==3.0.1 numpy SimpleITK==2.5.3).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
slices="${1:-300}"
bin="${VOXSTREAM_BIN:-target/release/voxstream}"
python="${DICOM_PYTHON:?set DICOM_PYTHON to a Python with pydicom, numpy and SimpleITK}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

"$python" - "$work/series" "$slices" <<'EOF'
import sys
from pathlib import Path
import numpy as np
sys.path.insert(0, "scripts")
from nifti_to_dicom import write_series

out, n = Path(sys.argv[1]), int(sys.argv[2])
z, y, x = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, 512), np.linspace(-1, 1, 512), indexing="ij")
body = (x / 0.8) ** 2 + (y / 0.6) ** 2 < 1
bone = body & ((x / 0.5) ** 2 + (y / 0.35) ** 2 > 0.8) & ((x / 0.5) ** 2 + (y / 0.35) ** 2 < 1)
rng = np.random.default_rng(1)
ct = np.where(body, 40, -1000) + np.where(bone, 900 + 300 * z, 0) + rng.normal(0, 12, body.shape)
write_series(np.clip(ct, -1024, 3071).astype(np.int16).transpose(2, 1, 0), (0.7, 0.7, 1.0), (0, 0, 0), out,
             description="synthetic CT")
EOF
echo "series: $slices files of 512x512, $(du -sh "$work/series" | cut -f1)"

measure() { # name command...
    local name=$1
    shift
    sync
    /usr/bin/time -f "%e %M" -o "$work/time" "$@" >/dev/null 2>"$work/err" || { cat "$work/err" >&2; exit 1; }
    read -r wall rss <"$work/time"
    printf '%-34s %7.2f s  %6d MiB\n' "$name" "$wall" $((rss / 1024))
}

measure "voxstream import (store written)" "$bin" import "$work/series" --out "$work/ct.zarr" --quiet --overwrite
measure "SimpleITK ImageSeriesReader" "$python" -c '
import sys, SimpleITK as sitk
reader = sitk.ImageSeriesReader()
reader.SetFileNames(reader.GetGDCMSeriesFileNames(sys.argv[1], recursive=True))
print(sitk.GetArrayFromImage(reader.Execute()).shape)' "$work/series"
measure "pydicom: read, sort, stack" "$python" -c '
import sys, pathlib, numpy as np, pydicom
files = [pydicom.dcmread(p) for p in pathlib.Path(sys.argv[1]).rglob("*") if p.is_file()]
files.sort(key=lambda d: float(d.ImagePositionPatient[2]))
print(np.stack([d.pixel_array * float(d.RescaleSlope) + float(d.RescaleIntercept) for d in files]).shape)' "$work/series"
