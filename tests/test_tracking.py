"""A run's curves in TensorBoard and Weights & Biases, from real short runs, read back with
TensorBoard's own reader and W&B's own CLI."""

import json
from pathlib import Path

import numpy as np
import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from paramimic.config import ExperimentConfig
from paramimic.task_space import TaskSpace
from paramimic.training.tracking import TensorBoardLog, marginal_figure
from paramimic.training.trainer import train_serial

WL19 = {
    "character": "hopper",
    "task": {"leg_length": [0.8, 1.2], "torso_length": [0.9, 1.1], "target_velocity": [1, 1]},
    "env": {"max_episode_seconds": 2.0},
    "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 2},
    "curriculum": {"p_mcmc": 1, "n_mcmc": 50, "chains": 4, "burn_in": 2},
    "actors": {"num_envs": 4},
    "train": {"checkpoint_every": 2},
}
L21 = {
    "character": "walker",
    "task": {"gravity": [0.5, 1.5], "jump_height": [0.0, 0.3]},
    "env": {"clip": "planar_jump", "max_episode_seconds": 2.0},
    "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 2},
    "curriculum": {"skill": {"batch_size": 2, "episodes_per_param": 2,
                             "base_min_iterations": 1, "base_max_iterations": 2}},
    "actors": {"num_envs": 4},
    "train": {"checkpoint_every": 2},
}  # fmt: skip


def _events(run: Path) -> EventAccumulator:
    acc = EventAccumulator(str(run / "tensorboard"), size_guidance={"images": 0, "scalars": 0})
    acc.Reload()
    return acc


def test_a_wl19_run_writes_every_metric_per_env_step_and_the_marginal_value_map(tmp_path):
    cfg = ExperimentConfig.model_validate(WL19)
    trainer = train_serial(cfg, 4 * 256, tmp_path / "run")
    acc = _events(tmp_path / "run")
    tags = acc.Tags()
    for tag in ("episodes/mean_return", "episodes/fall_percent", "ppo/policy_loss", "ppo/std",
                "speed/steps_per_second", "curriculum/mu", "curriculum/k"):  # fmt: skip
        assert tag in tags["scalars"], tag
    steps = [e.step for e in acc.Scalars("ppo/policy_loss")]
    assert steps == [256, 512, 768, 1024]  # one point per iteration, at its env steps
    rows = (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()
    last = json.loads(rows[-1])
    assert acc.Scalars("episodes/mean_return")[-1].value == np.float32(last["mean_return"])
    assert acc.Scalars("curriculum/mu")[-1].value == np.float32(trainer.marginal.mu)
    assert "curriculum/marginal_value" in tags["images"]  # every checkpoint interval
    assert [e.step for e in acc.Images("curriculum/marginal_value")] == [512, 1024]


def test_no_value_map_over_display_dims_that_do_not_vary():
    """A base body's shape dims are points: no heatmap of V̄ over them (matplotlib would warn
    of a singular extent and draw one colour), but one over dims that vary."""
    ranges = {"leg_length": (1.0, 1.0), "torso_length": (1.0, 1.0),
              "target_velocity": (0.5, 1.5), "gravity": (0.5, 1.0)}  # fmt: skip
    space = TaskSpace.from_ranges(ranges)

    def predict(pts):
        return pts.sum(axis=1)

    assert marginal_figure(space, ("leg_length", "torso_length"), predict) is None
    assert marginal_figure(space, ("leg_length", "gravity"), predict) is None
    fig = marginal_figure(space, ("target_velocity", "gravity"), predict, n=5)
    assert fig is not None and fig.axes[0].get_xlabel() == "target_velocity"


def test_an_l21_run_has_its_stage_elites_and_explored_ratio(tmp_path):
    cfg = ExperimentConfig.model_validate(L21)
    train_serial(cfg, 4 * 256, tmp_path / "run")
    tags = _events(tmp_path / "run").Tags()["scalars"]
    for tag in ("curriculum/stage", "curriculum/elites", "curriculum/explored_ratio",
                "curriculum/motion_version", "ppo/policy_loss"):  # fmt: skip
        assert tag in tags, tag


def test_a_resumed_run_drops_the_events_past_its_checkpoint(tmp_path):
    first = TensorBoardLog(tmp_path / "tb", 0)
    for step in (100, 200, 300):
        first.log({"env_steps": step, "mean_return": float(step)})
    first.close()
    again = TensorBoardLog(tmp_path / "tb", 200)  # resumed from the checkpoint at 200
    again.log({"env_steps": 300, "mean_return": -1.0})
    again.close()
    acc = EventAccumulator(str(tmp_path / "tb"))
    acc.Reload()
    points = [(e.step, e.value) for e in acc.Scalars("episodes/mean_return")]
    assert points == [(100, 100.0), (300, -1.0)]


def test_weights_and_biases_offline_gets_the_same_curves_without_a_network(tmp_path):
    import os
    import subprocess
    import sys

    cfg = ExperimentConfig.model_validate(WL19 | {"train": {"checkpoint_every": 2,
                                                           "wandb": "offline"}})  # fmt: skip
    env = {k: v for k, v in os.environ.items() if not k.startswith("WANDB_")}
    os.environ.update({"WANDB_SILENT": "true"})
    try:
        train_serial(cfg, 2 * 256, tmp_path / "run")
    finally:
        os.environ.pop("WANDB_SILENT", None)
    logs = list((tmp_path / "run" / "wandb").glob("offline-run-*/run-*.wandb"))
    assert len(logs) == 1
    wandb = Path(sys.executable).with_name("wandb")
    out = subprocess.run([str(wandb), "leet", "inspect", str(logs[0]), "--json"], env=env,
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    assert out.returncode == 0, out.stderr
    history = [json.loads(line)["history"] for line in out.stdout.splitlines()
               if '"type":"history"' in line]  # fmt: skip
    steps = [h["step"]["num"] for h in history]
    assert steps == [256, 512]
    rows = [json.loads(r) for r in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert history[-1]["item"]["episodes/mean_return"] == pytest.approx(rows[-1]["mean_return"])
    # the V̄ map at the checkpoint, an image W&B keeps as a file of the run
    assert history[-1]["item"]["curriculum/marginal_value._type"] == "image-file"
    assert (
        logs[0].parent / "files" / history[-1]["item"]["curriculum/marginal_value.path"]
    ).exists()
