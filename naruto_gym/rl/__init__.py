"""Reinforcement-learning helpers: observation transforms for learning, their vector-env
wrappers, and the Stable-Baselines3 adapter and features extractor (``naruto_gym.rl.sb3``,
needs ``stable-baselines3``)."""
