"""Real training runs on real MuJoCo: learning, checkpoints and resume."""

import json

import numpy as np
import pytest
import torch

from paramimic.config import ExperimentConfig
from paramimic.envs import env_for
from paramimic.evaluation import deterministic, run_episodes
from paramimic.training import checkpoint
from paramimic.training.trainer import SerialBackend, Trainer


def _config(**train) -> ExperimentConfig:
    return ExperimentConfig.model_validate(
        {
            "name": "test",
            "character": "walker",
            "task": {"target_velocity": [1.0, 1.0]},
            "env": {"max_episode_seconds": 10.0},
            "ppo": {"num_steps": 4096, "minibatch_size": 512},
            "curriculum": {"k": 0.0},
            "actors": {"num_envs": 16},
            "train": {"seed": 0, **train},
        }
    )


def _eval_return(trainer: Trainer, cfg: ExperimentConfig) -> float:
    tasks = np.tile(trainer.space.center, (8, 1))
    res = run_episodes(
        deterministic(trainer.learner.policy),
        lambda: env_for(cfg),
        tasks,
        num_envs=8,
        seed=123,
    )
    return float(np.mean([r.ret for r in res]))


@pytest.mark.slow
def test_short_training_run_improves_the_return(tmp_path):
    cfg = _config()
    trainer = Trainer(cfg, tmp_path)
    before = _eval_return(trainer, cfg)
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    trainer.train(backend, total_steps=25 * 4096)
    after = _eval_return(trainer, cfg)
    # the initial policy falls within ~2 s; after 100k steps it must stay up markedly longer
    assert after > 1.5 * before, (before, after)


def _assert_same_state(a, b):
    if isinstance(a, torch.Tensor):
        assert torch.equal(a, b)
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b)
    elif isinstance(a, dict):
        assert a.keys() == b.keys()
        for k in a:
            _assert_same_state(a[k], b[k])
    elif isinstance(a, list | tuple):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _assert_same_state(x, y)
    else:
        assert a == b


def test_checkpoint_resume_restores_everything(tmp_path):
    cfg = ExperimentConfig.model_validate(
        {
            "character": "walker",
            "task": {"left_leg_length": [0.8, 1.2], "right_leg_length": [0.8, 1.2]},
            "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 2},
            "curriculum": {"k": 10.0, "p_mcmc": 1, "n_mcmc": 50},
            "actors": {"num_envs": 4},
            "train": {"checkpoint_every": 1},
        }
    )
    first = Trainer(cfg, tmp_path)
    backend = SerialBackend(cfg, first.obs_dim, first.act_dim, first.curriculum)
    first.train(backend, total_steps=3 * 256)
    assert first.progress.iteration == 3
    assert first.curriculum.sampler.adaptive  # V̄ was fitted and S refilled by MCMC
    saved = checkpoint.load(tmp_path)
    assert saved["progress"]["iteration"] == 3

    second = Trainer(cfg, tmp_path)
    second.load_state_dict(saved)
    _assert_same_state(first.state_dict()["learner"], second.state_dict()["learner"])
    _assert_same_state(first.marginal.to_state(), second.marginal.to_state())
    _assert_same_state(first.curriculum.to_state(), second.curriculum.to_state())
    np.testing.assert_array_equal(first.curriculum.next_tasks(5), second.curriculum.next_tasks(5))
    backend2 = SerialBackend(cfg, second.obs_dim, second.act_dim, second.curriculum)
    second.train(backend2, total_steps=4 * 256)
    assert second.progress.iteration == 4  # the counter continues
    assert (tmp_path / "checkpoints" / "ckpt_000004.pt").is_file()


def test_a_resumed_run_drops_the_logged_iterations_its_checkpoint_never_saw(tmp_path):
    # the base walker alone: a task space without dimensions trains too
    cfg = ExperimentConfig.model_validate(
        {
            "character": "walker",
            "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 1},
            "actors": {"num_envs": 4},
            "train": {"checkpoint_every": 2},
        }
    )
    first = Trainer(cfg, tmp_path)
    first.train(SerialBackend(cfg, first.obs_dim, first.act_dim, first.curriculum), 2 * 256)
    # the run went on for 2 iterations after its checkpoint at 512 steps and was killed in the
    # middle of writing a third row
    log = tmp_path / "metrics.jsonl"
    with log.open("a") as f:
        f.write(json.dumps({"env_steps": 768}) + "\n" + json.dumps({"env_steps": 1024}) + "\n")
        f.write('{"env_steps": 12')
    second = Trainer(cfg, tmp_path)
    second.load_state_dict(checkpoint.load(tmp_path))
    second.train(SerialBackend(cfg, second.obs_dim, second.act_dim, second.curriculum), 3 * 256)
    steps = [json.loads(r)["env_steps"] for r in log.read_text().splitlines()]
    assert steps == [256, 512, 768]  # the lost rows gone, the resumed iteration logged once
