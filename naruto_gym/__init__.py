"""naruto-gym: a CPU-only Gymnasium testbed for active 3D reconstruction.

``import naruto_gym`` registers the environment ids:

* ``NarutoRecon-v0``: the default shipped single room, pose actions, 2000-step budget.
* ``NarutoReconApartment-v0``: the shipped multi-room apartment, 5000-step budget (the
  published MP3D budget).
* ``NarutoReconDiscrete-v0``: the default room with habitat-style discrete actions and a
  quarter-resolution camera, a cheap start for RL.
"""

from gymnasium.envs.registration import register

from naruto_gym.envs.naruto_recon_env import NarutoReconEnv

__all__ = ["NarutoReconEnv"]
__version__ = "0.1.0"

ENTRY_POINT = "naruto_gym.envs.naruto_recon_env:NarutoReconEnv"

register(id="NarutoRecon-v0", entry_point=ENTRY_POINT, max_episode_steps=2000)
register(
    id="NarutoReconApartment-v0",
    entry_point=ENTRY_POINT,
    max_episode_steps=5000,
    kwargs={"scene": "apartment"},
)
register(
    id="NarutoReconDiscrete-v0",
    entry_point=ENTRY_POINT,
    max_episode_steps=2000,
    kwargs={"action_mode": "discrete", "image_scale": 0.25},
)
