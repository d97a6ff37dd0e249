"""What the demo keeps of an episode for a person to watch, besides the scores.

* snapshots of the agent's map, evenly over the episode (``--map-snapshots``);
* the GIF's frames: the env's ``rgb_array`` frame (ground truth from above with the path,
  RGB, depth) beside the agent's map from above at that step (:mod:`.map_picture`);
* the Rerun recording (:class:`~naruto_agent.recording.EpisodeRecorder`): every step's camera
  and frames, the snapshots, the policy's layers, coverage and completion.

It only reads the episode (observations, infos, the map, the policy's layers).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import trimesh
from PIL import Image

from naruto_agent.demo.map_picture import draw_path, top_down_of_mesh


def snapshot_steps(steps: int, count: int) -> set[int]:
    """``count`` steps spread evenly over ``0..steps`` (the first and last included)."""
    if count <= 0:
        return set()
    return {int(round(mark)) for mark in np.linspace(0, steps, max(count, 2))}


class EpisodeWatch:
    """Map snapshots, GIF frames and the recording of one demo episode.

    Args:
        env: the episode's env (``render_mode="rgb_array"``).
        policy: the policy (its ``view_layers`` are recorded).
        map_mesh: returns the map of the episode now (the policy's own or the reference).
        steps: the step budget.
        gif_frames: frames of the GIF (0: none).
        gif_width: their width in pixels.
        map_snapshots: how many times the map is taken over the episode.
        recorder: where to record, or None.
        times: seconds by phase; ``pictures`` and ``recording`` are added to.
    """

    def __init__(self, env: Any, policy: Any, map_mesh: Any, steps: int, gif_frames: int,
                 gif_width: int, map_snapshots: int, recorder: Any | None,
                 times: dict[str, float]) -> None:
        self.env = env
        self.policy = policy
        self.map_mesh = map_mesh
        self.gif_every = max(1, steps // gif_frames) if gif_frames else 0
        self.gif_width = gif_width
        self.snapshots = snapshot_steps(steps, map_snapshots)
        self.recorder = recorder
        self.times = times
        self.frames: list[tuple[int, np.ndarray]] = []
        self.last_map: tuple[int, trimesh.Trimesh] | None = None
        self._map_picture: np.ndarray | None = None
        self._positions: list[np.ndarray] = []
        base = env.unwrapped
        self._top_down = base.top_down_map if self.gif_every else None
        self._bounds = np.asarray(base.scene.bounds, np.float64)

    def observe(self, step: int, observation: dict[str, Any], info: dict[str, Any],
                last: bool) -> None:
        """After reset (step 0) and after each step: record, take the map, keep a frame."""
        self._positions.append(np.asarray(observation["pose"], np.float64)[:3, 3].copy())
        clock = time.perf_counter()
        if self.recorder is not None:
            self.recorder.log_step(step, observation, info)
            self.recorder.log_policy(step, self.policy, last)
        if step in self.snapshots or last:
            mesh = self.map_mesh()
            self.last_map = (step, mesh)
            if self.recorder is not None:
                self.recorder.log_map(step, mesh)
            if self._top_down is not None:
                self._map_picture = top_down_of_mesh(mesh, self._top_down, self._bounds)
        self.times["recording"] = self.times.get("recording", 0.0) + time.perf_counter() - clock
        if self.gif_every and (step % self.gif_every == 0 or last):
            clock = time.perf_counter()
            self.frames.append((step, self._frame()))
            self.times["pictures"] += time.perf_counter() - clock

    def scores(self, step: int, metrics: dict[str, Any] | None) -> None:
        """A checkpoint's completion scores into the recording."""
        if self.recorder is not None:
            self.recorder.log_scores(step, metrics)

    def final_mesh(self, step: int) -> trimesh.Trimesh | None:
        """The map taken at ``step`` (the last), if it was taken then."""
        if self.last_map is not None and self.last_map[0] == step:
            return self.last_map[1]
        return None

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.close()

    def _frame(self) -> np.ndarray:
        """The env's frame with the agent's map beside it, scaled to the GIF's width."""
        frame = np.asarray(self.env.render())
        if self._map_picture is not None and self._top_down is not None:
            own = draw_path(self._map_picture, self._top_down, np.array(self._positions))
            if own.shape[0] == frame.shape[0]:
                frame = np.concatenate([frame, own], axis=1)
        picture = Image.fromarray(frame)
        height = max(1, round(picture.height * self.gif_width / picture.width))
        return np.asarray(picture.resize((self.gif_width, height), Image.BILINEAR))


def make_recorder(path: Any, camera: Any, title: str, record: bool, live: bool,
                  live_url: str, scene: Any = None) -> Any | None:
    """The episode's recorder, or None when nothing is to be recorded.

    Without ``rerun-sdk`` a recording asked by default is skipped with a message; a live view
    cannot be, so it raises.

    Raises:
        naruto_agent.recording.LiveViewerError: ``live`` and no viewer can be reached (or
            rerun-sdk is missing).
    """
    from naruto_agent.recording import EpisodeRecorder, LiveViewerError, rerun_available
    from naruto_agent.recording.live import RERUN_EXTRA_HINT

    if not (record or live):
        return None
    if not rerun_available():
        if live:
            raise LiveViewerError(f"--live needs rerun-sdk: {RERUN_EXTRA_HINT}")
        print(f"recording skipped: rerun-sdk is not installed ({RERUN_EXTRA_HINT})")
        return None
    recorder = EpisodeRecorder(path if record else None, camera, title=title,
                               live=(live_url or "spawn") if live else None)
    if scene is not None:
        recorder.log_scene(scene)
    return recorder
