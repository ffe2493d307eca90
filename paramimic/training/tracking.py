"""A run's curves in the tools RL users watch: TensorBoard event files beside metrics.jsonl
(always, unless `train.tensorboard: false`) and Weights & Biases (opt-in, `train.wandb`).

Both get the same values per env step: every scalar of a metrics row, the curriculum's state
([L21]: stage, phase, ER, elites) and, every checkpoint interval, the [WL19] V̄ map as an
image. TensorBoard's files are written with torch's `SummaryWriter` (torch.utils.tensorboard,
which needs the `tensorboard` package): the writer RL users already have beside torch. A run
resumed from an older checkpoint purges the events past it (`purge_step`), as metrics.jsonl
drops its rows. Writing never ends a run: an event the disk refuses is lost with a warning.
"""

from __future__ import annotations

import contextlib
import logging
import numbers
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from paramimic.messages import CurriculumSummary
from paramimic.task_space import TaskSpace

# metrics row key -> TensorBoard group (anything else: "run/")
GROUPS = {
    "ppo": ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_fraction", "skipped_steps",
            "update_steps", "explained_variance", "std", "policy_lr", "marginal_loss"),
    "episodes": ("episodes", "mean_return", "mean_length", "fall_percent", "diverged",
                 "deviated_percent", "mean_step_reward", "edge_fall_percent"),
    "speed": ("steps_per_second", "sample_steps_per_second", "policy_lag"),
    "actors": ("actors", "nodes", "actor_restarts", "actors_lost", "dropped_fragments",
               "fragment_errors"),
    "curriculum": ("mu", "range_width", "motion_version", "motion_loss"),
}  # fmt: skip
SKIPPED = {"time", "env_steps", "stage"}
SUMMARY = ("k", "buffer_size", "refills", "explored_ratio", "exploration_rate_surrounding",
           "exploration_rate_visited", "elites", "elite_mean_fitness",
           "phase_switches")  # fmt: skip
PHASES = {"exploration": 0.0, "refinement": 1.0}
STAGES = {"base": 0.0, "proxy": 1.0, "mixed": 2.0}
TAG_OF = {key: f"{group}/{key}" for group, keys in GROUPS.items() for key in keys}


def tag(key: str) -> str:
    return TAG_OF.get(key, f"run/{key}")


def scalars(row: Mapping, summary: CurriculumSummary | None = None) -> dict[str, float]:
    """The numeric values of a metrics row and of the curriculum's summary by tag; the [L21]
    bootstrap stage and phase as numbers (base 0, proxy 1, mixed 2; exploration 0, refinement
    1)."""
    values = {tag(k): float(v) for k, v in row.items() if k not in SKIPPED and _number(v)}
    if row.get("stage") in STAGES:
        values["curriculum/stage"] = STAGES[row["stage"]]
    if summary is not None:
        for name in SUMMARY:
            value = getattr(summary, name)
            if _number(value):
                values[f"curriculum/{name}"] = float(value)
        if summary.phase in PHASES:
            values["curriculum/phase"] = PHASES[summary.phase]
    return values


def marginal_figure(space: TaskSpace, dims: tuple[str, ...], predict, n: int = 21):
    """[WL19]'s V̄ over the two display dims (others at the box centre) as a matplotlib
    heatmap, or None without two display dims that vary (a base body's are points)."""
    free = dict(zip(space.names, space.free, strict=True))
    if len(dims) != 2 or not all(free.get(d) for d in dims):
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xs, ys, pts = space.grid(dims, n)
    values = predict(pts).reshape(len(ys), len(xs))
    fig, ax = plt.subplots(figsize=(4, 3.4))
    im = ax.imshow(values, origin="lower", aspect="auto", cmap="viridis",
                   extent=(xs[0], xs[-1], ys[0], ys[-1]))  # fmt: skip
    ax.set_xlabel(dims[0])
    ax.set_ylabel(dims[1])
    ax.set_title("marginal value V̄")
    fig.colorbar(im, ax=ax)
    fig.tight_layout()
    return fig


class TensorBoardLog:
    def __init__(self, log_dir: Path, purge_step: int) -> None:
        self.log_dir, self.purge_step = log_dir, purge_step
        self.writer = None
        self.failing = False
        self._open()

    def _open(self) -> None:
        """A writer (a new event file); after a failed write the old one is dropped, since its
        thread died with the error, and the next write opens another."""
        from torch.utils.tensorboard import SummaryWriter

        try:
            self.writer = SummaryWriter(str(self.log_dir), purge_step=self.purge_step or None)
            self.purge_step = 0  # a reopened writer purges nothing written since
        except OSError as e:
            self._failed(e)

    def _failed(self, error: OSError) -> None:
        if not self.failing:
            logging.getLogger(__name__).warning(f"TensorBoard events not written ({error})")
        self.failing, self.writer = True, None

    def _guard(self, write: Callable[[], None]) -> None:
        if self.writer is None:
            self._open()
            if self.writer is None:
                return
        try:
            write()
            self.failing = False
        except OSError as e:
            self._failed(e)

    def log(self, row: Mapping, summary: CurriculumSummary | None = None, figure=None) -> None:
        """A metrics row's and the summary's scalars at the row's env steps, and a figure (the
        V̄ map) if given."""
        step, values = int(row["env_steps"]), scalars(row, summary)

        def write() -> None:
            for key, value in values.items():
                self.writer.add_scalar(key, float(value), step)
            if figure is not None:
                self.writer.add_figure("curriculum/marginal_value", figure, step)

        self._guard(write)

    def close(self) -> None:
        if self.writer is not None:
            with contextlib.suppress(OSError):
                self.writer.close()


def _number(value) -> bool:
    return (
        isinstance(value, numbers.Real)
        and not isinstance(value, bool)
        and np.isfinite(float(value))
    )


class WandbLog:
    """Weights & Biases (`train.wandb: online | offline`; the `wandb` extra): the same values
    per env step in a W&B run named as the run's id, its files in the run directory's `wandb/`.
    `offline` needs no network or account (`wandb sync` uploads it later)."""

    def __init__(self, run_dir: Path, name: str, mode: str, project: str, config: dict) -> None:
        import wandb

        self.wandb = wandb
        self.run = wandb.init(project=project, name=name, dir=str(run_dir), mode=mode,
                              config=config, reinit="finish_previous")  # fmt: skip

    def log(self, row: Mapping, summary: CurriculumSummary | None = None, figure=None) -> None:
        values: dict = scalars(row, summary)
        if figure is not None:
            values["curriculum/marginal_value"] = self.wandb.Image(figure)
        self.run.log(values, step=int(row["env_steps"]))

    def close(self) -> None:
        self.run.finish()


def close_figure(figure) -> None:
    if figure is not None:
        import matplotlib.pyplot as plt

        plt.close(figure)
