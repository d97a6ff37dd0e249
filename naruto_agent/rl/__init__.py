"""Policies that play trained models, and their scripted baseline, for the harness.

* :mod:`~naruto_agent.rl.explorer_policy`: ``explorer``, the map-and-goal explorer trained by
  ``benchmarks/train_explorer.py`` (its packaged model in ``checkpoints/``), and
  ``explorer-untrained``, the same network untrained.
* :mod:`~naruto_agent.rl.scripted_explorer`: ``goal-walker``, the explorer's map, candidates
  and walker with a fixed rule in place of the network.
* :mod:`~naruto_agent.rl.ranker_policy`: ``goal-ranker``, the same walker deciding at every
  goal with the learned candidate ranker (:mod:`~naruto_agent.rl.candidate_ranker`, its
  packaged weights in ``checkpoints/``), and ``goal-ranker-untrained``, its untrained twin.
* :mod:`~naruto_agent.rl.ppo_policy`: :class:`PPOExplorer`, a PPO model over frames trained by
  ``benchmarks/train_ppo.py``.
"""
