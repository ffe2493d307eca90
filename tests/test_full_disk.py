"""A run directory on a disk that fills up and is freed again (a real tmpfs: needs root, as
the tests and CI run here): training goes on, metrics.jsonl keeps every iteration's row once,
the liveness file stays fresh, and the checkpoints written are whole and verified."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import time

import pytest

from paramimic.config import ExperimentConfig
from paramimic.training import checkpoint
from paramimic.training.trainer import SerialBackend, Trainer
from services.launch import liveness

pytestmark = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("mount") is None,
    reason="mounting a tmpfs needs root and mount(8)",
)


@pytest.fixture
def small_disk(tmp_path):
    """A 24 MB tmpfs at tmp_path/run, unmounted after the test."""
    run = tmp_path / "run"
    run.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=24m", "tmpfs", str(run)], check=True)
    try:
        yield run
    finally:
        subprocess.run(["umount", "-l", str(run)], check=False)


def _fill(folder) -> None:
    with contextlib.suppress(OSError), (folder / "filler").open("wb") as f:
        while True:
            f.write(b"\0" * (1 << 16))
            f.flush()


def test_a_full_run_directory_costs_no_rows_and_ends_with_whole_checkpoints(small_disk):
    cfg = ExperimentConfig.model_validate(
        {
            "character": "hopper",
            "task": {"target_velocity": [1.0, 1.0]},
            "env": {"max_episode_seconds": 2.0},
            "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 1},
            "actors": {"num_envs": 4},
            "train": {"checkpoint_every": 1, "seed": 0},
        }
    )
    trainer = Trainer(cfg, small_disk)
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    filler = small_disk / "filler"
    seen: list[int] = []
    stale: list[float] = []

    def on_metrics(m: dict) -> None:
        seen.append(m["iteration"])
        if m["iteration"] == 2:
            _fill(small_disk)  # full: rows, checkpoints and the liveness file find no room
        if m["iteration"] == 6:
            filler.unlink()  # freed again
        liveness.beat(small_disk)  # raises nothing on a full disk
        age = time.time() - (small_disk / liveness.HEARTBEAT).stat().st_mtime
        stale.append(age)

    failed: list[str] = []
    try:
        trainer.train(
            backend,
            total_steps=9 * 256,
            on_metrics=on_metrics,
            on_checkpoint=lambda path, it, *why: failed.extend(why) if path is None else None,
        )
    finally:
        backend.close()
    assert seen == list(range(1, 10))
    assert len(failed) >= 3 and all("not written" in w for w in failed)  # iterations 3-5
    rows = [json.loads(r) for r in (small_disk / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == seen  # every row, once, in order
    assert max(stale) < liveness.EVERY + 5.0
    state = checkpoint.load(small_disk)
    assert state["progress"]["iteration"] == 9
    ckpts = sorted((small_disk / "checkpoints").glob("ckpt_*.pt"))
    assert ckpts, "no checkpoint after the disk was freed"
    for file in ckpts:  # every file left has its manifest and matches it
        assert checkpoint.verify(file), file
    assert not list((small_disk / "checkpoints").glob(f"{checkpoint.TMP_PREFIX}*"))
