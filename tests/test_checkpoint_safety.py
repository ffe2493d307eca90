"""Checkpoints hold plain data, load without running code, and are only written from a
consistent, finite state; a damaged latest.pt falls back to the newest readable ckpt file."""

import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from paramimic.config import ExperimentConfig
from paramimic.training import checkpoint
from paramimic.training.trainer import SerialBackend, Trainer, TrainingDiverged

ROOT = Path(__file__).resolve().parent.parent


def _config(run_dir: Path, **train) -> ExperimentConfig:
    return ExperimentConfig.model_validate(
        {
            "name": "safety",
            "character": "walker",
            "task": {"left_leg_length": [0.8, 1.2], "target_velocity": [1.0, 1.0]},
            "env": {"max_episode_seconds": 2.0},
            "ppo": {"num_steps": 512, "minibatch_size": 256, "num_epochs": 2},
            "actors": {"num_envs": 4},
            "train": {"seed": 0, "run_dir": str(run_dir), "checkpoint_every": 1, **train},
        }
    )


class _Planted:
    """Unpickling this runs os.system: what a planted checkpoint would do."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _train(tmp_path: Path, iterations: int, **train) -> Trainer:
    cfg = _config(tmp_path, **train)
    trainer = Trainer(cfg, tmp_path)
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    trainer.train(backend, iterations * cfg.ppo.num_steps)
    backend.close()
    return trainer


def test_a_planted_checkpoint_is_refused_and_runs_nothing(tmp_path):
    marker = tmp_path / "pwned"
    d = checkpoint.checkpoint_dir(tmp_path)
    d.mkdir(parents=True)
    torch.save({"config": {}, "payload": _Planted(marker)}, d / checkpoint.LATEST)
    with pytest.raises(checkpoint.CheckpointError, match="not a plain-data checkpoint"):
        checkpoint.load(tmp_path)
    assert not marker.exists()
    # the real CLI: a clear message, exit 2, and still nothing ran
    env = os.environ | {"PYTHONPATH": str(ROOT)}
    cli = [sys.executable, "-m", "services.cli", "eval", str(tmp_path), "--episodes", "1"]
    p = subprocess.run(cli, capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 2, p.stderr
    assert "not a plain-data checkpoint" in p.stdout + p.stderr
    assert not marker.exists()
    # and the converter the message names runs nothing either
    with pytest.raises(checkpoint.CheckpointError, match="holds more than numpy arrays"):
        checkpoint.upgrade(d / checkpoint.LATEST)
    assert not marker.exists()


def test_trained_state_round_trips_as_plain_data(tmp_path):
    trainer = _train(tmp_path, 2)
    state = checkpoint.load(tmp_path)  # weights_only=True inside
    assert state["progress"]["iteration"] == 2
    assert isinstance(state["marginal"], dict)
    again = Trainer(trainer.cfg, tmp_path)
    again.load_state_dict(state)
    for a, b in zip(
        trainer.learner.policy.parameters(), again.learner.policy.parameters(), strict=True
    ):
        assert torch.equal(a, b)
    assert np.array_equal(trainer.learner.normalizer.mean, again.learner.normalizer.mean)


def test_old_pickled_checkpoints_say_how_to_convert_and_convert(tmp_path):
    _train(tmp_path, 1)
    latest = checkpoint.checkpoint_dir(tmp_path) / checkpoint.LATEST
    state = checkpoint.load(tmp_path)
    old = checkpoint.checkpoint_dir(tmp_path) / "ckpt_old.pt"
    torch.save(state, old)  # numpy arrays pickled: the older format
    with pytest.raises(checkpoint.CheckpointError, match="upgrade-checkpoint"):
        checkpoint.load(old)
    env = os.environ | {"PYTHONPATH": str(ROOT)}
    cli = [sys.executable, "-m", "services.cli", "upgrade-checkpoint", str(old)]
    subprocess.run(cli, check=True, capture_output=True, env=env, timeout=120)
    upgraded = checkpoint.load(old)
    assert upgraded["progress"] == state["progress"]
    assert latest.exists()


def test_non_finite_weights_are_never_written(tmp_path):
    trainer = _train(tmp_path, 1)
    state = trainer.state_dict()
    state["learner"]["policy"]["log_std"] = torch.full_like(
        state["learner"]["policy"]["log_std"], float("nan")
    )
    with pytest.raises(checkpoint.NonFiniteState, match="log_std"):
        checkpoint.save(tmp_path, state, 99)
    assert not (checkpoint.checkpoint_dir(tmp_path) / "ckpt_000099.pt").exists()
    assert checkpoint.load(tmp_path)["progress"]["iteration"] == 1


class _PoisonedBackend(SerialBackend):
    """Rewards turn NaN (a diverging reward term): every update's loss is non-finite."""

    def collect(self, weights, version):
        fragments = super().collect(weights, version)
        for f in fragments:
            f.rewards[:] = np.nan
        return fragments


def test_non_finite_updates_are_skipped_then_the_run_stops(tmp_path):
    cfg = _config(tmp_path, max_bad_updates=2)
    trainer = Trainer(cfg, tmp_path)
    before = [p.detach().clone() for p in trainer.learner.policy.parameters()]
    backend = _PoisonedBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    with pytest.raises(TrainingDiverged, match="2 updates in a row"):
        trainer.train(backend, 10 * cfg.ppo.num_steps)
    backend.close()
    after = list(trainer.learner.policy.parameters())
    assert all(torch.equal(a, b) for a, b in zip(before, after, strict=True))
    state = checkpoint.load(tmp_path)  # written on the way out, finite
    assert state["progress"]["iteration"] == 2


