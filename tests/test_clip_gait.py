"""A looping clip as a [WL19] reference gait (env.gait): the gait table, reference state
initialisation with the root's pose and velocity, fall contact, deviation termination and the
imitation measures of evaluation."""

import math

import mujoco
import numpy as np
import pytest
from pydantic import ValidationError
from scipy.spatial.transform import Rotation

from paramimic.characters.humanoid import humanoid_clip
from paramimic.config import ExperimentConfig
from paramimic.envs import make_env
from paramimic.evaluation import run_episodes, summarize
from paramimic.motion.clip import Clip
from paramimic.motion.clip_gait import ClipGait

GAIT = {"gait": "humanoid_walk", "physics_hz": 300, "init_noise": 0.0}


def _synthetic(loop="wrap", turn=0.0) -> Clip:
    """2 s per cycle, the root walking 1 m along +y facing +y, one revolute joint
    0.5 sin(2π t / 2) (the last frame closes the cycle), the heading turning `turn` rad a cycle."""
    t = np.linspace(0.0, 2.0, 41)
    root = np.column_stack([np.zeros_like(t), 0.5 * t, np.full_like(t, 0.9)])
    yaw = math.pi / 2 + turn * t / 2.0
    quat = Rotation.from_euler("z", yaw[:, None]).as_quat()
    return Clip(
        name="synthetic",
        durations=np.full(len(t), 0.05),
        root_position=root,
        root_quat=quat,
        spherical_names=(),
        spherical=np.zeros((len(t), 0, 4)),
        revolute_names=("knee",),
        revolute=(0.5 * np.sin(math.pi * t))[:, None],
        loop=loop,
    )


def _qpos(pose):
    q = np.zeros((len(pose.root_position), 8))
    q[:, :3] = pose.root_position
    q[:, 3:7] = Rotation.from_quat(pose.root_quat).as_quat(scalar_first=True)
    q[:, 7] = pose.revolute[:, 0]
    return q


def _gait(**kw) -> ClipGait:
    return ClipGait.from_clip(_synthetic(**kw), ("knee",), _qpos, np.array([7]))


def test_a_clip_gait_travels_along_x_at_the_clips_speed():
    g = _gait()
    assert g.period == pytest.approx(2.0)
    assert g.speed == pytest.approx(0.5)  # 1 m of travel in a 2-s cycle
    # the clip walked along +y facing +y: the gait walks along +x facing +x
    for phi in (0.0, 0.3, 0.9):
        assert g.root_rotation(phi).apply([1.0, 0.0, 0.0]) == pytest.approx([1, 0, 0], abs=1e-9)
        assert g.root_velocity(phi)[0] == pytest.approx([0.5, 0.0, 0.0], abs=1e-6)
    # the root path advances one cycle's travel per cycle
    assert g.root_path(0.25) == pytest.approx([0.25, 0.0], abs=1e-9)
    assert g.root_path(2.25) == pytest.approx([2.25, 0.0], abs=1e-9)


def test_joint_pose_and_velocity_are_the_clips_in_cycles():
    g = _gait()
    for phi in (0.0, 0.125, 0.5, 0.8):
        t = 2.0 * phi
        assert g.pose(phi) == pytest.approx([0.5 * math.sin(math.pi * t)], abs=2e-3)
        # d/dt 0.5 sin(π t) = 0.5 π cos(π t)
        assert g.velocity(phi) == pytest.approx([0.5 * math.pi * math.cos(math.pi * t)], abs=0.02)
    # periodic: φ and φ + 1 are the same pose
    assert g.pose(np.array([0.3, 1.3, 2.3])) == pytest.approx(np.full((3, 1), g.pose(0.3)[0]))


def test_the_cycles_net_turn_is_spread_over_the_cycle():
    """A clip that turns 0.2 rad a cycle would jump back 0.2 rad at every loop; the gait turns
    the heading by -0.2 φ, so the facing is continuous across the cycle's end."""
    g = _gait(turn=0.2)
    start = g.root_rotation(0.0).as_euler("ZYX")[0]
    end = g.root_rotation(0.999).as_euler("ZYX")[0]
    assert end - start == pytest.approx(0.0, abs=2e-3)
    assert g.root_velocity(0.5)[1] == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)


