"""Checks that a mesh file is an indoor scan the env can run, read from its geometry alone.

A folder of scans from another dataset brings files in other units, with another up axis,
or files that are no scan at all (an object, a point cloud). Each is found here before an
episode runs on it, with what to pass instead:

* **up axis**: floors, ceilings and the tops of furniture are a room's largest flat
  surfaces, so the axis along which most of the surface faces is the up axis; the surface
  lies mostly in the lower half along it (floor and furniture, whether or not the scan has a
  ceiling), which tells up from down. :func:`likely_up_axis` returns it where the geometry
  says so clearly, and :func:`check_up_axis` refuses a loaded scene that lies on its side or
  upside down.
* **units**: :func:`naruto_gym.scenes.units.check_metric_size`, applied when a file is
  loaded.
* **a scan at all**: :func:`check_room_sized` refuses a mesh smaller than a room.
"""

from __future__ import annotations

import numpy as np

from naruto_gym.scenes.mesh_scene import rotation_to_z_up

#: How much more surface must face along the up axis than along either other axis for the
#: geometry to name it (a floor with walls as high as the room is wide faces about equally).
CLEAR_AREA_RATIO = 1.15
#: How far below the middle of its height a room's surface must lie, as a share of the
#: height, for the geometry to tell up from down.
CLEAR_SIGN_SHARE = 0.03
#: The least horizontal side and height of a room an agent can move in (metres).
MIN_ROOM_SIDE_M = 1.0
MIN_ROOM_HEIGHT_M = 0.5
_AXES = ("x", "y", "z")


def _areas_and_centres(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    corners = np.asarray(vertices, np.float64)[np.asarray(faces)]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return normals, corners.mean(axis=1)


def likely_up_axis(vertices: np.ndarray, faces: np.ndarray) -> str | None:
    """The axis (``"x"``, ``"-x"``, ``"y"``, ...) that points up in a mesh, as
    :func:`~naruto_gym.scenes.mesh_scene.load_scene` takes it, or None where the geometry
    does not say clearly (a room as high as it is wide, an empty box).

    The up axis is the one most of the surface faces along (:data:`CLEAR_AREA_RATIO` more
    than along each other axis); it points up where the area-weighted surface lies below the
    middle of the mesh's extent along it (by :data:`CLEAR_SIGN_SHARE` of the extent; a mesh
    whose surface sits in the middle is taken to point along +axis).
    """
    if len(faces) == 0:
        return None
    normals, centres = _areas_and_centres(vertices, faces)
    facing = np.abs(normals).sum(axis=0)  # twice the area projected along each axis
    order = np.argsort(facing)[::-1]
    if not facing[order[0]] > CLEAR_AREA_RATIO * facing[order[1]]:
        return None
    axis = int(order[0])
    area = np.linalg.norm(normals, axis=1)
    low, high = np.min(vertices[:, axis]), np.max(vertices[:, axis])
    height = float(high - low)
    if not height > 0 or not area.sum() > 0:
        return None
    centre = float(np.average(centres[:, axis], weights=area))
    below_middle = (low + high) / 2 - centre
    if below_middle < -CLEAR_SIGN_SHARE * height:
        return f"-{_AXES[axis]}"
    return _AXES[axis]


def check_up_axis(vertices: np.ndarray, faces: np.ndarray, what: str, up_axis: str) -> None:
    """Refuse a scene (already turned z-up, read with ``up_axis``) that lies on its side or
    upside down by :func:`likely_up_axis`; a geometry that does not say clearly passes.

    Raises:
        ValueError: naming the axis the file's geometry points up along, in the file's own
            axes, and what to pass.
    """
    seen = likely_up_axis(vertices, faces)
    if seen is None or seen == "z":
        return
    in_file = file_axis(up_axis, seen)
    lies = "upside down" if seen == "-z" else "on its side"
    axis = in_file.lstrip("-")
    floor_side = "+" if in_file.startswith("-") else "-"
    raise ValueError(
        f"{what} read with up_axis={up_axis!r} lies {lies}: most of its surface (floors, "
        f"ceilings, furniture tops) faces along the file's {axis} axis, with the floor towards "
        f"{floor_side}{axis}. Pass up_axis={in_file!r} (PATH@{in_file} on the command line)"
    )


def file_axis(up_axis: str, loaded_axis: str) -> str:
    """The axis of the file that ``loaded_axis`` (an axis of the scene turned z-up after
    reading the file with ``up_axis``) is."""
    rotation = rotation_to_z_up(up_axis)  # file -> scene
    sign = -1.0 if loaded_axis.startswith("-") else 1.0
    direction = np.zeros(3)
    direction[_AXES.index(loaded_axis.lstrip("-"))] = sign
    in_file = rotation.T @ direction
    index = int(np.argmax(np.abs(in_file)))
    return ("-" if in_file[index] < 0 else "") + _AXES[index]


def check_room_sized(vertices: np.ndarray, what: str) -> None:
    """Refuse a mesh (z-up, in metres) too small to be a room an agent moves in.

    Raises:
        ValueError: giving its size, for a mesh under :data:`MIN_ROOM_SIDE_M` across either
            horizontal side or :data:`MIN_ROOM_HEIGHT_M` high (an object, or a file in
            kilometres).
    """
    extents = np.ptp(np.asarray(vertices, np.float64), axis=0)
    wide = extents[0] >= MIN_ROOM_SIDE_M and extents[1] >= MIN_ROOM_SIDE_M
    if wide and extents[2] >= MIN_ROOM_HEIGHT_M:
        return
    raise ValueError(
        f"{what} is not a scan of a room: it measures {extents[0]:.2f} x {extents[1]:.2f} x "
        f"{extents[2]:.2f} m (an agent needs at least {MIN_ROOM_SIDE_M:g} m across and "
        f"{MIN_ROOM_HEIGHT_M:g} m of height); remove it from the folder, or check its unit "
        "(mesh_units) and up axis"
    )
