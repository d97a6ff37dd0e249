"""Mapping: NARUTO's neural map with an uncertainty grid, and a fast TSDF alternative.

* :class:`NeuralMapper`: Co-SLAM-style neural field (OneBlob + hash grid, bias-free MLPs,
  SDF volume rendering) mapped with known poses, NARUTO's uncertainty grid and active ray
  sampling. PyTorch (the reference); ``device="auto"`` uses CUDA when present, where
  ``backend="auto"`` runs the field's encodings as fused Triton kernels.
* :class:`TsdfUncertaintyMapper`: TSDF fusion plus a count-derived uncertainty grid, same
  interface, much faster.

Both give the planner ``planner_view() -> (SdfVolume, SdfVolume)``. :class:`Mapper` lists
everything the NARUTO agent reads from a mapper; :func:`register_mapper` names a mapper of
one's own, or ``NarutoPolicy(mapper_kind="package.module:ClassName")`` takes it by its import
path (:mod:`naruto_agent.mapping.registry`, ``docs/mappers.md``). The building blocks of a
mapper (:class:`ObservedSpace`, :func:`add_unknown_space_uncertainty`, :class:`SdfVolume`,
:func:`mesh_from_sdf_function`, :func:`check_frame`) are exported here for that.
"""

from naruto_agent.mapping.backends import resolve_backend
from naruto_agent.mapping.base import (
    MAPPER_MEMBERS,
    Mapper,
    check_bounds,
    check_frame,
    missing_members,
    resolve_device,
)
from naruto_agent.mapping.config import NeuralMapperConfig
from naruto_agent.mapping.encoding import HashGridEncoding, NaiveHashGridEncoding, OneBlobEncoding
from naruto_agent.mapping.meshing import mesh_from_sdf_function
from naruto_agent.mapping.neural_mapper import NeuralMapper, select_active_rays
from naruto_agent.mapping.observed_space import (
    ObservedSpace,
    ObservedSpaceConfig,
    add_unknown_space_uncertainty,
)
from naruto_agent.mapping.occupancy import OccupancyGrid
from naruto_agent.mapping.registry import make_mapper, mapper_names, register_mapper
from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.mapping.tsdf_mapper import TsdfMapperConfig, TsdfUncertaintyMapper
from naruto_agent.mapping.uncertainty_grid import UncertaintyGrid, gaussian_nll

__all__ = [
    "MAPPER_MEMBERS",
    "HashGridEncoding",
    "Mapper",
    "NaiveHashGridEncoding",
    "NeuralMapper",
    "NeuralMapperConfig",
    "ObservedSpace",
    "ObservedSpaceConfig",
    "OccupancyGrid",
    "OneBlobEncoding",
    "SdfVolume",
    "TsdfMapperConfig",
    "TsdfUncertaintyMapper",
    "UncertaintyGrid",
    "add_unknown_space_uncertainty",
    "check_bounds",
    "check_frame",
    "gaussian_nll",
    "make_mapper",
    "mapper_names",
    "mesh_from_sdf_function",
    "missing_members",
    "register_mapper",
    "resolve_backend",
    "resolve_device",
    "select_active_rays",
]