def test_a_clip_that_does_not_loop_is_no_gait():
    with pytest.raises(ValueError, match="does not loop"):
        _gait(loop="none")


def test_the_humanoid_walk_gait_is_the_clip():
    clip = humanoid_clip("walk")
    env = make_env("humanoid", {}, GAIT)
    g = env._gait
    assert g.period == pytest.approx(clip.duration)
    hip = env.character.hip_height / (0.421546 + 0.40987 + 0.05)  # the hip height ratio: 1
    drift = clip.root_position[-1, :2] - clip.root_position[0, :2]
    assert g.speed == pytest.approx(hip * np.hypot(*drift) / clip.duration)
    assert env._target_v == pytest.approx(g.speed)  # no target: the clip's own speed
    q0 = env.definition.pose_qpos(env.character, clip.sample(np.array([0.0])))[0]
    assert g.pose(0.0) == pytest.approx(q0[env.character.qpos_idx], abs=1e-9)


def test_reset_starts_at_a_random_phase_in_the_clips_pose_and_velocity():
    env = make_env("humanoid", {}, GAIT)
    g, c, d = env._gait, env.character, env.data
    phases = set()
    for seed in range(4):
        env.reset(seed=seed)
        phi = env._phase
        phases.add(round(phi, 6))
        assert d.qpos[c.qpos_idx] == pytest.approx(
            np.clip(g.pose(phi), c.ctrl_low, c.ctrl_high), abs=1e-9
        )
        assert d.qvel[c.qvel_idx] == pytest.approx(g.velocity(phi), abs=1e-9)
        # the root: the clip's orientation and velocities (facing the target direction, +x)
        want = g.root_rotation(phi).as_quat(scalar_first=True)
        assert abs(np.dot(d.qpos[3:7], want)) == pytest.approx(1.0, abs=1e-9)
        linear, angular = g.root_velocity(phi)
        assert d.qvel[0:3] == pytest.approx(linear, abs=1e-9)
        assert d.qvel[3:6] == pytest.approx(angular, abs=1e-9)
        # the reference itself: no body error, no drift
        assert env.body_error()[1] == pytest.approx(0.0, abs=5e-3)  # (tables' interpolation)
        assert env.root_drift() == pytest.approx(0.0, abs=1e-9)
        assert env.facing_error() == pytest.approx(0.0, abs=1e-3)
    assert len(phases) == 4


def test_reset_faces_the_target_direction():
    env = make_env("humanoid", {}, GAIT | {"target_direction": math.pi / 2})
    env.reset(seed=0)
    g = env._gait
    linear, _ = g.root_velocity(env._phase)
    assert env.data.qvel[0:2] == pytest.approx([-linear[1], linear[0]], abs=1e-9)  # turned 90°
    fx, fy = env._facing()
    forward = g.root_rotation(env._phase).apply([1.0, 0.0, 0.0])
    assert math.atan2(fy, fx) == pytest.approx(
        math.pi / 2 + math.atan2(forward[1], forward[0]), abs=1e-6
    )


def test_a_body_far_from_its_reference_deviates_and_evaluation_does_not_end_it():
    env = make_env("humanoid", {}, GAIT | {"deviation_limit": 0.5})
    env.reset(seed=0)
    elbow = env.model.joint("right_elbow").qposadr[0]
    shoulder = env.model.joint("right_shoulder_x").qposadr[0]
    ref = env.data.qpos.copy()
    env.data.qpos[shoulder] += 2.5  # the right arm swung far up: the wrist ~0.9 m away
    mujoco.mj_kinematics(env.model, env.data)
    assert env.body_error()[1] > 0.5
    env.data.qpos[:] = ref
    env.data.qpos[elbow] += 0.05  # a small error: no deviation
    mujoco.mj_kinematics(env.model, env.data)
    assert 0 < env.body_error()[1] < 0.5
    # a whole step after the arm is thrown: the episode ends, as a deviation, not as a fall
    env.reset(seed=0)
    env.data.qpos[shoulder] += 2.5
    env.data.qvel[:] = 0.0
    info = env.step(np.zeros(env.action_space.shape))[4]
    assert info["deviated"] and not info["fell"]
    assert env.config.for_evaluation().deviation_limit is None


