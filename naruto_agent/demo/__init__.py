"""The main command: one episode of a policy (the NARUTO agent by default) and what to look at.

``naruto-demo`` (``python -m naruto_agent.demo``, or ``bash scripts/run_demo.sh`` after set-up)
runs one episode and writes into ``--output-dir`` (default ``outputs/demo``):

* ``reconstruction.ply``: the policy's own map as a mesh (the NARUTO agent's TSDF or neural
  map); for a policy that keeps no map, the reference TSDF fusion of the episode's frames;
* ``metrics.json``: that mesh scored against the ground truth (accuracy, completion,
  completion ratio over the whole and the observable surface), coverage, path length,
  collisions and time per step (also printed);
* ``curves.csv`` / ``curves.png``: coverage at every step, completion ratio at a few
  evaluation points (scored with cheaper settings than the final metrics);
* ``trajectory.png``: the trajectory on the top-down map, with the goals the policy chose;
* ``episode.gif``: the env's ``rgb_array`` frames (map, RGB, depth), subsampled, with the
  agent's map from above beside each;
* ``viewer.html``: a 3D view to open in a browser and turn, opening inside the scene
  (reconstruction cut away, trajectory, camera frustums, goals, a step slider); needs the
  ``viewer`` extra (plotly);
* ``episode.rrd``: a Rerun recording to scrub through (``--live`` streams it while the
  episode runs); needs the ``viewer`` extra (rerun-sdk). See docs/viewer.md.

Modules: :mod:`.run` (arguments and the episode loop), :mod:`.episode` (the record of what an
episode produced), :mod:`.watch` (map snapshots, GIF frames, the recording), :mod:`.outputs`
(files and pictures), :mod:`.map_picture` (the agent's map from above), :mod:`.viewer` (the
3D page and its reader).
"""

from naruto_agent.demo.run import DemoArgs, main, parse_args, run_demo

__all__ = ["DemoArgs", "main", "parse_args", "run_demo"]
