"""Fingerprint the library's behaviour, to check that a refactoring changes nothing.

Runs fixed-seed short episodes of every registered policy on shipped scenes (closed and open
variants), steps the batched env, generates procedural scenes, and scores a fixed mesh; it
writes what came out (coverage curves, paths, refusals, checksums) as JSON. Run it before and
after a change and compare the two files::

    python scripts/behaviour_fingerprint.py --output-file before.json
    python scripts/behaviour_fingerprint.py --output-file after.json --compare before.json

The reference TSDF fusion of Open3D is multithreaded and not bit-for-bit repeatable, so the
fingerprint leaves it out. Run it with ``--repeat`` first to see which entries repeat at all.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from naruto_agent.episode_loop import EpisodeHook


def digest(*arrays: Any) -> str:
    """A short hash of arrays' bytes, shapes and dtypes."""
    hasher = hashlib.sha256()
    for array in arrays:
        array = np.ascontiguousarray(np.asarray(array))
        hasher.update(str((array.shape, array.dtype.str)).encode())
        hasher.update(array.tobytes())
    return hasher.hexdigest()[:16]


class DepthDigests(EpisodeHook):
    """Keeps a digest of every step's depth frame."""

    def __init__(self) -> None:
        self.digests: list[str] = []

    def on_step(
        self, step: int, observation: dict[str, Any], info: dict[str, Any], last: bool
    ) -> None:
        self.digests.append(digest(observation["depth"]))


def policy_episode(policy_name: str, scene: str, steps: int, seed: int) -> dict[str, Any]:
    """A fixed-seed episode of a policy: coverage per step, path, refusals, frame hashes."""
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
    records, depths = StepRecords(), DepthDigests()
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
        "frames": digest(np.array(depths.digests)),
    }


def batched_env(num_envs: int, steps: int, seed: int) -> dict[str, Any]:
    """Checksums of the batched env's observations over a fixed-seed run."""
    from naruto_gym.vector import NarutoReconVectorEnv

    env = NarutoReconVectorEnv(num_envs, action_mode="discrete", image_scale=0.1)
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


def fingerprint() -> dict[str, Any]:
    scenes = ["replica_like_room", "two_rooms", "replica_like_room:no_ceiling+holes"]
    steps = {"passive": 60, "random": 200, "frontier": 200, "naruto": 200}
    out: dict[str, Any] = {"episodes": {}}
    for policy in ("passive", "random", "frontier", "naruto"):
        for scene in scenes:
            key = f"{policy}@{scene}"
            print(key, file=sys.stderr, flush=True)
            try:
                out["episodes"][key] = policy_episode(policy, scene, steps[policy], seed=3)
            except Exception as error:  # recorded: a change must not alter this either
                out["episodes"][key] = {"error": f"{type(error).__name__}: {error}"}
    print("batched env", file=sys.stderr, flush=True)
    out["batched_env"] = batched_env(16, 30, seed=5)
    print("procedural", file=sys.stderr, flush=True)
    out["procedural"] = procedural_scenes([0, 1, 7])
    print("scoring", file=sys.stderr, flush=True)
    out["scoring"] = scoring(seed=2)
    return out


def differences(before: Any, after: Any, where: str = "") -> list[str]:
    """Paths at which two fingerprints differ."""
    if isinstance(before, dict) and isinstance(after, dict):
        found = []
        for key in sorted(set(before) | set(after)):
            found += differences(before.get(key), after.get(key), f"{where}/{key}")
        return found
    return [] if before == after else [where or "/"]


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
        found = differences(json.loads(args.compare.read_text()), result)
        for path in found:
            print("differs:", path)
        print("same" if not found else f"{len(found)} differences")
        return 1 if found else 0
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
