import itertools

import mujoco
import numpy as np
import pytest

from paramimic.characters import get_character
from paramimic.characters.body import DENSITY
from paramimic.envs import ParamEnv

PLANAR = ("hopper", "walker")

WALKER = get_character("walker")


def _joint_anchor(model, data, body):
    return data.xanchor[model.body(body).jntadr[0]].copy()


def _leg_vector(shape, side="l"):
    c = WALKER.compile(shape)
    d = mujoco.MjData(c.model)
    mujoco.mj_kinematics(c.model, d)
    hip = _joint_anchor(c.model, d, f"thigh_{side}")
    ankle = _joint_anchor(c.model, d, f"foot_{side}")
    return hip - ankle


def test_longer_leg_is_longer_by_the_factor():
    base = np.linalg.norm(_leg_vector({}))
    long = np.linalg.norm(_leg_vector({"left_leg_length": 1.5}))
    other = np.linalg.norm(_leg_vector({"left_leg_length": 1.5}, side="r"))
    assert base == pytest.approx(0.9)  # thigh 0.45 + shin 0.45
    assert long == pytest.approx(1.5 * base)
    assert other == pytest.approx(base)  # the right leg keeps its length


def test_split_keeps_leg_length_and_moves_the_knee():
    c = WALKER.compile({"thigh_shin_split": 1.2})
    assert c.segment_lengths["thigh_l"] == pytest.approx(0.54)
    assert c.segment_lengths["shin_l"] == pytest.approx(0.36)
    assert np.linalg.norm(_leg_vector({"thigh_shin_split": 1.2})) == pytest.approx(0.9)


def test_mass_follows_volume():
    base = WALKER.compile()
    thigh = base.model.body("thigh_l")
    r, length = 0.05, 0.45
    volume = np.pi * r**2 * length + 4.0 / 3.0 * np.pi * r**3  # capsule
    assert base.model.body_mass[thigh.id] == pytest.approx(DENSITY * volume)
    scaled = WALKER.compile({"global_scale": 1.5})
    assert scaled.mass == pytest.approx(base.mass * 1.5**3)  # every dimension x1.5
    thin = WALKER.compile({"left_leg_length": 1.2})
    m = thin.model.body_mass[thin.model.body("thigh_l").id]
    assert m == pytest.approx(DENSITY * (np.pi * r**2 * length * 1.2 + 4 / 3 * np.pi * r**3))


@pytest.mark.parametrize("name", PLANAR)
def test_feet_touch_the_ground_and_servos_are_stable_pd(name):
    c = get_character(name).compile({"global_scale": 0.7})
    d = mujoco.MjData(c.model)
    mujoco.mj_kinematics(c.model, d)
    assert d.site_xpos[c.contact_site_ids, 2].min() == pytest.approx(0.0, abs=1e-9)
    m = c.model
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert m.opt.timestep == pytest.approx(1 / 600)
    assert np.all(m.actuator_biasprm[:, 2] < 0)  # position servo with damping kv (stable PD)
    assert np.all(m.actuator_forcelimited) and np.all(m.actuator_forcerange[:, 1] > 0)
    assert len(c.contact_site_ids) == 4 * len(get_character(name).feet)
    names = {m.site(i).name for i in c.ee_site_ids}
    assert {f"{f}_end" for f in get_character(name).feet} <= names


def test_unknown_shape_parameter_is_rejected():
    with pytest.raises(KeyError, match="no shape parameter 'arm_length'"):
        WALKER.compile({"arm_length": 1.0})


@pytest.mark.parametrize("name", PLANAR)
def test_every_corner_of_the_shape_ranges_survives_random_actions(name):
    definition = get_character(name)
    params = definition.shape_params
    task = {p.name: (p.low, p.high) for p in params}
    env = ParamEnv(name, task)
    rng = np.random.default_rng(0)
    for corner in itertools.product(*[(p.low, p.high) for p in params]):
        env.reset(seed=1, options={"task": np.array(corner)})
        for _ in range(1000):
            obs, r, *_ = env.step(rng.uniform(-1, 1, env.action_space.shape))
        assert np.isfinite(env.data.qpos).all() and np.isfinite(env.data.qvel).all(), corner
        assert np.isfinite(obs).all() and np.isfinite(r)
