"""Pictures with the real renderer (MuJoCo offscreen through EGL on Mesa's software renderer):
`paramimic render` GIF/MP4 of a family and a morph, `paramimic eval --heatmap` PNG."""

import os
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest
import yaml

from paramimic.evaluation import morph_path

TINY_BIPED = {
    "character": "biped_lower",
    "task": {"global_z": [0.6, 1.4], "thigh_l_z": [0.8, 1.2], "target_velocity": [1, 1]},
    "env": {"max_episode_seconds": 1.0},
    "ppo": {"num_steps": 128, "minibatch_size": 64, "num_epochs": 1},
    "actors": {"num_envs": 2},
    "train": {"total_steps": 128, "checkpoint_every": 1},
}


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "services.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        # MUJOCO_GL unset, as a new user has it: the CLI must choose a headless backend itself
        env={k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")},
    )


@pytest.fixture(scope="module")
def biped_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("render")
    cfg = tmp / "biped.yaml"
    cfg.write_text(yaml.safe_dump(TINY_BIPED))
    run = tmp / "run"
    res = _cli("train", cfg, "--serial", "--run-dir", run)
    assert res.returncode == 0, res.stdout + res.stderr
    return run


def _background_share(frame: np.ndarray) -> float:
    """Share of pixels equal to the most common color (the empty background)."""
    flat = frame.reshape(-1, frame.shape[-1])
    _, counts = np.unique(flat, axis=0, return_counts=True)
    return counts.max() / len(flat)


def test_render_family_gif_side_by_side(biped_run, tmp_path):
    out = tmp_path / "family.gif"
    res = _cli(
        "render", biped_run, "--shapes", "global_z=0.6;global_z=1.4,thigh_l_z=1.2",
        "--out", out, "--seconds", 0.5, "--width", 96, "--height", 64,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    frames = iio.imread(out)
    # 0.5 s at the 30 Hz control rate + the first frame, two bodies of 96 x 64 side by side
    assert frames.shape[0] == 16 and frames.shape[1:3] == (64, 192)
    first = frames[0][..., :3]
    assert _background_share(first) < 0.9  # floor, light and bodies, not an empty image
    # the two panels differ: a 0.6x and a 1.4x tall body
    assert np.abs(first[:, :96].astype(int) - first[:, 96:].astype(int)).mean() > 1.0
    # and the picture moves
    assert np.abs(frames[-1].astype(int) - frames[0].astype(int)).mean() > 0.1


def test_render_morph_mp4_seen_from_the_tallest_bodys_distance(biped_run, tmp_path):
    """A morphing body shrinks on screen: the camera keeps the tallest body's distance, where a
    family's panels each follow their own body's size; --fps keeps every n-th frame."""
    from paramimic.envs import ParamEnv
    from paramimic.render import camera_distance

    env = ParamEnv("biped_lower", {"global_z": (0.6, 1.4)})
    env.reset(seed=0, options={"task": [0.6]})
    tall = env.body_for(np.array([1.4]))
    assert camera_distance(env, tall) > camera_distance(env) + 0.1  # the sizes differ
    out = tmp_path / "morph.mp4"
    res = _cli(
        "render", biped_run, "--shapes", "global_z=1.4;global_z=0.6", "--morph",
        "--out", out, "--seconds", 0.6, "--width", 96, "--height", 64, "--fps", 15,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    frames = np.stack(list(iio.imiter(out)))
    # 0.6 s at the 30 Hz control rate is 19 frames with the first; every second one at 15 fps
    assert frames.shape[1:3] == (64, 96) and frames.shape[0] == 10
    # the small body at the end, seen from the tall body's distance: fewer body pixels
    first, last = _body_pixels(frames[0]), _body_pixels(frames[-1])
    assert 0 < last < 0.8 * first, (first, last)


def _body_pixels(frame: np.ndarray) -> int:
    """Pixels of the body: bluish grey, where the floor is neutral grey."""
    f = frame.astype(int)
    return int(((f[..., 2] - f[..., 0]) > 12).sum())


def test_render_rejects_bad_input(biped_run, tmp_path):
    res = _cli("render", biped_run, "--shapes", "height=2", "--out", tmp_path / "x.gif")
    assert res.returncode == 2 and "NAME=VALUE" in res.stdout
    res = _cli("render", biped_run, "--shapes", "global_z=3", "--out", tmp_path / "x.gif")
    assert res.returncode == 2 and "outside the task space" in res.stdout
    res = _cli("render", biped_run, "--shapes", "global_z=1", "--out", tmp_path / "x.avi")
    assert res.returncode == 2 and ".gif" in res.stdout
    res = _cli(
        "render", biped_run, "--shapes", "global_z=1", "--morph", "--out", tmp_path / "x.gif"
    )
    assert res.returncode == 2 and "at least two" in res.stdout
    res = _cli("render", biped_run, "--fps", 0, "--out", tmp_path / "x.gif")
    assert res.returncode == 2 and "--fps" in res.stdout


def test_eval_heatmap_png(biped_run, tmp_path):
    png = tmp_path / "heat.png"
    res = _cli("eval", biped_run, "--episodes", 2, "--grid", 3, "--heatmap", png)
    assert res.returncode == 0, res.stdout + res.stderr
    image = iio.imread(png)
    assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 200
    assert _background_share(image[..., :3]) < 0.95
    res = _cli("eval", biped_run, "--episodes", 2, "--heatmap", tmp_path / "heat.jpg")
    assert res.returncode == 2 and ".png" in res.stdout


def test_morph_path_interpolates_piecewise_linearly():
    path = [{"a": 1.0}, {"a": 2.0}, {"a": 0.0}]
    assert morph_path(path, 0.0) == {"a": 1.0}
    assert morph_path(path, 0.25) == {"a": 1.5}
    assert morph_path(path, 0.5) == {"a": 2.0}
    assert morph_path(path, 0.75) == {"a": 1.0}
    assert morph_path(path, 1.0) == {"a": 0.0}


def test_render_without_shapes_shows_the_base_body_and_the_four_corners(biped_run, tmp_path):
    out = tmp_path / "first_look.gif"
    res = _cli("render", biped_run, "--out", out, "--seconds", 0.2, "--width", 64,
               "--height", 48)  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    frames = iio.imread(out)
    assert frames.shape[1:3] == (48, 5 * 64)  # the base body and 4 corners of global_z x thigh_l_z
    first = frames[0][..., :3].astype(int)
    panels = [first[:, i * 64 : (i + 1) * 64] for i in range(5)]
    # the short corners (global_z 0.6) and the tall ones (1.4) are different pictures
    assert np.abs(panels[1] - panels[2]).mean() > 1.0
