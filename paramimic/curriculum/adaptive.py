"""The [WL19] curriculum as the sampler owns it: the buffer S, the latest V̄ and μ, k, and what
finished episodes report. Pure and serialisable (`to_state` / `from_state`); the sampler service
adds Ray and Redis around it, the serial trainer uses it in-process.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from paramimic.config import CurriculumConfig, ExperimentConfig
from paramimic.curriculum.mcmc import AdaptiveSampler, concentration
from paramimic.messages import CurriculumSummary, EpisodeReport, TaskDeal
from paramimic.rl.numpy_mlp import Layers, float32_layers, numpy_forward
from paramimic.task_space import TaskSpace

STATE_PARTS = ("core", "buffer", "marginal")
# `deals`: next_deal calls answered (an [L21] *batch* is a set of task parameters, `batch_count`)
STAT_FIELDS = ("episodes", "steps", "falls", "diverged", "return_sum", "tasks_served", "deals")


def marginal_function(layers: Layers, space: TaskSpace):
    """V̄ as a numpy function [n, d] -> [n] from exported layers (what the sampler runs MCMC on)."""
    layers = float32_layers(layers)

    def v_bar(a: np.ndarray) -> np.ndarray:
        x = space.scaled(a).astype(np.float32)
        return numpy_forward(layers, x)[:, 0].astype(np.float64)

    return v_bar


class AdaptiveCurriculum:
    """Alg. 1 l.3 and l.7 of [WL19] (S refilled by MCMC on exp(-k(V̄-μ)/μ); tasks drawn from S)."""

    STATE_PARTS = STATE_PARTS

    def __init__(
        self,
        space: TaskSpace,
        config: CurriculumConfig,
        seed: int,
        display_dims: Sequence[str] = (),
        origin: np.ndarray | None = None,
    ) -> None:
        self.space = space
        # where a widening range grows from (`WidenConfig.origin`); the box's centre by default
        self.origin = space.center if origin is None else np.asarray(origin, dtype=np.float64)
        self.config = config
        self.sampler = AdaptiveSampler(
            space, config.k_at(0), config.n_mcmc, config.chains, config.burn_in, seed=seed
        )
        self.k_ramp = config.k_ramp_iterations is not None  # k follows config.k_at
        self.display_dims = tuple(display_dims)[:2]
        self.layers: Layers | None = None  # the latest V̄ from the learner
        self.mu: float | None = None
        self.marginal_iteration = -1
        self.stats: dict[str, float] = dict.fromkeys(STAT_FIELDS, 0)
        self.width = config.widen.start if config.widen is not None else 1.0
        self.window = [0, 0]  # episodes and failures since the last widening decision
        self._stats_of: np.ndarray | None = None  # the buffer whose mean/std are cached
        self._stats: tuple[dict, dict] = ({}, {})

    @classmethod
    def from_config(cls, cfg: ExperimentConfig) -> AdaptiveCurriculum:
        space = TaskSpace.from_ranges(cfg.task)
        widen = cfg.curriculum.widen
        origin = None
        if widen is not None and widen.origin == "base":
            # the registry loads MuJoCo: only here, as the config's own validation does
            from paramimic.characters import registration

            origin = space.base(registration(cfg.character).character.param_names())
        return cls(
            space,
            cfg.curriculum,
            seed=cfg.train.seed + 3,
            display_dims=cfg.display_dims(),
            origin=origin,
        )

    @property
    def mode(self) -> str:
        return "uniform" if self.sampler.k == 0 else "adaptive"

    # --- the four things that change the state -----------------------------------------------

    def update_marginal(self, layers: Layers, mu: float, iteration: int, refill: bool) -> None:
        """Take the learner's V̄ and μ; refill S by MCMC if `refill` (every P_MCMC iterations)."""
        self.layers = float32_layers(layers)
        self.mu = float(mu)
        self.marginal_iteration = int(iteration)
        if self.k_ramp:
            self.sampler.k = self.config.k_at(self.marginal_iteration)
        if refill:
            v_bar = marginal_function(self.layers, self.space)
            self.sampler.refill(lambda a: v_bar(self.pull(a)), self.mu)

    def pull(self, tasks: np.ndarray) -> np.ndarray:
        """Tasks of the full box mapped into the current range: toward its origin (the base
        body) to `width` of their offset (the identity without `widen`)."""
        if self.width >= 1.0:
            return tasks
        return self.origin + self.width * (np.asarray(tasks) - self.origin)

    def next_tasks(self, n: int) -> np.ndarray:
        """n task parameters drawn from S: [n, d]."""
        tasks = self.pull(self.sampler.next_tasks(n))
        self.stats["tasks_served"] += n
        self.stats["deals"] += 1
        return tasks

    def next_deal(self, n: int) -> TaskDeal:
        """The tasks of n episodes as a deal (the [L21] curriculum adds motions and tags)."""
        return TaskDeal(self.next_tasks(n))

    def ingest(self, episodes: Iterable[EpisodeReport]) -> int:
        """Count finished episodes; the caller removes duplicates."""
        n = 0
        for e in episodes:
            n += 1
            self.stats["episodes"] += 1
            self.stats["steps"] += int(e.length)
            self.stats["falls"] += int(e.fell)
            self.stats["diverged"] += int(e.diverged)
            self.stats["return_sum"] += float(e.ret)
            self._widen(e)
        return n

    def _widen(self, episode: EpisodeReport) -> None:
        """Count a training episode toward the next widening decision (`WidenConfig`)."""
        rule = self.config.widen
        if rule is None or rule.promote_on == "edge" or self.width >= 1.0:
            return
        self.window[0] += 1
        failed = episode.ended_early if rule.promote_on == "early_ends" else episode.fell
        self.window[1] += int(failed)
        if self.window[0] >= rule.window:
            self._promote(*self.window)
            self.window = [0, 0]

    def _promote(self, episodes: int, failed: int) -> None:
        """The widening rule: grow by `step` when fewer than `promote_below` of them failed."""
        rule = self.config.widen
        if failed < rule.promote_below * episodes:
            self.width = min(1.0, round(self.width + rule.step, 9))  # no 0.30000000000000004

    def edge_tasks(self, n: int, seed: int) -> np.ndarray | None:
        """n tasks on the current range's edge (`promote_on: edge`), or None once the range is
        whole: uniform in the range, each pushed out along its offset from the origin until one
        free dimension sits at the range's bound (ADR's boundary sampling, one width for all)."""
        if self.width >= 1.0:
            return None
        rng = np.random.default_rng(seed)
        u = np.where(self.space.free, rng.uniform(-1.0, 1.0, (n, self.space.dim)), 0.0)
        u /= np.maximum(np.abs(u).max(axis=1, keepdims=True), 1e-12)
        # the range's half-extents on either side of the origin (the box's `pull`ed to `width`)
        reach = np.where(u >= 0, self.space.high - self.origin, self.origin - self.space.low)
        return self.origin + self.width * u * reach

    def judge_edge(self, episodes: int, falls: int) -> float:
        """The edge test's outcome (`edge_tasks`' episodes and how many fell) decides a
        widening; returns the width in use next."""
        if self.width < 1.0:
            self._promote(episodes, falls)
        return self.width

    def concentration(self, n: int = 20_000, seed: int = 0) -> dict[str, float] | None:
        """How narrowly the sampler draws now (`mcmc.concentration` over n uniform points of
        the box, through the current range); None before V̄ exists."""
        if self.layers is None or self.mu is None:
            return None
        tasks = self.space.sample(np.random.default_rng(seed), n)
        v_bar = marginal_function(self.layers, self.space)(self.pull(tasks))
        return concentration(v_bar, self.mu, self.sampler.k)

    def set_k(self, k: float) -> None:
        if not k >= 0:
            raise ValueError(f"k must be >= 0, got {k}")
        self.sampler.k = float(k)
        self.k_ramp = False  # a k set by hand ends the ramp

    # --- what the sampler persists, besides `to_state` --------------------------------------

    ENTRY_PARTS: tuple[str, ...] = ()  # parts kept entry by entry (`drain`, `entries`)

    def pending_parts(self) -> tuple[str, ...]:
        """Parts that the latest `ingest` changed besides "core" (none here)."""
        return ()

    def drain(self, part: str) -> tuple[dict, set[str]]:
        """Entries of an `ENTRY_PARTS` part added (JSON-able) and removed since the last call."""
        raise KeyError(part)

    def entries(self, part: str) -> dict:
        """Every entry of an `ENTRY_PARTS` part (JSON-able)."""
        raise KeyError(part)

    def views(self, parts: Iterable[str], n: int = 21) -> dict:
        """The public snapshots that depend on `parts` (written beside the summary): V̄ over the
        display dims when the marginal changed."""
        return {"grid": self.marginal_grid(n)} if "marginal" in parts else {}

    # --- views ----------------------------------------------------------------------------------

    def marginal_grid(self, n: int = 21) -> dict | None:
        """V̄ over the display dims (others at the box centre): values [len(ys)][len(xs)]."""
        if self.layers is None:
            return None
        space, dims = self.space, self.display_dims
        if len(dims) == 2:
            xs, ys, pts = space.grid(dims, n)  # type: ignore[arg-type]
        else:  # one free dimension (a line) or none (the centre)
            ys = np.zeros(0)
            pts = np.tile(space.center, (n if dims else 1, 1))
            xs = np.zeros(0)
            if dims:
                i = space.names.index(dims[0])
                xs = pts[:, i] = np.linspace(space.low[i], space.high[i], n)
        v = marginal_function(self.layers, space)(pts).reshape(max(len(ys), 1), -1)
        return {
            "dims": list(dims),
            "xs": xs.tolist(),
            "ys": ys.tolist(),
            "values": v.tolist(),
            "mu": self.mu,
            "iteration": self.marginal_iteration,
        }

    def summary(self) -> CurriculumSummary:
        """The public state: what the API shows under /curriculum."""
        s = self.stats
        mean, std = self._buffer_stats()
        episodes = max(s["episodes"], 1)
        return CurriculumSummary(
            mode=self.mode,
            k=self.sampler.k,
            mu=self.mu,
            marginal_iteration=self.marginal_iteration,
            refills=self.sampler.refills,
            buffer_adaptive=self.sampler.adaptive,
            buffer_size=len(self.sampler.buffer),
            buffer_mean=mean,
            buffer_std=std,
            task_names=list(self.space.names),
            episodes=int(s["episodes"]),
            mean_return=s["return_sum"] / episodes if s["episodes"] else None,
            fall_percent=100.0 * s["falls"] / episodes if s["episodes"] else None,
            tasks_served=int(s["tasks_served"]),
            range_width=self.width,
        )

    def _buffer_stats(self) -> tuple[dict, dict]:
        """Per-dimension mean and std of S, recomputed only when S is replaced."""
        buf = self.sampler.buffer
        if getattr(self, "_stats_of", None) is not buf:
            self._stats_of = buf
            self._stats = (
                self.space.to_dict(buf.mean(axis=0)),
                self.space.to_dict(buf.std(axis=0)),
            )
        return self._stats

    # --- state ----------------------------------------------------------------------------------

    def to_state(self, parts: Iterable[str] = STATE_PARTS) -> dict:
        """JSON-able state in three parts: `core` changes on every call, `buffer` on refills,
        `marginal` when the learner sends V̄; `parts` picks some of them."""
        state: dict = {}
        if "buffer" in parts:
            state["buffer"] = self.sampler.buffer.tolist()
        if "core" in parts:
            state["core"] = self.sampler.to_state(with_buffer=False) | {
                "mu": self.mu,
                "marginal_iteration": self.marginal_iteration,
                "stats": dict(self.stats),
                "width": self.width,
                "window": list(self.window),
                "k_ramp": self.k_ramp,
            }
        if "marginal" in parts:
            state["marginal"] = (
                None if self.layers is None else [[w.tolist(), b.tolist()] for w, b in self.layers]
            )
        return state

    def from_state(self, state: dict) -> None:
        core = dict(state["core"])
        self.mu = core.pop("mu")
        self.marginal_iteration = int(core.pop("marginal_iteration"))
        stats = core.pop("stats")
        if "batches" in stats:  # older states named the deals so
            stats["deals"] = stats.pop("batches")
        self.stats = dict.fromkeys(STAT_FIELDS, 0) | stats
        self.width = float(core.pop("width", 1.0 if self.config.widen is None else self.width))
        self.window = list(core.pop("window", [0, 0]))
        self.k_ramp = bool(core.pop("k_ramp", self.k_ramp))  # absent in older states
        self.sampler.from_state(core | {"buffer": state["buffer"]})
        marginal = state["marginal"]
        self.layers = None if marginal is None else float32_layers(marginal)
