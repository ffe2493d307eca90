"""Shape change on the fly ([WL19] §5.2): env.set_shape mid-episode."""

import numpy as np
import pytest

from paramimic.envs import ParamEnv


def _walk(env, steps, rng):
    for _ in range(steps):
        obs, r, terminated, truncated, info = env.step(
            0.2 * rng.standard_normal(env.action_space.shape)
        )
        assert not (terminated or truncated)
    return obs


@pytest.mark.parametrize(
    ("name", "task", "grow"),
    [
        (
            "walker",
            {"left_leg_length": (0.7, 1.3), "right_leg_length": (0.7, 1.3)},
            {"left_leg_length": 1.3, "right_leg_length": 1.3},
        ),
        ("biped_lower", {"global_z": (0.5, 1.5)}, {"global_z": 1.5}),
        (
            "quadruped",
            {"global_z": (0.5, 1.5), "global_x": (0.5, 1.5)},
            {"global_z": 1.4, "global_x": 0.6},
        ),
    ],
)
def test_growing_limbs_mid_episode_lifts_the_body_and_keeps_the_state(name, task, grow):
    env = ParamEnv(name, task, {"init_noise": 0.0})
    center = {k: (lo + hi) / 2 for k, (lo, hi) in task.items()}
    env.reset(seed=0, options={"task": {k: v * 0.8 for k, v in center.items()}})
    rng = np.random.default_rng(0)
    _walk(env, 3, rng)
    before, model_before = env.data, env.model
    joints = before.qpos[env.character.qpos_idx].copy()
    joint_vel = before.qvel[env.character.qvel_idx].copy()
    root_vel = before.qvel[:3].copy()
    phase, steps = env._phase, env._steps
    obs = env.set_shape(grow)
    after = env.data
    assert env.model is not model_before  # the body was rebuilt (its data carried over)
    assert all(env.character.shape[k] == v for k, v in grow.items())
    # state continuity: joint angles and velocities, root velocity, phase, step count
    np.testing.assert_array_equal(after.qpos[env.character.qpos_idx], joints)
    np.testing.assert_array_equal(after.qvel[env.character.qvel_idx], joint_vel)
    np.testing.assert_array_equal(after.qvel[:3], root_vel)
    assert (env._phase, env._steps) == (phase, steps)
    # the new shape is part of the task the policy observes
    for k, v in grow.items():
        assert env.task[env.task_space.names.index(k)] == v
    np.testing.assert_allclose(obs[: env.task_space.dim], env.task, rtol=1e-6)
    # no penetration deeper than 1 cm after the change
    depth = max((-env.data.contact.dist[i] for i in range(env.data.ncon)), default=0.0)
    assert depth < 0.01
    # and the episode goes on under the policy's control, finite
    _walk(env, 2, rng)
    assert np.all(np.isfinite(env.data.qpos))


def test_shrinking_keeps_the_average_com_velocity_continuous():
    env = ParamEnv("walker", {"global_scale": (0.5, 1.5)}, {"init_noise": 0.0})
    env.reset(seed=0, options={"task": [1.2]})
    rng = np.random.default_rng(1)
    _walk(env, 10, rng)
    v = env._com_vel
    env.set_shape({"global_scale": 0.8})
    obs, *_ = env.step(np.zeros(env.action_space.shape))
    # one control step later the 2-s average moved by a step's worth, not by the COM's jump
    assert abs(env._com_vel[0] - v[0]) < 0.2


def test_set_shape_rejects_parameters_outside_the_task():
    env = ParamEnv("walker", {"global_scale": (0.5, 1.5)})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="not a shape dimension"):
        env.set_shape({"torso_length": 1.1})
    with pytest.raises(ValueError, match="positive"):
        env.set_shape({"global_scale": -1.0})


def test_the_skill_env_changes_shape_on_the_fly_too():
    """set_shape lives in the env core: the [L21] env keeps its state, its gravity and its
    motion m_a (tabulated again on the new body)."""
    from paramimic.envs import SkillEnv

    env = SkillEnv(
        "humanoid",
        {"gravity": (0.5, 0.5), "leg_length": (0.8, 1.2)},
        {"clip": "humanoid_walk", "init_noise": 0.0},
    )
    env.reset(seed=0, options={"task": {"gravity": 0.5, "leg_length": 0.9}})
    for _ in range(3):
        env.step(np.zeros(env.action_space.shape))
    joints = env.data.qpos[env.character.qpos_idx].copy()
    phi = env._phi
    obs = env.set_shape({"leg_length": 1.1})
    assert env.character.shape["leg_length"] == 1.1 and env.task[1] == 1.1
    np.testing.assert_array_equal(env.data.qpos[env.character.qpos_idx], joints)
    assert env._phi == phi and env.model.opt.gravity[2] == pytest.approx(-0.5 * 9.81)
    assert env.observation_space.contains(obs)
    _, _, terminated, _, info = env.step(np.zeros(env.action_space.shape))
    assert not info["diverged"]


def test_setting_the_same_shape_every_step_changes_nothing():
    """A morph sets a shape every control step, often the one the body has: the trajectory is
    the one without the call (an earlier version lifted the body out of its soft contacts on
    every call and the humanoid, hovering on its toes, fell within 4 s)."""
    task = {"left_leg_length": (0.7, 1.3), "right_leg_length": (0.7, 1.3)}
    runs = []
    for morph in (False, True):
        env = ParamEnv("walker", task, {"init_noise": 0.0})
        env.reset(seed=0, options={"task": [1.1, 0.9]})
        rng = np.random.default_rng(0)
        for _ in range(40):
            if morph:
                env.set_shape({"left_leg_length": 1.1, "right_leg_length": 0.9})
            env.step(0.2 * rng.standard_normal(env.action_space.shape))
        runs.append(env.data.qpos.copy())
    np.testing.assert_array_equal(runs[0], runs[1])


def test_the_fig2a_humanoid_keeps_walking_while_its_legs_shrink_and_grow():
    """[WL19] §5.2, Fig. 1 on the shipped Fig. 2a controller: legs 1.0 -> 0.6 -> 1.0 over 8 s,
    rebuilt every control step, and it does not fall."""
    from paramimic.envs import env_for
    from paramimic.evaluation import deterministic, morph_episode
    from paramimic.training import checkpoint

    _, cfg, policy = checkpoint.load_policy("humanoid_fig2a")
    cfg.env = cfg.env.for_evaluation(10.0)
    env = env_for(cfg)
    task = np.ones(env.task_space.dim)  # the base body (every shape dimension at 1.0)
    path = [{"leg_length": 1.0}, {"leg_length": 0.6}, {"leg_length": 1.0}]
    out = morph_episode(deterministic(policy), env, task, path, 8.0)
    assert not out["fell"], out
    assert out["seconds"] == pytest.approx(8.0) and out["shape"] == {"leg_length": 1.0}
    assert out["distance"] > 3.0  # it walked on (the clip's speed is about 1.2 m/s)


def test_the_env_keeps_its_own_copy_of_the_task_it_was_reset_with():
    """A caller's array changed after a reset (play's sliders) changes nothing in the env:
    the body follows only through set_shape."""
    env = ParamEnv("walker", {"left_leg_length": (0.8, 1.2), "right_leg_length": (0.8, 1.2)})
    task = np.array([1.0, 1.0])
    env.reset(seed=0, options={"task": task})
    task[0] = 1.2
    assert env.task[0] == 1.0 and env.character.shape["left_leg_length"] == 1.0
