"""Policies that act on the env from outside, and the tools that run them.

* :mod:`~naruto_agent.policies`: the policy interface, the registry by name, the baselines
  (passive, random, frontier) and the stall watchdog; :mod:`~naruto_agent.naruto`: the NARUTO
  agent; :mod:`~naruto_agent.rl`: policies that play trained models (the explorer, PPO) and
  the scripted ``goal-walker``.
* Their parts: :mod:`~naruto_agent.mapping` (neural and TSDF maps, occupancy),
  :mod:`~naruto_agent.planning` (E-RRT paths, rotations) and :mod:`~naruto_agent.guards` (the
  open-scan guard).
* The tools: :mod:`~naruto_agent.benchmark` (``naruto-benchmark``), :mod:`~naruto_agent.demo`
  (``naruto-demo``) and :mod:`~naruto_agent.recording` (Rerun recordings), with the one episode
  loop they share (:mod:`~naruto_agent.episode_loop`), flags from dataclasses
  (:mod:`~naruto_agent.cli_args`) and user code by import path
  (:mod:`~naruto_agent.import_paths`).

Subpackages are imported on demand (``from naruto_agent.planning import plan_path``), so that
importing the package stays cheap and one part can be used without the others.
"""

__all__ = ["planning"]
