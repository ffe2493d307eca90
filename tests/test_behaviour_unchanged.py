"""The library's training loop gives the metrics it gave before the loop moved into
`paramimic/training/` and the messages were typed: fixed-seed serial runs of both methods,
iteration by iteration. `tests/data/serial_metrics.json` was written by this same run on the
code before that change (commit 171d3ab); regenerate it only for a change meant to alter
training (`python tests/test_behaviour_unchanged.py`)."""

import json
import shutil
import sys
import tempfile
from pathlib import Path

import pytest
import torch

from paramimic.config import ExperimentConfig
from paramimic.training.trainer import SerialBackend, Trainer

GOLDEN = Path(__file__).parent / "data" / "serial_metrics.json"
TINY = {
    "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 2, "hidden_sizes": [32, 32]},
    "actors": {"num_envs": 2},
    "train": {"seed": 3},
}
CONFIGS = {
    "wl19_walker": TINY | {
        "task": {"left_leg_length": [0.8, 1.2]},
        "env": {"max_episode_seconds": 1.0},
        "curriculum": {"k": 5.0, "p_mcmc": 1},
    },
    "l21_jump": TINY | {
        "task": {"gravity": [0.5, 1.5]},
        "env": {"clip": "planar_jump"},
        "curriculum": {"skill": {"base_min_iterations": 1, "base_max_iterations": 2,
                                 "p_every": 1}},
    },
}  # fmt: skip
# float rounding differs between CPUs (the kernels torch picks for the machine): on a machine
# with AMX the recorded runs differ by up to 4e-5 relative; a change to training (another random
# draw, another step) moves them by far more
RTOL = 1e-3
WALL_CLOCK = {"time", "steps_per_second", "sample_steps_per_second"}


def serial_metrics(name: str) -> list[dict]:
    torch.manual_seed(0)
    cfg = ExperimentConfig.model_validate(CONFIGS[name])
    with tempfile.TemporaryDirectory() as tmp:
        trainer = Trainer(cfg, Path(tmp))
        backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
        rows: list[dict] = []
        trainer.train(backend, total_steps=4 * 256, on_metrics=rows.append)
    return [{k: v for k, v in r.items() if k not in WALL_CLOCK} for r in rows]


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_a_fixed_seed_serial_run_gives_the_recorded_metrics(name):
    golden = json.loads(GOLDEN.read_text())[name]
    rows = serial_metrics(name)
    assert len(rows) == len(golden)
    for it, (row, want) in enumerate(zip(rows, golden, strict=True)):
        assert row.keys() == want.keys(), it
        for key, value in want.items():
            if isinstance(value, float):
                assert row[key] == pytest.approx(value, rel=RTOL, abs=1e-9), (it, key)
            else:
                assert row[key] == value, (it, key)


if __name__ == "__main__":
    out = {name: serial_metrics(name) for name in CONFIGS}
    GOLDEN.write_text(json.dumps(out, indent=1, sort_keys=True))
    print(f"wrote {GOLDEN}", file=sys.stderr)


BEFORE = Path(__file__).parent / "data" / "runs_before_training_moved"


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_a_run_written_before_the_move_resumes_and_evaluates(name, tmp_path):
    """A run directory and Redis state written by the code before the move (commit 171d3ab,
    `tests/data/runs_before_training_moved/make.py`): the sampler reloads the curriculum as the
    old one stored it, the trainer resumes the checkpoint and trains on, and the controller
    evaluates."""
    import redis
    import yaml

    from paramimic.evaluation import evaluate_config
    from paramimic.training import checkpoint
    from paramimic.training.method import method_for
    from services.keys import RunKeys
    from services.launch.redis_server import EmbeddedRedis
    from services.sampler.service import SamplerService

    run = tmp_path / name
    shutil.copytree(BEFORE / name, run, ignore=shutil.ignore_patterns("make.py"))
    cfg = ExperimentConfig.model_validate(yaml.safe_load((run / "config.yaml").read_text()))
    run_id = f"compat-{name}"
    with EmbeddedRedis(run / "redis", password="compat") as server:
        stored = redis.Redis.from_url(server.url).hget(RunKeys(run_id).curriculum, "summary")
        clip = method_for(cfg).spaces.clip_setup()
        sampler = SamplerService(cfg.model_dump(mode="json"), server.url, run_id, clip=clip)
        summary = json.loads(json.dumps(sampler.curriculum.summary().to_dict()))
        old = json.loads(stored)
        assert summary["episodes"] == old["episodes"] > 0
        shared = old.keys() & summary.keys()
        assert {k: summary[k] for k in shared} == {k: old[k] for k in shared}
        trainer = Trainer(cfg, run, sampler)
        trainer.load_state_dict(checkpoint.load(run))
        assert trainer.progress.iteration == 2
        backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
        trainer.train(backend, total_steps=3 * 256)
        assert trainer.progress.iteration == 3
    report = evaluate_config(trainer.learner.policy, cfg, 2, 7, 1, seconds=1.0)
    assert report["episodes"] == 2
