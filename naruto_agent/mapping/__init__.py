"""Mapping: NARUTO's neural map with an uncertainty grid, and a fast TSDF alternative.

* :class:`NeuralMapper`: Co-SLAM-style neural field (OneBlob + hash grid, bias-free MLPs,
  SDF volume rendering) mapped with known poses, NARUTO's uncertainty grid and active ray
  sampling. PyTorch (the reference); ``device="auto"`` uses CUDA when present, where
  ``backend="auto"`` runs the field's encodings as fused Triton kernels.
* :class:`TsdfUncertaintyMapper`: TSDF fusion plus a count-derived uncertainty grid, same
  interface, much faster.

Both give the planner ``planner_view() -> (SdfVolume, SdfVolume)``.
"""

from naruto_agent.mapping.backends import resolve_backend
from naruto_agent.mapping.base import Mapper, resolve_device
from naruto_agent.mapping.config import NeuralMapperConfig
from naruto_agent.mapping.encoding import HashGridEncoding, NaiveHashGridEncoding, OneBlobEncoding
from naruto_agent.mapping.neural_mapper import NeuralMapper, select_active_rays
from naruto_agent.mapping.occupancy import OccupancyGrid
from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.mapping.tsdf_mapper import TsdfMapperConfig, TsdfUncertaintyMapper
from naruto_agent.mapping.uncertainty_grid import UncertaintyGrid, gaussian_nll

__all__ = [
    "HashGridEncoding",
    "Mapper",
    "NaiveHashGridEncoding",
    "NeuralMapper",
    "NeuralMapperConfig",
    "OccupancyGrid",
    "OneBlobEncoding",
    "SdfVolume",
    "TsdfMapperConfig",
    "TsdfUncertaintyMapper",
    "UncertaintyGrid",
    "gaussian_nll",
    "resolve_backend",
    "resolve_device",
    "select_active_rays",
]
