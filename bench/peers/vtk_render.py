"""Renders one scene with VTK, as ParaView or 3D Slicer would on a CPU, and reports times and peak memory.

  vtk_render.py fixed-point   VOLUME.json SCENE.json WIDTH HEIGHT RUNS OUT.png
  vtk_render.py marching-cubes VOLUME.json SCENE.json WIDTH HEIGHT RUNS OUT.png

fixed-point: vtkFixedPointVolumeRayCastMapper (the CPU ray caster behind ParaView's and Slicer's CPU volume
rendering), sample distance = 0.5 x the smallest spacing (voxstream's default step), no automatic sample-distance
adjustment, one ray per pixel, linear interpolation. marching-cubes: vtkFlyingEdges3D (VTK's fastest marching
cubes, ParaView's Contour filter) with gradient normals, rendered by OpenGL on Mesa llvmpipe off-screen, Phong
interpolation, the scene's Phong coefficients. Prints one JSON line: load_s, prepare_s (first render or contour
extraction), frame_s (list of timed renders after one warm-up), peak_rss_bytes, triangles.
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
from PIL import Image  # noqa: E402


def load_image(volume):
    dtype = {"u8": np.uint8, "f32": np.float32}[volume["dtype"]]
    nx, ny, nz = volume["dims"]
    data = np.fromfile(volume["path"], dtype=dtype)
    if data.size != nx * ny * nz:
        raise SystemExit(f"{volume['path']}: expected {nx * ny * nz} samples, found {data.size}")
    image = vtk.vtkImageData()
    image.SetDimensions(nx, ny, nz)
    image.SetSpacing(*volume["spacing"])
    image.SetOrigin(*volume["origin"])
    array = numpy_support.numpy_to_vtk(data, deep=False)
    array.SetName("scalars")
    image.GetPointData().SetScalars(array)
    return image, data


def volume_property(scene):
    colour = vtk.vtkColorTransferFunction()
    opacity = vtk.vtkPiecewiseFunction()
    for v, r, g, b, a in scene["tf"]["points"]:
        colour.AddRGBPoint(v, r, g, b)
        opacity.AddPoint(v, a)
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(colour)
    prop.SetScalarOpacity(opacity)
    prop.SetScalarOpacityUnitDistance(scene["tf"]["unit_distance"])
    prop.SetInterpolationTypeToLinear()
    phong = scene["phong"]
    if scene["shading"] == "phong":
        prop.ShadeOn()
        prop.SetAmbient(phong["ambient"])
        prop.SetDiffuse(phong["diffuse"])
        prop.SetSpecular(phong["specular"])
        prop.SetSpecularPower(phong["shininess"])
    else:
        prop.ShadeOff()
    return prop


def main():
    kind, volume_path, scene_path, width, height, runs, out = sys.argv[1:8]
    width, height, runs = int(width), int(height), int(runs)
    volume = json.load(open(volume_path))
    scene = json.load(open(scene_path))

    start = time.perf_counter()
    image, _data = load_image(volume)
    load_s = time.perf_counter() - start

    renderer = vtk.vtkRenderer()
    renderer.SetBackground(0, 0, 0)
    window = vtk.vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetMultiSamples(0)
    window.SetSize(width, height)
    window.AddRenderer(renderer)

    triangles = None
    prepare_s = 0.0
    if kind == "fixed-point":
        mapper = vtk.vtkFixedPointVolumeRayCastMapper()
        mapper.SetInputData(image)
        mapper.AutoAdjustSampleDistancesOff()
        mapper.LockSampleDistanceToInputSpacingOff()
        mapper.SetSampleDistance(0.5 * min(volume["spacing"]))
        mapper.SetImageSampleDistance(1.0)
        actor = vtk.vtkVolume()
        actor.SetMapper(mapper)
        actor.SetProperty(volume_property(scene))
        renderer.AddVolume(actor)
    elif kind == "marching-cubes":
        start = time.perf_counter()
        contour = vtk.vtkFlyingEdges3D()
        contour.SetInputData(image)
        contour.SetValue(0, scene["iso"]["value"])
        contour.ComputeNormalsOn()
        contour.ComputeScalarsOff()
        contour.Update()
        prepare_s = time.perf_counter() - start
        surface = contour.GetOutput()
        triangles = surface.GetNumberOfPolys()
        mapper = vtk.vtkPolyDataMapper()
        mapper.SetInputData(surface)
        mapper.ScalarVisibilityOff()
        actor = vtk.vtkActor()
        actor.SetMapper(mapper)
        prop = actor.GetProperty()
        prop.SetColor(*scene["iso"]["color"])
        prop.SetSpecularColor(1, 1, 1)
        prop.SetAmbient(scene["phong"]["ambient"])
        prop.SetDiffuse(scene["phong"]["diffuse"])
        prop.SetSpecular(scene["phong"]["specular"])
        prop.SetSpecularPower(scene["phong"]["shininess"])
        prop.SetInterpolationToPhong()
        renderer.AddActor(actor)
    else:
        raise SystemExit(f"unknown kind {kind}")

    camera = renderer.GetActiveCamera()
    cam = scene["camera"]
    camera.SetPosition(*cam["eye"])
    camera.SetFocalPoint(*cam["target"])
    camera.SetViewUp(*cam["up"])
    camera.SetViewAngle(cam["fov"])
    renderer.ResetCameraClippingRange()

    start = time.perf_counter()
    window.Render()  # warm-up: builds the mapper's tables, gradients, min/max volume; uploads the surface
    first_s = time.perf_counter() - start
    frames = []
    if first_s > 60:
        runs = 1  # minutes per frame: one timed frame is enough
    for _ in range(runs):
        camera.Modified()
        start = time.perf_counter()
        window.Render()
        frames.append(time.perf_counter() - start)

    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(window)
    grab.SetInputBufferTypeToRGB()
    grab.ReadFrontBufferOff()
    grab.Update()
    pixels = numpy_support.vtk_to_numpy(grab.GetOutput().GetPointData().GetScalars())
    pixels = pixels.reshape(height, width, 3)[::-1]
    Image.fromarray(np.ascontiguousarray(pixels)).save(out)

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(json.dumps({"load_s": load_s, "prepare_s": prepare_s + first_s, "frame_s": frames,
                      "peak_rss_bytes": peak, "triangles": triangles}))


if __name__ == "__main__":
    main()
