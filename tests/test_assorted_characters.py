"""The assorted characters of [WL19] §5.3: biped (lower body), quadruped, fish and manta ray."""

import mujoco
import numpy as np
import pytest

from paramimic.characters import get_character, registration
from paramimic.characters.articulated import WATER_DENSITY
from paramimic.characters.body import DENSITY
from paramimic.envs import ParamEnv

ASSORTED = ("biped_lower", "quadruped", "fish", "manta")
SWIMMERS = ("fish", "manta")


def _corner(definition, which: str) -> dict[str, float]:
    return {p.name: getattr(p, which) for p in definition.shape_params}


def _mixed_corners(definition, n=4):
    rng = np.random.default_rng(7)
    return [
        {p.name: (p.low, p.high)[int(rng.integers(2))] for p in definition.shape_params}
        for _ in range(n)
    ]


def _hold(c, pose, seconds):
    """PD hold of `pose` from rest with the soles on the ground; returns the data after."""
    m, data = c.model, mujoco.MjData(c.model)
    data.qpos[c.qpos_idx] = pose
    mujoco.mj_kinematics(m, data)
    if len(c.contact_site_ids):
        data.qpos[2] -= data.site_xpos[c.contact_site_ids, 2].min() - 1e-3
    data.ctrl[:] = data.qpos[c.qpos_idx]
    mujoco.mj_forward(m, data)
    start = data.qpos[:3].copy()
    mujoco.mj_step(m, data, nstep=int(round(seconds / m.opt.timestep)))
    return data, start


@pytest.mark.parametrize("name", ASSORTED)
def test_shape_parameterization_is_global_and_local_per_segment(name):
    d = get_character(name)
    names = d.param_names()
    parts = [p.name for p in d.parts]
    # b_g ∈ R³ in (0.5, 1.5), b_l^i ∈ R³ in (0.7, 1.2) per body segment ([WL19] §5.3)
    assert len(names) == 3 + 3 * len(parts)
    for p in d.shape_params:
        expected = (0.5, 1.5) if p.name.startswith("global_") else (0.7, 1.2)
        assert (p.low, p.high) == expected
    assert {f"{parts[0]}_x", f"{parts[-1]}_z"} <= set(names)
    counts = {"biped_lower": 8, "quadruped": 14, "fish": 6, "manta": 8}
    assert len(parts) == counts[name]


@pytest.mark.parametrize("name", ASSORTED)
def test_mass_follows_volume(name):
    d = get_character(name)
    rho = WATER_DENSITY if name in SWIMMERS else DENSITY
    base = d.compile()
    part = d.parts[1]
    volume = np.prod(part.size) * (np.pi / 6 if name in SWIMMERS else 1.0)  # ellipsoid or box
    assert base.model.body_mass[base.model.body(part.name).id] == pytest.approx(rho * volume)
    # b_g = (1.5, 1, 1.2): every volume x1.8, so the whole mass x1.8
    g = d.compile({"global_x": 1.5, "global_z": 1.2})
    assert g.mass == pytest.approx(1.8 * base.mass)
    # one segment 1.2x longer along x: only its mass grows, by 1.2
    local = d.compile({f"{part.name}_x": 1.2})
    grown = local.model.body_mass[local.model.body(part.name).id]
    assert grown == pytest.approx(1.2 * rho * volume)
    assert local.mass - base.mass == pytest.approx(0.2 * rho * volume)


def test_joints_follow_the_scaled_segments():
    d = get_character("biped_lower")
    c = d.compile({"thigh_l_z": 1.2, "global_z": 1.5})
    m, data = c.model, mujoco.MjData(c.model)
    mujoco.mj_kinematics(m, data)
    hip = data.xanchor[m.body("thigh_l").jntadr[0]]
    knee = data.xanchor[m.body("shin_l").jntadr[0]]
    assert hip[2] - knee[2] == pytest.approx(0.42 * 1.2 * 1.5)  # thigh length x b_l x b_g
    # the soles rest on the ground: the lowest contact corner at z = 0
    assert data.site_xpos[c.contact_site_ids, 2].min() == pytest.approx(0.0, abs=1e-9)
    # DOF: root 6, torso 3, hips 3, knees 1, ankles 2 = 21 ([WL19] §5.3)
    assert m.nv == 21


