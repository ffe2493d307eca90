"""A user's BVH motion capture retargeted onto the humanoid (`paramimic clip import`), checked
against the source through MuJoCo's kinematics."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pybvh
import pytest

from paramimic.characters import registration
from paramimic.characters.bvh_import import import_bvh, kinematics
from paramimic.motion.clip import Y_UP_TO_Z_UP

CMU_FILE = (
    Path(__file__).resolve().parents[2] / "shared" / "motions" / "bvh" / "cmu_131_01_walk.bvh"
)
BONES = [  # humanoid (parent, child) bodies and the CMU joints at their ends
    ("left_hip", "left_knee", "LeftHip", "LeftKnee"),
    ("left_knee", "left_ankle", "LeftKnee", "LeftAnkle"),
    ("right_hip", "right_knee", "RightHip", "RightKnee"),
    ("right_knee", "right_ankle", "RightKnee", "RightAnkle"),
    ("left_shoulder", "left_elbow", "LeftShoulder", "LeftElbow"),
    ("left_elbow", "left_wrist", "LeftElbow", "LeftWrist"),
    ("right_shoulder", "right_elbow", "RightShoulder", "RightElbow"),
    ("right_elbow", "right_wrist", "RightElbow", "RightWrist"),
]
# the CMU file renamed as Mixamo and LAFAN1 name their bones: "LeftShoulder" is CMU's upper arm
# and those namings' clavicle (CMU's LeftCollar)
LIMBS = {"Collar": "Shoulder", "Shoulder": "Arm", "Elbow": "ForeArm", "Wrist": "Hand",
         "Hip": "UpLeg", "Knee": "Leg", "Ankle": "Foot"}  # fmt: skip
pytestmark = pytest.mark.skipif(not CMU_FILE.is_file(), reason="needs ../shared beside the repo")


@pytest.fixture(scope="module")
def cmu():
    return import_bvh(CMU_FILE)


def test_the_cmu_file_is_read_mapped_and_its_bones_followed(cmu):
    report = cmu.report
    assert report["skeleton"] == "cmu" and "chains" in report["why"]
    assert report["units_guess"] == "CMU's units (1/0.45 inch)" and report["up_axis"] == "+y"
    assert report["fps"] == 30.0 and report["frames"] == 249  # 8.27 s at 120 fps, resampled
    body, xpos, _ = kinematics(cmu.frames)
    source = pybvh.read_bvh_file(str(CMU_FILE)).resample(30.0)
    names = [n.name for n in source.nodes]
    positions = source.node_positions() @ Y_UP_TO_Z_UP.as_matrix().T
    for parent, child, a, b in BONES:
        mine = xpos[:, body.model.body(child).id] - xpos[:, body.model.body(parent).id]
        theirs = positions[:, names.index(b)] - positions[:, names.index(a)]
        cos = (mine * theirs).sum(-1) / np.linalg.norm(mine, axis=-1)
        cos /= np.linalg.norm(theirs, axis=-1)
        error = np.degrees(np.arccos(np.clip(cos, -1, 1)))
        if parent.endswith(("hip", "shoulder")):  # a ball joint: exact
            assert error.max() < 1e-3, (parent, child)
        else:  # a 1-DOF knee or elbow: its projection, as the report says
            mean, most = report["hinge_error_deg"][parent]
            assert error.mean() == pytest.approx(mean, abs=1e-3) and error.mean() < 1.0
            assert error.max() == pytest.approx(most, abs=1e-3) and error.max() < 10.0
    knees, elbows = cmu.frames[:, [20, 34]], cmu.frames[:, [29, 43]]
    assert (knees <= 1e-9).all() and (elbows >= -1e-9).all()  # 1-DOF joints bend their way


def test_the_feet_meet_the_floor(cmu):
    """No sinking, no floating: the lowest foot point is on the floor whenever the source
    stands, and not more than 3 cm below it in between."""
    body, _, sites = kinematics(cmu.frames)
    lowest = sites[:, body.contact_site_ids, 2].min(axis=1)
    assert lowest.min() > -0.03 and np.median(np.abs(lowest)) < 0.01
    assert cmu.report["lowest_foot_min_m"] == pytest.approx(lowest.min(), abs=1e-6)


@pytest.mark.parametrize(("naming", "prefix", "expected"), [("mixamo", "mixamorig:", "mixamo"),
                                                           ("lafan1", "", "lafan1")])  # fmt: skip
def test_other_namings_are_detected_by_names_and_chains(tmp_path, cmu, naming, prefix, expected):
    """The same motion named as Mixamo or LAFAN1 name bones (their LeftShoulder is the
    clavicle), in centimetres: the same clip, the units found."""
    toe = "ToeBase" if naming == "mixamo" else "Toe"
    limbs = LIMBS | {"Toe": toe}
    text = re.sub(
        r"\b(Left|Right)(Collar|Shoulder|Elbow|Wrist|Hip|Knee|Ankle|Toe)\b",
        lambda m: f"{prefix}{m[1]}{limbs[m[2]]}",
        CMU_FILE.read_text(),
    )
    trunk = {"Hips": "Hips", "Chest": "Spine", "Chest2": "Spine2", "Neck": "Neck", "Head": "Head"}
    text = re.sub(r"(ROOT|JOINT) (Hips|Chest2|Chest|Neck|Head)\b",
                  lambda m: f"{m[1]} {prefix}{trunk[m[2]]}", text)  # fmt: skip
    path = tmp_path / f"{naming}.bvh"
    path.write_text(text)
    pybvh.read_bvh_file(str(path)).scale(5.644).write(str(path))  # CMU units -> centimetres
    imported = import_bvh(path)
    assert imported.report["skeleton"] == expected
    assert imported.report["units_guess"] == "centimetres"
    np.testing.assert_allclose(imported.frames[:, 4:], cmu.frames[:, 4:], atol=1e-5)
    np.testing.assert_allclose(imported.frames[:, 1:4], cmu.frames[:, 1:4], atol=1e-4)


def test_trim_rate_mirror_and_bad_input(tmp_path, cmu):
    short = import_bvh(CMU_FILE, start=1.0, end=3.0, fps=60.0)
    assert short.report["frames"] == 121 and short.frames[0, 0] == pytest.approx(1 / 60)
    mirrored = import_bvh(CMU_FILE, mirror=True)
    np.testing.assert_allclose(mirrored.frames[:, 34], cmu.frames[:, 20], atol=1e-6)  # knees
    with pytest.raises(ValueError, match="not a readable BVH file"):
        (tmp_path / "bad.bvh").write_text("HIERARCHY\nROOT Hips\n{")
        import_bvh(tmp_path / "bad.bvh")
    (tmp_path / "map.yaml").write_text("hips: Hips\n")
    with pytest.raises(ValueError, match="roles .* missing"):
        import_bvh(CMU_FILE, skeleton=str(tmp_path / "map.yaml"))
    with pytest.raises(ValueError, match="keep no frames"):
        import_bvh(CMU_FILE, start=20.0)
    text = CMU_FILE.read_text()
    head, motion = text.split("MOTION")
    lines = motion.strip().splitlines()
    for name, body, words in (
        ("zero", f"{head}MOTION\nFrames: 0\nFrame Time: .0083333\n", "Frame count \\(0\\)"),
        ("slow", text.replace("Frame Time: .0083333", "Frame Time: 1e300"), "Frame Time"),
        ("nan", "\n".join([head + "MOTION", *lines[:3], lines[3].replace("0.0000", "nan", 1),
                           *lines[4:]]), "non-finite"),
    ):  # fmt: skip
        (tmp_path / f"{name}.bvh").write_text(body)
        with pytest.raises(ValueError, match=words):
            import_bvh(tmp_path / f"{name}.bvh")
    legs_only = re.sub(r"\bLeftElbow\b", "LeftForearm", text)  # no map covers it
    (tmp_path / "odd.bvh").write_text(legs_only)
    with pytest.raises(ValueError, match="no skeleton map fits .*no joint LeftElbow"):
        import_bvh(tmp_path / "odd.bvh")


def test_paramimic_clip_import_writes_a_clip_that_trains(tmp_path):
    """The command as a user runs it; the clip reads back as `env.clip` reads it and a
    SkillEnv steps on it."""
    from paramimic.envs.skill_env import SkillEnv

    out = tmp_path / "my_walk.txt"
    res = subprocess.run(
        [sys.executable, "-m", "services.cli", "clip", "import", str(CMU_FILE), "--out", str(out),
         "--start", "1", "--end", "4"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    assert "skeleton map 'cmu'" in res.stdout and out.is_file()
    said = " ".join(res.stdout.split())  # rich wraps long lines
    assert "12 joints of the file not used" in said and "LFingers" in said  # what it dropped
    assert "left_knee 0.0 deg" in said  # the fit errors of the 1-DOF joints
    clip = registration("humanoid").load_clip(str(out))
    assert clip.duration == pytest.approx(3.0, abs=0.04) and clip.loop == "none"
    env = SkillEnv("humanoid", {}, {"clip": str(out)})
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape))


def test_a_walk_becomes_a_gait_cycle_that_loops():
    """`--loop`: the gait cycle whose ends are most alike (0.6-2.5 s) within the walking part,
    its last pose made its first's, the root advancing: a [WL19] reference gait (`env.gait`)."""
    from paramimic.characters.bvh_import import _pose_features
    from paramimic.config import ExperimentConfig
    from paramimic.envs import env_for

    walk = import_bvh(CMU_FILE, start=1.5, end=6.5, loop=True)
    cycle = walk.report["cycle"]
    assert 0.6 <= cycle["end_s"] - cycle["start_s"] <= 2.5
    features = _pose_features(walk.frames)
    np.testing.assert_allclose(features[-1], features[0], atol=1e-9)
    assert np.linalg.norm(walk.frames[-1, [1, 3]] - walk.frames[0, [1, 3]]) > 0.5  # it travels
    clip = walk.clip("cmu_cycle", loop="wrap")
    assert clip.loop == "wrap"
    text = {"/tmp/cmu_cycle.txt": walk.text("wrap")}
    cfg = ExperimentConfig.model_validate(
        {"character": "humanoid", "env": {"gait": "/tmp/cmu_cycle.txt", "clip_texts": text}}
    )
    env = env_for(cfg)
    assert 0.5 < env.clip_speed < 2.0  # m/s: a walk
    env.reset(seed=0)


