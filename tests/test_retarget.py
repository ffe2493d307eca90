"""The planar gait retargeted to a body with legs of unequal length (paramimic/motion/retarget):
checked against MuJoCo's own kinematics of the compiled bodies."""

import mujoco
import numpy as np
import pytest

from paramimic.characters import get_character
from paramimic.characters.articulated import BIPED_LOWER_GAIT, QUADRUPED_GAIT
from paramimic.characters.legs import leg_chains
from paramimic.characters.planar import WALKER_GAIT
from paramimic.config import EnvConfig, ExperimentConfig
from paramimic.envs import env_for, make_env
from paramimic.motion.retarget import (
    RetargetedGait,
    ankle_position,
    leg_ik,
    retarget_pose,
)

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
    legs = leg_chains(walker, body.segment_lengths, base.segment_lengths)
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


def test_the_env_imitates_the_retargeted_gait_and_refuses_characters_without_legs():
    task = {"left_leg_length": (0.8, 0.8), "right_leg_length": (1.2, 1.2)}
    cfg = ExperimentConfig.model_validate(
        {"character": "walker", "task": task, "env": {"retarget": True}}
    )
    env = env_for(cfg)
    env.reset(seed=0)
    _, _, gait = _gait({"left_leg_length": 0.8, "right_leg_length": 1.2})
    for phi in (0.1, 0.55):
        np.testing.assert_allclose(env._reference_at(phi)[:6], gait.pose(phi), atol=2e-3)
    # the reward's pose bell under the reference's own PD targets (zero action), 10 resets x
    # 10 steps: the retargeted gait can be followed about as well as the base body's
    plain = env_for(cfg, cfg.env.model_copy(update={"retarget": False}))

    def pose_bell(e) -> float:
        bells = []
        for seed in range(10):
            e.reset(seed=seed)
            for _ in range(10):
                bells.append(e.step(np.zeros(6))[4]["reward_terms"]["pose"])
        return float(np.mean(bells))

    assert pose_bell(env) > 2.0 * pose_bell(plain)
    with pytest.raises(ValueError, match="env.retarget"):  # no legs to retarget
        ExperimentConfig.model_validate({"character": "fish", "env": {"retarget": True}})


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


# 3D characters: their legs' hip pitch, knee and ankle pitch hinges, the rest as the reference
LEGGED = {
    "biped_lower": (BIPED_LOWER_GAIT, {"thigh_l_z": 1.2, "shin_r_z": 0.8, "global_z": 1.1}),
    "quadruped": (QUADRUPED_GAIT, {"thigh_fr_z": 0.7, "shin_hl_z": 1.2, "thigh_hr_z": 1.1}),
}


def _ankles_3d(body, definition, pose: np.ndarray) -> np.ndarray:
    """Each leg's ankle (foot origin) relative to its hip (thigh origin) in the root's frame,
    (x, z), by MuJoCo's forward kinematics: [legs, 2]."""
    m = body.model
    d = mujoco.MjData(m)
    d.qpos[body.qpos_idx] = pose
    mujoco.mj_kinematics(m, d)
    rot = d.xmat[body.root_body_id].reshape(3, 3)
    rel = np.array(
        [(d.xpos[m.body(foot).id] - d.xpos[m.body(thigh).id]) @ rot for thigh, _, foot in
         definition.legs]
    )  # fmt: skip
    return rel[:, [0, 2]]


@pytest.mark.parametrize("character", sorted(LEGGED))
def test_every_ankle_of_a_3d_body_follows_the_base_path_scaled_by_the_shortest_leg(character):
    """In the sagittal plane (the hips' roll and yaw at 0), each ankle of a 3D body with legs
    of unequal length follows the base body's path scaled by its shortest leg; every other
    joint keeps the reference's angle."""
    reference, shape = LEGGED[character]
    definition = get_character(character)
    base, body = definition.compile({}), definition.compile(shape)
    legs = leg_chains(definition, body.segment_lengths, base.segment_lengths)
    gait = RetargetedGait(reference, legs)
    lengths = [leg.thigh + leg.shin for leg in legs]
    base_lengths = [leg.base_thigh + leg.base_shin for leg in legs]
    assert gait.scale == pytest.approx(
        min(a / b for a, b in zip(lengths, base_lengths, strict=True))
    )
    assert gait.scale < 1.0 and max(leg.scale for leg in legs) > gait.scale  # unequal legs
    sagittal = sorted(i for leg in legs for i in (leg.hip, leg.knee, leg.ankle))
    for phi in PHASES:
        q0 = np.zeros_like(reference.pose(phi))
        q0[sagittal] = reference.pose(phi)[sagittal]
        q1 = retarget_pose(q0, legs, gait.scale)
        want, got = _ankles_3d(base, definition, q0), _ankles_3d(body, definition, q1)
        np.testing.assert_allclose(got, gait.scale * want, atol=1e-9)
        for leg in legs:  # the foot keeps its angle to the root
            assert q1[[leg.hip, leg.knee, leg.ankle]].sum() == pytest.approx(
                q0[[leg.hip, leg.knee, leg.ankle]].sum(), abs=1e-12
            )
        # the whole gait: the hips' roll and yaw, the ankles' roll, the torso as the reference
        full, ref = gait.pose(phi), reference.pose(phi)
        others = np.setdiff1d(np.arange(len(ref)), sagittal)
        np.testing.assert_array_equal(full[others], ref[others])
        assert not np.allclose(full[sagittal], ref[sagittal], atol=1e-3)


