"""Writes a NIfTI volume as a CT series the way scanners and PACS exports do, with pydicom (independent of voxstream):
one file per axial slice, under names in no order the slices have, split over two subfolders, 12 bits stored in 16
with Rescale Intercept -1024 (stored = value + 1024), every tenth slice RLE-compressed. The test that imports it
(crates/voxstream/tests/dicom_import.rs) compares the store with the NIfTI's own import.

    python scripts/nifti_to_dicom.py IN.nii.gz OUT_FOLDER

`write_series` writes any array so (the Python package's tests use it).
"""
import random
import sys
from pathlib import Path

import numpy as np
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, RLELossless, generate_uid


def write_series(data, spacing, origin, out: Path, description="MNI152 as CT", ras=False):
    """Writes `data` (indexed x, y, z; values within -1024..3071) with `spacing` and `origin` (x, y, z, mm) as an
    axial CT series into `out`: its axes as DICOM's patient axes (LPS), or with `ras`, `data` and `origin` being in
    NIfTI's RAS (x to the right, y to the front), written in LPS as a scanner would (rows along -x, columns along -y,
    positions with x and y negated)."""
    if data.min() < -1024 or data.max() > 4095 - 1024:
        sys.exit(f"values {data.min()}..{data.max()} do not fit 12 bits with intercept -1024")
    dx, dy, dz = (float(v) for v in spacing)
    series, study = generate_uid(), generate_uid()
    rng = random.Random(7)
    names = [f"{rng.getrandbits(40):010x}" for _ in range(data.shape[2])]
    for k, name in enumerate(names):
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds = Dataset()
        ds.file_meta = meta
        ds.SOPClassUID = CTImageStorage
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.StudyInstanceUID, ds.SeriesInstanceUID = study, series
        ds.Modality = "CT"
        ds.SeriesDescription = description
        ds.InstanceNumber = rng.randrange(1, 10_000)
        flip = -1.0 if ras else 1.0
        ds.ImagePositionPatient = [flip * float(origin[0]), flip * float(origin[1]), float(origin[2]) + k * dz]
        ds.ImageOrientationPatient = [flip, 0, 0, 0, flip, 0]
        ds.PixelSpacing = [dy, dx]
        ds.SliceThickness = dz
        ds.Rows, ds.Columns = data.shape[1], data.shape[0]
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 12, 11, 0
        ds.RescaleIntercept, ds.RescaleSlope = -1024, 1
        pixels = (data[:, :, k].T.astype(np.int32) + 1024).astype(np.uint16)
        ds.PixelData = pixels.tobytes()
        if k % 10 == 3:
            ds.compress(RLELossless, pixels)
        folder = out / ("a" if k % 2 else "b")
        folder.mkdir(parents=True, exist_ok=True)
        ds.save_as(folder / name, enforce_file_format=True)


def main(nifti: Path, out: Path):
    import nibabel

    image = nibabel.load(nifti)
    header = image.header
    origin = [float(header["qoffset_x"]), float(header["qoffset_y"]), float(header["qoffset_z"])]
    # The template is in RAS (its qform); the series says so in DICOM's terms.
    write_series(np.asarray(image.dataobj), header.get_zooms()[:3], origin, out, ras=True)


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
