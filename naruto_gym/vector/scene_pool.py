"""The batched env's scenes: per agent the runtime of its current scene, built once per scene.

Agents given the same scene share one :class:`~naruto_gym.envs.scene_runtime.SceneRuntime`
(one ray-casting structure, one set of coverage samples), so a step casts the rays of all of
them in one call. Agents on a ``"procedural:..."`` stream get a new generated scene every
episode; those runtimes are kept in a bounded cache, keyed by the scene's seed, so a scene
drawn again is not built again. Agents of a :class:`~naruto_gym.vector.shared_scenes.
SharedSceneStreams` group share their group's generated scene for several episodes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from naruto_gym.envs.scene_runtime import SceneRuntime
from naruto_gym.envs.settings import EnvSettings
from naruto_gym.scenes.stream import (
    LruCache,
    ProceduralSceneSpec,
    is_procedural_name,
    parse_procedural_name,
)
from naruto_gym.sensors.pinhole import AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL_BATCHED
from naruto_gym.utils.threads import run_parallel
from naruto_gym.vector.shared_scenes import SharedSceneStreams, group_generator, group_sizes


@dataclass
class _Group:
    """A :class:`SharedSceneStreams` group's state: its stream, its agents, the episodes its
    agents start in a scene before the next (agents times ``episodes_per_scene``), its scene
    generator, its current scene's key, the episodes started in it, and the runtime it
    holds."""

    stream: ProceduralSceneSpec
    agents: range
    starts_per_scene: int
    generator: np.random.Generator | None = None
    key: tuple | None = None
    started: int = 0
    #: The runtime of the scene it last gave an agent, and that scene's key.
    held: SceneRuntime | None = None
    held_key: tuple | None = None


class ScenePool:
    """Per agent, the runtime of its current scene.

    Args:
        scenes: one entry per agent: a scene as ``NarutoReconEnv`` takes it, or a stream name
            ``"procedural:room"`` / ``"procedural:apartment"`` (with an optional ``":train"``
            or ``":test"`` split). Entries that are the same object share one runtime. Or a
            :class:`SharedSceneStreams` for ``num_envs`` agents.
        settings: the env's settings (the pinhole backend's ``"auto"`` choice is made for
            many frames at a time).
        cache_size: generated scenes' runtimes kept for reuse.

    Raises:
        ValueError: for a malformed procedural name.
    """

    def __init__(
        self,
        scenes: Sequence[Any] | SharedSceneStreams,
        settings: EnvSettings,
        cache_size: int,
        num_envs: int | None = None,
    ) -> None:
        self.settings = settings
        self._streams: list[ProceduralSceneSpec | None] = []
        self._cache: LruCache[SceneRuntime] = LruCache(cache_size)
        #: Per agent its SharedSceneStreams group (None: the agent draws its own scenes).
        self._group_of: list[_Group | None] = []
        self._runtimes: list[SceneRuntime | None] = []
        if isinstance(scenes, SharedSceneStreams):
            self._set_groups(scenes, int(num_envs))
            return
        self._group_of = [None] * len(scenes)
        self._runtimes = [None] * len(scenes)
        fixed: dict[int, SceneRuntime] = {}
        for index, item in enumerate(scenes):
            if is_procedural_name(item):
                spec = parse_procedural_name(item)
                self._streams.append(spec if spec.is_stream else None)
                if not spec.is_stream:
                    self._runtimes[index] = self._cached(("fixed", item), item)
                continue
            self._streams.append(None)
            key = id(item)
            if key not in fixed:
                fixed[key] = self.build(item)
            self._runtimes[index] = fixed[key]

    def _set_groups(self, shared: SharedSceneStreams, num_envs: int) -> None:
        specs = shared.specs()
        start = 0
        for k, size in enumerate(group_sizes(shared, num_envs)):
            group = _Group(
                specs[k % len(specs)],
                range(start, start + size),
                size * shared.episodes_per_scene,
            )
            self._group_of += [group] * size
            self._streams += [group.stream] * size
            start += size
        self._runtimes = [None] * num_envs

    # -- what agents see -------------------------------------------------------------------
    def __getitem__(self, agent: int) -> SceneRuntime | None:
        """The runtime of ``agent``'s current scene (None for a stream before its reset)."""
        return self._runtimes[agent]

    @property
    def runtimes(self) -> list[SceneRuntime | None]:
        """Per agent, its current scene's runtime (None on a stream before the first reset)."""
        return list(self._runtimes)

    def distinct(self) -> list[SceneRuntime]:
        """The runtimes agents are in now, each once, in the order of their first agent."""
        return list(
            {id(runtime): runtime for runtime in self._runtimes if runtime is not None}.values()
        )

    @property
    def has_streams(self) -> bool:
        """Whether some agent draws new generated scenes (every episode, or with its group)."""
        return any(self._streams)

    @property
    def cached(self) -> int:
        """How many runtimes of generated scenes the cache holds."""
        return len(self._cache)

    def template(self) -> SceneRuntime:
        """A runtime to take the spaces and cameras from: the first agent's, or with only
        streams one generated scene's (they do not depend on the scene)."""
        first = next((runtime for runtime in self._runtimes if runtime is not None), None)
        if first is not None:
            return first
        spec = next(s for s in self._streams if s is not None)
        return self._cached(
            (spec.kind, spec.draw_seed(np.random.default_rng(0)), spec.openings), spec
        )

    def groups(self, agents: np.ndarray, selected: np.ndarray) -> list[np.ndarray]:
        """Indices into ``agents`` (where ``selected``), grouped by the agents' scene, groups
        in the order of their first agent."""
        picked = np.flatnonzero(selected)
        if len(picked) == 0:
            return []
        runtimes = [self._runtimes[agent] for agent in np.asarray(agents)[picked].tolist()]
        first = runtimes[0]
        if all(runtime is first for runtime in runtimes):  # one scene for all: no dictionary
            return [picked.astype(np.int64)]
        groups: dict[int, list[int]] = {}
        for k, runtime in zip(picked.tolist(), runtimes, strict=True):
            groups.setdefault(id(runtime), []).append(k)
        return [np.array(group, np.int64) for group in groups.values()]

    # -- building --------------------------------------------------------------------------
    def build(self, scene: Any) -> SceneRuntime:
        """A new runtime of ``scene`` (a name, path or ``Scene``), its coverage samples (and
        observable surface) made at once."""
        runtime = SceneRuntime.load(
            scene,
            self.settings,
            # Many frames at a time: "auto" rasterizes denser meshes than for one frame.
            auto_max_triangles_per_pixel=AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL_BATCHED,
        )
        runtime.coverage  # noqa: B018 - builds the samples (and observable surface) now
        return runtime

    def draw_scenes(
        self,
        agents: np.ndarray,
        rngs: Sequence[np.random.Generator],
        threads: int,
        seeds: Sequence[int | None] | None = None,
    ) -> None:
        """Give each stream agent of ``agents`` the scene its generator draws next, and each
        agent of a :class:`SharedSceneStreams` group its group's current scene, drawn anew
        when the group has had its episodes in the last one (the other agents keep theirs).

        The scenes not cached yet are built two or more at a time (one per thread of
        :func:`run_parallel`; the ray casts and compiled loops of a build release the GIL):
        agents that start their episodes together, as in RL training, need a new scene each.
        Each scene is a function of its draw alone, so the result is the one-by-one build's.

        Args:
            agents: the agents starting a new episode.
            rngs: their generators, in the same order (each draws its scene's seed; a group's
                agents take their group's scene instead).
            threads: the most threads to build in.
            seeds: the seeds the agents are reset with (None: not seeded); a group all of
                whose agents are seeded draws its scene anew from its first agent's seed.
        """
        seeds = [None] * len(agents) if seeds is None else list(seeds)
        self._reseed_groups(agents, seeds)
        keys: list[tuple | None] = []
        for agent, rng in zip(agents, rngs, strict=True):
            stream, group = self._streams[agent], self._group_of[agent]
            if group is not None:
                keys.append(self._group_key(group))
            else:
                keys.append(
                    None
                    if stream is None
                    else (stream.kind, stream.draw_seed(rng), stream.openings)
                )
        missing = {
            key: self._streams[agent]
            for agent, key in zip(agents, keys, strict=True)
            if key is not None and key not in self._cache and self._held(agent, key) is None
        }
        built: dict[tuple, SceneRuntime] = {}
        if len(missing) > 1 and threads > 1:
            order = iter(list(missing))  # claimed one key at a time by whichever thread is free

            def build(_: int) -> None:
                for key in order:
                    built[key] = self._build_key(key, missing[key])

            run_parallel(build, min(threads, len(missing)))
        for agent, key in zip(agents, keys, strict=True):
            if key is None:
                continue
            runtime = self._held(agent, key) or self._cached(key, self._streams[agent], built)
            group = self._group_of[agent]
            if group is not None:
                group.held, group.held_key = runtime, key
            self._runtimes[agent] = runtime

    def _held(self, agent: int, key: tuple) -> SceneRuntime | None:
        """The runtime of scene ``key`` held by ``agent``'s group (it keeps its scene's
        runtime whatever the cache lets go), None when it holds another."""
        group = self._group_of[agent]
        if group is None or group.held_key != key:
            return None
        return group.held

    def _reseed_groups(self, agents: np.ndarray, seeds: list[int | None]) -> None:
        """Seed the generator of each group whose agents all reset with seeds, from its first
        agent's seed, and let it draw a new scene; give an unseeded group a random one."""
        seed_of = {int(a): s for a, s in zip(agents, seeds, strict=True)}
        done: set[int] = set()
        for agent in agents:
            group = self._group_of[agent]
            if group is None or id(group) in done:
                continue
            done.add(id(group))
            first = seed_of.get(group.agents[0])
            if first is not None and all(seed_of.get(a) is not None for a in group.agents):
                group.generator, group.key, group.started = group_generator(first), None, 0
            elif group.generator is None:
                group.generator = np.random.default_rng()

    def _group_key(self, group: _Group) -> tuple:
        """The key of the scene the next agent of ``group`` to reset starts in: the group's
        scene, or the next of its stream once the group has had its episodes there."""
        if group.key is None or group.started >= group.starts_per_scene:
            stream = group.stream
            group.key = (stream.kind, stream.draw_seed(group.generator), stream.openings)
            group.started = 0
        group.started += 1
        return group.key

    def clear(self) -> None:
        """Let go of every agent's runtime (and every group's)."""
        self._runtimes = [None] * len(self._runtimes)
        for group in self._group_of:
            if group is not None:
                group.held = group.held_key = None

    def _cached(
        self,
        key: tuple,
        spec: ProceduralSceneSpec | str,
        built: dict[tuple, SceneRuntime] | None = None,
    ) -> SceneRuntime:
        """The cached runtime of scene ``key``, made when missing (taken from ``built`` when
        it was made there already)."""
        return self._cache.get(
            key, lambda: built.pop(key) if built and key in built else self._build_key(key, spec)
        )

    def _build_key(self, key: tuple, spec: ProceduralSceneSpec | str) -> SceneRuntime:
        return self.build(spec if isinstance(spec, str) else spec.scene(key[1]))
