"""``SharedSceneStreams``: agents in groups on shared generated scenes, each kept for a number
of episodes, for the batched env's ``scene``.

With scene streams as the batched env's ``scene`` (``"procedural:small:train"``, ...), every
agent draws and builds a scene of its own at every episode and casts its rays in that scene
alone. For training on many scenes that is the dearest part of a step. ``SharedSceneStreams``
puts the agents in groups of ``agents_per_scene``: a group explores one scene drawn from its
stream, for ``episodes_per_scene`` episodes of each of its agents, then the next scene of the
stream. A scene is built once for many episodes, and one ray cast a step carries the rays of
a whole group.

    from naruto_gym.rl.explorer_env import TRAIN_MIX
    from naruto_gym.vector import NarutoReconVectorEnv, SharedSceneStreams

    scenes = SharedSceneStreams(TRAIN_MIX, agents_per_scene=4, episodes_per_scene=4)
    envs = NarutoReconVectorEnv(16, scene=scenes, action_mode="discrete")

Agents ``0 .. G-1`` form group 0, the next ``G`` group 1, and so on (``G`` is
``agents_per_scene``; the last group may be smaller); group ``k`` draws from
``streams[k % len(streams)]``, so with as many groups as streams (or a multiple) every stream
has as many agents. A group's scene is replaced when one of its agents starts an episode after
the group has started ``G * episodes_per_scene`` episodes in it; an agent still in an episode
of the old scene moves to the new one at its next reset. A reset that seeds every agent of a
group (``reset(seed=s)``) draws the group's scene anew from a generator seeded by its first
agent's seed, so the same seed gives the same scenes and starts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from naruto_gym.scenes.stream import ProceduralSceneSpec, is_procedural_name, parse_procedural_name

__all__ = ["SharedSceneStreams"]

#: Mixed into a group's seed, so that its scene draws do not repeat its first agent's own
#: generator (seeded with the same number).
GROUP_SEED_TAG = 0x5CE9E


@dataclass(frozen=True)
class SharedSceneStreams:
    """Groups of agents sharing a scene drawn from a stream, for several episodes (module
    docstring).

    Args:
        streams: scene stream names (``"procedural:<kind>[:<split>][:<openings>]"`` without a
            seed, e.g. :data:`naruto_gym.rl.explorer_env.TRAIN_MIX`), at least one.
        agents_per_scene: the agents of a group, who share its scene.
        episodes_per_scene: episodes each agent of a group starts in a scene before the
            group moves on to the next scene of its stream.

    Raises:
        ValueError: no stream, a name that is not a scene stream (a fixed scene or no
            procedural name), or a count that is not a positive integer.
    """

    streams: tuple[str, ...]
    agents_per_scene: int = 4
    episodes_per_scene: int = 4

    def __post_init__(self) -> None:
        streams = (self.streams,) if isinstance(self.streams, str) else tuple(self.streams)
        if not streams:
            raise ValueError("SharedSceneStreams needs at least one scene stream")
        for name in streams:
            if not is_procedural_name(name) or not parse_procedural_name(name).is_stream:
                raise ValueError(
                    f"SharedSceneStreams takes scene streams such as 'procedural:small:train' "
                    f"(no seed), got {name!r}; for fixed scenes pass them to the env's scene "
                    "directly"
                )
        object.__setattr__(self, "streams", streams)
        for name in ("agents_per_scene", "episodes_per_scene"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
            object.__setattr__(self, name, int(value))

    def group_of(self, agent: int) -> int:
        """The group of ``agent``."""
        return int(agent) // self.agents_per_scene

    def agent_streams(self, num_envs: int) -> list[str]:
        """Each of ``num_envs`` agents' stream (its group's)."""
        return [self.streams[self.group_of(i) % len(self.streams)] for i in range(num_envs)]

    def specs(self) -> list[ProceduralSceneSpec]:
        """The parsed streams, in order."""
        return [parse_procedural_name(name) for name in self.streams]

    def share(self, start: int) -> SharedSceneStreams:
        """The same groups for a share of the agents that starts at agent ``start`` (a
        worker's share of a sharded env): its first group is agent ``start``'s, whose stream
        comes first.

        Raises:
            ValueError: ``start`` is not the first agent of a group.
        """
        if start % self.agents_per_scene:
            raise ValueError(
                f"a share of agents starting at agent {start} splits a group of "
                f"agents_per_scene={self.agents_per_scene}: give each worker a multiple of "
                "agents_per_scene agents (num_envs a multiple of workers * agents_per_scene)"
            )
        turn = self.group_of(start) % len(self.streams)
        return SharedSceneStreams(
            self.streams[turn:] + self.streams[:turn],
            self.agents_per_scene,
            self.episodes_per_scene,
        )


def group_generator(seed: int) -> np.random.Generator:
    """The scene generator of a group whose first agent is reset with ``seed``."""
    return np.random.default_rng([int(seed), GROUP_SEED_TAG])


def group_sizes(shared: SharedSceneStreams, num_envs: int) -> list[int]:
    """The number of agents of each group of ``num_envs`` agents."""
    size = shared.agents_per_scene
    return [min(size, num_envs - start) for start in range(0, num_envs, size)]
