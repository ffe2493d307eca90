"""Reference clips: the DeepMimic loader on the shipped clips, slerp, the humanoid replay, and the
procedural planar jump."""

import json

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paramimic.characters import get_character
from paramimic.characters.humanoid import HUMANOID, humanoid_clip
from paramimic.motion.clip import Clip, load_deepmimic
from paramimic.motion.procedural import GRAVITY, JUMP_APEX, planar_jump_clip

FRAMES = {"walk": 39, "run": 25, "jump": 107, "backflip": 29, "cartwheel": 164}


@pytest.fixture(scope="module")
def humanoid():
    return HUMANOID.compile()


@pytest.mark.parametrize("name", sorted(FRAMES))
def test_shipped_clip_loads(name):
    clip = humanoid_clip(name)
    assert clip.num_frames == FRAMES[name]
    assert clip.loop == "wrap"
    assert np.allclose(np.linalg.norm(clip.root_quat, axis=-1), 1.0)
    assert np.allclose(np.linalg.norm(clip.spherical, axis=-1), 1.0)
    knees = [clip.revolute_names.index(k) for k in ("right_knee", "left_knee")]
    elbows = [clip.revolute_names.index(k) for k in ("right_elbow", "left_elbow")]
    assert np.all(clip.revolute[:, knees] <= 1e-6), "knees bend backwards (<= 0)"
    assert np.all(clip.revolute[:, elbows] >= -1e-6), "elbows bend forwards (>= 0)"
    # Z up: the root starts at pelvis height, standing upright (its local y is the world z)
    assert 0.7 < clip.root_position[0, 2] < 0.95
    up = Rotation.from_quat(clip.root_quat[0]).apply([0.0, 1.0, 0.0])
    assert up[2] > 0.9


def test_sample_hits_frames_and_slerps_between():
    clip = humanoid_clip("walk")
    pose = clip.sample(clip.times[:-1])  # the last frame's time starts the next cycle
    assert np.allclose(pose.root_position, clip.root_position[:-1])
    assert np.allclose(np.abs(np.sum(pose.spherical * clip.spherical[:-1], axis=-1)), 1.0)
    # halfway between frames 3 and 4: the rotation halfway along the geodesic
    mid = clip.sample(0.5 * (clip.times[3] + clip.times[4]))
    q3, q4 = Rotation.from_quat(clip.spherical[3]), Rotation.from_quat(clip.spherical[4])
    qm = Rotation.from_quat(mid.spherical[0])
    assert np.allclose((q3.inv() * qm).magnitude(), 0.5 * (q3.inv() * q4).magnitude(), atol=1e-9)
    assert np.allclose(mid.revolute[0], 0.5 * (clip.revolute[3] + clip.revolute[4]))
    # a wrapping clip carries on one cycle later, moved forward by one cycle's displacement
    later = clip.sample(clip.times[5] + clip.duration)
    drift = clip.root_position[-1] - clip.root_position[0]
    assert np.allclose(later.root_position[0, :2], clip.root_position[5, :2] + drift[:2])
    assert later.root_position[0, 2] == pytest.approx(clip.root_position[5, 2])


