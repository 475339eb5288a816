"""Type stubs of the native module (Rust, PyO3); use the wrappers in ``voxstream`` instead."""

from os import PathLike
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

__version__: str

_Vec3 = Tuple[float, float, float]
_Vec3i = Tuple[int, int, int]
_CameraTuple = Tuple[_Vec3, _Vec3, _Vec3, float]

class Volume:
    def __init__(self, source: Union[str, PathLike], *, width: int = 512, height: int = 512, budget_mb: int = 256,
                 value_range: Optional[Tuple[float, float]] = None, in_memory: bool = False,
                 cache_dir: Optional[str] = None, cache_mb: Optional[int] = None,
                 request_timeout: Optional[float] = None, retries: Optional[int] = None,
                 concurrent_requests: Optional[int] = None) -> None: ...
    @property
    def name(self) -> str: ...
    @property
    def info(self) -> Dict[str, Any]: ...
    @property
    def default_camera(self) -> _CameraTuple: ...
    @property
    def level_dims(self) -> List[Tuple[int, int, int]]: ...
    @property
    def dtype(self) -> Optional[str]: ...
    def read_region(self, level: int, lower: Tuple[int, int, int], size: Tuple[int, int, int]) -> np.ndarray: ...
    def render(self, *, width: int = 512, height: int = 512, budget_mb: int = 256, backend: str = "cpu",
               mode: str = "converged", camera: Optional[_CameraTuple] = None,
               tf_points: Optional[List[List[float]]] = None, tf_file: Optional[str] = None,
               iso: Sequence[float] = ..., iso_colors: Sequence[_Vec3] = ..., iso_opacities: Sequence[float] = ...,
               shadows: bool = False, light: Optional[_Vec3] = None, background: _Vec3 = ..., step: float = 0.5,
               lod_bias: float = 0.0, shading: Optional[str] = None, blending: bool = True,
               preintegrate: bool = False, adaptive_step: Optional[float] = None, faithful: bool = False,
               float32: bool = False, region: Optional[Tuple[_Vec3i, _Vec3i]] = None,
               projection: str = "composite", clip_planes: Sequence[Tuple[_Vec3, _Vec3]] = ...,
               view: Optional[str] = None, azimuth: Optional[float] = None, elevation: Optional[float] = None,
               zoom: Optional[float] = None) -> Tuple[np.ndarray, Dict[str, Any]]: ...

def import_volume(source: Union[str, np.ndarray], out: str, *, spacing: Optional[_Vec3] = None,
                  origin: Optional[_Vec3] = None, brick_size: int = 32, overwrite: bool = False,
                  nan_as: Optional[float] = None, resolution: Optional[int] = None,
                  amplify: Optional[float] = None,
                  progress: Optional[Callable[[int, int], Any]] = None) -> Dict[str, Any]: ...

def scene_names() -> List[str]: ...

def fuse(dataset: str, out: Optional[str] = None, *, points: Optional[str] = None, trajectory: Optional[str] = None,
         poses: str = "ground-truth", voxel: float = 0.01, window: int = 16, sub_cache: int = 2,
         confidence: float = 3.0, frames: Optional[int] = None, memory_mb: int = 1024, overwrite: bool = False,
         sign_only: bool = False, progress: Optional[Callable[[int, int], Any]] = None) -> Dict[str, Any]: ...

def synthesize_rgbd(mesh: str, out: str, *, frames: int = 300, noise: bool = True, object_size: float = 0.5,
                    radius: float = 1.2, height: float = 0.5, sweep: float = 360.0, up: str = "y", seed: int = 0x5EED,
                    level: bool = False, overwrite: bool = False) -> int: ...