def test_a_clip_gait_falls_on_a_fall_contact_only():
    env = make_env("humanoid", {}, GAIT)
    env.reset(seed=0)
    obs, r, term, trunc, info = env.step(np.zeros(env.action_space.shape))
    assert not info["fell"] and not term
    env.data.qpos[2] = -0.05  # the root down in the floor
    mujoco.mj_forward(env.model, env.data)
    assert env.fall_contact()


def test_evaluation_reports_the_imitation_measures():
    env_cfg = GAIT | {"max_episode_seconds": 0.5}
    results = run_episodes(
        lambda obs: np.zeros((len(obs), 28), np.float32),
        lambda: make_env("humanoid", {}, env_cfg),
        np.zeros((2, 0)),
        num_envs=2,
        seed=0,
    )
    report = summarize(results)
    clip = humanoid_clip("walk")
    speed = (
        float(np.hypot(*(clip.root_position[-1, :2] - clip.root_position[0, :2]))) / clip.duration
    )
    assert report["clip_speed"] == pytest.approx(speed, rel=1e-6)
    assert 0 < report["mean_body_error"] < 0.5
    assert report["mean_root_drift"] >= 0
    assert 0 <= report["mean_facing_error"] <= math.pi
    assert report["speed_ratio"] == pytest.approx(report["mean_forward_speed"] / speed)
    assert report["speed_over_target"] == pytest.approx(report["speed_ratio"])  # the base body
    assert 0.0 <= report["on_target_share"] <= 1.0


def test_a_bodys_speed_is_judged_against_its_own_normalized_target():
    """[WL19] Table 1 on the humanoid: legs 1.5x walk the clip 1.5x as fast; the evaluation's
    speed over target is each body's speed over its own target (hand-worked: speeds 1.0 and
    1.0 m/s against targets 1.0 and 1.2 -> 1.0 and 0.833, mean 0.917, one of two within 15 %)."""
    from paramimic.evaluation import EpisodeResult

    base = make_env("humanoid", {}, GAIT)
    long = make_env("humanoid", {"leg_length": (1.5, 1.5)}, GAIT)
    base.reset(seed=0)
    long.reset(seed=0)
    assert long.target_speed == pytest.approx(1.5 * base.target_speed, rel=1e-9)
    assert base.target_speed == pytest.approx(base.clip_speed)
    one = dict(task=np.zeros(0), ret=1.0, task_return=0.0, length=30, fell=False, distance=1.0)
    results = [EpisodeResult(**one, seconds=1.0, target_speed=t) for t in (1.0, 1.2)]
    report = summarize(results)
    assert report["speed_over_target"] == pytest.approx((1.0 + 1.0 / 1.2) / 2)
    assert report["on_target_share"] == 0.5


def test_configs_name_a_clip_gait_plainly(tmp_path):
    still = tmp_path / "still.txt"  # a user's clip that does not loop
    text = (humanoid_clip.__globals__["DATA"] / "humanoid3d_walk.txt").read_text()
    still.write_text(text.replace('"wrap"', '"none"'))
    cfg = ExperimentConfig.model_validate(
        {"character": "humanoid", "env": {"gait": "humanoid_walk", "deviation_limit": 0.5}}
    )
    assert cfg.env.gait == "humanoid_walk" and cfg.env.clip is None
    bad = [
        ({"gait": "humanoid_walk", "clip": "humanoid_walk"}, "not both"),
        ({"gait": "humanoid_moonwalk"}, "env.gait 'humanoid_moonwalk' does not fit"),
    ]
    for env, message in bad:
        with pytest.raises(ValidationError, match=message):
            ExperimentConfig.model_validate({"character": "humanoid", "env": env})
    # whether a file parses and loops is the train preflight's (validation reads no files)
    from paramimic.training.preflight import PreflightError, preflight

    unchecked = ExperimentConfig.model_validate(
        {"character": "humanoid", "env": {"gait": str(still)}}
    )
    with pytest.raises(PreflightError, match="env.gait: clip .* does not loop"):
        preflight(unchecked)


