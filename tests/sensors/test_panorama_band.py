"""The panorama that casts only the rows near the horizon (``panorama_horizon_deg``): its rows
are the full panorama's, to the bit, in the single and the batched env; the rows it leaves out
read 0 and cost no ray; bad values are refused by name."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_gym.envs.naruto_recon_env import NarutoReconEnv
from naruto_gym.sensors.panorama import EquirectangularCamera
from naruto_gym.vector import NarutoReconVectorEnv

SCENE = "procedural:small:17"
SETTINGS = {
    "action_mode": "discrete",
    "image_scale": 0.05,
    "panorama_shape": (32, 64),
    "coverage_samples": 2000,
}


def test_rows_cast_are_those_within_the_band_of_the_horizon():
    camera = EquirectangularCamera(32, 64, horizon_deg=30)
    start, stop = camera.cast_rows
    elevations = np.rad2deg(camera.row_elevations)
    assert np.all(np.abs(elevations[start:stop]) <= 30)
    assert abs(elevations[start - 1]) > 30 and abs(elevations[stop]) > 30
    assert camera.cast_directions.shape == ((stop - start) * 64, 3)
    assert np.array_equal(
        camera.cast_directions, EquirectangularCamera(32, 64).ray_directions[start * 64 : stop * 64]
    )
    assert EquirectangularCamera(32, 64).cast_rows == (0, 32)
    assert EquirectangularCamera(32, 64, horizon_deg=90).cast_rows == (0, 32)


def test_batched_band_panorama_equals_the_full_panoramas_rows_and_casts_fewer_rays():
    full = NarutoReconVectorEnv(4, scene=SCENE, **SETTINGS)
    band = NarutoReconVectorEnv(4, scene=SCENE, panorama_horizon_deg=30, **SETTINGS)
    start, stop = band.panorama_camera.cast_rows
    assert band.single_observation_space == full.single_observation_space
    observed = [full.reset(seed=3)[0], band.reset(seed=3)[0]]
    moves = np.random.default_rng(0).choice([0, 6, 7], size=(12, 4))
    for step in range(len(moves) + 1):
        whole, cut = observed
        assert np.array_equal(whole["panorama"][:, start:stop], cut["panorama"][:, start:stop])
        assert not cut["panorama"][:, :start].any() and not cut["panorama"][:, stop:].any()
        assert whole["panorama"][:, :start].any()  # the full one does see above the band
        assert np.array_equal(whole["depth"], cut["depth"])
        assert np.array_equal(whole["pose"], cut["pose"])
        # What a policy trained on the band makes of the full env's panorama.
        np.testing.assert_array_equal(
            band.panorama_camera.keep_cast_rows(whole["panorama"]), cut["panorama"]
        )
        if step < len(moves):
            observed = [full.step(moves[step])[0], band.step(moves[step])[0]]
    assert band.rays_cast < full.rays_cast
    full.close()
    band.close()


def test_single_env_band_panorama_equals_the_full_panoramas_rows():
    full = NarutoReconEnv(SCENE, **SETTINGS)
    band = NarutoReconEnv(SCENE, panorama_horizon_deg=30, **SETTINGS)
    start, stop = band.panorama_camera.cast_rows
    (whole, _), (cut, info) = full.reset(seed=1), band.reset(seed=1)
    for action in (0, 6, 0, 7, 0):
        assert np.array_equal(whole["panorama"][start:stop], cut["panorama"][start:stop])
        assert not cut["panorama"][:start].any() and not cut["panorama"][stop:].any()
        # The share of no-hit pixels counts the rows cast: the zeros outside are not misses.
        assert info["panorama_no_hit_share"] == pytest.approx(
            np.mean(cut["panorama"][start:stop] <= 0)
        )
        whole, *_ = full.step(action)
        cut, *_, info = band.step(action)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (0, "greater than 0"),
        (95, "at most 90"),
        (float("nan"), "finite number"),
        (1.0, "keeps no row"),
        ("30", "finite number"),
    ],
)
def test_bad_band_is_refused_by_name(value, message):
    with pytest.raises(ValueError, match="panorama_horizon_deg") as error:
        NarutoReconVectorEnv(1, scene=SCENE, panorama_horizon_deg=value, **SETTINGS)
    assert message in str(error.value)


def test_band_without_a_panorama_is_refused():
    with pytest.raises(ValueError, match="panorama_shape=None"):
        NarutoReconEnv(SCENE, **{**SETTINGS, "panorama_shape": None}, panorama_horizon_deg=30)
