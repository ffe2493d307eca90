"""What must fail before a run starts anything, checked once by `paramimic train` before Redis
and Ray. Validating a config reads no files and checks no paths, so a run's saved config can be
re-read anywhere (eval, render, export, play; actors on other machines) after what it once
pointed to has moved."""

from __future__ import annotations

from pathlib import Path

from paramimic.config import ExperimentConfig
from paramimic.training import checkpoint


class PreflightError(ValueError):
    """A run that cannot start; the message names the config field."""


def preflight(cfg: ExperimentConfig) -> None:
    """The warm start's source (`train.init_from`) is a checkpoint or a run directory with one."""
    source = cfg.train.init_from
    if source is None:
        return
    if not Path(source).exists():
        raise PreflightError(f"train.init_from: no checkpoint or run directory at {source}")
    try:
        checkpoint.resolve(Path(source))
    except (FileNotFoundError, checkpoint.CheckpointError) as e:
        raise PreflightError(f"train.init_from: {e}") from None
