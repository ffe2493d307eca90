"""`paramimic export` gives the policy the actors run, as ONNX (run by
onnxruntime) and TorchScript, with a sidecar whose observation layout adds up."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from paramimic.characters import REGISTRY
from paramimic.config import ExperimentConfig
from paramimic.envs import env_for, make_env
from paramimic.training.trainer import SerialBackend, Trainer

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A real (short) training run, so that the normalizer is not the identity."""
    run_dir = tmp_path_factory.mktemp("run")
    cfg = ExperimentConfig.model_validate({
        "character": "walker", "task": {"left_leg_length": [0.8, 1.2]},
        "env": {"max_episode_seconds": 2.0},
        "ppo": {"num_steps": 512, "minibatch_size": 256, "num_epochs": 1},
        "actors": {"num_envs": 4}, "train": {"run_dir": str(run_dir)},
    })  # fmt: skip
    trainer = Trainer(cfg, run_dir)
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    trainer.train(backend, 2 * 512)
    backend.close()
    env = env_for(cfg)
    rng = np.random.default_rng(0)
    obs = np.stack([env.reset(seed=i)[0] for i in range(50)])  # real observations, and noise
    obs = np.concatenate(
        [obs, obs[rng.integers(0, 50, 950)] + rng.normal(0, 0.5, (950, obs.shape[1]))]
    )
    expected = trainer.learner.policy.numpy_policy().act(obs.astype(np.float32), None)[0]
    return run_dir, obs.astype(np.float32), expected


def _export(run_dir: Path, fmt: str, out: Path) -> dict:
    env = os.environ | {"PYTHONPATH": str(ROOT)}
    cli = [sys.executable, "-m", "services.cli", "export", str(run_dir), "--format", fmt,
           "--out", str(out)]  # fmt: skip
    res = subprocess.run(cli, capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    return json.loads(out.with_name(out.name + ".json").read_text())


def test_onnx_gives_the_actors_actions(run, tmp_path):
    import onnxruntime

    run_dir, obs, expected = run
    meta = _export(run_dir, "onnx", tmp_path / "policy.onnx")
    session = onnxruntime.InferenceSession(str(tmp_path / "policy.onnx"))
    got = session.run(["action"], {"obs": obs})[0]
    np.testing.assert_allclose(got, expected, atol=1e-5)
    assert meta["input"]["shape"] == ["batch", obs.shape[1]]
    assert sum(s["size"] for s in meta["observation_layout"]) == obs.shape[1]
    assert meta["task_space"] == {"left_leg_length": [0.8, 1.2]}


def test_torchscript_gives_the_actors_actions(run, tmp_path):
    run_dir, obs, expected = run
    _export(run_dir, "torchscript", tmp_path / "policy.pt")
    module = torch.jit.load(str(tmp_path / "policy.pt"))
    got = module(torch.from_numpy(obs)).detach().numpy()
    np.testing.assert_allclose(got, expected, atol=1e-5)


# every [WL19] gait env of the registry (skill envs have no named layout: the sidecar says null)
GAIT_ENVS = {
    env_id: kwargs
    for reg in REGISTRY.values()
    for env_id, kwargs in reg.env_specs().items()
    if "clip" not in kwargs.get("config", {})
}


@pytest.mark.parametrize("env_id", sorted(GAIT_ENVS))
def test_observation_layout_adds_up_for_every_gait_env(env_id):
    env = make_env(**GAIT_ENVS[env_id])
    sizes = [size for _, size in env.observation_layout()]
    assert sum(sizes) == env.observation_space.shape[0] and min(sizes) > 0
