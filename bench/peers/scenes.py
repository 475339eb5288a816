"""The scenes of the peer comparison: volume, camera, transfer function, shading, and which tools render them.

Conventions are VTK's, shared by every tool and the reference (bench/peers/reference):
- sample (i, j, k) sits at origin + spacing * (i, j, k); origin is 0 for every prepared volume;
- the camera is vtkCamera's: eye, focal point (target), view up, vertical view angle in degrees;
- transfer functions are piecewise linear in the stored value; alpha is the opacity over `unit_distance` world units
  (VTK's ScalarOpacityUnitDistance), colours are linear, composited over black;
- Phong: ambient 0.25, diffuse 0.75, specular 0.25, shininess 16 (voxstream's defaults), a directional headlight.

Fog scenes use a transfer function vdb_render can express: constant colour c and an extinction linear in the value,
sigma(v) = k * v / vmax per world unit, i.e. alpha(v) = 1 - exp(-k * v / vmax * unit_distance), tabulated with 65
points. vdb_render gets density = v / vmax (prepare_data.py's density_scale), scatter = c * k * voxel,
absorb = (1 - c) * k * voxel (its extinction is per voxel of density 1), a white light, and shadows disabled.
"""
import json
import math
from pathlib import Path

PHONG = {"ambient": 0.25, "diffuse": 0.75, "specular": 0.25, "shininess": 16.0}
RESOLUTIONS = (512, 1024)


def fog_tf(colour, k, vmax, unit=1.0, points=65):
    """The transfer function of a fog: colour, extinction k * v / vmax per world unit."""
    pts = []
    for i in range(points):
        v = vmax * i / (points - 1)
        pts.append([v, *colour, 1.0 - math.exp(-k * v / vmax * unit)])
    return {"points": pts, "unit_distance": unit}


def orbit_camera(dims, spacing, direction, up, fov=30.0, distance_factor=2.1):
    extent = [(d - 1) * s for d, s in zip(dims, spacing)]
    centre = [e / 2 for e in extent]
    radius = 0.5 * math.sqrt(sum(e * e for e in extent))
    norm = math.sqrt(sum(d * d for d in direction))
    eye = [c + radius * distance_factor * d / norm for c, d in zip(centre, direction)]
    return {"eye": eye, "target": centre, "up": list(up), "fov": fov}


MNI_FOG = {"colour": [1.0, 0.8, 0.65], "k": 0.025, "vmax": 255.0}
MNI_SOFT = fog_tf(**MNI_FOG)
MNI_SHADED = {"points": [[0, 0, 0, 0, 0], [60, 0.75, 0.55, 0.45, 0.0], [100, 0.9, 0.75, 0.65, 0.08],
                         [160, 1.0, 0.95, 0.9, 0.3], [255, 1.0, 1.0, 1.0, 0.5]], "unit_distance": 1.0}
# Thin shells: narrow opacity peaks (6 values wide) at three tissue values, the kind of transfer function that
# pre-integration is for (a peak the field crosses between two samples is integrated, not missed).
MNI_SHELLS = {"points": [[0, 0, 0, 0, 0], [77, 1.0, 0.6, 0.3, 0.0], [80, 1.0, 0.6, 0.3, 0.5], [83, 1.0, 0.6, 0.3, 0.0],
                         [127, 0.3, 0.9, 0.4, 0.0], [130, 0.3, 0.9, 0.4, 0.5], [133, 0.3, 0.9, 0.4, 0.0],
                         [177, 0.4, 0.5, 1.0, 0.0], [180, 0.4, 0.5, 1.0, 0.7], [183, 0.4, 0.5, 1.0, 0.0],
                         [255, 0, 0, 0, 0]], "unit_distance": 1.0}
FROG = json.loads((Path(__file__).resolve().parents[2] / "docs/examples/frog-tf.json").read_text())
DRAGON_FOG = {"colour": [0.9, 0.75, 0.55], "k": 0.03, "vmax": 1.0}
DRAGON = fog_tf(**DRAGON_FOG)
MNI_ISO = {"value": 70.0, "color": [0.9, 0.75, 0.65]}


def scenes(data: Path):
    """Every scene; `volume` names data/NAME.json; `upsampled` scenes use the 4x volume (so the reference, which
    samples the scene's own volume, steps in 4x smaller voxels: `reference_step_scale`)."""
    def meta(name):
        return json.loads((data / f"{name}.json").read_text())

    mni, frog, dragon = meta("mni"), meta("frog"), meta("dragon")
    mni_camera = orbit_camera(mni["dims"], mni["spacing"], (-0.8, 1.4, 0.6), (0, 0, 1), distance_factor=2.4)
    frog_camera = orbit_camera(frog["dims"], frog["spacing"], (0.5, -1.0, 1.3), (0, 0, 1), distance_factor=2.8)
    dragon_camera = orbit_camera(dragon["dims"], dragon["spacing"], (0.5, 0.35, 1.0), (0, 1, 0), distance_factor=3.4)
    result = []
    for x4 in (False, True):
        suffix = "_x4" if x4 else ""
        label = "-x4" if x4 else ""
        upsampled = {"reference_step_scale": 4.0 if x4 else 1.0}
        result += [
            {"name": f"mni-soft{label}", "volume": f"mni{suffix}", "mode": "volume",
             "tf": MNI_SOFT, "shading": "none", "camera": mni_camera, "fog": MNI_FOG,
             "tools": ["voxstream", "voxstream-faithful", "voxstream-step1", "vtk-fixed-point", "vdb_render"], **upsampled},
            {"name": f"frog{label}", "volume": f"frog{suffix}", "mode": "volume",
             "tf": FROG, "shading": "none", "camera": frog_camera,
             "tools": ["voxstream", "voxstream-faithful", "voxstream-step1", "vtk-fixed-point"], **upsampled},
            {"name": f"dragon{label}", "volume": f"dragon{suffix}", "mode": "volume",
             "tf": DRAGON, "shading": "none", "camera": dragon_camera,
             "fog": DRAGON_FOG, "tools": ["voxstream", "voxstream-faithful", "voxstream-step1", "vtk-fixed-point", "vdb_render"], **upsampled},
        ]
        result.append({"name": f"mni-iso{label}", "volume": f"mni{suffix}", "mode": "isosurface",
                       "iso": MNI_ISO, "shading": "phong", "camera": mni_camera,
                       "tools": ["voxstream", "vtk-marching-cubes"], **upsampled})
        if not x4:
            result += [
                {"name": "mni-shaded", "volume": "mni", "mode": "volume",
                 "tf": MNI_SHADED, "shading": "phong", "camera": mni_camera,
                 "tools": ["voxstream", "voxstream-faithful", "voxstream-step1", "vtk-fixed-point"], "reference_step_scale": 1.0},
                # The reference steps twice as finely: the shells are a tenth of a voxel thick where MNI is steep.
                {"name": "mni-shells", "volume": "mni", "mode": "volume",
                 "tf": MNI_SHELLS, "shading": "none", "camera": mni_camera,
                 "tools": ["voxstream", "voxstream-faithful", "voxstream-step1", "vtk-fixed-point"], "reference_step_scale": 0.5},
            ]
    return result


def headlight(camera):
    d = [e - t for e, t in zip(camera["eye"], camera["target"])]
    n = math.sqrt(sum(v * v for v in d))
    return [v / n for v in d]
