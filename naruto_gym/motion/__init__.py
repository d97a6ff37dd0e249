"""How the agent moves: actions turned into bounded pose steps
(:mod:`~naruto_gym.motion.actions`, compiled in ``pose_kernels``), collisions of its sphere
(:mod:`~naruto_gym.motion.collision`) and the scanned space an agent may not leave
(:mod:`~naruto_gym.motion.scanned_space`, compiled lookups in ``lattice_kernels``)."""