@pytest.mark.parametrize("name", ASSORTED)
def test_base_and_corner_shapes_hold_the_reference_pose_for_two_seconds(name):
    """PD hold of the reference motion's rest pose with the gains tuned on the base body:
    the base and the smallest and largest corners (every b at its minimum / maximum, 0.35x to
    1.8x per segment) stay standing or floating in place for 2 s."""
    d = get_character(name)
    rest = registration(name).gait.rest_pose()
    for shape in (None, _corner(d, "low"), _corner(d, "high")):
        c = d.compile(shape)
        data, start = _hold(c, rest, 2.0)
        assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))
        up = data.xmat[c.root_body_id].reshape(3, 3)[:, 2]
        assert up[2] > 0.95, (name, shape)
        if name in SWIMMERS:
            assert np.linalg.norm(data.qpos[:3] - start) < 0.02, (name, shape)
        else:
            assert data.qpos[2] > 0.95 * start[2], (name, shape)
        assert np.linalg.norm(data.qvel) < 0.5, (name, shape)


@pytest.mark.parametrize("name", ASSORTED)
def test_mixed_corner_shapes_compile_and_simulate(name):
    """Mixed corners (e.g. 0.5x wide, 1.5x tall on 0.7x feet) need balance, not just a PD
    hold: they may topple, but the simulation stays finite and within MuJoCo's limits."""
    d = get_character(name)
    rest = registration(name).gait.rest_pose()
    for shape in _mixed_corners(d):
        c = d.compile(shape)
        data, _ = _hold(c, rest, 2.0)
        assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))
        assert not data.warning.number[: int(mujoco.mjtWarning.mjWARN_BADQACC) + 1].any()


@pytest.mark.parametrize("name", ASSORTED)
def test_a_thousand_random_action_steps_stay_finite(name):
    d = get_character(name)
    task = {p.name: (p.low, p.high) for p in d.shape_params}
    env = ParamEnv(name, task)
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=0)
    for _ in range(1000):
        obs, r, terminated, truncated, info = env.step(rng.uniform(-1, 1, env.action_space.shape))
        assert np.all(np.isfinite(obs)) and np.isfinite(r) and 0.0 < r <= 1.0
        assert not info["diverged"]
        if terminated or truncated:
            obs, _ = env.reset()


@pytest.mark.parametrize("name", SWIMMERS)
def test_swimmers_move_in_water_and_never_fall(name):
    """The fluid model acts: flapping the reference stroke moves the body, with no gravity
    and no floor; episodes end only at the time limit."""
    env = ParamEnv(name, {}, {"max_episode_seconds": 3.0, "init_noise": 0.0})
    c = env.character
    assert env.model.opt.density == WATER_DENSITY and not np.any(env.model.opt.gravity)
    assert env.model.ngeom == len(get_character(name).parts)  # no floor
    assert np.all(env.model.geom_fluid[:, 0] == 1.0)  # ellipsoid lift and drag on every body
    obs, _ = env.reset(seed=0)
    start = env.data.qpos[:3].copy()
    steps = 0
    while True:
        obs, r, terminated, truncated, info = env.step(np.zeros(env.action_space.shape))
        steps += 1
        if terminated or truncated:
            break
    assert truncated and not info["fell"] and steps == 90
    assert np.linalg.norm(env.data.qpos[:3] - start) > 0.05  # the stroke pushed the water
    assert c.mass > 0


def test_swimmer_drag_slows_a_coasting_body():
    env = ParamEnv("fish", {}, {"init_noise": 0.0})
    env.reset(seed=0)
    d = env.data
    d.ctrl[:] = d.qpos[env.character.qpos_idx]
    d.qvel[:] = 0.0
    d.qvel[0] = 1.0
    mujoco.mj_step(env.model, d, nstep=600)
    assert 0.0 < d.qvel[0] < 0.9  # drag, no gravity to sink it
    assert abs(d.qvel[2]) < 0.05