def test_the_walk_gait_is_a_gymnasium_env():
    import gymnasium as gym

    env = gym.make("paramimic/HumanoidWalkGait-v0")
    obs, _ = env.reset(seed=0)
    assert env.unwrapped.clip_speed == pytest.approx(0.978, abs=1e-3)
    assert env.unwrapped.config.physics_hz == 300
    obs, *_ = env.step(env.action_space.sample())
    assert obs.shape == env.observation_space.shape


def test_phase_sampling_follows_the_failures_with_a_uniform_floor():
    from paramimic.motion.phase import PhaseSampler

    s = PhaseSampler(bins=4, alpha=0.5, uniform=0.2)
    assert s.probabilities() == pytest.approx([0.25] * 4)  # nothing failed yet
    s.update(0.3, failed=True)  # bin 1: EMA 0 -> 0.5
    s.update(0.6, failed=False)  # bin 2 stays 0
    # smoothed over the circle: [0.125, 0.25, 0.125, 0] / 0.5, times 0.8, plus 0.05 each
    assert s.probabilities() == pytest.approx([0.25, 0.45, 0.25, 0.05])
    s.update(1.3, failed=False)  # bin 1 again (the cycle wraps): 0.5 -> 0.25
    assert s.failure == pytest.approx([0.0, 0.25, 0.0, 0.0])
    rng = np.random.default_rng(0)
    draws = np.array([s.sample(rng) for _ in range(4000)])
    counts = np.bincount((draws * 4).astype(int), minlength=4) / len(draws)
    assert counts == pytest.approx([0.25, 0.45, 0.25, 0.05], abs=0.03)


def test_a_clip_gait_env_learns_where_its_episodes_fail():
    env = make_env("humanoid", {}, GAIT | {"phase_sampling": "failures", "phase_bins": 5})
    env.reset(seed=0)
    start = env._phase0
    while True:  # zero actions: the humanoid falls within seconds
        *_, term, trunc, info = env.step(np.zeros(env.action_space.shape))
        if term or trunc:
            break
    assert info["fell"] or info["deviated"] or trunc
    failed = info["fell"] or info["deviated"]
    b = int(start * 5)
    assert env._phases.failure[b] == pytest.approx(0.02 * failed)
    assert make_env("humanoid", {}, env.config.for_evaluation())._phases is None


def test_a_clip_gait_family_changes_shape_on_the_fly():
    """[WL19] §5.2 on the humanoid's clip gait: a longer-legged body gets its own gait table (the
    clip's root path scaled by its hip height) and keeps walking from the same phase."""
    env = make_env("humanoid", {"leg_length": (0.8, 1.2)}, GAIT)
    env.reset(seed=0, options={"task": {"leg_length": 1.0}})
    base_speed = env.clip_speed
    env.step(np.zeros(env.action_space.shape))
    phase = env._phase
    obs = env.set_shape({"leg_length": 1.2})
    assert env._phase == phase and obs.shape == env.observation_space.shape
    ratio = env.character.hip_height / env._base.hip_height
    assert env.clip_speed == pytest.approx(base_speed * ratio)
    *_, info = env.step(np.zeros(env.action_space.shape))
    assert not info["diverged"]


