"""Recordings: what a policy shows (layers), the recorder's file read back, the live viewer's
checks, and the benchmark's --record."""

from __future__ import annotations

import json
import time

import gymnasium as gym
import numpy as np
import pytest
import trimesh

import naruto_gym  # noqa: F401  (registers the env ids)
from naruto_agent.policies import (
    BoxesLayer,
    EnvContext,
    FrontierPolicy,
    LinesLayer,
    PointsLayer,
    RandomPolicy,
    ScalarLayer,
)
from naruto_agent.policies.layers import layer_names, subsample
from naruto_agent.recording import LiveViewerError, reach_viewer
from naruto_agent.recording.live import viewer_address
from naruto_gym.sensors.pinhole import PinholeCamera

rerun = pytest.importorskip("rerun", reason="the viewer extra (rerun-sdk) is not installed")

from naruto_agent.recording import EpisodeRecorder, read_recording  # noqa: E402


# -- layers -----------------------------------------------------------------------------------
def test_layers_check_their_names_shapes_and_colours():
    points = PointsLayer("frontier/near", [[0, 0, 0], [1, 1, 1]])
    assert points.points.shape == (2, 3) and points.colour == (255, 200, 0)
    assert PointsLayer("empty", []).points.shape == (0, 3)
    assert LinesLayer("planned path", ([[0, 0, 0], [1, 0, 0]],)).strips[0].shape == (2, 3)
    boxes = BoxesLayer("blocked", [[0, 0, 0], [1, 1, 1]], 0.1)
    assert boxes.half_sizes.shape == (2, 3)
    assert ScalarLayer("observed space (%)", 3).value == 3.0
    with pytest.raises(ValueError, match="layer name"):
        PointsLayer("bad//name", [[0, 0, 0]])
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        PointsLayer("goal", [[0, 0]])
    with pytest.raises(ValueError, match="colour"):
        PointsLayer("goal", [[0, 0, 0]], colour=(300, 0, 0))
    with pytest.raises(ValueError, match="unique"):
        layer_names([ScalarLayer("a", 1), ScalarLayer("a", 2)])
    assert len(subsample(np.zeros((100, 3)), 10)) == 10


def test_a_policy_shows_nothing_by_default():
    assert RandomPolicy().view_layers() == []


def _episode(policy, steps):
    env = gym.make("NarutoRecon-v0", scene="replica_like_room", image_scale=0.1,
                   action_mode=policy.preferred_action_mode)
    policy.bind(EnvContext.from_env(env, max_episode_steps=steps))
    observation, info = env.reset(seed=0, options=policy.reset_options())
    policy.reset(observation, info, seed=0)
    actions = []
    for _ in range(steps):
        action = policy.act(observation, info)
        actions.append(np.asarray(action))
        yield policy
        observation, _, _, _, info = env.step(action)
    env.close()
    return actions


def test_frontier_policy_shows_its_frontier_and_goal():
    policy = FrontierPolicy()
    shown = [{layer.name: layer for layer in p.view_layers()} for p in _episode(policy, 25)]
    assert all("frontier" in layers and len(layers["frontier"].points) for layers in shown)
    heading = [layers for layers in shown if "goal" in layers]
    assert heading, "the policy never headed for a goal in 25 steps"
    assert len(heading[-1]["planned path"].strips[0]) >= 1


def test_reading_naruto_layers_changes_nothing():
    from naruto_agent.naruto import NarutoPolicy

    def actions(show):
        policy = NarutoPolicy()
        taken, seen = [], set()
        for live in _episode(policy, 12):
            if show:
                seen |= {layer.name for layer in live.view_layers()}
            taken.append(live.machine.plan.goal.copy() if live.machine.plan else None)
        return policy, seen

    quiet, _ = actions(show=False)
    shown, names = actions(show=True)
    assert {"goals chosen", "frontier", "uncertain surfaces", "observed space (%)"} <= names
    assert {"goal", "planned path"} <= names
    assert [plan["goal"].tolist() for plan in quiet.plans if "goal" in plan] == [
        plan["goal"].tolist() for plan in shown.plans if "goal" in plan
    ]


