"""voxstream: render volumes larger than memory, from Python.

Open any source the ``voxstream`` command opens (a built-in scene, a voxstream store, another tool's OME-Zarr image
on disk or at an ``http(s)://``, ``s3://``, ``gs://`` or ``az://`` URL, a mesh or particle file) and render it at
full resolution within a memory budget: only the bricks the rays need are read, coarse first.

>>> import voxstream as vs
>>> volume = vs.open("sponge")
>>> image = volume.render(size=(256, 256))      # numpy array (256, 256, 4) uint8, RGBA
>>> image.shape
(256, 256, 4)

``Session`` renders progressive frames for interactive loops, ``import_volume`` writes a store from a file or a
numpy array (or, on a Dask cluster, a dask array), ``render_frames`` renders a camera path (``orbit``) on a Dask
cluster, ``fuse`` fuses an RGB-D sequence into a store, ``Camera`` and ``TransferFunction`` describe the view.
"""

from ._camera import Camera
from ._transfer import TransferFunction
from ._volume import Session, Volume, open, scenes
from ._import import import_volume
from ._fusion import fuse, synthesize_rgbd
from ._distributed import orbit, render_frames, render_sort_last
from ._native import __version__

__all__ = ["Camera", "Session", "TransferFunction", "Volume", "fuse", "import_volume", "open", "orbit",
           "render_frames", "render_sort_last", "scenes", "synthesize_rgbd", "__version__"]
