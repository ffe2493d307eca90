import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from paramimic.envs import REWARD_TERMS, ParamEnv, registered_envs

LEGS = {
    "left_leg_length": (0.7, 1.3),
    "right_leg_length": (0.7, 1.3),
    "target_velocity": (0.5, 1.5),
}


@pytest.mark.parametrize("env_id", sorted(registered_envs()))
def test_registered_envs_pass_gymnasium_checks(env_id):
    env = gym.make(env_id)
    check_env(env.unwrapped)
    u = env.unwrapped
    assert isinstance(u.model, mujoco.MjModel) and isinstance(u.data, mujoco.MjData)
    # 30 Hz control ([WL19] Table 2) at the character's physics rate (600 Hz in the paper) or
    # the id's own (the humanoid's clip gaits run at 300 Hz)
    hz = registered_envs()[env_id].get("config", {}).get("physics_hz", u.registration.physics_hz)
    assert u.frame_skip == hz // 30 and u.model.opt.timestep == pytest.approx(1 / hz)
    env.close()


def test_gym_make_takes_the_env_section_as_config():
    """As Stable-Baselines3 and RLlib make it: gym.make(id, config={...})."""
    env = gym.make("paramimic/Walker-v0", config={"max_episode_seconds": 2.0, "physics_hz": 300})
    u = env.unwrapped
    assert u.config.max_episode_seconds == 2.0 and u.frame_skip == 10
    assert u.model.opt.timestep == pytest.approx(1 / 300)
    env.close()


def test_reset_uses_the_given_task_and_builds_that_body():
    env = ParamEnv("walker", LEGS)
    obs, info = env.reset(
        seed=0,
        options={"task": {"left_leg_length": 0.7, "right_leg_length": 1.3, "target_velocity": 1.5}},
    )
    np.testing.assert_allclose(info["task"], [0.7, 1.3, 1.5])
    np.testing.assert_allclose(obs[:3], [0.7, 1.3, 1.5], rtol=1e-6)  # a is part of the state
    assert env.character.leg_lengths == pytest.approx([0.9 * 1.3, 0.9 * 0.7])  # right, left
    tasks = np.array([env.reset(seed=s)[1]["task"] for s in range(200)])
    assert np.all(tasks >= [0.7, 0.7, 0.5]) and np.all(tasks <= [1.3, 1.3, 1.5])
    assert tasks[:, 0].std() > 0.1  # drawn uniformly when not given


def test_task_outside_the_space_is_rejected():
    env = ParamEnv("walker", LEGS)
    with pytest.raises(ValueError, match="not inside the task space"):
        env.reset(options={"task": [2.0, 1.0, 1.0]})
    with pytest.raises(ValueError, match="unknown task parameters"):
        ParamEnv("walker", {"wing_span": (1, 2)})


def test_reward_terms_are_bells_and_info_carries_them():
    env = ParamEnv("walker", LEGS)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(30):
        obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, 6))
        assert 0.0 < r <= 1.0
        assert set(info["reward_terms"]) == set(REWARD_TERMS)
        for k in ("pose", "velocity", "com_velocity", "direction", "torque"):
            assert 0.0 <= info["reward_terms"][k] <= 1.0
        assert 0.0 <= info["reward_terms"]["end_effector"] <= 3.0  # Σ over 3 end-effectors
        assert info["dphi"] == 1.0 and info["reward_spike"] == 0.0
        if term or trunc:
            break


def test_reward_matches_eq_4_to_7_on_a_known_state():
    env = ParamEnv("walker", {"target_velocity": (1.0, 1.0)})
    env.reset(seed=0)
    _, r, _, _, info = env.step(np.zeros(6))
    t = info["reward_terms"]
    w = np.array([5, 2, 2, 1, 1, 1], float)  # Table 3, biped (lower body)
    weighted = (
        w[0] * t["pose"]
        + w[1] * t["velocity"]
        + w[2] * t["end_effector"]
        + w[3] * t["com_velocity"]
        + w[4] * t["direction"]
        + w[5] * t["torque"]
    )
    assert r == pytest.approx(weighted / (5 + 2 + 2 * 2 + 1 + 1 + 1))  # two end effectors
    assert t["task"] == pytest.approx((t["com_velocity"] + t["direction"]) / 14)


def test_pushed_over_body_falls_and_terminates():
    env = ParamEnv("walker", {"global_scale": (1.4, 1.4)})
    env.reset(seed=0)
    env.data.qpos[2] = 1.3  # pitch the torso far back
    _, _, term, trunc, info = env.step(np.zeros(6))
    assert term and not trunc and info["fell"] and not info["diverged"]


def test_time_limit_truncates():
    env = ParamEnv("walker", {}, config={"max_episode_seconds": 0.2})
    env.reset(seed=0)
    ends = [env.step(np.zeros(6))[2:4] for _ in range(6)]  # 0.2 s at 30 Hz = 6 steps
    assert ends[-1] == (False, True)
    assert not any(term or trunc for term, trunc in ends[:-1])


def test_diverging_simulation_ends_the_episode_not_the_process():
    env = ParamEnv("walker", {})
    obs0, _ = env.reset(seed=0)
    env.data.qvel[:] = np.nan
    obs, r, term, trunc, info = env.step(np.zeros(6))
    assert term and info["diverged"] and r == 0.0
    assert np.isfinite(obs).all()
    obs, _ = env.reset(seed=1)  # and the env keeps working
    assert np.isfinite(env.step(np.zeros(6))[0]).all()


def test_same_seed_same_episode():
    def roll(seed):
        env = ParamEnv("walker", LEGS)
        env.reset(seed=seed)
        return np.array([env.step(np.full(6, 0.1))[0] for _ in range(20)])

    np.testing.assert_array_equal(roll(5), roll(5))


def test_a_policy_blind_to_the_shape_sees_the_base_body_and_controls_the_real_one():
    task = {"left_leg_length": (0.7, 1.3), "right_leg_length": (0.7, 1.3)}
    seen = ParamEnv("walker", task)
    blind = ParamEnv("walker", task, config={"observe_shape": False})
    body = {"left_leg_length": 0.8, "right_leg_length": 1.25}
    o_seen, _ = seen.reset(seed=1, options={"task": body})
    o_blind, info = blind.reset(seed=1, options={"task": body})
    np.testing.assert_allclose(o_seen[:2], [0.8, 1.25])
    np.testing.assert_allclose(o_blind[:2], [1.0, 1.0])  # the base body's parameters
    np.testing.assert_allclose(info["task"], [0.8, 1.25])  # the body it controls
    np.testing.assert_allclose(o_blind[2:], o_seen[2:])  # the rest of the state is the same
    assert blind.character.shape == seen.character.shape != blind._base.shape
    blind.set_shape({"left_leg_length": 1.2})  # a shape change on the fly stays hidden
    np.testing.assert_allclose(blind._last_obs[:2], [1.0, 1.0])
