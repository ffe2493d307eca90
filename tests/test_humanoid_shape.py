"""The DeepMimic humanoid with the [WL19] Fig. 2 shape parameterization: leg length, arm
length, height and thickness (a, c), each leg's length (b), the upper and the lower body's
thickness (d)."""

import mujoco
import numpy as np
import pytest

from paramimic.characters import get_character
from paramimic.config import EnvConfig
from paramimic.envs.skill_env import SkillEnv

HUMANOID = get_character("humanoid")


def _anchors(shape):
    c = HUMANOID.compile(shape)
    d = mujoco.MjData(c.model)
    mujoco.mj_kinematics(c.model, d)

    def anchor(body):
        return d.xanchor[c.model.body(body).jntadr[0]].copy()

    return c, anchor


def _mass(c, body):
    return float(c.model.body_mass[c.model.body(body).id])


def test_limbs_scale_by_their_length_parameter():
    base, a0 = _anchors(None)
    long, a1 = _anchors({"leg_length": 1.5, "arm_length": 0.5})
    thigh0 = np.linalg.norm(a0("left_hip") - a0("left_knee"))
    shin0 = np.linalg.norm(a0("left_knee") - a0("left_ankle"))
    assert thigh0 == pytest.approx(0.421546) and shin0 == pytest.approx(0.40987)
    assert np.linalg.norm(a1("left_hip") - a1("left_knee")) == pytest.approx(1.5 * thigh0)
    assert np.linalg.norm(a1("left_knee") - a1("left_ankle")) == pytest.approx(1.5 * shin0)
    upper0 = np.linalg.norm(a0("right_shoulder") - a0("right_elbow"))
    assert np.linalg.norm(a1("right_shoulder") - a1("right_elbow")) == pytest.approx(0.5 * upper0)
    # the trunk keeps its proportions
    spine0 = np.linalg.norm(a0("chest") - a0("neck"))
    assert np.linalg.norm(a1("chest") - a1("neck")) == pytest.approx(spine0)
    assert long.leg_lengths[0] == pytest.approx(1.5 * base.leg_lengths[0])


def test_masses_follow_the_shapes_volumes():
    base = HUMANOID.compile()
    assert base.mass == pytest.approx(45.0)  # the file's masses (kg)
    tall = HUMANOID.compile({"height": 1.5})
    assert tall.mass == pytest.approx(45.0 * 1.5**3)  # every dimension x1.5
    thick = HUMANOID.compile({"thickness": 1.2})
    assert _mass(thick, "root") == pytest.approx(6.0 * 1.2**3)  # a sphere
    # thigh capsule: r = 0.055, cylinder 0.3; legs 1.5x longer -> cylinder 0.45
    legs = HUMANOID.compile({"leg_length": 1.5})
    r = 0.055
    ratio = (np.pi * r**2 * 0.45 + 4 / 3 * np.pi * r**3) / (
        np.pi * r**2 * 0.3 + 4 / 3 * np.pi * r**3
    )
    assert _mass(legs, "left_hip") == pytest.approx(4.5 * ratio)
    assert _mass(legs, "chest") == pytest.approx(14.0)


def test_each_leg_has_its_own_length_on_top_of_both():
    """Fig. 2b: left x right leg; MuJoCo's kinematics put the knee and ankle where the scaled
    segments say, and the reward normalization sees the asymmetry ([WL19] Table 1)."""
    from paramimic.envs.reward_normalization import reward_scales

    base, a0 = _anchors(None)
    c, a1 = _anchors({"leg_length": 1.2, "left_leg_length": 1.1, "right_leg_length": 0.9})
    for side, scale in (("left", 1.2 * 1.1), ("right", 1.2 * 0.9)):
        for upper, lower in ((f"{side}_hip", f"{side}_knee"), (f"{side}_knee", f"{side}_ankle")):
            length0 = np.linalg.norm(a0(upper) - a0(lower))
            assert np.linalg.norm(a1(upper) - a1(lower)) == pytest.approx(scale * length0)
    right, left = c.leg_lengths
    assert (right, left) == pytest.approx((1.08 * base.leg_lengths[0], 1.32 * base.leg_lengths[1]))
    assert c.hip_height == pytest.approx(1.2 * (base.hip_height - 0.05) + 0.05)  # the mean leg
    scales = reward_scales(c.leg_lengths, base.leg_lengths, c.mass, base.mass)
    # l_µ / l⁰_µ = 1.2; 1 - l_σ/l_µ = 1 - 0.12/1.2 (the population std of 1.08 and 1.32 x l0)
    assert scales.velocity == pytest.approx(1.2 * 0.9) and scales.direction == pytest.approx(0.9)


