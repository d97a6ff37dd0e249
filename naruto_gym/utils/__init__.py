"""Utilities shared by the package's layers: checks of settings with errors that say what to
pass (:mod:`~naruto_gym.utils.checks`), the thread pool of the compiled loops
(:mod:`~naruto_gym.utils.threads`) and the refusal of Open3D and Embree work after a fork
(:mod:`~naruto_gym.utils.fork_safety`)."""
