"""Fingerprint the library's behaviour, to check that a refactoring changes nothing.

Runs fixed-seed short episodes of every registered policy on shipped scenes (closed and open
variants), steps the batched env, generates procedural scenes, and scores a fixed mesh; it
writes what came out (coverage curves, paths, refusals, depth-frame summaries, checksums) as
JSON. Run it before and after a change and compare the two files::

    python scripts/behaviour_fingerprint.py --output-file before.json
    python scripts/behaviour_fingerprint.py --output-file after.json --compare before.json

``--compare`` says "same" when every entry is equal, except the episodes' depth frames, which
need only agree within :data:`DEPTH_TOLERANCE_M` (their summaries: valid-pixel count exactly;
mean, minimum, maximum and a sparse grid of pixels within the tolerance). Each episode also
keeps an exact digest of its frames; the comparison lists where those differ, for
information, but they do not decide "same".

The reference TSDF fusion of Open3D is multithreaded and not bit-for-bit repeatable, so the
fingerprint leaves it out.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.episode_loop import EpisodeHook

#: Metres by which two fingerprints' depth summaries may differ and still be "same": float
#: rounding. The rasterizing and the ray-casting pinhole backends hit the same triangles but
#: compute the distance along a pixel's ray in float32 and float64: their depths differ by
#: at most about 1e-6 m on 99.99 % of the pixels in rooms of a few metres (docs/environment.md,
#: "Pinhole backends"), which moves a frame's mean, extremes and grid far less than this. A
#: change of behaviour (another pose, another triangle hit) moves them by millimetres or more.
DEPTH_TOLERANCE_M = 1e-4
#: Rows and columns of the sparse grid of pixels whose depth each frame's summary keeps.
DEPTH_GRID_SIDE = 8
#: Decimals the depth summaries are stored with (well below the tolerance).
DEPTH_DECIMALS = 7
#: The summary fields compared within :data:`DEPTH_TOLERANCE_M`; ``valid`` must be equal.
DEPTH_FIELDS_WITHIN_TOLERANCE = ("mean", "min", "max", "grid")


def digest(*arrays: Any) -> str:
    """A short hash of arrays' bytes, shapes and dtypes."""
    hasher = hashlib.sha256()
    for array in arrays:
        array = np.ascontiguousarray(np.asarray(array))
        hasher.update(str((array.shape, array.dtype.str)).encode())
        hasher.update(array.tobytes())
    return hasher.hexdigest()[:16]


def depth_summary(depth: np.ndarray) -> dict[str, Any]:
    """What a depth frame is compared by: its valid (hit) pixel count, the mean, minimum
    and maximum of its valid depths (0 when none), and the depths at a regular
    ``DEPTH_GRID_SIDE`` x ``DEPTH_GRID_SIDE`` grid of pixels (0 where no hit)."""
    depth = np.asarray(depth, np.float64)
    valid = depth[depth > 0]
    rows = np.linspace(0, depth.shape[0] - 1, DEPTH_GRID_SIDE).round().astype(int)
    columns = np.linspace(0, depth.shape[1] - 1, DEPTH_GRID_SIDE).round().astype(int)
    grid = depth[np.ix_(rows, columns)].ravel()
    return {
        "valid": int(valid.size),
        "mean": round(float(valid.mean()) if valid.size else 0.0, DEPTH_DECIMALS),
        "min": round(float(valid.min()) if valid.size else 0.0, DEPTH_DECIMALS),
        "max": round(float(valid.max()) if valid.size else 0.0, DEPTH_DECIMALS),
        "grid": [round(float(value), DEPTH_DECIMALS) for value in grid],
    }


class DepthFrames(EpisodeHook):
    """Keeps every step's depth frame as a summary (:func:`depth_summary`) and a digest."""

    def __init__(self) -> None:
        self.summaries: list[dict[str, Any]] = []
        self.digests: list[str] = []

    def on_step(
        self, step: int, observation: dict[str, Any], info: dict[str, Any], last: bool
    ) -> None:
        self.summaries.append(depth_summary(observation["depth"]))
        self.digests.append(digest(observation["depth"]))


