"""Reward normalization ([WL19] §4.3, Table 1) on hand-worked leg lengths and masses."""

import numpy as np
import pytest

from paramimic.envs import ParamEnv
from paramimic.envs.reward_normalization import RewardScales, reward_scales


def test_symmetric_legs_scale_velocity_by_mean_leg_length():
    # legs 1.2 and 1.2 vs base 0.9 and 0.9: l_µ = 1.2, l_σ = 0 -> velocity 1.2/0.9 = 4/3,
    # direction max(0.5, 1 - 0) = 1; mass 100 vs 50 -> energy 50/100 = 0.5
    s = reward_scales(np.array([1.2, 1.2]), np.array([0.9, 0.9]), 100.0, 50.0)
    assert s.velocity == pytest.approx(4.0 / 3.0)
    assert s.direction == pytest.approx(1.0)
    assert s.energy == pytest.approx(0.5)


def test_asymmetric_legs_lower_velocity_and_direction():
    # legs 0.8 and 1.2: l_µ = 1.0, l_σ = sqrt(((0.2)² + (0.2)²)/2) = 0.2
    # symmetry = max(0.5, 1 - 0.2/1.0) = 0.8; velocity = (1.0/0.9) * 0.8 = 0.888..
    s = reward_scales(np.array([0.8, 1.2]), np.array([0.9, 0.9]), 30.0, 60.0)
    assert s.direction == pytest.approx(0.8)
    assert s.velocity == pytest.approx(0.8 / 0.9)
    assert s.energy == pytest.approx(2.0)  # a lighter body's torques count double


def test_symmetry_factor_is_floored_at_one_half():
    # legs 0.1 and 1.9: l_µ = 1.0, l_σ = 0.9 -> 1 - 0.9 = 0.1 -> floored at 0.5
    s = reward_scales(np.array([0.1, 1.9]), np.array([1.0, 1.0]), 1.0, 1.0)
    assert s.direction == 0.5
    assert s.velocity == pytest.approx(0.5)


def test_four_legs_and_no_legs():
    # quadruped legs 0.6, 0.6, 0.6, 1.0: l_µ = 0.7, l_σ = sqrt((3·0.01 + 0.09)/4) = sqrt(0.03)
    legs = np.array([0.6, 0.6, 0.6, 1.0])
    sym = 1.0 - np.sqrt(0.03) / 0.7
    s = reward_scales(legs, np.full(4, 0.64), 10.0, 10.0)
    assert s.direction == pytest.approx(sym)
    assert s.velocity == pytest.approx(0.7 / 0.64 * sym)
    # a swimmer has no legs: only the energy term is scaled
    assert reward_scales(np.array([]), np.array([]), 20.0, 10.0) == RewardScales(1.0, 1.0, 0.5)


def _env_scales(normalize: bool, **shape):
    env = ParamEnv(
        "walker",
        {k: (v, v) for k, v in shape.items()} | {"target_velocity": (1.0, 1.0)},
        {"reward": {"normalize": normalize}},
    )
    env.reset(seed=0)
    return env


def test_env_uses_the_scales_of_its_body():
    # walker legs: thigh + shin = 0.9 m at scale 1; left 1.2x, right 0.8x -> 1.08 and 0.72
    env = _env_scales(True, left_leg_length=1.2, right_leg_length=0.8)
    legs = np.array([0.72, 1.08])
    sym = 1.0 - legs.std() / legs.mean()
    np.testing.assert_allclose(np.sort(env.character.leg_lengths), legs)
    assert env._target_v == pytest.approx(legs.mean() / 0.9 * sym)
    assert env._scales.energy == pytest.approx(env._base.mass / env.character.mass)
    # observed target speed is the normalized one
    off = _env_scales(False, left_leg_length=1.2, right_leg_length=0.8)
    assert off._target_v == 1.0 and off._scales == RewardScales.identity()


def test_energy_scale_reaches_the_torque_bell():
    """Same state, heavier body: the torque bell's exponent is scaled by m0/m = 1/1.3³, so the
    normalized bell is the unnormalized one raised to that power."""
    env = _env_scales(True, global_scale=1.3)
    energy = env._scales.energy
    assert energy == pytest.approx(env._base.mass / env.character.mass)
    assert energy == pytest.approx(1.0 / 1.3**3)
    env.step(np.full(env.action_space.shape, 0.5, np.float32))  # torques to penalize
    ref = env._reference_at(env._phase)
    normalized = env._reward(ref)[1]["torque"]
    env._scales = RewardScales(env._scales.velocity, env._scales.direction, 1.0)
    plain = env._reward(ref)[1]["torque"]
    assert plain < 0.99
    assert normalized == pytest.approx(plain**energy)
