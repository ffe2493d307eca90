"""The planar gait retargeted to a body with legs of unequal length (paramimic/motion/retarget):
checked against MuJoCo's own kinematics of the compiled bodies."""

import mujoco
import numpy as np
import pytest

from paramimic.characters import get_character
from paramimic.characters.planar import WALKER_GAIT
from paramimic.config import ExperimentConfig
from paramimic.envs import make_env
from paramimic.motion.retarget import RetargetedGait, ankle_position, leg_ik, planar_legs

PHASES = np.linspace(0.0, 1.0, 13)


def _ankles(body, pose: np.ndarray) -> np.ndarray:
    """Each ankle (foot body origin) relative to its hip (thigh origin) in the torso's frame,
    (x, z): [2, 2], by MuJoCo's forward kinematics."""
    m = body.model
    d = mujoco.MjData(m)
    d.qpos[body.qpos_idx] = pose
    mujoco.mj_kinematics(m, d)
    rot = d.xmat[body.root_body_id].reshape(3, 3)
    rows = []
    for side in ("r", "l"):
        hip, ankle = d.xpos[m.body(f"thigh_{side}").id], d.xpos[m.body(f"foot_{side}").id]
        rows.append(((ankle - hip) @ rot)[[0, 2]])
    return np.array(rows)


def _gait(shape: dict[str, float]):
    walker = get_character("walker")
    base, body = walker.compile({}), walker.compile(shape)
    legs = planar_legs(walker, body.segment_lengths, base.segment_lengths)
    return base, body, RetargetedGait(WALKER_GAIT, legs)


@pytest.mark.parametrize("legs", [(0.8, 1.2), (1.3, 0.7), (0.7, 0.9)])
def test_every_ankle_follows_the_base_path_scaled_by_the_shortest_leg(legs):
    base, body, gait = _gait({"left_leg_length": legs[0], "right_leg_length": legs[1]})
    assert gait.scale == pytest.approx(min(legs))
    for phi in PHASES:
        want = min(legs) * _ankles(base, WALKER_GAIT.pose(phi))
        np.testing.assert_allclose(_ankles(body, gait.pose(phi)), want, atol=1e-9)
        # each foot keeps its angle to the torso: hip + knee + ankle of every leg
        q0, q1 = WALKER_GAIT.pose(phi), gait.pose(phi)
        np.testing.assert_allclose(q1[0:3].sum(), q0[0:3].sum(), atol=1e-12)
        np.testing.assert_allclose(q1[3:6].sum(), q0[3:6].sum(), atol=1e-12)
        assert np.all(q1[[1, 4]] <= 0.0)  # the knees bend the way they are built to


def test_a_long_leg_bends_more_and_the_shortest_leg_keeps_the_reference():
    _, _, gait = _gait({"left_leg_length": 0.8, "right_leg_length": 1.2})
    poses, reference = gait.pose(PHASES), WALKER_GAIT.pose(PHASES)
    np.testing.assert_allclose(poses[:, 3:6], reference[:, 3:6], atol=1e-12)  # left: 0.8
    assert np.all(poses[:, 1] < reference[:, 1])  # right knee (1.2) flexed further


def test_legs_scaled_alike_get_the_reference_itself():
    for shape in ({}, {"left_leg_length": 0.7, "right_leg_length": 0.7}, {"global_scale": 1.3}):
        _, _, gait = _gait(shape)
        np.testing.assert_allclose(gait.pose(PHASES), WALKER_GAIT.pose(PHASES), atol=1e-12)
        np.testing.assert_allclose(
            gait.velocity(PHASES), WALKER_GAIT.velocity(PHASES), rtol=1e-6, atol=1e-6
        )


def test_velocity_is_the_time_derivative_of_the_retargeted_pose():
    _, _, gait = _gait({"left_leg_length": 1.3, "right_leg_length": 0.75})
    dt = 1e-3  # s; φ advances dt / period
    for phi in PHASES:
        numeric = (gait.pose(phi + dt / gait.period) - gait.pose(phi)) / dt
        np.testing.assert_allclose(gait.velocity(phi + 0.5 * dt / gait.period), numeric, atol=1e-4)


def test_ik_inverts_fk_and_reaches_for_points_out_of_reach():
    rng = np.random.default_rng(0)
    hip, knee = rng.uniform(-0.8, 1.5, 50), rng.uniform(-2.3, -0.01, 50)
    x, z = ankle_position(hip, knee, 0.5, 0.4)
    h, k = leg_ik(x, z, 0.5, 0.4)
    np.testing.assert_allclose(h, hip, atol=1e-9)
    np.testing.assert_allclose(k, knee, atol=1e-9)
    h, k = leg_ik(np.array([0.3]), np.array([-2.0]), 0.5, 0.4)  # 2.02 m away: a straight leg
    assert k[0] == 0.0 and h[0] == pytest.approx(np.arctan2(0.3, 2.0))


def test_the_env_imitates_the_retargeted_gait_and_refuses_3d_characters():
    task = {"left_leg_length": (0.8, 0.8), "right_leg_length": (1.2, 1.2)}
    cfg = ExperimentConfig.model_validate(
        {"character": "walker", "task": task, "env": {"retarget": True}}
    )
    env = make_env(cfg.character, cfg.task, cfg.env)
    env.reset(seed=0)
    _, _, gait = _gait({"left_leg_length": 0.8, "right_leg_length": 1.2})
    for phi in (0.1, 0.55):
        np.testing.assert_allclose(env._reference_at(phi)[:6], gait.pose(phi), atol=2e-3)
    # the reward's pose bell under the reference's own PD targets (zero action), 10 resets x
    # 10 steps: the retargeted gait can be followed about as well as the base body's
    plain = make_env(cfg.character, cfg.task, cfg.env.model_copy(update={"retarget": False}))

    def pose_bell(e) -> float:
        bells = []
        for seed in range(10):
            e.reset(seed=seed)
            for _ in range(10):
                bells.append(e.step(np.zeros(6))[4]["reward_terms"]["pose"])
        return float(np.mean(bells))

    assert pose_bell(env) > 2.0 * pose_bell(plain)
    with pytest.raises(ValueError, match="env.retarget"):
        ExperimentConfig.model_validate({"character": "biped_lower", "env": {"retarget": True}})


def test_retarget_is_refused_for_a_skill_clip():
    with pytest.raises(ValueError, match="env.retarget"):
        ExperimentConfig.model_validate(
            {"character": "walker", "env": {"retarget": True, "clip": "planar_jump"}}
        )


def test_a_shape_change_on_the_fly_retargets_the_reference():
    """[WL19] §5.2 with env.retarget: the reference the env imitates after `set_shape` is the new
    body's retargeted gait, at the same phase."""
    legs = {"left_leg_length": (0.7, 1.3), "right_leg_length": (0.7, 1.3)}
    env = make_env("walker", legs, {"retarget": True})
    env.reset(seed=0, options={"task": {"left_leg_length": 1.0, "right_leg_length": 1.0}})
    for _ in range(5):
        env.step(np.zeros(6))
    phase = env._phase
    env.set_shape({"left_leg_length": 1.25, "right_leg_length": 0.75})
    assert env._phase == phase
    _, _, gait = _gait({"left_leg_length": 1.25, "right_leg_length": 0.75})
    np.testing.assert_allclose(env._reference_at(phase)[:6], gait.pose(phase), atol=2e-3)
    assert not np.allclose(gait.pose(phase), WALKER_GAIT.pose(phase), atol=1e-2)
