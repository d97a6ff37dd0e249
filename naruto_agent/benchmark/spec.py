"""What one benchmark episode is: scene, policy, seed, budget and env settings.

An :class:`EpisodeSpec` is plain data (JSON-able), so it travels to worker processes and Ray
tasks unchanged, and its hash tells a rerun whether a stored record was made with the same
settings.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from naruto_agent.benchmark.checks import check_scene
from naruto_gym.scenes.units import MESH_UNITS
from naruto_gym.utils.checks import check_bool, check_choice, check_integer, check_number

UP_AXES = ("x", "y", "z", "-x", "-y", "-z", "auto")
"""Up axes of a mesh file (``"auto"``: read from a recognised dataset layout)."""
TRAJECTORY_FILE = "traj.txt"
#: Env keywords the harness sets itself (from the scene argument, the policy and the budget),
#: which ``env_kwargs`` may therefore not hold.
SPEC_ENV_KEYWORDS = frozenset(
    {"scene", "up_axis", "mesh_units", "action_mode", "max_episode_steps"}
)
#: Fields added to :class:`EpisodeSpec` after records were stored, with their defaults: the
#: hash leaves them out at these values.
HASH_OMITS_AT_DEFAULT: dict[str, Any] = {
    "mesh_units": "m",
    "ground_truth": "auto",
    "reference_image_scale": 0.25,
}
_NO_DEFAULT = object()


@dataclass(frozen=True)
class SceneSpec:
    """A scene argument: a catalogue name or a mesh path, with the mesh file's up axis and
    length unit (``"m"``, ``"cm"`` or ``"mm"``, rescaled to metres on loading)."""

    scene: str
    up_axis: str = "z"
    mesh_units: str = "m"

    @property
    def label(self) -> str:
        """Short name for tables and folders: the catalogue name, else the mesh file's stem
        (its folder's name when the file is called ``mesh``)."""
        path = Path(self.scene)
        if path.suffix == "":
            return _slug(self.scene)
        stem = path.parent.name if path.stem == "mesh" and path.parent.name else path.stem
        return _slug(stem)

    @property
    def is_path(self) -> bool:
        return Path(self.scene).suffix != ""


def parse_scene(argument: str, up_axis: str = "z", mesh_units: str = "m") -> SceneSpec:
    """``"NAME"``, ``"PATH"`` or ``"PATH@AXIS"`` (e.g. ``room.obj@y``) to a :class:`SceneSpec`.

    Args:
        argument: the scene argument.
        up_axis: the up axis of a mesh path written without ``@AXIS`` (``--up-axis``); an
            ``@AXIS`` wins over it, and catalogue names ignore both.
        mesh_units: the length unit of a mesh path (``--mesh-units``); catalogue names,
            which are in metres, ignore it.

    Raises:
        ValueError: an empty scene, an unknown axis or an unknown unit.
    """
    check_choice("up_axis", up_axis, UP_AXES)
    check_choice("mesh_units", mesh_units, tuple(MESH_UNITS))
    scene = argument
    if "@" in argument:
        scene, _, written = argument.rpartition("@")
        if written not in UP_AXES:
            raise ValueError(
                f"unknown up axis {written!r} in {argument!r}; write PATH@AXIS with AXIS one "
                f"of {', '.join(UP_AXES)}"
            )
        up_axis = written
    if not scene:
        raise ValueError(f"empty scene in {argument!r}; use NAME, PATH or PATH@AXIS")
    if not SceneSpec(scene).is_path:
        return SceneSpec(scene)
    return SceneSpec(scene, up_axis, mesh_units)


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "scene"


def split_policy_kwargs(kwargs: dict[str, Any], policies: list[str]) -> dict[str, dict[str, Any]]:
    """Constructor arguments per policy from either form of ``--policy-kwargs``.

    Keyed by policy (``{"random": {"max_run_steps": 20}}``): every key is one of
    ``policies`` and every value an object. Flat (``{"max_run_steps": 20}``): the arguments
    of the one policy, allowed when there is one policy.

    Raises:
        ValueError: a flat form with several policies, or keys that name no given policy.
    """
    if not kwargs:
        return {}
    keyed = all(key in policies and isinstance(value, dict) for key, value in kwargs.items())
    if keyed:
        return {key: dict(value) for key, value in kwargs.items()}
    if len(policies) == 1:
        return {policies[0]: dict(kwargs)}
    strays = sorted(key for key in kwargs if key not in policies)
    raise ValueError(
        f"--policy-kwargs with several policies must be keyed by policy name, e.g. "
        f"'{{\"{policies[0]}\": {{...}}}}'; {strays or sorted(kwargs)} name no policy of "
        f"{policies} (with one policy its arguments may also be given directly)"
    )


def policy_label(policy: str) -> str:
    """Registry name, or the class name of a ``module:Class`` import path."""
    return _slug(policy.rpartition(":")[2] if ":" in policy else policy)


@dataclass(frozen=True)
class EpisodeSpec:
    """One benchmark episode.

    Attributes:
        scene: catalogue name or mesh path.
        up_axis: up axis of a mesh file.
        policy: registry name (``passive``, ``random``, ``frontier``) or ``module:Class``.
        seed: episode seed (env reset and the policy's own randomness).
        steps: step budget.
        image_scale: camera resolution factor (0.25 gives 170 x 300).
        policy_kwargs: constructor arguments of the policy.
        env_kwargs: further ``gymnasium.make`` keyword arguments of the env.
        reconstruct: fuse frames with the reference TSDF mapper and score the result.
        eval_points: completion-ratio checkpoints during the episode (0: final only).
        eval_samples: surface samples per mesh of the final score (200,000 as published).
        checkpoint_samples: surface samples per mesh at the checkpoints (cheaper).
        eval_samples_per_m2: least density of a mesh's samples where nearest distances are
            measured to it (2,000 per m^2, the published density on Replica; 0 for the
            sample counts alone, as the published evaluation). Large scenes need it: see
            :mod:`naruto_gym.evaluation.metrics`.
        device: Open3D device of the reference mapper.
        mesh_units: length unit of a mesh file (``"m"``, ``"cm"``, ``"mm"``).
        ground_truth: what the scores are measured against: ``"auto"`` (the culled ground
            truth where the scene folder holds one) or ``"full"``; see
            :mod:`naruto_gym.evaluation.ground_truth`.
        reference_image_scale: the camera resolution factor the reference map is fused at,
            whatever ``image_scale`` the policy sees (0.25, the leaderboard's); see
            :mod:`naruto_agent.benchmark.reference_frames`.
    """

    scene: str
    policy: str
    seed: int
    steps: int
    up_axis: str = "z"
    image_scale: float = 0.25
    policy_kwargs: dict[str, Any] = field(default_factory=dict)
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    reconstruct: bool = True
    eval_points: int = 4
    eval_samples: int = 200_000
    checkpoint_samples: int = 50_000
    eval_samples_per_m2: float = 2_000.0
    device: str = "auto"
    mesh_units: str = "m"
    ground_truth: str = "auto"
    reference_image_scale: float = 0.25

    def __post_init__(self) -> None:
        check_integer("seed", self.seed, low=0)
        check_integer("steps", self.steps, low=1)
        check_choice("up_axis", self.up_axis, UP_AXES)
        check_choice("mesh_units", self.mesh_units, tuple(MESH_UNITS))
        set_here = sorted(SPEC_ENV_KEYWORDS & set(self.env_kwargs))
        if set_here:
            raise ValueError(
                f"env_kwargs must not set {set_here}: the harness sets them from the scene "
                "argument, the policy and --max-episode-steps (give a mesh file's axis and "
                "unit with --up-axis / --mesh-units or PATH@AXIS)"
            )
        check_number("image_scale", self.image_scale, low=0.0)
        check_number("reference_image_scale", self.reference_image_scale, low=0.0)
        check_choice("ground_truth", self.ground_truth, ("auto", "full"))
        check_bool("reconstruct", self.reconstruct)
        check_integer("eval_points", self.eval_points, low=0)
        check_integer("eval_samples", self.eval_samples, low=1)
        check_integer("checkpoint_samples", self.checkpoint_samples, low=1)
        check_number(
            "eval_samples_per_m2 (0: no density bound)",
            self.eval_samples_per_m2,
            low=0.0,
            low_open=False,
        )

    @property
    def scene_label(self) -> str:
        return SceneSpec(self.scene, self.up_axis).label

    @property
    def policy_label(self) -> str:
        return policy_label(self.policy)

    @property
    def episode_id(self) -> str:
        return f"{self.scene_label}/{self.policy_label}/seed{self.seed}"

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> EpisodeSpec:
        return cls(**data)

    @property
    def config_hash(self) -> str:
        """Short hash of every setting: a stored record with another hash is out of date.

        A field of :data:`HASH_OMITS_AT_DEFAULT` at its default is left out, so that the
        records stored before the field existed stay current."""
        settings = {
            name: value
            for name, value in self.as_dict().items()
            if HASH_OMITS_AT_DEFAULT.get(name, _NO_DEFAULT) != value
        }
        text = json.dumps(settings, sort_keys=True, default=str)
        return hashlib.sha1(text.encode()).hexdigest()[:12]

    def record_path(self, output_dir: str | Path) -> Path:
        """Where this episode's record lives under an output folder."""
        return (
            Path(output_dir)
            / "records"
            / self.scene_label
            / self.policy_label
            / f"seed{self.seed}.json"
        )


def default_policy_kwargs(policy: str, scene: SceneSpec) -> dict[str, Any]:
    """Policy arguments the harness fills in: a passive policy replays the ``traj.txt`` that
    lies beside a mesh file (e.g. the Replica sample); others get nothing."""
    if policy == "passive" and scene.is_path:
        trajectory = Path(scene.scene).parent / TRAJECTORY_FILE
        if trajectory.is_file():
            return {"trajectory": str(trajectory.resolve())}
    return {}


def build_specs(
    scenes: list[str],
    policies: list[str],
    seeds: list[int],
    steps: int,
    up_axis: str = "z",
    mesh_units: str = "m",
    **settings: Any,
) -> list[EpisodeSpec]:
    """The episodes of scenes x policies x seeds, ordered scene-major.

    Args:
        scenes: ``NAME``, ``PATH`` or ``PATH@AXIS`` arguments.
        policies: policy names or import paths.
        seeds: episode seeds.
        steps: step budget of every episode.
        up_axis: the up axis of mesh paths written without ``@AXIS``.
        mesh_units: the length unit of mesh paths (catalogue names are in metres).
        **settings: further :class:`EpisodeSpec` fields (``image_scale``, ``eval_points``...);
            ``policy_kwargs`` here is a dict from policy name to its arguments, or the
            arguments themselves when there is one policy (:func:`split_policy_kwargs`).

    A policy file (``path/to/file.py:Class``) is recorded by its absolute path, so that
    workers in another folder find it.
    """
    if not scenes or not policies or not seeds:
        raise ValueError("need at least one scene, one policy and one seed")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct, got {seeds}")
    per_policy = split_policy_kwargs(settings.pop("policy_kwargs", {}) or {}, policies)
    specs = []
    for argument in scenes:
        scene = parse_scene(argument, up_axis, mesh_units)
        check_scene(scene.scene, scene.is_path)
        for policy in policies:
            kwargs = {**default_policy_kwargs(policy, scene), **per_policy.get(policy, {})}
            for seed in seeds:
                specs.append(
                    EpisodeSpec(
                        scene=scene.scene,
                        up_axis=scene.up_axis,
                        mesh_units=scene.mesh_units,
                        policy=_absolute_policy_file(policy),
                        seed=int(seed),
                        steps=int(steps),
                        policy_kwargs=kwargs,
                        **settings,
                    )
                )
    ids = [spec.episode_id for spec in specs]
    if len(set(ids)) != len(ids):
        raise ValueError("two scenes or policies share a label; give them distinct names")
    return specs


def _absolute_policy_file(policy: str) -> str:
    """``path/to/file.py:Class`` with the file's absolute path; other names unchanged."""
    from naruto_agent.policies.registry import is_policy_file

    source, separator, attribute = policy.rpartition(":")
    if not separator or not is_policy_file(source):
        return policy
    return f"{Path(source).expanduser().resolve()}:{attribute}"
