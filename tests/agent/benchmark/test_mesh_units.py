"""The harness takes a mesh file's length unit as the demo and the env do: ``--mesh-units``
(``SceneSpec`` / ``EpisodeSpec.mesh_units``), applied to the scenes given as files."""

from __future__ import annotations

import json

import pytest

from naruto_agent.benchmark import EpisodeSpec, build_specs, parse_scene
from naruto_agent.benchmark.cli import main
from tests.scenes.test_mesh_units import ROOM_M, _room, _write

#: A few cheap steps: a tiny camera, few coverage samples, no reference map to score.
CHEAP_RUN = [
    "--policies", "random", "--seeds", "0", "--max-episode-steps", "3", "--workers", "0",
    "--image-scale", "0.05", "--eval-points", "0", "--no-reconstruct", "--no-plots",
    "--no-progress", "--env-kwargs", '{"coverage_samples": 500, "panorama_shape": [8, 16]}',
]  # fmt: skip


def test_a_mesh_file_takes_the_unit_and_a_catalogue_name_stays_in_metres():
    assert parse_scene("room.ply", mesh_units="cm") == parse_scene("room.ply@z", "z", "cm")
    assert parse_scene("room.ply", mesh_units="cm").mesh_units == "cm"
    assert parse_scene("two_rooms", mesh_units="cm").mesh_units == "m"
    specs = build_specs(["two_rooms", "room.ply@y"], ["random"], [0], 5, mesh_units="mm")
    assert [(spec.up_axis, spec.mesh_units) for spec in specs] == [("z", "m"), ("y", "mm")]
    with pytest.raises(ValueError, match="mesh_units must be one of"):
        parse_scene("room.ply", mesh_units="km")
    with pytest.raises(ValueError, match="mesh_units must be one of"):
        EpisodeSpec("room.ply", "random", 0, 5, mesh_units="inch")
    with pytest.raises(ValueError, match=r"env_kwargs must not set \['mesh_units'\].*--mesh-units"):
        EpisodeSpec("room.ply", "random", 0, 5, env_kwargs={"mesh_units": "mm"})


def test_the_hash_of_a_spec_in_metres_is_the_one_stored_before_the_unit_existed():
    """Records stored before ``mesh_units`` (and the later settings left out of the hash at
    their defaults) existed stay current (their hash is the one of the settings without
    them); another unit is another hash."""
    import hashlib

    from naruto_agent.benchmark.spec import HASH_OMITS_AT_DEFAULT

    spec = EpisodeSpec("room.ply", "random", 0, 5)
    assert "mesh_units" in HASH_OMITS_AT_DEFAULT
    settings = {
        key: value for key, value in spec.as_dict().items() if key not in HASH_OMITS_AT_DEFAULT
    }
    stored = hashlib.sha1(json.dumps(settings, sort_keys=True, default=str).encode())
    assert spec.config_hash == stored.hexdigest()[:12]
    assert EpisodeSpec("room.ply", "random", 0, 5, mesh_units="mm").config_hash != spec.config_hash


def test_naruto_benchmark_runs_a_millimetre_mesh_with_mesh_units(tmp_path, capsys):
    """Without ``--mesh-units`` the millimetre room's episode fails with the unit to pass;
    with ``--mesh-units mm`` it runs in the room rescaled to metres."""
    path = _write(tmp_path, _room(ROOM_M, 1000.0), "room_mm")
    wrong = tmp_path / "wrong"
    assert main(["--scenes", path, "--output-dir", str(wrong), *CHEAP_RUN]) == 1
    (record_file,) = (wrong / "records").rglob("seed0.json")
    record = json.loads(record_file.read_text())
    assert record["status"] == "failed" and "mesh_units='mm'" in record["error"]

    right = tmp_path / "right"
    assert (
        main(["--scenes", path, "--mesh-units", "mm", "--output-dir", str(right), *CHEAP_RUN]) == 0
    )
    (record_file,) = (right / "records").rglob("seed0.json")
    record = json.loads(record_file.read_text())
    assert record["status"] == "ok" and record["config"]["mesh_units"] == "mm"
    assert record["steps_run"] == 3
    assert main(["--scenes", path, "--mesh-units", "km", *CHEAP_RUN]) != 0
    capsys.readouterr()
