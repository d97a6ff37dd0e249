"""The checks of a run made before any episode starts: its scene names (policies are
checked by ``naruto_agent.benchmark.cli.check_policies``), and how its settings differ from
the leaderboard's.

A typo in one name among many would otherwise surface as a failed record for every episode of
that scene, after the other episodes had run; the check reads no mesh. A run at other
settings than the leaderboard's is said so before it starts and in its records and table.
"""

from __future__ import annotations

from typing import Any

from naruto_gym.scenes.catalogue import check_scene_name


def check_scene(scene: str, is_path: bool = False) -> None:
    """Raise ``ValueError`` when ``scene`` (a catalogue name, ``NAME:OPENINGS`` or
    ``procedural:<kind>:<seed>``) names nothing an episode could load.

    Mesh paths (``is_path``) are left to the episode: the worker that runs it (a Ray node,
    say) may see files this machine does not, and a missing one is recorded as that
    episode's failure.
    """
    if is_path:
        return
    try:
        check_scene_name(scene)
    except FileNotFoundError as error:
        raise ValueError(str(error)) from None


#: The settings of the leaderboard's runs (docs/benchmarks/leaderboard.md) that a row's scores
#: depend on, by :class:`~naruto_agent.benchmark.spec.EpisodeSpec` field.
LEADERBOARD_SETTINGS: dict[str, Any] = {
    "image_scale": 0.25,
    "reference_image_scale": 0.25,
    "eval_samples": 200_000,
    "eval_samples_per_m2": 2_000.0,
    "env_kwargs": {},
    "reconstruct": True,
    "ground_truth": "auto",
}
#: Of :data:`LEADERBOARD_SETTINGS`, the one that changes what the policy sees but not how the
#: reference map is scored (:mod:`~naruto_agent.benchmark.reference_frames`).
POLICY_ONLY_SETTINGS = frozenset({"image_scale"})


def leaderboard_differences(settings: dict[str, Any]) -> dict[str, Any]:
    """How an episode's settings (an ``EpisodeSpec.as_dict()``) differ from the leaderboard's.

    Returns:
        ``{"differences": [...], "scores_comparable": bool}``: one line per differing setting
        (``"image_scale 0.1 (leaderboard: 0.25)"``), and whether the reference map's scores
        still compare with a leaderboard row (only the policy's camera differs: the map is
        fused at the leaderboard's camera whatever the policy sees).
    """
    differences, comparable = [], True
    for name, expected in LEADERBOARD_SETTINGS.items():
        value = settings.get(name, expected)
        if value != expected:
            differences.append(f"{name} {value!r} (leaderboard: {expected!r})")
            comparable = comparable and name in POLICY_ONLY_SETTINGS
    return {"differences": differences, "scores_comparable": comparable}


def leaderboard_note(differences: list[str], scores_comparable: bool) -> str:
    """The note a run prints (and its table carries) when its settings differ from the
    leaderboard's; empty when they do not."""
    if not differences:
        return ""
    head = f"settings differ from the leaderboard's: {'; '.join(differences)}. "
    if scores_comparable:
        return head + (
            "The reference map is still fused at the leaderboard's camera and scored as the "
            "leaderboard is, so its scores compare with a leaderboard row; the policy's own "
            "map, its coverage and its behaviour follow its own camera."
        )
    return head + (
        "The scores do not compare with the leaderboard's rows; run with the leaderboard's "
        "settings to compare."
    )
