"""Learning to explore: the map-and-goal explorer's parts, and adapters for RL libraries.

* :mod:`~naruto_gym.rl.egocentric_map` (compiled loops in ``egocentric_map_kernels``): the
  egocentric top-down map an agent builds from its own depth, panorama and poses.
* :mod:`~naruto_gym.rl.goal_actions`: goal actions, a choice among a few reachable candidate
  goals every ``steps_per_goal`` env steps: the candidates
  (:mod:`~naruto_gym.rl.goal_candidates`), the planner over the agent's map
  (:mod:`~naruto_gym.rl.goal_planner`) and the walker that turns a goal into moves
  (:mod:`~naruto_gym.rl.goal_walker`).
* :mod:`~naruto_gym.rl.explorer_env`: the explorer's env settings, training mix and RLlib env
  creator; :mod:`~naruto_gym.rl.explorer_sb3`: its Stable-Baselines3 features extractor.
* :mod:`~naruto_gym.rl.sb3`: the Stable-Baselines3 ``VecEnv`` over the batched env and a
  features extractor of frames (needs ``stable-baselines3``); :mod:`~naruto_gym.rl.rllib_env`:
  the RLlib env creator. The frame observations are shaped by :mod:`naruto_gym.wrappers`.

Importing the package imports no learning library.
"""
