"""The reward equations worked out by hand ([WL19] Eq. 4-7, [L21] Eq. 5-8), and the env's reward
on a state built by hand."""

import math

import mujoco
import numpy as np
import pytest

from paramimic.config import ExperimentConfig
from paramimic.envs import ParamEnv, env_for
from paramimic.envs.rewards import (
    WL19Terms,
    l21_reward,
    l21_task,
    l21_tracking,
    l21_tracking_reward,
    wl19_imitation,
    wl19_regularization,
    wl19_reward,
    wl19_reward_product,
    wl19_task,
    wl19_weights,
)


def test_wl19_imitation_bells():
    # pose: ‖(0.1, −0.1)‖² = 0.02, / dim 2 = 0.01, / σ1 0.02 = 0.5
    # velocity: ‖(1, 1)‖² = 2, / 2 = 1, / σ2 0.5 = 2
    # end-effectors: ‖(0.1, 0.2, 0.2)‖² = 0.09, / 3 = 0.03, / σ3 0.2 = 0.15; the second is exact
    pose, vel, ee = wl19_imitation(
        np.array([0.1, -0.1]),
        np.array([1.0, 1.0]),
        np.array([[0.1, 0.2, 0.2], [0.0, 0.0, 0.0]]),
        0.02,
        0.5,
        0.2,
    )
    assert pose == pytest.approx(math.exp(-0.5))
    assert vel == pytest.approx(math.exp(-2.0))
    np.testing.assert_allclose(ee, [math.exp(-0.15), 1.0])


def test_wl19_task_bells():
    # COM velocity: ‖(0.2, 0)‖² = 0.04, / 2 = 0.02, / σ4 0.2 = 0.1
    # direction: ‖(1, 1)‖² = 2, / 2 = 1, / σ5 0.05 = 20, × symmetry scale 0.5 = 10
    com, direction = wl19_task((0.2, 0.0), (1.0, 1.0), 0.2, 0.05, 0.5)
    assert com == pytest.approx(math.exp(-0.1))
    assert direction == pytest.approx(math.exp(-10.0))


def test_wl19_regularization_bell():
    # τ/τmax = (0.5, −0.5): ‖·‖² = 0.5, / 2 = 0.25, / σ6 0.1 = 2.5, × energy m0/m = 2 → 5
    bell = wl19_regularization(np.array([50.0, -50.0]), np.array([100.0, 100.0]), 0.1, 2.0)
    assert bell == pytest.approx(math.exp(-5.0))


def test_wl19_weights_and_reward():
    # Table 3 weights (5, 2, 2 per effector, 1, 1, 1) with two effectors sum to 14
    w = wl19_weights(5, 2, 2, 1, 1, 1, n_ee=2)
    np.testing.assert_allclose(np.array(w) * 14, [5, 2, 2, 1, 1, 1])  # w3 once per effector
    terms = WL19Terms(0.5, 0.25, np.array([1.0, 0.0]), 0.8, 0.6, 0.1)
    # (5·0.5 + 2·0.25 + 2·1 + 2·0 + 1·0.8 + 1·0.6 + 1·0.1) / 14 = 6.5 / 14
    assert wl19_reward(terms, w) == pytest.approx(6.5 / 14)
    # without a reference motion only the task and the torque count: (0.8 + 0.6 + 0.1) / 3
    w0 = wl19_weights(5, 2, 2, 1, 1, 1, n_ee=2, imitation=False)
    assert wl19_reward(terms, w0) == pytest.approx(1.5 / 3)
    ones = WL19Terms(1.0, 1.0, np.ones(2), 1.0, 1.0, 1.0)
    assert wl19_reward(ones, w) == pytest.approx(1.0)  # the reward lies in (0, 1]


def test_wl19_product_of_the_bells():
    w = wl19_weights(5, 2, 2, 1, 1, 1, n_ee=2)
    terms = WL19Terms(0.5, 0.25, np.array([0.9, 0.8]), 0.8, 0.6, 0.1)
    # every bell a factor, each end-effector's too: 0.5 · 0.25 · 0.9 · 0.8 · 0.8 · 0.6 · 0.1
    assert wl19_reward_product(terms, w) == pytest.approx(0.5 * 0.25 * 0.72 * 0.8 * 0.6 * 0.1)
    # a term of weight 0 is left out (here the direction bell)
    w_no_dir = wl19_weights(5, 2, 2, 1, 0, 1, n_ee=2)
    assert wl19_reward_product(terms, w_no_dir) == pytest.approx(0.5 * 0.25 * 0.72 * 0.8 * 0.1)
    # without a reference motion only the task and the torque bells
    w0 = wl19_weights(5, 2, 2, 1, 1, 1, n_ee=2, imitation=False)
    assert wl19_reward_product(terms, w0) == pytest.approx(0.8 * 0.6 * 0.1)
    ones = WL19Terms(1.0, 1.0, np.ones(2), 1.0, 1.0, 1.0)
    assert wl19_reward_product(ones, w) == pytest.approx(1.0)
    # a body that stands still meets the end-effector, direction and torque bells: the sum
    # still pays it half of a walking step, the product a twentieth (terms as measured on the
    # walker: a standing and a walking controller, docs/results/families-that-learn.md)
    stand = WL19Terms(0.39, 0.17, np.array([0.86, 0.86]), 0.28, 1.0, 0.63)
    walk = WL19Terms(0.91, 0.46, np.array([1.0, 1.0]), 0.97, 1.0, 0.38)
    assert wl19_reward(stand, w) / wl19_reward(walk, w) > 0.6
    assert wl19_reward_product(stand, w) / wl19_reward_product(walk, w) < 0.1


