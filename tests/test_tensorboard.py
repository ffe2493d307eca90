"""TensorBoard event files of real short runs, read back with TensorBoard's own reader."""

import json
from pathlib import Path

import numpy as np
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from paramimic.config import ExperimentConfig
from paramimic.training.tensorboard import TensorBoardLog
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
        first.metrics({"env_steps": step, "mean_return": float(step)})
    first.close()
    again = TensorBoardLog(tmp_path / "tb", 200)  # resumed from the checkpoint at 200
    again.metrics({"env_steps": 300, "mean_return": -1.0})
    again.close()
    acc = EventAccumulator(str(tmp_path / "tb"))
    acc.Reload()
    points = [(e.step, e.value) for e in acc.Scalars("episodes/mean_return")]
    assert points == [(100, 100.0), (300, -1.0)]