def test_deviated_episodes_are_reported_as_such_not_as_falls():
    """The training metrics count deviations apart from falls (episode_metrics)."""
    from paramimic.rl.rollout import RolloutWorker
    from paramimic.training.trainer import episode_metrics

    cfg = GAIT | {"deviation_limit": 0.3, "max_episode_seconds": 3.0}
    w = RolloutWorker(lambda: make_env("humanoid", {}, cfg), 2, 1, 28, seed=0)
    f = w.collect(60, use_policy=False)  # zero actions: the reference's PD targets alone
    assert f.episodes and all(e.ended_early for e in f.episodes if e.length < 90)
    deviated = [e for e in f.episodes if e.deviated]
    assert deviated and not any(e.fell for e in deviated)
    m = episode_metrics(f.episodes)
    assert m["deviated_percent"] == pytest.approx(100.0 * len(deviated) / len(f.episodes))
    assert f.episodes[0].to_dict()["deviated"] == f.episodes[0].deviated


def _term_before_and_after_a_turn(env, term: str, turn: Rotation, seed: int):
    """A clip gait's reward term in its reference state at a random phase, and again after the
    whole body is turned by `turn` (joints kept); the env is left turned."""
    env.reset(seed=seed)
    env._sense()
    ref = env._reference_at(env._phase)
    before = env._reward(ref)[1][term]
    rot = Rotation.from_quat(env.data.qpos[3:7], scalar_first=True)
    env.data.qpos[3:7] = (turn * rot).as_quat(scalar_first=True)
    mujoco.mj_forward(env.model, env.data)
    env._sense()
    return before, env._reward(ref)[1][term]


def test_end_effectors_in_the_heading_frame_imitate_the_bodys_tilt():
    """reward.end_effector_frame: heading compares the end-effectors relative to the root in its
    heading frame, so a body that leans away from its reference loses the term; in the root's
    own frame (the default) the same lean goes unseen."""
    cartwheel = GAIT | {"gait": "humanoid_cartwheel"}
    ee = {}
    for frame in ("root", "heading"):
        env = make_env("humanoid", {}, cartwheel | {"reward": {"end_effector_frame": frame}})
        lean = Rotation.from_euler("y", 1.0)  # 57° about the world's y axis, joints kept
        ee[frame] = _term_before_and_after_a_turn(env, "end_effector", lean, seed=3)
    n_ee = len(env.character.ee_site_ids)
    for frame in ee:  # the reference state matches its reference in both frames
        assert ee[frame][0] == pytest.approx(n_ee, abs=0.05)
    assert ee["root"][1] == pytest.approx(ee["root"][0], abs=1e-9)
    assert ee["heading"][1] < 0.7 * n_ee
    # the heading frame needs a reference root orientation: a clip gait's
    with pytest.raises(ValidationError, match="end_effector_frame: heading needs a clip gait"):
        ExperimentConfig.model_validate(
            {"character": "humanoid", "env": {"reward": {"end_effector_frame": "heading"}}}
        )


def test_the_facing_term_follows_the_clips_own_facing():
    """reward.facing: clip wants the clip's root facing at this phase (turned onto the target
    direction) where [WL19]'s d′ is the target direction: the cartwheel, which faces across its
    path, is paid for facing as its reference does and loses the term when its yaw turns away;
    the target facing pays it for a yaw the clip never has."""
    cartwheel = GAIT | {"gait": "humanoid_cartwheel", "target_direction": 0.7}
    terms = {}
    for facing in ("target", "clip"):
        env = make_env("humanoid", {}, cartwheel | {"reward": {"facing": facing}})
        turn = Rotation.from_euler("z", 1.0)  # the whole body turned 57° about the vertical
        terms[facing] = (
            *_term_before_and_after_a_turn(env, "direction", turn, seed=5),
            env.heading_error(),
        )
    assert terms["clip"][0] == pytest.approx(1.0, abs=0.02)
    assert terms["clip"][1] < 0.01 and terms["clip"][2] == pytest.approx(1.0, abs=0.05)
    assert env.facing_error() == pytest.approx(1.0, abs=0.05)  # the turn, whatever the reward
    assert terms["target"][0] < 0.5  # the cartwheel does not face its target direction
    with pytest.raises(ValidationError, match="facing: clip needs a clip gait"):
        ExperimentConfig.model_validate(
            {"character": "humanoid", "env": {"reward": {"facing": "clip"}}}
        )