def test_l21_tracking_task_and_mix():
    # r_q: ‖(0.3, 0.4)‖² = 0.25, / σ_q² (0.5²) = 1; r_ee: 0.16 / 0.4² = 1
    # r_com: 0.09 / 0.3² = 1; r_time: 0.2² / 0.1² = 4
    terms = l21_tracking(
        np.array([0.3, 0.4]),
        np.array([[0.0, 0.4, 0.0]]),
        np.array([0.3, 0.0, 0.0]),
        0.2,
        0.5,
        0.4,
        0.3,
        0.1,
    )
    np.testing.assert_allclose(terms, [math.exp(-1), math.exp(-1), math.exp(-1), math.exp(-4)])
    # Eq. 6 with (0.28, 0.28, 0.28, 0.16)
    r = l21_tracking_reward(terms, 0.28, 0.28, 0.28, 0.16)
    assert r == pytest.approx(0.84 * math.exp(-1) + 0.16 * math.exp(-4))
    # Eq. 8: a jump 0.05 m short with σ_task 0.1: exp(−0.25)
    assert l21_task(-0.05, 0.1) == pytest.approx(math.exp(-0.25))
    # Eq. 5, spike weights (1.0, 10.0)
    assert l21_reward(0.5, 0.2, 1.0, 10.0) == pytest.approx(2.5)


def test_param_env_reward_on_a_state_built_by_hand():
    """The walker posed exactly on its reference at φ = 1/4, joint velocities on the reference,
    PD targets at the pose, facing +x, standing still against a 1 m/s target: every imitation
    bell is 1, the torque bell is that of the servo damping −kv·q̇, the direction bell is 1 and
    the COM velocity bell is exp(−1² / (0.2 · 2))."""
    env = ParamEnv("walker", {"target_velocity": (1.0, 1.0)})
    env.reset(seed=0)
    c, d, rc = env.character, env.data, env.config.reward
    phase = 0.25  # a tabulated sample: the reference is exact there
    gait = env.motion
    mujoco.mj_resetData(env.model, d)
    d.qpos[c.qpos_idx] = gait.pose(phase)
    d.qvel[c.qvel_idx] = gait.velocity(phase)
    d.ctrl[:] = gait.pose(phase)
    mujoco.mj_forward(env.model, d)
    env._sense()
    env._com_vel = (0.0, 0.0, 0.0)
    reward, terms = env._reward(env._reference_at(phase))

    kv = np.array([j.kv_ratio * j.kp for j in env.definition.joints])
    tau = np.clip(-kv * gait.velocity(phase), -c.torque_limit, c.torque_limit)
    x = tau / c.torque_limit
    torque = math.exp(-(x @ x) / (rc.sigma_torque * len(x)))  # Eq. 7, base body: m0/m = 1
    com = math.exp(-1.0 / (rc.sigma_com_velocity * 2))  # Eq. 6: (0 − 1)² over dim 2
    assert terms["pose"] == pytest.approx(1.0)
    assert terms["velocity"] == pytest.approx(1.0)
    assert terms["end_effector"] == pytest.approx(2.0)  # two feet, each bell 1
    assert terms["torque"] == pytest.approx(torque, rel=1e-6)
    assert terms["direction"] == pytest.approx(1.0)
    assert terms["com_velocity"] == pytest.approx(com)
    # Eq. 4 with Table 3 weights, w3 = 2 per foot: (5 + 2 + 2·2 + 1·com + 1·1 + 1·torque) / 14
    assert reward == pytest.approx((5 + 2 + 4 + com + 1 + torque) / 14, rel=1e-6)


def test_param_env_pays_the_product_when_configured():
    cfg = ExperimentConfig.model_validate(
        {"character": "walker", "env": {"reward": {"combine": "product"}}}
    )
    env = env_for(cfg)
    env.reset(seed=0)
    sigma = env.config.reward.sigma_end_effector
    for _ in range(3):
        ref = env._ref_next.copy()  # the reference this step is rewarded against
        _, reward, *_, info = env.step(np.zeros(env.action_space.shape))
        t = info["reward_terms"]
        err = (env.data.sensordata[env._ee] - ref[env._ee]).reshape(-1, 3)
        feet = np.exp(-(err**2).sum(axis=1) / (sigma * 3))  # Eq. 5, one bell per foot
        assert feet.sum() == pytest.approx(t["end_effector"])
        product = t["pose"] * t["velocity"] * t["com_velocity"] * t["direction"] * t["torque"]
        assert reward == pytest.approx(product * feet.prod(), rel=1e-9)