def test_loader_rejects_bad_files(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("not json")
    with pytest.raises(ValueError, match="not a DeepMimic clip"):
        load_deepmimic(bad)
    bad.write_text(json.dumps({"Loop": "wrap", "Frames": [[0.1] * 40, [0.0] * 40]}))
    with pytest.raises(ValueError, match="44 numbers"):
        load_deepmimic(bad)
    with pytest.raises(KeyError, match="shipped"):
        humanoid_clip("moonwalk")


def test_hinge_triples_equal_ball_joints(humanoid):
    """The x-y-z hinge decomposition puts every body exactly where ball joints would."""
    spec = HUMANOID.spec()
    for a in list(spec.actuators):
        spec.delete(a)
    for s in list(spec.sensors):
        spec.delete(s)
    for name in HUMANOID.spherical:
        for axis in "xyz":
            spec.delete(spec.joint(f"{name}_{axis}"))
        spec.body(name).add_joint(name=name, type=mujoco.mjtJoint.mjJNT_BALL)
    ball = spec.compile()
    clip = humanoid_clip("cartwheel")
    pose = clip.sample(clip.times[::7])
    qpos = HUMANOID.pose_qpos(humanoid, pose)
    d, d2 = mujoco.MjData(humanoid.model), mujoco.MjData(ball)
    for i in range(len(qpos)):
        d.qpos[:] = qpos[i]
        d2.qpos[:7] = qpos[i, :7]
        for s, name in enumerate(HUMANOID.spherical):
            adr = ball.jnt_qposadr[ball.joint(name).id]
            d2.qpos[adr : adr + 4] = Rotation.from_quat(pose.spherical[i, s]).as_quat(
                scalar_first=True
            )
        for r, name in enumerate(HUMANOID.revolute):
            d2.qpos[ball.jnt_qposadr[ball.joint(name).id]] = pose.revolute[i, r]
        mujoco.mj_kinematics(humanoid.model, d)
        mujoco.mj_kinematics(ball, d2)
        assert np.allclose(d.xpos, d2.xpos, atol=1e-9)


# The run clip itself puts one heel 5.9 cm under the floor at its heel strikes (frames 11, 23);
# the hinge model equals a ball-joint model to 1e-9 (above), so that is the data, not the mapping.
PENETRATION = {"run": 0.06}


@pytest.mark.parametrize("name", sorted(FRAMES))
def test_replay_keeps_feet_on_the_ground(humanoid, name):
    """Every frame on the humanoid: the lowest foot point is within 5 cm of the ground unless the
    character is airborne (lowest point above 5 cm); flights are few, contiguous intervals."""
    clip = humanoid_clip(name)
    qpos = HUMANOID.pose_qpos(humanoid, clip.sample(clip.times))
    m, d = humanoid.model, mujoco.MjData(humanoid.model)
    lowest = np.empty(len(qpos))
    for i, row in enumerate(qpos):
        d.qpos[:] = row
        mujoco.mj_kinematics(m, d)
        lowest[i] = d.site_xpos[humanoid.contact_site_ids, 2].min()
    assert lowest.min() >= -PENETRATION.get(name, 0.05)
    grounded = lowest <= 0.05
    assert grounded.mean() > 0.4, "most frames have a foot on the ground"
    if name == "walk":
        assert grounded.all() and np.abs(lowest).max() < 0.02
    if name == "jump":
        airborne = np.flatnonzero(~grounded)
        assert len(airborne) > 5 and np.all(np.diff(airborne) == 1), "one flight"


def test_planar_jump_clip():
    walker = get_character("walker")
    joints = tuple(j.name for j in walker.joints)
    clip = planar_jump_clip(joints, 0.45, 0.45, 0.05)
    assert clip.revolute_names == joints and clip.loop == "none"
    z = clip.root_position[:, 2]
    standing = 0.05 + 0.9
    assert z[0] == pytest.approx(standing) and z[-1] == pytest.approx(standing)
    assert z.min() < standing - 0.15  # a real crouch
    take_off = z[np.argmax(clip.revolute[:, 2] < -0.34)]  # ankle fully extended
    assert z.max() == pytest.approx(take_off + JUMP_APEX, abs=2e-3)
    # in flight the root follows gravity: constant second difference −g dt²
    dt = 1.0 / 60.0
    air = np.flatnonzero(z > take_off + 0.01)
    acc = np.diff(z[air], 2) / dt**2
    assert acc == pytest.approx(-GRAVITY, rel=1e-6)
    # flat feet in stance: pitch + hip + knee + ankle = 0 at the start and the end
    pitch = Rotation.from_quat(clip.root_quat).as_rotvec() @ np.array([0.0, -1.0, 0.0])
    assert pitch[0] + clip.revolute[0, :3].sum() == pytest.approx(0.0)
    with pytest.raises(ValueError, match="at least 2 frames"):
        Clip(
            "x",
            np.zeros(1),
            np.zeros((1, 3)),
            np.zeros((1, 4)),
            (),
            np.zeros((1, 0, 4)),
            (),
            np.zeros((1, 0)),
        )
