"""naruto-gym: a CPU-only Gymnasium testbed for active 3D reconstruction.

``import naruto_gym`` registers the environment ids:

* ``NarutoRecon-v0``: the default shipped single room, pose actions, 2000-step budget.
* ``NarutoReconApartment-v0``: the shipped multi-room apartment, 5000-step budget (the
  published MP3D budget).
* ``NarutoReconDiscrete-v0``: the default room with habitat-style discrete actions and a
  quarter-resolution camera, a cheap start for RL.

Each id also has a vector entry point: ``gymnasium.make_vec(id, num_envs=64,
vectorization_mode="vector_entry_point")`` gives the batched env of
:func:`naruto_gym.vector.make_vector_env` (``NarutoReconVectorEnv`` in this process, or
``ShardedVectorEnv`` over ``workers`` processes).

Its parts: :mod:`~naruto_gym.envs` (the single env) and :mod:`~naruto_gym.vector` (the batched
envs); :mod:`~naruto_gym.sensors` (pinhole and panorama frames), :mod:`~naruto_gym.motion`
(actions, collisions, the scanned space), :mod:`~naruto_gym.coverage` (the reward) and
:mod:`~naruto_gym.observability` (the surface an agent can ever see, compiled in
``observability_kernels``); :mod:`~naruto_gym.scenes` (meshes, the generator, the catalogue,
the suite); :mod:`~naruto_gym.evaluation` (scoring); :mod:`~naruto_gym.wrappers` (learning
observations, final metrics) and :mod:`~naruto_gym.rl` (the explorer's map and goal actions,
SB3 and RLlib adapters); :mod:`~naruto_gym.geometry`, :mod:`~naruto_gym.rendering` (the
top-down picture) and :mod:`~naruto_gym.utils`.
"""

from gymnasium.envs.registration import register

from naruto_gym.envs.naruto_recon_env import NarutoReconEnv

__all__ = ["NarutoReconEnv"]
__version__ = "0.2.0"

ENTRY_POINT = "naruto_gym.envs.naruto_recon_env:NarutoReconEnv"
VECTOR_ENTRY_POINT = "naruto_gym.vector:make_vector_env"

# Variants are keyword presets of one class (budget: the published Replica / MP3D frames).
PRESETS: dict[str, tuple[int, dict]] = {
    "NarutoRecon-v0": (2000, {}),
    "NarutoReconApartment-v0": (5000, {"scene": "apartment"}),
    "NarutoReconDiscrete-v0": (2000, {"action_mode": "discrete", "image_scale": 0.25}),
}
for _env_id, (_budget, _kwargs) in PRESETS.items():
    register(
        id=_env_id,
        entry_point=ENTRY_POINT,
        max_episode_steps=_budget,
        kwargs=_kwargs,
        # The batched env (make_vector_env): gymnasium.make_vec(id, num_envs,
        # vectorization_mode="vector_entry_point"). No additional_wrappers (Gymnasium refuses
        # them with a vector entry point): the env adds the final reconstruction metrics itself.
        vector_entry_point=VECTOR_ENTRY_POINT,
    )
