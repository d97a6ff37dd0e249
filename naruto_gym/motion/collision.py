"""Collision handling of the agent, a sphere carrying the camera.

A move is checked along its whole segment against the ground-truth mesh (never against a
map), clipped to the scene bounds, and refused when it would leave the scanned space (an
agent slipping out of a scan with holes). Two escape rules are available:

* ``"scanned_space"`` (default): the end of the move must see scanned surface below it in
  every direction and must not be above the scan (:mod:`naruto_gym.motion.scanned_space`).
  It is answered from a lazily filled lattice, so a step casts no extra ray once the
  lattice around a place is known, and it does not refuse moves in a scan that merely lacks
  a ceiling.
* ``"published"``: NARUTO's rule, refuse a move whose end sees more than
  ``escape_no_hit_threshold`` (50 %) no-hit pixels on a whole-sphere panorama. It works on
  closed meshes; without a ceiling half of every panorama is empty, so it refuses moves
  inside the room.

``"off"`` (or ``escape_no_hit_threshold=None``) switches the check off.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from naruto_gym.geometry.sweep_kernels import fraction_inside_box
from naruto_gym.motion.scanned_space import ScannedSpace, ScannedSpaceConfig
from naruto_gym.observability import inside_free_space_many, is_inside_free_space
from naruto_gym.scenes.mesh_scene import face_normals_of
from naruto_gym.sensors.panorama import EquirectangularCamera, no_hit_share, render_panorama
from naruto_gym.sensors.raycaster import RayCaster

ESCAPE_RULES = ("scanned_space", "published", "off")


@dataclass(frozen=True)
class MoveResult:
    """Where a move ended and why it stopped short."""

    position: np.ndarray
    collided: bool
    reason: str  # "", "surface", "bounds" or "escape"


def points_close(a: np.ndarray, b: np.ndarray) -> bool:
    """``np.allclose(a, b)`` for two 3-vectors (same tolerances), without its per-call cost
    on the step path."""
    pairs = zip(np.asarray(a).tolist(), np.asarray(b).tolist(), strict=True)
    return all(abs(x - y) <= 1e-8 + 1e-5 * abs(y) for x, y in pairs)


def segment_fraction_inside_box(
    start: np.ndarray, end: np.ndarray, box_min: np.ndarray, box_max: np.ndarray
) -> float:
    """Largest t in [0, 1] with start + t (end - start) inside the box (start assumed inside;
    :func:`~naruto_gym.geometry.sweep_kernels.fraction_inside_box`)."""
    return float(fraction_inside_box(
        np.asarray(start, np.float64), np.asarray(end, np.float64),
        np.asarray(box_min, np.float64), np.asarray(box_max, np.float64),
    ))


class CollisionChecker:
    """Moves a sphere of ``radius_m`` through a scene without touching its surfaces.

    Args:
        raycaster: the ground-truth scene.
        bounds: (2, 3) scene bounds; the sphere's centre stays ``radius_m`` inside them.
        radius_m: agent radius (0.05 m in the published system).
        escape_no_hit_threshold: the published rule refuses a move whose end sees more than
            this share of no-hit panorama pixels (0.5 in the published system); None
            switches every escape check off.
        escape_panorama: the (small) panorama used by the published rule.
        escape_rule: ``"scanned_space"`` (default), ``"published"`` or ``"off"`` (see the
            module docstring).
        face_normals: (F, 3) triangle normals (computed from the caster's mesh when None).
        scanned_space_config: settings of the scanned-space rule.
    """

    def __init__(
        self,
        raycaster: RayCaster,
        bounds: np.ndarray,
        radius_m: float = 0.05,
        escape_no_hit_threshold: float | None = 0.5,
        escape_panorama: EquirectangularCamera | None = None,
        escape_rule: str = "scanned_space",
        face_normals: np.ndarray | None = None,
        scanned_space_config: ScannedSpaceConfig | None = None,
    ) -> None:
        if radius_m <= 0:
            raise ValueError(f"agent radius must be positive, got {radius_m}")
        if escape_rule not in ESCAPE_RULES:
            raise ValueError(f"escape_rule must be one of {ESCAPE_RULES}, got {escape_rule!r}")
        if escape_no_hit_threshold is not None and not 0 <= escape_no_hit_threshold <= 1:
            raise ValueError(
                "escape_no_hit_threshold must be a share in [0, 1] or None, got "
                f"{escape_no_hit_threshold}"
            )
        self.raycaster = raycaster
        self.radius_m = float(radius_m)
        self.box_min = np.asarray(bounds[0], np.float64) + radius_m
        self.box_max = np.asarray(bounds[1], np.float64) - radius_m
        self.escape_no_hit_threshold = escape_no_hit_threshold
        self.escape_panorama = escape_panorama or EquirectangularCamera(32, 64)
        self.escape_rule = "off" if escape_no_hit_threshold is None else escape_rule
        self.face_normals = (
            face_normals if face_normals is not None
            else face_normals_of(raycaster.vertices, raycaster.faces)
        )
        self.scanned_space = ScannedSpace(
            raycaster, self.face_normals, bounds, scanned_space_config
        )
        self._last_clearance: tuple[np.ndarray, float] | None = None

    @property
    def max_no_hit_share(self) -> float:
        """Whole-sphere no-hit share the published free-space test accepts."""
        threshold = self.escape_no_hit_threshold
        return 0.5 if threshold is None else float(threshold)

    def start_test(self) -> Callable[[np.ndarray], bool]:
        """The exact free-space test for start poses and viewpoints under this rule."""
        if self.escape_rule == "scanned_space":
            return self.scanned_space.is_inside
        normals, share = self.face_normals, self.max_no_hit_share
        return lambda position: is_inside_free_space(self.raycaster, normals, position, share)

    def start_test_many(self) -> Callable[[np.ndarray], np.ndarray]:
        """:meth:`start_test` of (K, 3) points at once ((K,) bool, the same answers)."""
        if self.escape_rule == "scanned_space":
            return self.scanned_space.is_inside_many
        normals, share = self.face_normals, self.max_no_hit_share
        return lambda positions: inside_free_space_many(self.raycaster, normals, positions, share)

    def clearance(self, position: np.ndarray) -> float:
        """Distance from ``position`` to the nearest surface, metres."""
        return float(self.raycaster.unsigned_distance(np.asarray(position)[None])[0])

    def _cached_clearance(self, position: np.ndarray) -> float:
        """:meth:`clearance`, remembering the last point: a move's end is the next start, so
        the escape rule's query at the end costs no extra query per step."""
        if self._last_clearance is not None and np.array_equal(self._last_clearance[0], position):
            return self._last_clearance[1]
        value = self.clearance(position)
        self._last_clearance = (np.array(position, np.float64), value)
        return value

    def inside_bounds(self, position: np.ndarray) -> bool:
        return bool(np.all(position >= self.box_min) and np.all(position <= self.box_max))

    def sees_escape(self, position: np.ndarray, clearance_m: float | None = None) -> bool:
        """True when ``position`` lies outside the scanned space under the escape rule
        (``clearance_m``: its distance to the nearest surface, when known)."""
        if self.escape_rule == "off":
            return False
        if self.escape_rule == "scanned_space":
            return not self.scanned_space.contains(position, clearance_m)
        panorama = render_panorama(self.raycaster, self.escape_panorama, position)
        return no_hit_share(panorama) > self.escape_no_hit_threshold

    def refuses_escape(self, start: np.ndarray, end: np.ndarray) -> bool:
        """Whether the escape rule refuses a move from ``start`` to ``end``.

        Under the scanned-space rule an agent that is already outside (an exact start pose
        put it there) may still move, as long as it goes no further out: no more empty
        support sectors below (then no more support rays missing, then no farther from the
        surface below), and no higher above the scan. It is never trapped where it was placed.
        """
        clearance = self._cached_clearance(end) if self.escape_rule == "scanned_space" else None
        if not self.sees_escape(end, clearance):
            return False
        if self.escape_rule != "scanned_space" or not self.sees_escape(start):
            return True
        space = self.scanned_space
        return not (
            space.outside_degree(end) <= space.outside_degree(start)
            and end[2] <= max(start[2], space.top_m)
        )

    def move(self, start: np.ndarray, target: np.ndarray) -> MoveResult:
        """Move from ``start`` towards ``target`` as far as the sphere fits."""
        start = np.asarray(start, np.float64)
        target = np.asarray(target, np.float64)
        if points_close(start, target):
            return MoveResult(start.copy(), False, "")
        box_fraction = segment_fraction_inside_box(start, target, self.box_min, self.box_max)
        end = start + box_fraction * (target - start)
        # From a start already closer than the radius (an exact start pose), the sphere may
        # move on as long as it gets no closer than it already is.
        clearance = min(self.radius_m, self._cached_clearance(start) - 1e-4)
        surface_fraction, stop_clearance = self.raycaster.sweep(start, end, max(clearance, 0))
        position = start + surface_fraction * (end - start)
        if surface_fraction > 0.0:
            # Where the sweep stops is one of its samples: the escape rule's clearance query
            # there (and the next move's at its start) is already answered.
            self._last_clearance = (position.copy(), stop_clearance)
        if surface_fraction < 1.0:
            reason = "surface"
        elif box_fraction < 1.0:
            reason = "bounds"
        else:
            reason = ""
        if not points_close(position, start) and self.refuses_escape(start, position):
            return MoveResult(start.copy(), True, "escape")
        return MoveResult(position, reason != "", reason)
