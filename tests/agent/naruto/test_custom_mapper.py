"""The NARUTO agent plans on a mapper of one's own (``examples/my_mapper.py``), named by import
path, through the Python API and both command-line tools."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import naruto_gym  # noqa: F401  (registers the env)
from naruto_agent.benchmark.cli import main as benchmark_main
from naruto_agent.demo import main as demo_main
from naruto_agent.mapping import Mapper
from naruto_agent.naruto import NarutoPolicy
from naruto_agent.policies import EnvContext

REPO_ROOT = Path(__file__).resolve().parents[3]
MAPPER = "examples.my_mapper:VoxelTsdfMapper"
SCENE = "replica_like_room"
#: The agent moves from the first step (no look-around), so a short episode plans and moves.
AGENT = {"mapper_kind": MAPPER, "device": "cpu", "initial_look_around": False}
TINY_RUN = [
    "--max-episode-steps",
    "20",
    "--image-scale",
    "0.1",
    "--eval-points",
    "0",
    "--eval-samples",
    "5000",
    "--no-progress",
]


def run_benchmark(policy_kwargs: dict) -> int:
    """``naruto-benchmark``'s exit code for one tiny NARUTO episode on :data:`SCENE` with
    these constructor arguments, recorded under ``runs/`` of the working directory."""
    return benchmark_main(
        [
            "--scenes",
            SCENE,
            "--seeds",
            "0",
            "--policies",
            "naruto",
            "--workers",
            "0",
            "--no-plots",
            "--output-dir",
            "runs",
            "--policy-kwargs",
            json.dumps(policy_kwargs),
            *TINY_RUN,
        ]
    )


@pytest.fixture
def user_folder(tmp_path, monkeypatch):
    """A working directory holding ``examples/my_mapper.py``, as a user's checkout does, and
    nothing else on ``sys.path`` that finds it; imported ``examples`` modules are dropped
    before and after."""
    (tmp_path / "examples").mkdir()
    shutil.copy2(REPO_ROOT / "examples" / "my_mapper.py", tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    hidden = ("", str(tmp_path), str(REPO_ROOT))
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in hidden])

    def forget() -> None:
        for name in [n for n in sys.modules if n == "examples" or n.startswith("examples.")]:
            del sys.modules[name]

    forget()
    yield tmp_path
    forget()


def test_the_example_mapper_drives_the_agent(user_folder):
    env = gym.make(
        "NarutoRecon-v0", scene=SCENE, image_scale=0.1, panorama_shape=None, max_episode_steps=41
    )
    policy = NarutoPolicy(mapper_kind=MAPPER, device="cpu")
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=0, options=policy.reset_options())
    policy.reset(observation, info, seed=0)
    start, coverage = observation["pose"][:3, 3].copy(), [info["coverage"]]
    for _ in range(40):
        observation, _, _, _, info = env.step(policy.act(observation, info))
        coverage.append(info["coverage"])
    assert type(policy.mapper).__name__ == "VoxelTsdfMapper" and isinstance(policy.mapper, Mapper)
    assert policy.plans and policy.sdf is not None and policy.uncertainty is not None
    assert np.linalg.norm(observation["pose"][:3, 3] - start) > 0.5  # it went to a goal
    assert coverage[-1] > coverage[0] + 0.3
    reconstruction = policy.reconstruction()
    scores = env.unwrapped.evaluate(reconstruction.mesh, sdf=reconstruction.sdf, num_samples=20_000)
    assert scores["accuracy_cm"] < 3.0 and scores["mad_cm"] is not None


def test_settings_and_a_file_path_reach_the_example_mapper(user_folder):
    env = gym.make("NarutoRecon-v0", scene=SCENE, image_scale=0.1, panorama_shape=None)
    policy = NarutoPolicy(
        mapper_kind="examples/my_mapper.py:VoxelTsdfMapper",
        device="cpu",
        mapper_settings={"voxel_size_m": 0.1, "truncation_m": 0.3},
    )
    policy.bind(EnvContext.from_env(env))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    assert policy.mapper.distances.voxel_size == 0.1 and policy.mapper.truncation_m == 0.3
    with pytest.raises(ValueError, match="truncation_m must span at least two voxels"):
        policy = NarutoPolicy(mapper_kind=MAPPER, mapper_settings={"truncation_m": 0.05})
        policy.bind(EnvContext.from_env(env))
        policy.reset(observation, info, seed=0)


def test_the_demo_runs_the_agent_on_the_example_mapper(user_folder, capsys):
    kwargs = {key: value for key, value in AGENT.items() if key != "mapper_kind"}
    demo_main(
        [
            "--policy",
            "naruto",
            "--mapper-kind",
            MAPPER,
            "--scene",
            SCENE,
            "--policy-kwargs",
            json.dumps(kwargs),
            "--output-dir",
            "out",
            "--gif-frames",
            "0",
            "--no-viewer",
            "--no-record",
            "--checkpoint-samples",
            "5000",
            *TINY_RUN,
        ]
    )
    metrics = json.loads((user_folder / "out" / "metrics.json").read_text())
    assert metrics["map"] == "the policy's own map (NarutoPolicy.mesh())"
    assert metrics["mesh_faces"] > 1000 and metrics["path_length_m"] > 0.3
    assert metrics["goals_chosen"] >= 1


def test_the_benchmark_runs_the_agent_on_the_example_mapper(user_folder, capsys):
    code = run_benchmark(AGENT)
    assert code == 0, capsys.readouterr()
    record = json.loads(
        (user_folder / "runs/records/replica_like_room/naruto/seed0.json").read_text()
    )
    assert record["status"] == "ok" and record["config"]["policy_kwargs"] == AGENT
    assert record["path_length_m"] > 0.3
    assert record["own_map_metrics"]["mad_cm"] is not None  # the example's SDF, scored


def test_the_demo_refuses_a_bad_mapper_with_the_reason(user_folder, capsys):
    with pytest.raises(SystemExit):
        demo_main(["--policy", "naruto", "--mapper-kind", "octomap", "--output-dir", "out"])
    assert "unknown mapper 'octomap'; use one of ['neural', 'tsdf']" in capsys.readouterr().err
    (user_folder / "examples" / "partial.py").write_text(
        "class Partial:\n    def integrate(self, rgb, depth, pose, frame):\n        return True\n"
    )
    with pytest.raises(SystemExit):
        demo_main(["--policy", "naruto", "--mapper-kind", "examples.partial:Partial"])
    assert (
        "lacks what the NARUTO agent reads: integrate_panorama(), planner_view(), sdf(), "
        "extract_mesh()"
    ) in capsys.readouterr().err


def test_the_mappers_page_example_is_the_one_in_examples():
    """docs/mappers.md shows examples/my_mapper.py in full (saved as my_mapper.py)."""
    from tests.docs_examples import load_page

    written = [b for b in load_page(REPO_ROOT / "docs" / "mappers.md") if b.write]
    assert [b.write for b in written] == ["my_mapper.py"]
    shipped = (REPO_ROOT / "examples" / "my_mapper.py").read_text(encoding="utf-8")
    assert written[0].code == shipped, (
        "docs/mappers.md's my_mapper.py block and examples/my_mapper.py differ: copy the file "
        "into the page's block"
    )


def test_the_benchmark_says_why_a_bad_mapper_fails_its_episodes(user_folder, capsys):
    code = run_benchmark({"mapper_kind": "octomap"})
    assert code == 1
    assert (
        "replica_like_room/naruto/seed0: ValueError: mapper_kind: unknown mapper 'octomap'"
        in capsys.readouterr().out
    )