def test_the_shipped_cmu_walk_is_what_the_importer_writes():
    """paramimic/data/cmu's clip is the shared file's gait cycle as `clip import --loop` writes
    it (its README's command), and it is the built-in clip humanoid_cmu_walk."""
    from paramimic.characters.humanoid import CLIPS, humanoid_clip

    walk = import_bvh(CMU_FILE, start=1.5, end=6.5, loop=True)
    shipped = json.loads(CLIPS["cmu_walk"].read_text())
    assert shipped["Loop"] == "wrap"
    np.testing.assert_allclose(np.asarray(shipped["Frames"]), walk.frames, atol=1e-7)
    clip = humanoid_clip("cmu_walk")
    assert clip.name == "humanoid_cmu_walk" and clip.loop == "wrap"


@pytest.mark.parametrize("clip", ["walk", "run", "jump", "backflip", "cartwheel"])
def test_a_shipped_clip_round_trips_through_bvh(tmp_path, clip):
    """`paramimic clip export --bvh` then import at the same frame rate, before any foot
    correction: every joint within 0.02 rad RMS of the original (the geodesic angle of the
    ball joints' rotations, the hinges' angles)."""
    from scipy.spatial.transform import Rotation

    from paramimic.characters.bvh_import import _columns, clip_frames, export_bvh

    original = clip_frames(f"humanoid_{clip}")
    path = export_bvh(original, tmp_path / f"{clip}.bvh")
    back = import_bvh(path, fps=1.0 / original[0, 0], ground=False)
    assert back.report["skeleton"] == "deepmimic" and back.report["metres_per_unit"] == 1.0
    n = min(len(back.frames), len(original))
    errors = []
    for c, width in _columns().values():
        if width == 1:
            errors.append(np.abs(back.frames[:n, c] - original[:n, c]))
        else:
            a = Rotation.from_quat(original[:n, c : c + 4], scalar_first=True)
            b = Rotation.from_quat(back.frames[:n, c : c + 4], scalar_first=True)
            errors.append((a.inv() * b).magnitude())
    rms = float(np.sqrt(np.mean(np.concatenate(errors) ** 2)))
    assert rms < 0.02, rms
    np.testing.assert_allclose(back.frames[:n, 1:4], original[:n, 1:4], atol=1e-3)