def test_an_interrupt_inside_an_update_writes_no_checkpoint(tmp_path):
    trainer = _train(tmp_path, 1)
    backend = SerialBackend(trainer.cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    real_update = trainer.learner.update

    def interrupted(batch):
        real_update(batch)  # the weights moved, the counters not yet: half an iteration
        raise KeyboardInterrupt

    trainer.learner.update = interrupted
    with pytest.raises(KeyboardInterrupt):
        trainer.train(backend, 5 * trainer.cfg.ppo.num_steps)
    backend.close()
    d = checkpoint.checkpoint_dir(tmp_path)
    assert sorted(p.name for p in d.glob("ckpt_*.pt")) == ["ckpt_000001.pt"]
    assert checkpoint.load(tmp_path)["progress"]["iteration"] == 1


def test_damaged_latest_falls_back_and_old_files_are_pruned(tmp_path):
    _train(tmp_path, 4, keep_checkpoints=2)
    d = checkpoint.checkpoint_dir(tmp_path)
    assert sorted(p.name for p in d.glob("ckpt_*.pt")) == ["ckpt_000003.pt", "ckpt_000004.pt"]
    (d / ".tmp-stale.pt").write_bytes(b"half a file")  # a crashed writer's leftover
    latest = d / checkpoint.LATEST
    latest.unlink()  # a hard link to ckpt_4: replace it by a truncated copy
    latest.write_bytes((d / "ckpt_000004.pt").read_bytes()[:1000])
    (d / "ckpt_000004.pt").unlink()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        state = checkpoint.load(tmp_path)
    assert state["progress"]["iteration"] == 3
    assert any("damaged or truncated" in str(w.message) for w in caught)
    garbage = d / ".garbage"  # random bytes replacing latest.pt: damaged, not "unsafe"
    garbage.write_bytes(np.random.default_rng(0).bytes(4096))
    os.replace(garbage, latest)
    with pytest.warns(UserWarning, match="damaged or truncated"):
        assert checkpoint.load(tmp_path)["progress"]["iteration"] == 3
    checkpoint.save(tmp_path, state, 5, keep=2)
    assert not (d / ".tmp-stale.pt").exists()
    assert checkpoint.load(tmp_path)["progress"]["iteration"] == 3  # the state saved as ckpt 5


def _rewrite_member(path: Path, edit) -> None:
    """`path` rewritten as a valid zip archive whose tensor data member is `edit(bytes)`: the
    damage a bit flip or a bad write leaves inside an archive that still opens."""
    import zipfile

    with zipfile.ZipFile(path) as z:
        members = {i.filename: z.read(i.filename) for i in z.infolist()}
    data = max((n for n in members if "/data/" in n), key=lambda n: len(members[n]))
    members[data] = edit(members[data])
    path.unlink()
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
        for name, blob in members.items():
            z.writestr(name, blob)


def test_checkpoints_prove_themselves(tmp_path):
    """A NaN written into the tensor data of a valid latest.pt is caught by its manifest, and
    without the manifest by the finiteness check; either way the newest good file is used."""
    _train(tmp_path, 3)
    d = checkpoint.checkpoint_dir(tmp_path)
    assert (d / "ckpt_000003.pt.sha256").is_file() and (d / "latest.pt.sha256").is_file()
    latest = d / checkpoint.LATEST
    nan = np.full(4, np.nan, np.float32).tobytes()
    copy = latest.read_bytes()
    latest.unlink()  # a hard link to ckpt_3: damage a copy
    latest.write_bytes(copy)
    _rewrite_member(latest, lambda b: nan + b[len(nan) :])
    with pytest.warns(UserWarning, match="does not match its manifest"):
        assert checkpoint.load(tmp_path)["progress"]["iteration"] == 3  # ckpt_3 is intact
    (d / "latest.pt.sha256").unlink()  # no manifest: the NaN itself is found
    (d / "ckpt_000003.pt").unlink()
    with pytest.warns(UserWarning, match="non-finite value at /learner"):
        assert checkpoint.load(tmp_path)["progress"]["iteration"] == 2
    (d / "ckpt_000002.pt.sha256").unlink()  # a file of an older release: loads, with a warning
    with pytest.warns(UserWarning, match="no manifest"):
        assert checkpoint.read(d / "ckpt_000002.pt")["progress"]["iteration"] == 2


def test_plain_non_finite_numbers_are_refused_and_pruning_counts_iterations(tmp_path):
    trainer = _train(tmp_path, 1)
    state = trainer.state_dict()
    bad = state | {"marginal": state["marginal"] | {"mu": float("nan")}}
    with pytest.raises(checkpoint.NonFiniteState, match="/marginal/mu"):
        checkpoint.save(tmp_path, bad, 9)
    for it in (999_999, 1_000_000, 1_000_001):  # as strings, 1_000_000 < 999_999
        checkpoint.save(tmp_path, state, it, keep=2)
    d = checkpoint.checkpoint_dir(tmp_path)
    names = sorted(p.name for p in d.glob("ckpt_*.pt"))
    assert names == ["ckpt_1000000.pt", "ckpt_1000001.pt"]
    assert not (d / "ckpt_999999.pt.sha256").exists()
