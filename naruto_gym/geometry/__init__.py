"""Geometry shared by the envs and the agents: pose and rotation helpers
(:mod:`~naruto_gym.geometry.transforms`), the egocentric frame of a map crop
(:mod:`~naruto_gym.geometry.egocentric`), the compiled sphere sweep
(:mod:`~naruto_gym.geometry.sweep_kernels`) and sorted lookups
(:mod:`~naruto_gym.geometry.sorted_search`)."""
