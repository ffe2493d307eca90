"""Ground-contact fitting of a new body ([WL19] Eq. 1) and its use at reset."""

import mujoco
import numpy as np
import pytest

from paramimic.characters import get_character, registration
from paramimic.characters.ground_fit import fit_ground_contact, lift_to_ground
from paramimic.envs import ParamEnv

CASES = [("walker", 0.0), ("walker", 0.3), ("biped_lower", 0.3), ("quadruped", 0.0)]


def _height(c) -> tuple[int, int]:
    """(height joint id, height qpos address) of a planar or free root."""
    m = c.model
    if m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE:
        return 0, 2
    j = m.joint("rootz").id
    return j, int(m.jnt_qposadr[j])


def _contacts(c, data, qpos):
    data.qpos[:] = qpos
    mujoco.mj_kinematics(c.model, data)
    return data.site_xpos[c.contact_site_ids].copy()


def _eq1(points, targets, q, q0, idx, w=0.01):
    r = points - targets
    dq = q[idx] - q0[idx]
    return float((r * r).sum() + w * dq @ dq)


@pytest.mark.parametrize(("name", "phase"), CASES)
def test_fit_puts_the_base_contacts_on_the_ground_closer_than_the_lift(name, phase):
    d = get_character(name)
    motion = registration(name).gait
    base = d.compile()
    bd = mujoco.MjData(base.model)
    q_base = base.model.qpos0.copy()
    q_base[base.qpos_idx] = motion.pose(phase)
    q_base = lift_to_ground(base.model, bd, q_base, base.contact_site_ids, _height(base)[1])
    targets = _contacts(base, bd, q_base)
    on_ground = targets[:, 2] < 2e-3
    assert on_ground.sum() >= 2
    rng = np.random.default_rng(1)
    fitted = 0
    for _ in range(6):
        shape = {p.name: float(rng.uniform(p.low, p.high)) for p in d.shape_params}
        c = d.compile(shape)
        data = mujoco.MjData(c.model)
        q0 = c.model.qpos0.copy()
        q0[c.qpos_idx] = motion.pose(phase)
        joint, h = _height(c)
        fit = fit_ground_contact(
            c.model, data, q0, targets, c.contact_site_ids, joint, c.model.actuator_trnid[:, 0]
        )
        lift = lift_to_ground(c.model, data, q0, c.contact_site_ids, h)
        points, lifted = _contacts(c, data, fit.qpos), _contacts(c, data, lift)
        # every point the base has on the ground is on the ground (5 mm), none below it
        assert np.abs(points[on_ground, 2]).max() < 5e-3
        assert points[:, 2].min() > -5e-3
        if fit.method == "slsqp":
            fitted += 1
            # the root moved only vertically
            other = np.setdiff1d(np.arange(c.model.nq), [h, *c.qpos_idx])
            np.testing.assert_array_equal(fit.qpos[other], q0[other])
            # Eq. 1 is lower than the lift's: the contacts are where the base has them
            idx = np.array(c.qpos_idx)
            assert _eq1(points, targets, fit.qpos, q0, idx) < _eq1(lifted, targets, lift, q0, idx)
            assert fit.objective == pytest.approx(_eq1(points, targets, fit.qpos, q0, idx))
            assert ((points - targets) ** 2).sum() < ((lifted - targets) ** 2).sum()
    assert fitted >= 5  # SLSQP solves nearly all; the lift is the fallback


def test_the_base_body_needs_no_fit():
    """Fitting the base to its own contacts changes nothing but noise-level height."""
    d = get_character("biped_lower")
    c = d.compile()
    data = mujoco.MjData(c.model)
    q0 = c.model.qpos0.copy()
    q0[c.qpos_idx] = registration("biped_lower").gait.pose(0.3)
    q0 = lift_to_ground(c.model, data, q0, c.contact_site_ids, 2)
    targets = _contacts(c, data, q0)
    fit = fit_ground_contact(
        c.model, data, q0, targets, c.contact_site_ids, 0, c.model.actuator_trnid[:, 0]
    )
    assert fit.method == "slsqp"
    np.testing.assert_allclose(fit.qpos, q0, atol=1e-5)


def test_fallback_lift_when_the_optimizer_fails():
    """A problem SLSQP cannot solve (here: undefined targets) falls back to the vertical lift,
    which puts the lowest contact point on the ground."""
    c = get_character("walker").compile({"global_scale": 1.2})
    data = mujoco.MjData(c.model)
    q0 = c.model.qpos0.copy()
    targets = np.zeros((len(c.contact_site_ids), 3))
    targets[:, 0] = np.nan
    joint, h = _height(c)
    fit = fit_ground_contact(
        c.model, data, q0, targets, c.contact_site_ids, joint, c.model.actuator_trnid[:, 0]
    )
    assert fit.method == "lift"
    assert _contacts(c, data, fit.qpos)[:, 2].min() == pytest.approx(0.0, abs=1e-9)


