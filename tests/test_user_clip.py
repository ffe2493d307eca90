"""A clip is a file or a name. A user's DeepMimic-format clip file that is not in the
repo, with two task parameters declared from the measure library, trains on a real local Ray
with the sampler in Redis and reports a' for both; bad files fail before anything starts,
naming the problem; `paramimic clip info` reads a file the same way and measures m0."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from paramimic.config import ConfigError, load_config
from paramimic.training.preflight import PreflightError, preflight

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "paramimic" / "data" / "deepmimic" / "humanoid3d_jump.txt"


def _user_clip(tmp_path: Path, edit=None, name: str = "my_jump.txt") -> Path:
    """The shipped jump with a transformed root path (shifted 2 m and travelling twice as
    far), written where only this test knows it; `edit(raw)` may break it."""
    raw = json.loads(SHIPPED.read_text())
    frames = np.array(raw["Frames"])
    frames[:, 1] = 2.0 + 2.0 * (frames[:, 1] - frames[0, 1])  # root x (DeepMimic's y-up frame)
    raw["Frames"] = frames.tolist()
    if edit is not None:
        edit(raw)
    path = tmp_path / name
    path.write_text(json.dumps(raw))
    return path


def _config(tmp_path: Path, clip: Path, task: dict | None = None) -> Path:
    cfg = {
        "character": "humanoid",
        "env": {"clip": str(clip), "max_episode_seconds": 1.0},
        "task": task or {"gravity": [0.8, 1.2]},
        "ppo": {"num_steps": 256, "minibatch_size": 128, "num_epochs": 1},
        "actors": {"num_actors": 2, "num_envs": 2},
        "train": {"checkpoint_every": 100},
    }
    path = tmp_path / "user.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def test_clip_info_reads_a_user_file(tmp_path):
    clip = _user_clip(tmp_path)
    res = subprocess.run([sys.executable, "-m", "services.cli", "clip", "info", str(clip),
                          "--json"], capture_output=True, text=True, timeout=120)  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    info = json.loads(res.stdout)
    frames = np.array(json.loads(clip.read_text())["Frames"])
    assert info["frames"] == len(frames)
    assert info["duration_s"] == pytest.approx(frames[:-1, 0].sum(), abs=1e-4)
    # DeepMimic's x stays x in our Z-up world: the doubled root path
    assert info["root_travel_m"][0] == pytest.approx(frames[-1, 1] - frames[0, 1], abs=1e-3)
    assert len(info["spherical_joints"]) == 8 and len(info["revolute_joints"]) == 4


def _clip_info(clip: str | Path) -> dict:
    res = subprocess.run([sys.executable, "-m", "services.cli", "clip", "info", str(clip),
                          "--json"], capture_output=True, text=True, timeout=120)  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    return json.loads(res.stdout)


@pytest.mark.parametrize("name", ["backflip", "cartwheel", "jump", "run", "walk"])
def test_clip_info_measures_each_shipped_clip(name):
    """Every measure on m0, checked against what the file itself says: frames and duration;
    the root's total rotation (the norm of the summed keyframe-to-keyframe rotation vectors of
    the file's root quaternions, which no change of world frame alters); for cyclic clips, the
    COM travels as far as the root over one cycle."""
    path = SHIPPED.parent / f"humanoid3d_{name}.txt"
    info = _clip_info(path)
    frames = np.array(json.loads(path.read_text())["Frames"])
    assert info["frames"] == len(frames)
    assert info["duration_s"] == pytest.approx(frames[:-1, 0].sum(), abs=1e-4)
    root = Rotation.from_quat(frames[:, [5, 6, 7, 4]])  # DeepMimic stores w, x, y, z
    turned = np.linalg.norm((root[1:] * root[:-1].inv()).as_rotvec().sum(axis=0))
    m = info["measures"]
    assert m["root_rotation"] == pytest.approx(turned, rel=0.03, abs=0.03)
    assert m["contact_match"] == 1.0 and m["com_rise"] >= 0.0
    if name == "backflip":  # one turn about the lateral axis, fast in the air
        assert m["root_rotation axis=pitch"] == pytest.approx(2 * np.pi, rel=0.03)
        assert m["airborne_angular_velocity axis=pitch"] > 5.0
    if name in ("run", "walk"):  # cyclic: over a cycle the COM travels as far as the root
        travel = np.linalg.norm(frames[-1, [1, 3]] - frames[0, [1, 3]])
        assert m["com_distance"] == pytest.approx(travel, rel=0.03)
        assert m["average_com_speed"] == pytest.approx(travel / info["duration_s"], rel=0.03)


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda raw: raw.update(Frames=[f[:40] for f in raw["Frames"]]), "44 numbers each"),
        (lambda raw: raw["Frames"][3].__setitem__(5, float("nan")), "non-finite"),
        (lambda raw: raw["Frames"][2].__setitem__(0, 0.0), "non-positive duration"),
        (lambda raw: raw.update(Loop="bounce"), "Loop must be"),
        (lambda raw: raw.pop("Frames"), "not a DeepMimic clip"),
        (lambda raw: raw["Frames"][0].__setitem__(0, 1e308), "frames last at most 10 s"),
    ],
    ids=["joint-count", "nan", "duration", "loop", "no-frames", "forever"],
)
def test_bad_clip_files_fail_before_anything_starts(tmp_path, edit, words):
    """The train preflight parses the file (validating the config reads none)."""
    clip = _user_clip(tmp_path, edit)
    cfg = load_config(_config(tmp_path, clip))
    with pytest.raises(PreflightError) as err:
        preflight(cfg)
    assert "env.clip" in str(err.value) and words in str(err.value)


def test_truncated_deep_and_missing_files_are_named(tmp_path):
    clip = _user_clip(tmp_path)
    deep = tmp_path / "deep.txt"
    deep.write_text("[" * 100_000 + "]" * 100_000)  # deeper than Python's JSON parser goes
    with pytest.raises(PreflightError, match="nested too deep"):
        preflight(load_config(_config(tmp_path, deep)))
    clip.write_text(clip.read_text()[:500])  # truncated JSON
    with pytest.raises(PreflightError, match="env.clip: .*not a DeepMimic clip"):
        preflight(load_config(_config(tmp_path, clip)))
    with pytest.raises(PreflightError, match="env.clip: cannot read .*nowhere.txt"):
        preflight(load_config(_config(tmp_path, tmp_path / "nowhere.txt")))
    with pytest.raises(ConfigError, match="env.clip 'nowhere' does not fit"):  # a name, no file
        load_config(_config(tmp_path, "nowhere"))


# two parameters declared from the measure library, as a user would write them in YAML
DECLARED = {
    "gravity": [0.8, 1.2],
    "rise": {"measure": "com_rise", "range": [0.0, 0.5]},
    "kick": {"measure": "peak_end_effector_height", "body": "right_ankle", "range": [0.1, 1.0],
             "reward": "continuous"},
}  # fmt: skip


def test_a_user_clip_trains_on_ray_with_the_sampler_in_redis(distributed, tmp_path):
    cfg = load_config(_config(tmp_path, _user_clip(tmp_path), DECLARED))
    assert set(cfg.env.skill.measures) == {"rise", "kick"}
    assert cfg.task["kick"] == (0.1, 1.0)
    trainer, backend = distributed(cfg, tmp_path)
    trainer.train(backend, total_steps=2 * 256)
    assert trainer.progress.iteration >= 2
    summary = trainer.curriculum.summary()  # the sampler actor's, its state in Redis
    assert summary.episodes > 0
    # a' for both declared parameters, measured on the episodes (the untrained humanoid's
    # ankles and COM move: not the commanded values, and inside the box)
    achieved = summary.achieved
    for name in ("rise", "kick"):
        lo, hi = cfg.task[name]
        a = achieved[name]
        assert lo <= a["min"] <= a["mean"] <= a["max"] <= hi, (name, a)
    assert achieved["kick"]["max"] > achieved["kick"]["min"]


def test_a_clip_path_is_stored_absolute_and_may_start_with_home(tmp_path, monkeypatch):
    """`env.clip: ~/my_jump.txt` reads the user's file; the run's saved config holds the absolute
    path, so a resume from another directory reads the same file."""
    monkeypatch.setenv("HOME", str(tmp_path))
    _user_clip(tmp_path)
    cfg = preflight(load_config(_config(tmp_path, Path("~/my_jump.txt"))))
    assert cfg.env.clip == str(tmp_path.resolve() / "my_jump.txt")
    monkeypatch.chdir(tmp_path)
    assert preflight(load_config(_config(tmp_path, Path("my_jump.txt")))).env.clip == cfg.env.clip


def test_the_clip_travels_with_the_run_not_its_path(tmp_path):
    """`paramimic train`'s preflight carries the clip file's text in the run's config: the saved
    config reads, builds its env and evaluates where the file is not (another machine, or the
    file moved), and resuming with the file in place is no config change."""
    from paramimic.config import ExperimentConfig, resume_conflicts
    from paramimic.envs import env_for

    clip = _user_clip(tmp_path)
    cfg = load_config(_config(tmp_path, clip))
    carried = preflight(cfg)
    assert carried.env.clip_texts == {str(clip.resolve()): clip.read_text()}
    saved = carried.model_dump(mode="json")
    clip.rename(tmp_path / "moved.txt")  # the file is gone from where the config names it
    again = ExperimentConfig.model_validate(saved)
    env = env_for(again)
    assert env.clip.duration == pytest.approx(env_for(carried).clip.duration)
    env.reset(seed=0)
    (tmp_path / "moved.txt").rename(clip)
    assert resume_conflicts(saved, load_config(_config(tmp_path, clip))) == []
