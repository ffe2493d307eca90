"""Shipped controllers: a run cut down to a small weights-only file that `paramimic eval`
(and play, render, export) take by name, as a user runs them: a real subprocess, real files."""

import json
import os

import pytest
import torch
from test_cli import _cli, _train_serial

from paramimic.training import checkpoint
from services.learner import controllers

WALK = {
    "name": "tiny_walk",
    "character": "humanoid",
    "shape_space": "full",
    "shape_scale": 0.0,
    "env": {"gait": "humanoid_walk", "physics_hz": 300, "max_episode_seconds": 1.0},
    "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 1, "hidden_sizes": [32, 32]},
    "actors": {"num_envs": 4},
    "train": {"total_steps": 256, "checkpoint_every": 1},
}

# One test writes a controller into the installed package's folder, as `paramimic controllers
# add` does for a user, and another loads every file there: on two xdist workers the second
# would meet the first's file half-way (added, or removed between the listing and the load).
# The module's tests run on one worker, in turn.
pytestmark = pytest.mark.xdist_group("shipped_controllers")


def test_a_run_ships_as_a_controller_that_eval_takes_by_name(tmp_path):
    _, run = _train_serial(tmp_path, WALK)
    name = f"test_tiny_walk_{os.getpid()}"
    try:
        res = _cli("controllers", "add", run, "--name", name)
        assert res.returncode == 0, res.stdout + res.stderr
        path = controllers.find(name)
        assert path is not None and path.parent == controllers.directory()
        assert path.stat().st_mode & 0o777 == 0o644  # an installed file every user can read
        full = checkpoint.resolve(run)
        assert path.stat().st_size < full.stat().st_size / 2  # no optimizer, no sampler state
        state = checkpoint.read(path)  # plain data: loads with weights_only
        assert set(state) == {"config", "obs_dim", "act_dim", "marginal", "progress", "learner"}
        assert set(state["learner"]) == {"policy", "normalizer"}  # no optimizers
        torch.load(path, weights_only=True)
        res = _cli("controllers", "list")
        assert name in res.stdout and "humanoid_walk" in res.stdout
        out = tmp_path / "eval.json"
        res = _cli("eval", name, "--episodes", 2, "--seconds", 0.5, "--out", out)
        assert res.returncode == 0, res.stdout + res.stderr
        report = json.loads(out.read_text())
        assert report["episodes"] == 2 and report["config"] == "tiny_walk"
        assert {"mean_body_error", "mean_root_drift", "speed_ratio"} <= set(report)
    finally:
        path = controllers.directory() / f"{name}.pt"
        path.unlink(missing_ok=True)
    res = _cli("eval", name, "--episodes", 2)  # gone: a clear error, not a traceback
    assert res.returncode != 0 and "no checkpoint" in res.stdout + res.stderr


def test_a_controller_name_must_be_plain():
    with pytest.raises(ValueError, match="letters, digits"):
        controllers.add(controllers.directory(), "../escape")
    assert controllers.find("../escape") is None


def test_every_shipped_controller_loads_by_name_and_acts_in_its_own_env():
    """Each file in the package's controllers folder (the walk, the run, the cartwheel, the CMU
    walk, the Fig. 2b family...) loads with today's config schema and acts in the env its config
    builds: a config change that would break `paramimic play NAME` after install fails here."""
    import numpy as np

    from paramimic.envs import env_for

    names = sorted(p.stem for p in controllers.directory().glob("*.pt"))
    assert "humanoid_walk" in names and "humanoid_fig2b" in names
    for name in names:
        state, cfg, policy = checkpoint.load_policy(name)
        env = env_for(cfg)
        obs, _ = env.reset(seed=0)
        assert obs.shape == (state["obs_dim"],), name
        actions, _, _ = policy.act(obs[None], None)
        assert actions.shape == (1, state["act_dim"]), name
        _, _, terminated, _, _ = env.step(actions[0])
        assert np.all(np.isfinite(actions)) and not terminated, name
