"""napari plugin: voxstream and OME-Zarr stores as multiscale layers (``reader``), and a dock widget that renders
napari's 3D view with voxstream at full resolution within a memory budget (``widget``). Declared in
``voxstream/napari.yaml`` (npe2)."""
