"""Reinforcement-learning adapters: the Stable-Baselines3 ``VecEnv`` and features extractor
(``naruto_gym.rl.sb3``, needs ``stable-baselines3``) and the RLlib env creator
(``naruto_gym.rl.rllib_env``). The observations they hand out are shaped by
:mod:`naruto_gym.wrappers`."""
