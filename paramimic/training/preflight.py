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


def preflight(cfg: ExperimentConfig) -> ExperimentConfig:
    """The run's config with the text of its clip files carried in it (`env.clip_texts`), once
    the warm start's source (`train.init_from`) is found to be a checkpoint or a run directory
    with one."""
    _check_source(cfg.train.init_from)
    return carry_clips(cfg)


def carry_clips(cfg: ExperimentConfig) -> ExperimentConfig:
    """`cfg` with the content of the clip files its `env.clip` / `env.gait` name in
    `env.clip_texts` (built-in clips need none)."""
    from paramimic.characters import registration

    builtin = registration(cfg.character).clips
    texts = dict(cfg.env.clip_texts)
    for field in ("clip", "gait"):
        name = getattr(cfg.env, field)
        if name is None or name in builtin or name in texts:
            continue
        try:
            texts[name] = Path(name).read_text()
        except OSError as e:
            raise PreflightError(f"env.{field}: cannot read {name}: {e}") from None
    if texts == cfg.env.clip_texts:
        return cfg
    return cfg.model_copy(update={"env": cfg.env.model_copy(update={"clip_texts": texts})})


def _check_source(source: Path | None) -> None:
    if source is None:
        return
    if not Path(source).exists():
        raise PreflightError(f"train.init_from: no checkpoint or run directory at {source}")
    try:
        checkpoint.resolve(Path(source))
    except (FileNotFoundError, checkpoint.CheckpointError) as e:
        raise PreflightError(f"train.init_from: {e}") from None