def test_a_3d_env_imitates_its_retargeted_gait():
    """env.retarget on biped_lower: the reference the env tabulates is the body's retargeted
    gait. With both legs scaled alike (global_z) it is the reference itself where the reference
    bends the knees the way they are built to; where it overextends one (the biped's knee
    target reaches +0.1 rad, beyond the joint's range), the knee bends as far the other way and
    the ankle stays where the reference puts it."""
    reference, shape = LEGGED["biped_lower"]
    definition = get_character("biped_lower")
    base, body = definition.compile({}), definition.compile(shape)
    legs = leg_chains(definition, body.segment_lengths, base.segment_lengths)
    gait = RetargetedGait(reference, legs)
    cfg = ExperimentConfig.model_validate(
        {"character": "biped_lower", "task": {k: (v, v) for k, v in shape.items()},
         "env": {"retarget": True}}
    )  # fmt: skip
    env = env_for(cfg)
    env.reset(seed=0)
    joints = len(reference.pose(0.0))
    for phi in (0.1, 0.55):
        np.testing.assert_allclose(env._reference_at(phi)[:joints], gait.pose(phi), atol=2e-3)
    alike = make_env("biped_lower", {"global_z": (1.2, 1.2)}, {"retarget": True})
    alike.reset(seed=0)
    knees = [leg.knee for leg in legs]
    bent = overextended = 0
    for phi in np.linspace(0.0, 1.0, 41):
        ref, got = reference.pose(phi), alike._reference_at(phi)[:joints]
        if np.all(np.abs(ref[knees]) > 0.03):  # away from the knee's turn at 0 (interpolation)
            want = ref.copy()
            for leg in legs:
                h, k, a = ref[[leg.hip, leg.knee, leg.ankle]]
                if k > 0.0:  # mirrored (thigh = shin): the same ankle and foot angle h + k + a
                    overextended += 1
                    want[[leg.hip, leg.knee, leg.ankle]] = h + k, -k, a + k
                else:
                    bent += 1
            np.testing.assert_allclose(got, want, atol=2e-3)
    assert bent > 0 and overextended > 0


def _feet_over_a_cycle(env) -> np.ndarray:
    """The lowest contact point of each foot [40, 2] (right, left) over one cycle of the env's
    reference gait on its body, from MuJoCo's kinematics."""
    c, g = env.character, env._gait
    data = mujoco.MjData(c.model)
    feet = [[c.model.site(f"{f}_c{i}").id for i in range(4)] for f in ("right_ankle", "left_ankle")]
    out = []
    for phi in np.linspace(0.0, 1.0, 40, endpoint=False):
        data.qpos[:] = 0.0
        data.qpos[2] = g.root_height(phi)
        data.qpos[3:7] = g.root_rotation(phi).as_quat(scalar_first=True)
        data.qpos[c.qpos_idx] = g.pose(phi)
        mujoco.mj_kinematics(c.model, data)
        out.append([data.site_xpos[f, 2].min() for f in feet])
    return np.array(out)


def test_the_humanoid_clip_gait_retargeted_keeps_both_feet_on_the_ground():
    """[WL19] Fig. 2b on the mocap walk: legs 1.1x and 0.9x. The clip's angles put the long
    leg's foot 8 cm into the floor and leave the short one's 7 cm above it; retargeted, each
    foot follows the base foot's path (the shortest leg's scale), as on the base body."""
    from paramimic.envs import ParamEnv

    gait = EnvConfig(gait="humanoid_walk", physics_hz=300)
    legs = {"left_leg_length": (1.1, 1.1), "right_leg_length": (0.9, 0.9)}
    base = _feet_over_a_cycle(ParamEnv("humanoid", {}, gait))
    plain = _feet_over_a_cycle(ParamEnv("humanoid", legs, gait))
    retargeted = ParamEnv("humanoid", legs, gait.model_copy(update={"retarget": True}))
    fixed = _feet_over_a_cycle(retargeted)
    assert plain[:, 1].min() < -0.05 and plain[:, 0].min() > 0.05  # sunk and floating
    assert fixed.min(axis=0) == pytest.approx(base.min(axis=0), abs=0.01)
    assert fixed.min(axis=1).max() < 0.01  # a foot on the ground all through the cycle
    left = retargeted._gait.joints.index("left_knee")
    assert (retargeted._gait.pose(np.linspace(0, 1, 20))[:, left] <= 0).all()  # knees bend back