def test_reset_fits_new_bodies_to_the_ground():
    """With ground_fit on (the default) the env fits a non-base body in a reference pose to
    the base's contacts in that pose: every point the base has on the ground is within 5 mm of
    it, none below; resets start from such postures (+1 mm clearance)."""
    env = ParamEnv("biped_lower", {"thigh_l_z": (0.7, 1.2), "global_z": (0.5, 1.5)})
    motion = registration("biped_lower").gait
    base, bd = env._base, env._base_data
    rng = np.random.default_rng(3)
    for seed in range(4):
        env.reset(seed=seed)
        c, data = env.character, env.data
        assert data.site_xpos[c.contact_site_ids, 2].min() == pytest.approx(1e-3, abs=1e-4)
        q = data.qpos.copy()
        q[c.qpos_idx] = motion.pose(rng.random()) + 0.05 * rng.standard_normal(len(c.qpos_idx))
        q[c.qpos_idx] = np.clip(q[c.qpos_idx], c.ctrl_low, c.ctrl_high)
        fitted = env.ground_posture(q)
        bd.qpos[:] = lift_to_ground(base.model, bd, q, base.contact_site_ids, 2)
        mujoco.mj_kinematics(base.model, bd)
        on_ground = bd.site_xpos[base.contact_site_ids, 2] < 2e-3
        z = _contacts(c, mujoco.MjData(c.model), fitted)[:, 2]
        assert z.min() > -5e-3
        assert np.abs(z[on_ground]).max() < 5e-3


def test_fit_is_bit_identical_whatever_the_process_blas_threads():
    """A Ray worker runs BLAS on one thread, the learner on all cores; the fit must not care."""
    from threadpoolctl import threadpool_limits

    env = ParamEnv("hopper", {"leg_length": (0.8, 1.2), "target_velocity": (1.0, 1.0)})

    def postures():
        return np.array([(env.reset(seed=s), env.data.qpos.copy())[1] for s in range(20)])

    with threadpool_limits(limits=1, user_api="blas"):
        one = postures()
    with threadpool_limits(limits=2, user_api="blas"):
        two = postures()
    assert one.tobytes() == two.tobytes()


def test_a_shaped_humanoid_on_its_clip_gait_starts_on_the_base_bodys_contacts():
    """[WL19] Eq. 1 at reset for the humanoid on the mocap walk: the contact points the base body
    has on the ground in the same pose are on the ground on each shaped body (5 mm), none below."""
    from paramimic.config import EnvConfig

    d = get_character("humanoid")
    rng = np.random.default_rng(2)
    config = EnvConfig(gait="humanoid_walk", physics_hz=300, init_noise=0.0)
    for _ in range(4):
        shape = {
            p.name: float(rng.uniform(max(p.low, 0.7), min(p.high, 1.3))) for p in d.shape_params
        }
        env = ParamEnv("humanoid", {k: (v, v) for k, v in shape.items()}, config)
        env.reset(seed=0)
        targets = env._base_data.site_xpos[env._base.contact_site_ids]
        on_ground = targets[:, 2] < 2e-3
        assert on_ground.sum() >= 1  # a heel at this phase
        points = env.data.site_xpos[env.character.contact_site_ids]
        assert np.abs(points[on_ground, 2]).max() < 5e-3, shape
        assert points[:, 2].min() > -5e-3, shape


def test_a_fit_that_would_crouch_the_body_falls_back_to_the_lift():
    """`env.ground_fit_max_change`: mid-stride, a humanoid with longer legs reaches the base's
    swing-foot points by crouching (a body 0.7 m off its reference at reset); with the limit,
    such fits fall back to the lift and every reset starts near its reference."""
    from paramimic.config import EnvConfig

    task = {"leg_length": (1.05, 1.05), "arm_length": (0.97, 0.97)}
    worst = {}
    for limit in (None, 0.5):
        config = EnvConfig(gait="humanoid_walk", physics_hz=300, ground_fit_max_change=limit)
        env = ParamEnv("humanoid", task, config)
        errors = []
        for seed in range(12):
            env.reset(seed=seed)
            errors.append(env.body_error()[1])
        worst[limit] = max(errors)
    assert worst[None] > 0.4 and worst[0.5] < 0.2, worst