def policy_episode(policy_name: str, scene: str, steps: int, seed: int) -> dict[str, Any]:
    """A fixed-seed episode of a policy: coverage per step, path, refusals, and its depth
    frames (per-step summaries and one digest of them all)."""
    import gymnasium as gym

    import naruto_gym  # noqa: F401
    from naruto_agent.episode_loop import StepRecords, run_episode_loop
    from naruto_agent.policies import make_policy

    kwargs: dict[str, Any] = {}
    if policy_name == "naruto":
        # A long planning limit: the plan then depends on the seed, not on the load.
        kwargs = {"mapper_kind": "tsdf", "planner": {"time_limit_s": 120.0}}
    policy = make_policy(policy_name, **kwargs)
    env = gym.make(
        "NarutoRecon-v0",
        scene=scene,
        action_mode=policy.preferred_action_mode,
        image_scale=0.125,
        max_episode_steps=steps,
    )
    records, depths = StepRecords(), DepthFrames()
    run_episode_loop(env, policy, steps, seed, [records, depths])
    refusals = sum(records.collisions.values())
    coverage = [round(value, 6) for value in records.coverage[1:]]
    positions = [np.round(position, 4).tolist() for position in records.positions[1:]]
    env.close()
    policy.close()
    return {
        "coverage": coverage,
        "path": positions,
        "refusals": refusals,
        "depth": depths.summaries,
        "depth_digest": digest(np.array(depths.digests)),
    }


def batched_env(num_envs: int, steps: int, seed: int) -> dict[str, Any]:
    """Checksums of the batched env's observations over a fixed-seed run, its frames drawn
    as RL draws them (``pinhole_backend="auto"``)."""
    from naruto_gym.vector import NarutoReconVectorEnv

    env = NarutoReconVectorEnv(
        num_envs, action_mode="discrete", image_scale=0.1, pinhole_backend="auto"
    )
    env.action_space.seed(seed)
    observations, _ = env.reset(seed=seed)
    hashes = [digest(*(observations[key] for key in sorted(observations)))]
    rng = np.random.default_rng(seed)
    rewards = []
    for _ in range(steps):
        actions = rng.integers(0, 10, num_envs)
        observations, reward, _, _, info = env.step(actions)
        hashes.append(digest(*(observations[key] for key in sorted(observations))))
        rewards.append(np.round(np.asarray(reward, float), 6).tolist())
    env.close()
    return {"observations": digest(np.array(hashes)), "rewards": digest(np.array(rewards))}


def procedural_scenes(seeds: list[int]) -> dict[str, str]:
    """Checksums of generated scenes (vertices, faces, colours)."""
    from naruto_gym.scenes.catalogue import resolve_scene

    out = {}
    for kind in ("room", "apartment"):
        for seed in seeds:
            scene = resolve_scene(f"procedural:{kind}:{seed}")
            out[f"{kind}:{seed}"] = digest(
                np.round(scene.vertices, 6), scene.faces, scene.corner_colours
            )
    return out


def scoring(seed: int) -> dict[str, Any]:
    """The scores of a fixed mesh (the ground truth shifted 1 cm) after a short episode."""
    import gymnasium as gym
    import trimesh

    import naruto_gym  # noqa: F401

    env = gym.make("NarutoRecon-v0", image_scale=0.125, action_mode="discrete")
    env.reset(seed=seed)
    for action in [0, 0, 6, 6, 6, 0, 7, 7, 0, 0]:
        env.step(action)
    scene = env.unwrapped.scene
    mesh = trimesh.Trimesh(np.asarray(scene.vertices) + 0.01, np.asarray(scene.faces))
    scores = env.unwrapped.evaluate(mesh)
    env.close()
    return {
        key: (round(float(value), 6) if isinstance(value, (int, float)) else value)
        for key, value in scores.items()
        if not isinstance(value, (dict, list))
    }


#: Env steps of a policy's fingerprint episodes (200 for a policy not listed).
EPISODE_STEPS = {"passive": 60}


def fingerprint() -> dict[str, Any]:
    """Every registered policy's episodes on three scenes, the batched env, generated scenes
    and the scores of a fixed mesh."""
    scenes = ["replica_like_room", "two_rooms", "replica_like_room:no_ceiling+holes"]
    from naruto_agent.policies import policy_names

    out: dict[str, Any] = {"episodes": {}}
    for policy in policy_names():
        for scene in scenes:
            key = f"{policy}@{scene}"
            print(key, file=sys.stderr, flush=True)
            try:
                steps = EPISODE_STEPS.get(policy, 200)
                out["episodes"][key] = policy_episode(policy, scene, steps, seed=3)
            except Exception as error:  # recorded: a change must not alter this either
                out["episodes"][key] = {"error": f"{type(error).__name__}: {error}"}
    print("batched env", file=sys.stderr, flush=True)
    out["batched_env"] = batched_env(16, 30, seed=5)
    print("procedural", file=sys.stderr, flush=True)
    out["procedural"] = procedural_scenes([0, 1, 7])
    print("scoring", file=sys.stderr, flush=True)
    out["scoring"] = scoring(seed=2)
    return out


