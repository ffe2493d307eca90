"""SkillEnv: continuous-time imitation ([L21] §4), the traces, hindsight and fitness it reports."""

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paramimic.config import EnvConfig, SkillConfig
from paramimic.envs import make_env
from paramimic.envs.skill_env import SkillEnv
from paramimic.envs.skill_motion import at
from paramimic.messages import SkillOutcome

TASK = {"gravity": (0.2, 1.65), "jump_height": (0.0, 0.6)}


@pytest.fixture
def env():
    return SkillEnv("walker", TASK, EnvConfig(clip="planar_jump"))


def _run(env, action_fn, options=None, seed=0):
    obs, _ = env.reset(seed=seed, options=options)
    rows = []
    while True:
        a = action_fn(len(rows))
        obs, r, te, tr, info = env.step(a)
        rows.append((r, te, tr, info))
        if te or tr:
            return rows


def test_spaces_and_make_env(env):
    assert isinstance(make_env("walker", TASK, EnvConfig(clip="planar_jump")), SkillEnv)
    assert env.action_space.shape == (env.nj + 1,)  # (d_t, τ_t)
    assert env.trace_shape == (16, env.root_nv + env.nj + 1)
    obs, info = env.reset(seed=1, options={"task": {"gravity": 1.0, "jump_height": 0.2}})
    assert env.observation_space.contains(obs)
    assert info["task"] == pytest.approx([1.0, 0.2])
    with pytest.raises(ValueError, match="not inside the task space"):
        env.reset(options={"task": [3.0, 0.2]})
    with pytest.raises(ValueError, match="motion trace must have shape"):
        env.reset(options={"task": [1.0, 0.2], "motion": np.zeros((3, 3))})
    with pytest.raises(ValueError, match="needs env.clip"):
        SkillEnv("walker", TASK, EnvConfig())


def test_reference_time_advances_by_exp_tau_and_pd_target_is_displaced_m0(env):
    env.reset(seed=0, options={"task": [1.0, 0.14]})
    c = env.character
    a = np.zeros(env.nj + 1)
    a[env.nj] = np.log(2.0)  # τ = ln 2: the reference advances 2 control steps per step
    a[0] = 0.2  # a hip displacement of 0.2 * action_scale
    phi_before = env._phi
    _, _, _, _, info = env.step(a)
    assert info["dphi"] == pytest.approx(2.0)
    assert env._phi == pytest.approx(phi_before + 2.0)
    target = at(env._q0, env._phi)[c.qpos_idx]
    target[0] += 0.2 * env.config.action_scale
    assert env.data.ctrl == pytest.approx(np.clip(target, c.ctrl_low, c.ctrl_high))
    _, _, _, _, info = env.step(np.zeros(env.nj + 1))
    assert info["dphi"] == pytest.approx(1.0)


def test_time_reward_compares_with_the_motion_time_warp(env):
    trace = np.zeros(env.trace_shape)
    trace[:, -1] = np.log(2.0)  # m_a runs twice as fast as m0
    env.reset(seed=0, options={"task": [1.0, 0.14], "motion": trace})
    a = np.zeros(env.nj + 1)
    _, _, _, _, info = env.step(a)  # Δφ = 1 against τ̂ = ln 2: exp(−(1 − 2)² / 0.1²) ≈ 0
    assert info["reward_terms"]["time"] == pytest.approx(np.exp(-1 / 0.01))
    a[env.nj] = np.log(2.0)
    _, _, _, _, info = env.step(a)
    assert info["reward_terms"]["time"] == pytest.approx(1.0)


def test_a_completed_episode_reports_trace_hindsight_fitness_and_the_spike(env):
    rng = np.random.default_rng(0)
    d = rng.uniform(-0.1, 0.1, env.nj)
    tau = 0.05

    def act(t):
        return np.concatenate([d / env.config.action_scale, [tau]])

    rows = _run(env, act, {"task": [1.0, 0.3]})
    r, te, tr, info = rows[-1]
    assert te and not tr and not info["fell"]
    assert len(rows) == pytest.approx(env.length / np.exp(tau), abs=1.5)
    skill = info["skill"]
    assert skill.completed and 0.1 < skill.fitness <= 1.0 + 0.1
    trace = skill.trace
    assert trace.shape == env.trace_shape
    assert trace[:, env.root_nv : env.root_nv + env.nj] == pytest.approx(np.tile(d, (16, 1)))
    assert trace[:, -1] == pytest.approx(tau)
    # hindsight: a' keeps gravity and takes the jump height the episode reached
    assert skill.achieved[0] == 1.0
    assert skill.achieved[1] == pytest.approx(np.clip(env.jump_height(), 0.0, 0.6))
    # Eq. 8 spike with w_task = 10 when the clip ends, nothing before
    expected = 10.0 * np.exp(-((env.jump_height() - 0.3) ** 2) / 0.1**2)
    assert info["reward_spike"] == pytest.approx(expected)
    assert all(row[3]["reward_spike"] == 0.0 for row in rows[:-1])
    assert all(0.0 <= row[0] <= 1.0 for row in rows[:-1])  # continuous tracking, w = 1


