"""Mesh culling before evaluation: keep only what the trajectory could have seen.

The rule of the active-mapping literature (Feng et al., NARUTO, CVPR 2024, and the Co-SLAM
evaluation it follows): a reconstructed face is kept when at least one of its vertices lies
inside the view frustum of at least one pose of the trajectory (every 2nd pose by default)
*and* is not hidden, i.e. its z-depth is at most the ground-truth scene's depth along its line
of sight plus a margin (3 cm). Surfaces a mapper invents where the camera never looked (neural
fields extrapolate) are thereby not counted against its accuracy.

The ground-truth depth is ray-cast with Embree, not rasterised with OpenGL, in one of two ways:

* ``depth_scale=None`` (default): one ray per tested (vertex, pose) pair, from the camera
  centre through the vertex, so every vertex is compared with the ground-truth depth
  *exactly* along its own line of sight: the limit of an infinitely fine depth image
  (:mod:`.rays`).
* ``depth_scale=s`` in (0, 1]: the literature's way, a full depth image rendered by
  :class:`~naruto_gym.sensors.pinhole.RgbdRenderer` at ``s`` times the camera resolution
  (same field of view), each vertex reading the pixel it projects into (:mod:`.depth_image`).
  Kept for comparison; it differs from the per-vertex rays only for vertices within a pixel
  of a depth edge.

Lines of sight that hit nothing count as unoccluded. A :class:`CullingCache` carries what one
call learnt to the next call on a longer trajectory (:mod:`.cache`);
:func:`visible_vertex_mask_reference` applies the rule the straightforward way, as the oracle
(:mod:`.reference`). :class:`CullingSettings` tunes how many rays are cast, never the result.
"""

from naruto_gym.evaluation.culling.cache import CullingCache
from naruto_gym.evaluation.culling.mask import cull_mesh, visible_vertex_mask
from naruto_gym.evaluation.culling.reference import visible_vertex_mask_reference
from naruto_gym.evaluation.culling.settings import (
    DEFAULT_CULL_DEPTH_SCALE,
    DEFAULT_CULL_EVERY,
    DEFAULT_DEPTH_MARGIN_M,
    DEFAULT_SETTINGS,
    CullingSettings,
)

__all__ = [
    "DEFAULT_CULL_DEPTH_SCALE",
    "DEFAULT_CULL_EVERY",
    "DEFAULT_DEPTH_MARGIN_M",
    "DEFAULT_SETTINGS",
    "CullingCache",
    "CullingSettings",
    "cull_mesh",
    "visible_vertex_mask",
    "visible_vertex_mask_reference",
]