@dataclass
class Comparison:
    """Where two fingerprints differ.

    Attributes:
        differences: paths at which they differ beyond the tolerance ("same" when empty).
        exact_depth_differences: paths of depth digests that differ while the depth frames
            agree within the tolerance (information only).
        max_depth_difference_m: the largest difference between compared depth values.
    """

    differences: list[str] = field(default_factory=list)
    exact_depth_differences: list[str] = field(default_factory=list)
    max_depth_difference_m: float = 0.0

    @property
    def same(self) -> bool:
        return not self.differences


def compare(
    before: Any, after: Any, tolerance_m: float = DEPTH_TOLERANCE_M, where: str = ""
) -> Comparison:
    """Compare two fingerprints: entries named ``depth`` (lists of :func:`depth_summary`)
    within ``tolerance_m``, entries named ``depth_digest`` for information only, every other
    entry exactly."""
    result = Comparison()
    _compare_into(result, before, after, tolerance_m, where)
    return result


def _compare_into(
    result: Comparison, before: Any, after: Any, tolerance_m: float, where: str
) -> None:
    if isinstance(before, dict) and isinstance(after, dict):
        depth_agrees = True
        for key in sorted(set(before) | set(after)):  # "depth" sorts before "depth_digest"
            path = f"{where}/{key}"
            if key in before and key in after and key == "depth":
                depth_agrees = _compare_depth(result, before[key], after[key], tolerance_m, path)
            elif key in before and key in after and key == "depth_digest":
                if before[key] != after[key] and depth_agrees:
                    result.exact_depth_differences.append(path)
            else:
                _compare_into(result, before.get(key), after.get(key), tolerance_m, path)
    elif before != after:
        result.differences.append(where or "/")


def _compare_depth(
    result: Comparison, before: Any, after: Any, tolerance_m: float, where: str
) -> bool:
    """Two episodes' depth summaries: the same frame count and valid-pixel counts, the depths
    within the tolerance. Adds one difference for the episode when they are not, and says
    whether they are."""
    if not isinstance(before, list) or not isinstance(after, list) or len(before) != len(after):
        result.differences.append(f"{where} (frame count)")
        return False
    beyond, largest = [], 0.0
    for index, (one, other) in enumerate(zip(before, after, strict=True)):
        agrees = one.get("valid") == other.get("valid")
        for name in DEPTH_FIELDS_WITHIN_TOLERANCE:
            first = np.atleast_1d(np.asarray(one.get(name), float))
            second = np.atleast_1d(np.asarray(other.get(name), float))
            if first.shape != second.shape:
                agrees = False
                continue
            gap = float(np.max(np.abs(first - second), initial=0.0))
            largest = max(largest, gap)
            agrees = agrees and gap <= tolerance_m  # NaN counts as a difference
        if not agrees:
            beyond.append(index)
    result.max_depth_difference_m = max(result.max_depth_difference_m, largest)
    if beyond:
        result.differences.append(
            f"{where} ({len(beyond)} of {len(before)} frames beyond {tolerance_m:g} m or with "
            f"other hit counts, the first {beyond[0]}; largest difference {largest:.3g} m)"
        )
    return not beyond


def main() -> int:
    from naruto_agent.cli_args import refuse_renamed_flags

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-file", type=Path, required=True, help="where to write the JSON")
    parser.add_argument("--compare", type=Path, help="a fingerprint to compare against")
    refuse_renamed_flags(parser, ["--output-file", "--compare"])
    args = parser.parse_args()
    result = fingerprint()
    args.output_file.write_text(json.dumps(result, indent=1))
    if args.compare:
        comparison = compare(json.loads(args.compare.read_text()), result)
        for path in comparison.differences:
            print("differs:", path)
        for path in comparison.exact_depth_differences:
            print("depth digest differs (frames within the tolerance):", path)
        print(
            f"largest depth difference: {comparison.max_depth_difference_m:.3g} m "
            f"(tolerance {DEPTH_TOLERANCE_M:g} m)"
        )
        print("same" if comparison.same else f"{len(comparison.differences)} differences")
        return 0 if comparison.same else 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
