"""A particle splatter peer, as a ParaView user would run it (its "Gaussian Resampling" filter is
vtkGaussianSplatter): read the particles, splat them into a DIM³ grid, volume-render the grid with VTK's fixed-point
CPU ray caster at 512², off-screen. Prints one JSON line: read_s, splat_s, first_frame_s, total_s (from start to
the first image), peak_rss_bytes, particles.

  splat.py POINTS.ply|ATOMS.gro DIM OUT.png

PLY: binary little-endian float x, y, z vertices (what bench/peers/geometry.sh writes). GRO: positions in nm.
The splat radius is 2 grid cells (VTK's radius is a fraction of the grid's diagonal), splats summed into a density;
the camera is VTK's reset
camera turned 30° (the images are not compared with voxstream's: this measures time and memory).
"""
import json
import os
import resource
import sys
import time

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import numpy as np  # noqa: E402
import vtk  # noqa: E402
from vtk.util import numpy_support  # noqa: E402


def read_points(path):
    if path.endswith(".gro"):
        lines = open(path).read().splitlines()
        count = int(lines[1])
        return np.array([[float(l[20:28]), float(l[28:36]), float(l[36:44])] for l in lines[2:2 + count]],
                        dtype=np.float32)
    with open(path, "rb") as f:
        header = b""
        while not header.endswith(b"end_header\n"):
            line = f.readline()
            if not line:
                raise SystemExit(f"{path}: no end_header")
            header += line
        count = next(int(l.split()[2]) for l in header.decode().splitlines() if l.startswith("element vertex"))
        return np.fromfile(f, dtype=np.float32, count=count * 3).reshape(count, 3)


def main():
    path, dim, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    start = time.perf_counter()
    points = read_points(path)
    vtk_points = vtk.vtkPoints()
    vtk_points.SetData(numpy_support.numpy_to_vtk(points, deep=True))
    cloud = vtk.vtkPolyData()
    cloud.SetPoints(vtk_points)
    read_s = time.perf_counter() - start

    t = time.perf_counter()
    splat = vtk.vtkGaussianSplatter()
    splat.SetInputData(cloud)
    splat.SetSampleDimensions(dim, dim, dim)
    splat.SetRadius(2.0 / (dim * 3 ** 0.5))
    splat.ScalarWarpingOff()
    splat.SetAccumulationModeToSum()  # a density (VTK's default keeps the maximum of overlapping splats)
    splat.Update()
    grid = splat.GetOutput()
    splat_s = time.perf_counter() - t
    # Densities of clustered particles are heavy-tailed: the transfer function follows the non-empty voxels'
    # percentiles (as a user would set it by eye), not the range.
    values = numpy_support.vtk_to_numpy(grid.GetPointData().GetScalars())
    filled = values[values > 0]
    p50, p90, p999 = (float(np.percentile(filled, q)) for q in (50, 90, 99.9)) if filled.size else (0.0, 1.0, 1.0)
    colour = vtk.vtkColorTransferFunction()
    colour.AddRGBPoint(p50, 0.2, 0.3, 0.8)
    colour.AddRGBPoint(p999, 1.0, 0.9, 0.6)
    opacity = vtk.vtkPiecewiseFunction()
    opacity.AddPoint(p50, 0.0)
    opacity.AddPoint(p90, 0.05)
    opacity.AddPoint(p999, 0.6)
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(colour)
    prop.SetScalarOpacity(opacity)
    prop.SetInterpolationTypeToLinear()
    mapper = vtk.vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputData(grid)
    mapper.AutoAdjustSampleDistancesOff()
    mapper.SetImageSampleDistance(1.0)
    volume = vtk.vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)
    renderer = vtk.vtkRenderer()
    renderer.AddVolume(volume)
    window = vtk.vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetSize(512, 512)
    window.AddRenderer(renderer)
    renderer.ResetCamera()
    renderer.GetActiveCamera().Azimuth(30)
    renderer.GetActiveCamera().Elevation(20)
    renderer.ResetCameraClippingRange()
    t = time.perf_counter()
    window.Render()
    first_frame_s = time.perf_counter() - t
    total_s = time.perf_counter() - start
    capture = vtk.vtkWindowToImageFilter()
    capture.SetInput(window)
    writer = vtk.vtkPNGWriter()
    writer.SetFileName(out)
    writer.SetInputConnection(capture.GetOutputPort())
    writer.Write()
    print(json.dumps({
        "particles": int(points.shape[0]), "grid": dim, "read_s": read_s, "splat_s": splat_s,
        "first_frame_s": first_frame_s, "total_s": total_s,
        "peak_rss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
    }))


if __name__ == "__main__":
    main()