def test_tracking_m0_scores_higher_fitness_than_flailing(env):
    rng = np.random.default_rng(1)
    calm = _run(env, lambda t: np.zeros(env.nj + 1), {"task": [1.0, 0.14]})[-1][3]["skill"]
    wild = []
    for seed in range(3):
        rows = _run(
            env, lambda t: np.append(rng.uniform(-1, 1, env.nj), 0.0), {"task": [1.0, 0.14]}, seed
        )
        wild.append(rows[-1][3]["skill"].fitness)
    assert calm.fitness > 0.5
    assert max(wild) < calm.fitness


def test_gravity_is_per_env_and_changes_the_flight(env):
    other = SkillEnv("walker", TASK, EnvConfig(clip="planar_jump"))
    env.reset(seed=0, options={"task": [0.2, 0.14]})
    other.reset(seed=0, options={"task": [1.0, 0.14]})
    assert env.model.opt.gravity[2] == pytest.approx(-0.2 * 9.81)
    assert other.model.opt.gravity[2] == pytest.approx(-9.81)
    heights = []
    for g in (1.0, 0.5):
        _run(env, lambda t: np.zeros(env.nj + 1), {"task": [g, 0.14]})
        heights.append(env.jump_height())
    assert heights[1] > heights[0]  # the same take-off flies higher on a lighter planet


def test_divergence_and_falls_end_the_episode(env):
    env.reset(seed=0, options={"task": [1.0, 0.14]})
    env.data.qvel[:] = 1e5
    _, r, te, _, info = env.step(np.zeros(env.nj + 1))
    assert te and info["diverged"] and r == 0.0
    assert info["skill"].fitness == 0.0 and info["skill"].trace is None
    rows = _run(env, lambda t: np.append(np.full(env.nj, -1.0), 0.0), {"task": [1.0, 0.14]})
    assert rows[-1][3]["fell"] and rows[-1][1]
    assert rows[-1][3]["skill"].fitness == 0.0


def test_humanoid_servos_hold_the_first_frame_of_the_jump():
    """Stable PD on the hinge triples holds the clip's pose: no collapse while the open-loop
    hold lasts (without balance feedback a 3D body tips over after about a second)."""
    env = SkillEnv(
        "humanoid", {"gravity": (1.0, 1.0)}, EnvConfig(clip="humanoid_jump", init_noise=0.0)
    )
    trace = np.zeros(env.trace_shape)
    trace[:, -1] = -3.0  # τ̂ = −3: m_a barely moves from its first frame
    env.reset(seed=0, options={"motion": trace})
    a = np.zeros(env.nj + 1)
    a[env.nj] = -3.0 / env.skill.tau_scale
    root = env.character.root_body_id
    height = env.data.xpos[root, 2]
    for _ in range(10):  # 1/3 s of PD hold
        _, _, te, _, info = env.step(a)
        assert not te
    assert env.data.xpos[root, 2] == pytest.approx(height, abs=0.03)
    tracking = env.data.qpos[env.character.qpos_idx] - env.data.ctrl
    assert np.abs(tracking).max() < 0.15
    mujoco.mj_kinematics(env.model, env.data)
    assert env.data.site_xpos[env.character.contact_site_ids, 2].min() < 0.02


def test_checks_the_gymnasium_api(env):
    from gymnasium.utils.env_checker import check_env

    check_env(env, skip_render_check=True)
    assert isinstance(env, gym.Env)
    assert SkillConfig().w_q + SkillConfig().w_ee + SkillConfig().w_com + SkillConfig().w_time == (
        pytest.approx(1.0)
    )