def test_a_clip_renders_beside_its_source_skeleton(tmp_path):
    """`paramimic clip render FILE.bvh`, as a user runs it (MUJOCO_GL unset): the humanoid
    playing the import, the source's bones drawn beside it in red; a clip alone has none."""
    import os

    import imageio.v3 as iio

    def render(clip: str, out: Path) -> np.ndarray:
        env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
        res = subprocess.run(
            [sys.executable, "-m", "services.cli", "clip", "render", clip, "--out", str(out),
             "--width", "320", "--height", "240", "--start", "3.0", "--end", "3.2"],
            capture_output=True, text=True, timeout=300, env=env,
        )  # fmt: skip
        assert res.returncode == 0, res.stdout + res.stderr
        return iio.imread(out, index=None)

    def red(image: np.ndarray) -> int:
        r, g, b = (image[..., i].astype(int) for i in range(3))
        return int(((r > 120) & (r > 2 * g) & (r > 2 * b)).sum())

    with_source = render(str(CMU_FILE), tmp_path / "bvh.gif")
    alone = render("humanoid_walk", tmp_path / "walk.gif")
    assert len(with_source) == 7 and with_source[0].shape[:2] == (240, 320)
    assert red(with_source[3]) > 20 and red(alone[3]) == 0


def test_the_rest_forward_is_detected_and_can_be_given(cmu):
    detected = cmu.report["forward_axis"]
    assert detected[0] in "+-" and detected[-1] in "xz"  # horizontal in the Y-up CMU file
    np.testing.assert_array_equal(import_bvh(CMU_FILE, forward=detected).frames, cmu.frames)
    # said to face another way: the joints whose twist no bone shows (neck, ankles) turn with it,
    # the hips and knees the bones carry do not
    turned = import_bvh(CMU_FILE, forward="+x" if detected[-1] == "z" else "+z")
    leaves = np.r_[12:16, 21:25, 35:39]
    assert np.abs(turned.frames[:, leaves] - cmu.frames[:, leaves]).max() > 0.1
    np.testing.assert_allclose(turned.frames[:, 16:21], cmu.frames[:, 16:21], atol=1e-9)
    with pytest.raises(ValueError, match="along the up axis"):
        import_bvh(CMU_FILE, forward="-y")
    with pytest.raises(ValueError, match="--forward 'north'"):
        import_bvh(CMU_FILE, forward="north")