def test_upper_and_lower_body_thickness_apart():
    """Fig. 2d: the lower body (pelvis and legs) and the upper body (chest, neck, arms) thicken
    on their own; lengths do not change, masses follow the volumes."""
    base, a0 = _anchors(None)
    c, a1 = _anchors({"upper_thickness": 1.5, "lower_thickness": 0.5})
    assert _mass(c, "root") == pytest.approx(6.0 * 0.5**3)  # the pelvis: a sphere
    assert _mass(c, "chest") == pytest.approx(_mass(base, "chest") * 1.5**3)  # a sphere
    thigh, upper_arm = c.model.geom("left_hip"), c.model.geom("left_shoulder")
    assert thigh.size[0] == pytest.approx(0.5 * base.model.geom("left_hip").size[0])
    assert upper_arm.size[0] == pytest.approx(1.5 * base.model.geom("left_shoulder").size[0])
    for body in ("left_knee", "left_ankle", "right_elbow", "neck"):
        assert a1(body) == pytest.approx(a0(body))


@pytest.mark.parametrize(
    "shape",
    [
        {"leg_length": 0.5, "arm_length": 0.5, "height": 0.75, "thickness": 0.5},
        {"leg_length": 2.0, "arm_length": 1.5, "height": 1.5, "thickness": 1.5},
        {"leg_length": 1.5, "arm_length": 1.0, "height": 1.0, "thickness": 0.7},
        {"left_leg_length": 1.1, "right_leg_length": 0.9, "upper_thickness": 1.5},
    ],
)
def test_shaped_humanoid_stands_in_the_clip_pose_with_feet_on_the_ground(shape):
    """The jump clip's first frame on a shaped body: the root path is scaled by the hip
    height, so the feet start on the ground; the servos hold the pose for 1/3 s."""
    env = SkillEnv(
        "humanoid",
        {"gravity": (1.0, 1.0), **{k: (v, v) for k, v in shape.items()}},
        EnvConfig(clip="humanoid_jump", init_noise=0.0),
    )
    trace = np.zeros(env.trace_shape)
    trace[:, -1] = -3.0
    env.reset(seed=0, options={"motion": trace})
    c, d = env.character, env.data
    mujoco.mj_kinematics(env.model, d)
    assert d.site_xpos[c.contact_site_ids, 2].min() == pytest.approx(0.0, abs=0.03)
    a = np.zeros(env.nj + 1)
    a[env.nj] = -3.0 / env.skill.tau_scale
    height = d.xpos[c.root_body_id, 2]
    for _ in range(10):
        _, _, terminated, _, _ = env.step(a)
        assert not terminated
    assert d.xpos[c.root_body_id, 2] == pytest.approx(height, rel=0.1)
    assert np.all(np.isfinite(d.qpos))


def test_the_full_shape_space_is_the_documented_family():
    """`shape_space: full` is Fig. 2a/c's four parameters (what the shipped controller and saved
    runs were trained with); the per-leg and per-half ones are named in `task` to vary."""
    from paramimic.config import ExperimentConfig
    from paramimic.training.method import method_for

    full = {"character": "humanoid", "shape_space": "full", "env": {"gait": "humanoid_walk"}}
    cfg = ExperimentConfig.model_validate(full)
    assert list(cfg.task) == ["leg_length", "arm_length", "height", "thickness"]
    legs = ExperimentConfig.model_validate(
        full | {"task": {"left_leg_length": [0.9, 1.1], "right_leg_length": [0.9, 1.1]}}
    )
    assert legs.task["left_leg_length"] == (0.9, 1.1) and len(legs.task) == 6
    obs = method_for(legs).spaces.obs_dim - method_for(cfg).spaces.obs_dim
    assert obs == 2  # the two leg lengths observed
