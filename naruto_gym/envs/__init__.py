"""The single env: :mod:`~naruto_gym.envs.naruto_recon_env` (``NarutoReconEnv``), its keyword
arguments (:mod:`~naruto_gym.envs.settings`, checked by :mod:`~naruto_gym.envs.validation`)
and what it builds once per scene (:mod:`~naruto_gym.envs.scene_runtime`)."""