def test_motion_trace_displaces_m0_as_eq2():
    """m_a = m0 ⊕ d̂: joints add, the free root turns by q exp(d1) in its local frame."""
    env = SkillEnv("humanoid", {"gravity": (1.0, 1.0)}, EnvConfig(clip="humanoid_jump"))
    trace = np.zeros(env.trace_shape)
    trace[:, 0:3] = [0.1, 0.0, 0.05]  # root position
    trace[:, 3:6] = [0.0, 0.3, 0.0]  # root rotation vector
    trace[:, 6 + 2] = 0.2  # the third actuated hinge
    env.reset(seed=0, options={"motion": trace})
    q0, qa = env._q0[5], env._qa[5]
    assert qa[:3] == pytest.approx(q0[:3] + [0.1, 0.0, 0.05])
    turned = q0[3:7].copy()
    mujoco.mju_quatIntegrate(turned, np.array([0.0, 0.3, 0.0]), 1.0)
    assert np.allclose(qa[3:7], turned) or np.allclose(qa[3:7], -turned)
    idx = env.character.qpos_idx
    assert qa[idx] - q0[idx] == pytest.approx(np.eye(env.nj)[2] * 0.2)


def test_declared_measures_pay_their_rewards_and_relabel_by_the_same_measure():
    """A take-off energy (spike at take-off, in multiples of m0's) and a foot's peak
    height (continuous) declared in the config: each is paid as declared, a' and a0 come from
    the same measure."""
    measures = {
        "energy": {"measure": "takeoff_kinetic_energy", "unit": "reference"},
        "reach": {"measure": "peak_end_effector_height", "body": "foot_r",
                  "reward": "continuous"},
    }  # fmt: skip
    task = {"gravity": (0.3, 0.3), "energy": (0.5, 2.0), "reach": (0.1, 0.4)}
    env = SkillEnv("walker", task, EnvConfig(clip="planar_jump", skill={"measures": measures}))
    energy, reach = env.measured
    assert (energy.event, reach.event) == ("takeoff", "clip_end")
    assert energy.sigma == pytest.approx(1.5 / 6) and reach.sigma == pytest.approx(0.3 / 6)
    # a0: m0's own energy is 1 reference unit; the foot's peak height is m0's (0.1-0.4 m)
    ref = env.reference
    a0 = env.reference_task()
    assert a0[1] == pytest.approx(1.0)
    assert a0[2] == pytest.approx(np.clip(ref.end_effectors["foot_r"][:, 2].max(), 0.1, 0.4))
    goal = np.array([0.3, 1.2, 0.25])  # at 0.3 G tracking m0 with no displacement takes off
    rows = _run(env, lambda t: np.zeros(env.nj + 1), {"task": goal})
    traj = env.episode_trajectory()
    air = traj.airborne
    takeoffs = np.flatnonzero(air[1:] & ~air[:-1])  # row i+1 is step i's state
    assert len(takeoffs) >= 1  # tracking m0 leaves the ground
    spikes = [i for i, row in enumerate(rows) if row[3]["reward_spike"] > 0]
    assert spikes == [takeoffs[0]]  # paid once, at the step that took off
    e_off = traj.kinetic_energy[takeoffs[0] + 1] / env._reference_si["energy"]
    expected = 10.0 * np.exp(-(((e_off - 1.2) / 0.25) ** 2))
    assert rows[spikes[0]][3]["reward_spike"] == pytest.approx(expected)
    # continuous: every step pays 0.1 r_task on the peak so far, next to 0.9 r_tracking
    for i in (3, len(rows) // 2):
        peak = traj.end_effectors["foot_r"][: i + 2, 2].max()
        r_task = np.exp(-(((peak - 0.25) / 0.05) ** 2))
        assert rows[i][3]["reward_terms"]["task"] == pytest.approx(r_task)
        tracking = rows[i][0] - rows[i][3]["reward_spike"] - 0.1 * r_task
        assert 0.0 <= tracking <= 0.9 + 1e-9
    # hindsight: a' by the same measures on the whole episode, clipped into the box
    achieved = rows[-1][3]["skill"].achieved
    assert achieved[1] == pytest.approx(np.clip(e_off, 0.5, 2.0))
    assert achieved[2] == pytest.approx(np.clip(traj.end_effectors["foot_r"][:, 2].max(), 0.1, 0.4))


def test_a_zero_range_measure_is_a_constraint_in_the_fitness():
    """rotation fixed at 0 turns: Eq. 10 adds w_constraint r_constraint to the fitness of the
    same episode (same seed, same actions: the measure changes no dynamics)."""
    measures = {"turn": {"measure": "root_rotation", "axis": "pitch", "unit": "turns",
                         "sigma": 0.5}}  # fmt: skip
    base = SkillEnv("walker", {"gravity": (1.0, 1.0)}, EnvConfig(clip="planar_jump"))
    fixed = SkillEnv("walker", {"gravity": (1.0, 1.0), "turn": (0.0, 0.0)},
                     EnvConfig(clip="planar_jump", skill={"measures": measures}))  # fmt: skip
    f0 = _run(base, lambda t: np.zeros(base.nj + 1), {"task": [1.0]})[-1][3]["skill"]
    f1 = _run(fixed, lambda t: np.zeros(fixed.nj + 1), {"task": [1.0, 0.0]})[-1][3]["skill"]
    assert f0.completed and f1.completed
    # the untrained walker's torso pitches forward by about 1 rad on the way (0.15 turns)
    turned = fixed.measure(fixed.measured[0])
    pitch = np.arctan2(-fixed.data.xmat[fixed.character.root_body_id][6],
                       fixed.data.xmat[fixed.character.root_body_id][8])  # fmt: skip
    assert turned == pytest.approx(abs(pitch) / (2 * np.pi), abs=0.01)
    # W_CONSTRAINT 0.1 x exp(-(turned / 0.5)²)
    assert f1.fitness - f0.fitness == pytest.approx(0.1 * np.exp(-((turned / 0.5) ** 2)))
    # the constraint's miss in σ_task, for `curriculum.skill.constraint_tolerance`
    assert f1.constraint_error == pytest.approx(turned / 0.5)
    assert f0.constraint_error is None  # no constraint


def test_a_reference_unit_needs_a_measure_the_clip_has():
    """the walker's jump never turns its root: 'multiples of the clip's rotation' is refused."""
    measures = {"turn": {"measure": "root_rotation", "axis": "yaw", "unit": "reference"}}
    with pytest.raises(ValueError, match="task.turn: root_rotation is 0 on the clip"):
        SkillEnv("walker", {"turn": (0.5, 2.0)},
                 EnvConfig(clip="planar_jump", skill={"measures": measures}))  # fmt: skip


def test_rsi_starts_pi0_episodes_mid_clip_in_the_clips_pose_and_velocity():
    """DeepMimic's reference state initialisation for [L21]'s π0: with env.skill.rsi = 1 every
    episode without a motion trace starts at a random phase of the clip, moving as the clip
    does; it reports no a', trace or fitness (never the elite set) and pays no task reward."""
    import mujoco

    from paramimic.envs.skill_env import SkillEnv

    env = SkillEnv(
        "humanoid",
        {"gravity": (1.0, 1.0)},
        {"clip": "humanoid_jump", "frame_skip": 20, "init_noise": 0.0, "skill": {"rsi": 1.0}},
    )
    starts = set()
    for seed in range(3):
        env.reset(seed=seed)
        phi = env._phi
        assert 0 < phi < env.length - 1
        starts.add(round(phi, 6))
        q = at(env._qa, phi)
        c = env.character
        assert env.data.qpos[c.qpos_idx] == pytest.approx(q[c.qpos_idx])
        want = np.zeros(env.model.nv)
        mujoco.mj_differentiatePos(env.model, want, env.dt, q, at(env._qa, phi + 1))
        assert env.data.qvel == pytest.approx(want)
        assert env.data.site_xpos[c.contact_site_ids, 2].min() >= 1e-3 - 1e-9  # not in the floor
    assert len(starts) == 3
    while True:
        *_, term, trunc, info = env.step(np.zeros(env.action_space.shape))
        assert info["reward_terms"]["task"] == 0.0
        if term or trunc:
            break
    assert info["skill"] == SkillOutcome(None, 0.0, None, False)
    # a motion trace (P_θ's m_a, past π0) or evaluation: the clip's start, as [L21]
    env.reset(seed=0, options={"motion": np.zeros(env.trace_shape)})
    assert env._phi == 0.0
    evaluation = SkillEnv("humanoid", {"gravity": (1.0, 1.0)}, env.config.for_evaluation())
    evaluation.reset(seed=0)
    assert evaluation._phi == 0.0


def test_hold_seconds_goes_on_past_the_clips_end_and_says_whether_the_body_stood():
    """Judging a one-shot skill: the clip's summary as at its end (a', F, the spike paid then),
    then `hold_seconds` more of the last frame; `held` is whether it stood without a fall."""
    plain = SkillEnv("walker", TASK, EnvConfig(clip="planar_jump"))
    held = SkillEnv("walker", TASK, EnvConfig(clip="planar_jump", skill={"hold_seconds": 1.0}))
    zero = np.zeros(plain.action_space.shape)
    rows = _run(plain, lambda t: zero, {"task": [1.0, 0.3]})
    ends = len(rows)
    assert rows[-1][3]["skill"].completed and not rows[-1][3]["fell"]
    rows_held = _run(held, lambda t: zero, {"task": [1.0, 0.3]})
    end = rows_held[ends - 1][3]  # the same step: the clip ends, the episode does not
    assert not (rows_held[ends - 1][1] or rows_held[ends - 1][2]) and "skill" not in end
    assert end["reward_spike"] == pytest.approx(rows[-1][3]["reward_spike"])
    r, te, tr, info = rows_held[-1]
    assert te and not tr
    skill = info["skill"]
    for key in ("achieved", "fitness", "completed"):
        assert getattr(skill, key) == pytest.approx(getattr(rows[-1][3]["skill"], key))
    if skill.held:  # stood: 30 more control steps (1 s at 30 Hz)
        assert len(rows_held) == ends + 30 and not info["fell"]
    else:  # fell while holding
        assert len(rows_held) < ends + 30 and info["fell"]
    assert sum(row[3]["reward_spike"] > 0 for row in rows_held) == 1  # paid once


def test_body_error_against_m_a_by_hand():
    """The body position error of a skill: zero in m_a's own pose wherever the root stands and
    faces; a bent elbow moves only the bodies after it, each by the chord of its circle."""
    env = SkillEnv(
        "humanoid", {"gravity": (1.0, 1.0)}, EnvConfig(clip="humanoid_jump", init_noise=0.0)
    )
    env.reset(seed=0)
    m, d = env.model, env.data
    env._phi = 12.0  # a reference row: m_a's pose exactly
    d.qpos[:] = env._qa[12]
    d.qpos[0] += 3.0  # elsewhere on the floor, turned 1 rad about the vertical
    root = Rotation.from_quat(d.qpos[3:7], scalar_first=True)
    d.qpos[3:7] = (Rotation.from_euler("z", 1.0) * root).as_quat(scalar_first=True)
    mujoco.mj_kinematics(m, d)
    assert env.body_error() == pytest.approx((0.0, 0.0), abs=1e-9)
    joint = m.joint("right_elbow")
    elbow = joint.bodyid[0]
    o, axis = d.xanchor[joint.id].copy(), d.xaxis[joint.id].copy()
    moved = [b for b in range(m.nbody) if b != elbow and m.body_rootid[b] and _below(m, b, elbow)]
    chords = []
    for b in [elbow, *moved]:
        r = d.xpos[b] - o
        chords.append(2 * np.linalg.norm(r - (r @ axis) * axis) * np.sin(0.3))
    d.qpos[joint.qposadr[0]] += 0.6
    mujoco.mj_kinematics(m, d)
    n = m.nbody - env.character.root_body_id - 1
    assert max(chords) > 0.05  # the wrist
    assert env.body_error() == pytest.approx((sum(chords) / n, max(chords)), rel=1e-6)


def _below(m, b: int, ancestor: int) -> bool:
    while b > 0:
        b = m.body_parentid[b]
        if b == ancestor:
            return True
    return False


def test_evaluation_reports_a_skills_body_error_and_no_root_path():
    from paramimic.evaluation import run_episodes, summarize

    task = {"gravity": (1.0, 1.0)}
    env = SkillEnv("humanoid", task, EnvConfig(clip="humanoid_jump", frame_skip=20))
    zero = np.zeros(env.action_space.shape, np.float32)
    results = run_episodes(
        lambda obs: np.tile(zero, (len(obs), 1)),
        lambda: SkillEnv("humanoid", task, EnvConfig(clip="humanoid_jump", frame_skip=20)),
        np.ones((2, 1)),
        num_envs=2,
        seed=0,
    )
    report = summarize(results)
    assert 0 < report["mean_body_error"] < 0.5
    assert "mean_root_drift" not in report and "speed_ratio" not in report


def test_a_training_time_limit_truncates_a_skill_and_its_stand():
    cfg = EnvConfig(clip="humanoid_jump", frame_skip=20, skill={"hold_seconds": 1.0})
    env = SkillEnv("humanoid", {"gravity": (1.0, 1.0)}, cfg)
    assert env.horizon_seconds == pytest.approx(env.clip.duration + 1.0, abs=env.dt)
    zero = np.zeros(env.action_space.shape)
    env.set_time_limit(0.3)  # 9 control steps: mid-clip
    rows = _run(env, lambda i: zero)
    assert len(rows) == 9
    _, te, tr, info = rows[-1]
    assert tr and not te and not info["fell"]
    assert info["skill"].completed is False
    env.set_time_limit(None)
    assert len(_run(env, lambda i: zero)) > 9  # the env's own end again


def test_without_time_warp_the_reference_runs_in_real_time_whatever_tau_asks():
    """[L21] §7.2's A2: `time_warp: false` ignores the policy's τ and every motion's τ̂, so φ
    advances one control step per step, r_time pays 1 and the trace records τ = 0; with the
    warp on, the same actions advance φ by exp(τ) per step."""
    skill = {"time_warp": False}
    plain = SkillEnv("walker", TASK, EnvConfig(clip="planar_jump", skill=skill))
    warped = SkillEnv("walker", TASK, EnvConfig(clip="planar_jump"))
    trace = np.zeros(plain.trace_shape)
    trace[:, -1] = 0.5  # a motion that asks for e^0.5 control steps per step
    a = np.zeros(plain.nj + 1)
    a[plain.nj] = 0.4 / plain.skill.tau_scale
    for env in (plain, warped):
        env.reset(seed=0, options={"motion": trace})
        for _ in range(5):
            _, _, te, _, _ = env.step(a)
            assert not te
    assert plain._phi == pytest.approx(5.0)
    assert warped._phi == pytest.approx(5 * np.exp(0.4))
    assert plain._tracking(plain._phi, 0.0)[3] == pytest.approx(1.0)  # r_time: τ = τ̂ = 0
    assert np.all(np.asarray(plain._rec["d"])[:, -1] == 0.0)


@pytest.mark.parametrize("sigma", [0.05, 0.5])
def test_evaluation_counts_a_task_achieved_within_sigma_of_every_measured_goal(sigma):
    """[L21] family evaluation: a task is achieved when every measured parameter lands within
    its σ_task of the goal (a constraint unclipped: a' of a zero-width range is always the
    goal), the clip is completed and the character does not fall."""
    from paramimic.evaluation import run_episodes, summarize

    measures = {"turn": {"measure": "root_rotation", "axis": "pitch", "unit": "turns",
                         "sigma": sigma}}  # fmt: skip
    task = {"gravity": (1.0, 1.0), "turn": (0.0, 0.0)}
    cfg = EnvConfig(clip="planar_jump", skill={"measures": measures})
    probe = SkillEnv("walker", task, cfg)
    zero = np.zeros(probe.nj + 1)
    # the episodes run_episodes(seed=0) plays: its reset seeds, drawn in task order
    draw = np.random.default_rng(0)
    turned = []
    for _ in range(2):
        rows = _run(probe, lambda t: zero, {"task": [1.0, 0.0]}, int(draw.integers(2**31 - 1)))
        info = rows[-1][3]
        assert info["skill"].completed and not info["fell"]
        assert info["skill"].achieved[1] == 0.0  # hindsight a' is clipped into the range
        turned.append(probe.measure(probe.measured[0]))
        assert probe.task_errors() == {"turn": pytest.approx(turned[-1] / sigma)}
    assert max(turned) > 0.05  # the untrained torso pitches

    seen = []
    results = run_episodes(
        lambda obs: np.tile(zero, (len(obs), 1)),
        lambda: SkillEnv("walker", task, cfg),
        np.array([[1.0, 0.0]] * 2),
        num_envs=2,
        seed=0,
        motions=lambda tasks: seen.append(tasks.copy()) or None,
    )
    assert len(seen) == 1 and seen[0].shape == (2, 2)  # one deal for every task
    errors = [t / sigma for t in turned]
    for r, e in zip(results, errors, strict=True):
        assert r.task_errors == {"turn": pytest.approx(e)}
        assert r.achieved == (e <= 1.0)
    report = summarize(results)
    assert report["achieved_share"] == np.mean([e <= 1.0 for e in errors])
    assert report["task_error_sigmas"]["turn"] == pytest.approx(np.mean(errors))


def test_a_skill_that_leaves_its_reference_deviates_not_falls_and_evaluation_runs_on():
    """env.deviation_limit on an [L21] skill, as on a clip gait: a body farther than the limit
    from m_a's at φ (root-relative, heading frame), or the root's height, ends the episode as a
    deviation (never a fall, no completed clip, no fitness); evaluation runs without the rule."""
    config = {"clip": "humanoid_jump", "frame_skip": 20, "init_noise": 0.0,
              "deviation_limit": 0.3}  # fmt: skip
    env = SkillEnv("humanoid", {"gravity": (1.0, 1.0)}, config)
    zero = np.zeros(env.action_space.shape)
    env.reset(seed=0)
    assert not env._deviated()  # on the reference at the start
    shoulder = env.model.joint("right_shoulder_x").qposadr[0]
    env.data.qpos[shoulder] += 2.5  # the right arm swung far up: the wrist ~0.9 m away
    mujoco.mj_kinematics(env.model, env.data)
    assert env.body_error()[1] > 0.3 and env._deviated()
    # the root lifted 0.4 m, every body where the clip has it relative to the root: the height
    env.reset(seed=0)
    env.data.qpos[2] += 0.4
    mujoco.mj_kinematics(env.model, env.data)
    assert env.body_error()[1] < 0.3 and env._deviated()
    env.reset(seed=0)
    env.data.qpos[shoulder] += 2.5
    env.data.qvel[:] = 0.0
    _, _, term, trunc, info = env.step(zero)
    assert term and not trunc and info["deviated"] and not info["fell"]
    assert info["skill"].fitness == 0.0 and not info["skill"].completed
    evaluation = SkillEnv("humanoid", {"gravity": (1.0, 1.0)}, env.config.for_evaluation())
    evaluation.reset(seed=0)
    evaluation.data.qpos[shoulder] += 2.5
    evaluation.data.qvel[:] = 0.0
    assert not evaluation.step(zero)[4]["deviated"]


def test_rsi_start_phases_follow_where_a_skills_episodes_fail():
    """env.phase_sampling: failures on a skill's RSI: the clip's phase in bins (a line, not a
    cycle), each bin's failure rate learned from the RSI episodes that started there."""
    config = {"clip": "humanoid_backflip", "frame_skip": 20, "phase_sampling": "failures",
              "phase_bins": 4, "phase_alpha": 0.5, "skill": {"rsi": 1.0}}  # fmt: skip
    env = SkillEnv("humanoid", {"gravity": (1.0, 1.0)}, config)
    sampler = env._phases
    assert sampler is not None and not sampler.wrap
    env.reset(seed=0)
    start = env._start
    assert env._phi == pytest.approx(start * (env.length - 1.0))
    while True:  # zero actions: the humanoid falls before the backflip's end
        *_, term, trunc, info = env.step(np.zeros(env.action_space.shape))
        if term or trunc:
            break
    assert info["fell"]
    expected = np.zeros(4)
    expected[int(start * 4)] = 0.5  # EMA 0 -> 0.5 in the bin it started in
    assert sampler.failure == pytest.approx(expected)
    sampler.failure[:] = [0.0, 0.0, 0.0, 1.0]  # only the clip's last quarter fails
    # smoothed over the line: [0, 0, 0.25, 0.75] / 1.0, times 0.9, plus 0.025 each
    assert sampler.probabilities() == pytest.approx([0.025, 0.025, 0.25, 0.7])
    starts = []
    for seed in range(200):
        env.reset(seed=seed)
        starts.append(env._phi / (env.length - 1.0))
    counts = np.bincount((np.asarray(starts) * 4).astype(int), minlength=4) / len(starts)
    assert counts == pytest.approx([0.025, 0.025, 0.25, 0.7], abs=0.08)
    evaluation = SkillEnv("humanoid", {"gravity": (1.0, 1.0)}, env.config.for_evaluation())
    assert evaluation._phases is None
