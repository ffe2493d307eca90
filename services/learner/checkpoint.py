"""Checkpoints on disk, written atomically (temp file + rename)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import torch

LATEST = "latest.pt"


def checkpoint_dir(run_dir: Path) -> Path:
    return Path(run_dir) / "checkpoints"


def save(run_dir: Path, state: dict, iteration: int) -> Path:
    """Write ckpt_<iteration>.pt and point latest.pt at the same bytes; both atomically."""
    d = checkpoint_dir(run_dir)
    d.mkdir(parents=True, exist_ok=True)
    path = d / f"ckpt_{iteration:06d}.pt"
    fd, tmp = tempfile.mkstemp(dir=d, prefix=".tmp-", suffix=".pt")
    try:
        with os.fdopen(fd, "wb") as f:
            torch.save(state, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    latest_tmp = d / f".tmp-latest-{os.getpid()}"
    latest_tmp.unlink(missing_ok=True)
    os.link(path, latest_tmp)
    os.replace(latest_tmp, d / LATEST)
    return path


def resolve(path: Path) -> Path:
    """A checkpoint file, or a run directory / checkpoint directory holding latest.pt."""
    path = Path(path)
    if path.is_file():
        return path
    for candidate in (checkpoint_dir(path) / LATEST, path / LATEST):
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(f"no checkpoint at {path} (looked for {checkpoint_dir(path) / LATEST})")


def load(path: Path) -> dict:
    return torch.load(resolve(path), map_location="cpu", weights_only=False)
