"""Recordings of episodes to watch and scrub through: Rerun files and live viewers.

* :class:`EpisodeRecorder`: writes an episode (camera, frames, trajectory, the growing map,
  the policy's layers, coverage and completion) into a ``.rrd`` file and/or a live viewer;
* :func:`read_recording` / :class:`RecordingContents`: read a file back without a viewer;
* :func:`reach_viewer`, :class:`LiveViewerError`: reach a live viewer (or say why not);
* :func:`rerun_available`: whether the ``viewer`` extra's ``rerun-sdk`` is installed;
* :func:`simplify_mesh`, :func:`frustum_segments`: light meshes and camera outlines, shared
  with the demo's 3D page.

It sits above the policies (it draws what :meth:`~naruto_agent.policies.Policy.view_layers`
returns); policies never import it. See docs/viewer.md.
"""

from naruto_agent.recording.live import LiveViewerError, reach_viewer, rerun_available
from naruto_agent.recording.meshes import frustum_segments, simplify_mesh
from naruto_agent.recording.reader import RecordingContents, read_recording
from naruto_agent.recording.recorder import EpisodeRecorder

__all__ = [
    "EpisodeRecorder",
    "LiveViewerError",
    "RecordingContents",
    "frustum_segments",
    "reach_viewer",
    "read_recording",
    "rerun_available",
    "simplify_mesh",
]
