"""The check of a run's scene names, made before any episode starts (policies are checked
by ``naruto_agent.benchmark.cli.check_policies``).

A typo in one name among many would otherwise surface as a failed record for every episode of
that scene, after the other episodes had run; the check reads no mesh.
"""

from __future__ import annotations

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

