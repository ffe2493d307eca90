"""What must fail before a run starts anything, checked once by `paramimic train` before Redis
and Ray. Validating a config reads no files and checks no paths, so a run's saved config can be
re-read anywhere (eval, render, export, play; actors on other machines) after what it once
pointed to has moved."""

from __future__ import annotations

from pathlib import Path

from paramimic.config import ExperimentConfig
from paramimic.training import checkpoint
from paramimic.training.method import method_for


class PreflightError(ValueError):
    """A run that cannot start; the message names the config field."""


def preflight(cfg: ExperimentConfig) -> ExperimentConfig:
    """The run's config as it will run: its method's rules met (`method_for`), its clip files
    named by absolute path with their text carried in it (`env.clip_texts`), parsed, a gait
    that loops; and the warm start's source (`train.init_from`) a checkpoint or a run
    directory with one."""
    _check_source(cfg.train.init_from)
    cfg = carry_clips(cfg)
    _check_clips(cfg)
    method_for(cfg)
    return cfg


def carry_clips(cfg: ExperimentConfig) -> ExperimentConfig:
    """`cfg` with the clip files its `env.clip` / `env.gait` name stored absolute (`~` expanded,
    from the working directory: a resume from elsewhere names the same file) and their content
    in `env.clip_texts` (built-in clips need none)."""
    from paramimic.characters import registration

    builtin = registration(cfg.character).clips
    texts, update = dict(cfg.env.clip_texts), {}
    for field in ("clip", "gait"):
        name = getattr(cfg.env, field)
        if name is None or name in builtin:
            continue
        if name not in texts:
            name = str(Path(name).expanduser().resolve())
            update[field] = name
        if name in texts:
            continue
        try:
            texts[name] = Path(name).read_text()
        except OSError as e:
            raise PreflightError(f"env.{field}: cannot read {name}: {e}") from None
    if texts != cfg.env.clip_texts:
        update["clip_texts"] = texts
    if not update:
        return cfg
    return cfg.model_copy(update={"env": cfg.env.model_copy(update=update)})


def _check_clips(cfg: ExperimentConfig) -> None:
    """Each clip parses in the character's format; a reference gait loops."""
    from paramimic.characters import registration

    for field in ("clip", "gait"):
        name = getattr(cfg.env, field)
        if name is None:
            continue
        try:
            clip = registration(cfg.character).load_clip(name, cfg.env.clip_texts)
        except (ValueError, KeyError) as e:
            raise PreflightError(f"env.{field}: {e}") from None
        if field == "gait" and clip.loop != "wrap":
            raise PreflightError(
                f"env.gait: clip {name!r} does not loop (Loop {clip.loop!r}); a [WL19] "
                "reference gait must be cyclic; imitate it as a skill with env.clip"
            )


def _check_source(source: Path | None) -> None:
    if source is None:
        return
    if not Path(source).exists() and checkpoint.shipped(str(source)) is None:
        raise PreflightError(
            f"train.init_from: no checkpoint, run directory or shipped controller at {source}"
        )
    try:
        checkpoint.resolve(Path(source))
    except (FileNotFoundError, checkpoint.CheckpointError) as e:
        raise PreflightError(f"train.init_from: {e}") from None