# -- the recorder -------------------------------------------------------------------------
def test_recording_reads_back(tmp_path):
    camera = PinholeCamera().scaled(0.05)
    recorder = EpisodeRecorder(tmp_path / "run" / "episode.rrd", camera, title="test")
    recorder.log_scene(trimesh.creation.box(extents=(4.0, 4.0, 3.0)))
    spheres = {}
    for step in range(6):
        pose = np.eye(4)
        pose[0, 3] = 0.1 * step
        observation = {
            "pose": pose,
            "rgb": np.full((camera.height, camera.width, 3), 20 * step, np.uint8),
            "depth": np.full((camera.height, camera.width), 1.5, np.float32),
        }
        layers = [PointsLayer("frontier", np.random.default_rng(step).random((5, 3))),
                  PointsLayer("goals", np.ones((2, 3)) * (step // 4)),
                  ScalarLayer("score", step)]
        if step < 3:
            layers.append(LinesLayer("planned path", (np.zeros((2, 3)) + step,)))
        spheres[step] = trimesh.creation.icosphere(subdivisions=1 + step // 2)
        recorder.observe(step, observation, {"coverage": 0.1 * step}, map_mesh=lambda s=step:
                         spheres[s], map_every=2, last=step == 5)
        recorder.log_layers(step, layers)
    recorder.log_scores(5, {"completion_ratio_pct": 42.0, "observable_completion_ratio_pct": None})
    recorder.close()

    contents = read_recording(tmp_path / "run" / "episode.rrd")
    assert contents.steps["world/camera"] == list(range(6))
    assert contents.steps["world/camera/rgb"] == list(range(6))
    assert contents.steps["world/camera/depth"] == [0]  # every 10th step
    assert contents.steps["metrics/coverage (%)"] == list(range(6))
    assert contents.steps["world/map"] == [0, 2, 4, 5]
    assert contents.steps["world/policy/frontier"] == list(range(6))
    # A layer is logged again only when it changed (the viewer shows the latest one).
    assert contents.steps["world/policy/goals"] == [0, 4]
    # The trajectory every 10 steps from the second position on, and whole at the end.
    assert contents.steps["world/trajectory"] == [5]
    # Batched by size: a chunk or so per entity, not one per step and entity.
    assert contents.chunks <= 2 * len(contents.entities)
    assert contents.steps["policy/score"] == list(range(6))
    assert contents.steps["metrics/completion ratio (%)"] == [5]
    assert "metrics/observable completion ratio (%)" not in contents.steps
    assert contents.steps["world/ground_truth"] == []  # static
    # The path was shown up to step 2 and cleared at step 3.
    assert contents.steps["world/policy/planned path"] == [0, 1, 2, 3]
    assert "Clear:is_recursive" in contents.columns["world/policy/planned path"]
    assert "Pinhole:image_from_camera" in contents.columns["world/camera"]
    assert len(contents.map_faces) == len(spheres[5].faces)
    assert np.allclose(np.linalg.norm(contents.map_vertices, axis=1), 1.0, atol=1e-5)


def test_recorder_needs_a_file_or_a_viewer():
    with pytest.raises(ValueError, match="file"):
        EpisodeRecorder(None, PinholeCamera())


def test_read_recording_says_when_the_file_is_missing(tmp_path):
    with pytest.raises(FileNotFoundError, match="no recording"):
        read_recording(tmp_path / "none.rrd")


# -- the live viewer ------------------------------------------------------------------------
def test_viewer_addresses():
    assert viewer_address("spawn")[:2] == ("127.0.0.1", 9876)
    assert viewer_address("example.org:9000") == (
        "example.org", 9000, "rerun+http://example.org:9000/proxy")
    assert viewer_address("rerun+http://10.0.0.2:9877/proxy")[1] == 9877
    with pytest.raises(ValueError, match="live viewer address"):
        viewer_address("http://example.org:9000")


def test_an_unreachable_viewer_fails_at_once_with_what_to_do(tmp_path):
    started = time.perf_counter()
    with pytest.raises(LiveViewerError, match="no Rerun viewer answers"):
        reach_viewer("127.0.0.1:9")  # the discard port: nothing listens
    with pytest.raises(LiveViewerError):
        EpisodeRecorder(tmp_path / "x.rrd", PinholeCamera(), live="127.0.0.1:9")
    assert time.perf_counter() - started < 10


def test_a_viewer_that_cannot_start_fails_with_what_to_do():
    import os

    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        pytest.skip("a display is there: a spawned viewer would open a window")
    from naruto_agent.recording.live import DEFAULT_PORT, listening

    if listening("127.0.0.1", DEFAULT_PORT):
        pytest.skip("a Rerun viewer already listens on this machine")
    with pytest.raises(LiveViewerError, match="no display"):
        reach_viewer("spawn", wait_s=5)


# -- the benchmark's --record -------------------------------------------------------------
def test_benchmark_records_every_episode(tmp_path):
    from naruto_agent.benchmark.cli import main

    out = tmp_path / "bench"
    failed = main(["--policies", "random", "--seeds", "0", "--max-episode-steps", "4",
                   "--workers", "0", "--record", "--output-dir", str(out), "--no-plots",
                   "--eval-points", "0",
                   "--eval-samples", "5000", "--image-scale", "0.1", "--no-progress"])
    assert not failed
    files = sorted((out / "recordings").rglob("*.rrd"))
    assert [path.relative_to(out / "recordings").as_posix() for path in files] == [
        "replica_like_room/random/seed0.rrd"]
    contents = read_recording(files[0])
    assert contents.steps["world/camera"] == list(range(5))
    assert contents.steps["world/map"][-1] == 4 and len(contents.map_faces) > 0
    record = json.loads(next((out / "records").rglob("*.json")).read_text())
    assert record["steps_run"] == 4


def test_stall_watchdog_triggers_show_in_the_recording(tmp_path):
    """A policy that stands still: the watchdog's trigger at step 20 is logged as a text line
    and a point, once."""
    from naruto_agent.policies import Policy, pose_action

    class StandStill(Policy):
        def __init__(self):
            super().__init__()
            self.use_stall_watchdog()

        def act(self, observation, info=None):
            self.check_stall(observation, info)
            return pose_action(observation["pose"])

        def recover_from_stall(self, event):
            return "none (a test)"

    policy = StandStill()
    camera = PinholeCamera().scaled(0.05)
    recorder = EpisodeRecorder(tmp_path / "stall.rrd", camera)
    observation = {"pose": np.eye(4)}
    for step in range(1, 26):
        policy.act(observation, {})
        recorder.log_stalls(step, policy)
    recorder.close()
    contents = read_recording(tmp_path / "stall.rrd")
    assert contents.steps["events/stalls"] == [20]
    assert contents.steps["world/stalls"] == [20]
