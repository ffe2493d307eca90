"""The [L21] curriculum as the sampler owns it: elites with their traces, the motions m_a it deals
with each task, batches, exploration/refinement phases, and ER over N.

- Elites (§5.2): every finished episode is offered at the parameter a' it achieved (hindsight)
  with its fitness F; the k-d tree set keeps the best per neighbourhood, with its trace.
- Motions (§5.3): in the `base` stage the tasks are the reference a0 and m_a = m0 (π0 learns to
  track); in `proxy` each task's m_a is the kNN proxy of Eq. 14; in `mixed` a random choice
  between P_θ(a) (the learner's latest network) and the proxy. The learner moves the stage.
- Batches (§6): `batch_size` parameters, each dealt for `episodes_per_param` episodes; an
  exploration batch comes from A_s, a refinement batch from A_h by MCMC on exp(−k(V̄−μ)/μ)
  (Eq. 17); every `probe_every`-th batch samples the other region so that both exploration
  rates stay measured (§6.3). A batch's exploration rate is the share of its episodes that
  entered the elite set beating what they replaced by more than 0.02 (§6.1).
Pure and serialisable like `AdaptiveCurriculum`, whose V̄, μ, k and counters it keeps.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace

import numpy as np

from paramimic.config import CurriculumConfig, ExperimentConfig
from paramimic.curriculum.adaptive import AdaptiveCurriculum, marginal_function
from paramimic.curriculum.density import (
    SURROUNDING,
    VISITED,
    Density,
    PhaseSwitch,
    explored_ratio,
    sample_band,
)
from paramimic.curriculum.elite_set import EliteRule, EliteSet, Offer
from paramimic.curriculum.knn_proxy import knn_proxy
from paramimic.curriculum.mcmc import metropolis_hastings, surrogate_log_density
from paramimic.messages import CurriculumSummary, EpisodeReport, SkillOutcome, TaskDeal
from paramimic.rl.numpy_mlp import Layers, float32_layers, numpy_forward
from paramimic.task_space import TaskSpace

STAGES = ("base", "proxy", "mixed")
HISTORY = 1000  # (N, ER) points kept
OPEN_BATCHES = 8  # batches still counted when late episodes arrive
PROBES = 2048  # fixed points on which ER is estimated
RECENT = 200  # latest episodes whose a' the summary reports


class SkillCurriculum(AdaptiveCurriculum):
    STATE_PARTS = ("core", "buffer", "marginal", "elites", "motion", "traces")

    def __init__(
        self,
        space: TaskSpace,
        config: CurriculumConfig,
        seed: int,
        reference: np.ndarray,
        trace_shape: tuple[int, int],
        display_dims: Sequence[str] = (),
    ) -> None:
        super().__init__(space, config, seed, display_dims)
        self.sc = sc = config.skill
        self.metric = space.metric  # distances on the normalized box
        rule = EliteRule(sc.elite_radius, sc.fitness_threshold, sc.improvement)
        self.elites = EliteSet(space.dim, self.metric, rule)
        self.traces: dict[str, np.ndarray] = {}
        self.added: dict[str, np.ndarray] = {}  # traces changed since `drain_traces`
        self.removed: set[str] = set()
        self.reference = np.asarray(reference, np.float64)
        self.trace_shape = tuple(trace_shape)
        self.phase = PhaseSwitch(rule=self._rule())
        self.stage = "base"
        self.motion_layers: Layers | None = None
        self.motion_version = 0
        self.motion_loss: float | None = None
        self.batch: dict | None = None
        self.batches: dict[int, dict] = {}
        self.batch_count = 0
        self.history: list[tuple[int, float]] = []  # (N episodes, ER)
        self.improvements = 0
        self.achieved: list[list[float]] = []  # a' of the latest RECENT episodes (hindsight)
        self.probes = space.sample(np.random.default_rng(seed + 7), PROBES)
        self._density: Density | None = None

    @classmethod
    def from_config(
        cls, cfg: ExperimentConfig, trace_shape: Sequence[int], reference: Sequence[float]
    ) -> SkillCurriculum:
        """The curriculum of an experiment; the clip's trace shape and its parameter a0 come
        from the env (`SkillEnv.clip_setup`, via `paramimic.training.method.L21`), the config's
        `curriculum.skill.reference` overriding entries of a0."""
        space = TaskSpace.from_ranges(cfg.task)
        reference = np.array(reference, np.float64)
        for name, value in cfg.curriculum.skill.reference.items():
            reference[space.names.index(name)] = value
        return cls(
            space,
            cfg.curriculum,
            seed=cfg.train.seed + 3,
            reference=reference,
            trace_shape=trace_shape,
            display_dims=cfg.display_dims(),
        )

    @property
    def mode(self) -> str:
        return "uniform" if self.sc.sampling == "uniform" else "skill"

    @property
    def rng(self) -> np.random.Generator:
        return self.sampler.rng  # one generator, saved with the core state

    # --- density and regions ----------------------------------------------------------------

    @property
    def density(self) -> Density:
        if self._density is None:
            live = self.elites.live()
            self._density = Density(self.space, self.elites.params[live], self.sc.bandwidth)
        return self._density

    def explored_ratio(self) -> float:
        return explored_ratio(self.density, self.probes, self.sc.density_visited)

    # --- dealing tasks ------------------------------------------------------------------------

    def next_tasks(self, n: int) -> np.ndarray:
        return self.next_deal(n).tasks

    def next_deal(self, n: int) -> TaskDeal:
        """n tasks from the current batch with the motions m_a to imitate (None: m0), tagged
        with the batch, its region and the motion version."""
        quota = self.sc.batch_size * self.sc.episodes_per_param
        current = None if self.batch is None else self.batches.get(self.batch["id"])
        if current is None or current["ingested"] >= quota:
            self._new_batch()
        b = self.batch
        idx = (b["served"] + np.arange(n)) % len(b["params"])
        b["served"] += n
        tasks = np.asarray(b["params"])[idx]
        self.stats["tasks_served"] += n
        self.stats["deals"] += 1
        return TaskDeal(tasks, self.motions_for(tasks), b["id"], b["region"], self.motion_version)

    def _new_batch(self) -> None:
        sc, rng, B = self.sc, self.rng, self.sc.batch_size
        self.batch_count += 1
        if self.stage == "base" or (sc.sampling != "uniform" and len(self.elites) == 0):
            # π0 learns m0 at a0 first, whatever samples the tasks afterwards (§5.3)
            params, region = np.tile(self.reference, (B, 1)), "reference"
        elif sc.sampling == "uniform":
            params, region = self.space.sample(rng, B), "uniform"
        else:
            region = SURROUNDING if self.phase.phase == "exploration" else VISITED
            if self.batch_count % sc.probe_every == 0:  # §6.3: occasional samples elsewhere
                region = VISITED if region == SURROUNDING else SURROUNDING
            if region == SURROUNDING:
                params = sample_band(
                    self.space, self.density, rng, B, sc.density_surrounding, sc.density_visited
                )
            else:
                params = self._refinement_samples(B)
            if len(params) < B:  # a thin band: fill from A_h, then the reference
                more = sample_band(
                    self.space, self.density, rng, B - len(params), sc.density_visited
                )
                params = np.concatenate([params, more, np.tile(self.reference, (B, 1))])[:B]
        self.batch = {"id": self.batch_count, "region": region, "params": params, "served": 0}
        self.batches[self.batch_count] = {"region": region, "ingested": 0, "improved": 0}
        for old in sorted(self.batches)[:-OPEN_BATCHES]:
            del self.batches[old]

    def _refinement_samples(self, n: int) -> np.ndarray:
        """n parameters in A_h by Metropolis-Hastings on exp(−k(V̄−μ)/μ) (Eq. 17)."""
        D, k = self.sc.density_visited, self.sampler.k  # k = 10 ([L21] §6.2), set via the API
        v_bar = None if self.layers is None else marginal_function(self.layers, self.space)
        mu = self.mu

        def log_density(a: np.ndarray) -> np.ndarray:
            inside = self.density(a) >= D
            lp = np.zeros(len(a))
            if v_bar is not None and mu is not None and mu > 0 and k > 0:
                lp = surrogate_log_density(v_bar(a), mu, k)
            return np.where(inside, lp, -np.inf)

        cc = self.config
        with np.errstate(invalid="ignore"):  # −∞ − −∞: a chain outside A_h stays rejected
            x = metropolis_hastings(log_density, self.space, self.rng, 4 * n, cc.chains, cc.burn_in)
        x = x[self.density(x) >= D]
        return x[self.rng.permutation(len(x))[:n]]

    def motions_for(self, tasks: np.ndarray) -> np.ndarray | None:
        """m_a for each task: None in the base stage (m0); else the kNN proxy (Eq. 14), or in
        the mixed stage P_θ(a) for a random half; m0 always without motion parameterization."""
        if self.stage == "base" or len(self.elites) == 0 or not self.sc.motion_parameterization:
            return None
        sc = self.sc
        out = np.stack(
            [
                knn_proxy(self.elites, self.traces.__getitem__, a, sc.knn_k, sc.knn_sigma)
                for a in tasks
            ]
        )
        if self.stage == "mixed" and self.motion_layers is not None:
            use_net = self.rng.random(len(tasks)) < 0.5
            if use_net.any():
                x = self.space.scaled(tasks[use_net])
                out[use_net] = numpy_forward(self.motion_layers, x).reshape(-1, *self.trace_shape)
        return out

    def performed_motions(self, tasks: np.ndarray) -> np.ndarray | None:
        """m_a for performing each task (evaluation, play), chosen without chance: P_θ(a) once
        the bootstrap's mixed stage uses it, the kNN proxy (Eq. 14) in the proxy stage, None
        (m0) in the base stage or without motion parameterization."""
        if self.stage == "base" or len(self.elites) == 0 or not self.sc.motion_parameterization:
            return None
        tasks = np.atleast_2d(np.asarray(tasks, np.float64))
        if self.stage == "mixed" and self.motion_layers is not None:
            x = self.space.scaled(tasks)
            return numpy_forward(self.motion_layers, x).reshape(-1, *self.trace_shape)
        sc = self.sc
        return np.stack(
            [
                knn_proxy(self.elites, self.traces.__getitem__, a, sc.knn_k, sc.knn_sigma)
                for a in tasks
            ]
        )

    # --- what finished episodes report ---------------------------------------------------------

    def _holds_constraints(self, skill: SkillOutcome | None) -> bool:
        """An episode the elite set may consider: a completed clip with its hindsight a' (and,
        with `constraint_tolerance`, every constraint held within that many σ_task)."""
        if skill is None or skill.achieved is None:
            return False
        tol = self.sc.constraint_tolerance
        return tol is None or skill.constraint_error is None or skill.constraint_error <= tol

    def ingest(self, episodes: Iterable[EpisodeReport]) -> int:
        """Count episodes and offer each with a trace to the elite set at its achieved a'."""
        episodes = list(episodes)
        n = super().ingest(episodes)
        changed = False
        for e in episodes:
            skill = e.skill
            if skill is not None and skill.achieved is not None:
                self.achieved.append([float(x) for x in skill.achieved])
            offer = Offer(False)
            if self._holds_constraints(skill) and skill.trace is not None:
                offer = self.elites.offer(
                    np.asarray(skill.achieved, np.float64), float(skill.fitness), e.episode_id
                )
            if offer.accepted:
                changed = True
                key = e.episode_id
                self.traces[key] = self.added[key] = np.asarray(skill.trace, np.float64)
                for old in offer.replaced:
                    self.traces.pop(old, None)
                    self.added.pop(old, None)
                    self.removed.add(old)
                self.stats["elites_added"] = self.stats.get("elites_added", 0) + 1
            self.improvements += int(offer.improved)
            batch = e.tags.batch
            record = None if batch is None else self.batches.get(batch)
            if record is not None:
                record["ingested"] += 1
                record["improved"] += int(offer.improved)
                self._maybe_close(batch, record)
        del self.achieved[:-RECENT]
        if changed:
            self._density = None
        return n

    def _maybe_close(self, batch_id: int, record: dict) -> None:
        """Once a batch has all its episodes: its exploration rate feeds the phase switch and
        ER is recorded. Late episodes of a closed batch (dealt ahead) count only as elites."""
        if (
            "closed" in record
            or record["ingested"] < self.sc.batch_size * self.sc.episodes_per_param
        ):
            return
        rate = record["improved"] / record["ingested"]
        if record["region"] in (VISITED, SURROUNDING):
            before = self.phase.phase
            self.phase.observe(record["region"], rate, self.marginal_iteration)
            self._count_switch(before)
        self.history.append((int(self.stats["episodes"]), self.explored_ratio()))
        del self.history[:-HISTORY]
        record["closed"] = rate
        self._tick()

    # --- the phase rules of [L21] §7.3 ---------------------------------------------------------

    def _rule(self) -> str:
        return "curriculum" if self.sc.sampling == "uniform" else self.sc.sampling

    def _count_switch(self, before: str) -> None:
        if self.phase.phase != before:
            self.stats["phase_switches"] = self.stats.get("phase_switches", 0) + 1

    def _tick(self, update: bool = False) -> None:
        """The rules on the clock, ER and mastery; their clock starts when π0 is done.
        `update`: called at a policy update (mastering measures the visited skills then)."""
        if self.stage == "base" or self.sc.sampling == "uniform":
            self.phase.started = max(self.marginal_iteration, 0)
            return
        sc, before = self.sc, self.phase.phase
        er = self.history[-1][1] if self.history else None
        refining = sc.sampling == "mastering" and before == "refinement"
        if refining and update:
            value = self.visited_value()
            if value is not None:
                self.phase.progress.append(value)
        self.phase.tick(
            self.marginal_iteration,
            er,
            refining and self.mastered(),
            sc.phase_updates,
            sc.phase_timeout,
            sc.exploration_complete,
        )
        self._count_switch(before)

    def visited_value(self) -> float | None:
        """The mean V̄ over the live elites: the worth of the visited region's skills."""
        live = self.elites.live()
        if self.layers is None or not len(live):
            return None
        return float(marginal_function(self.layers, self.space)(self.elites.params[live]).mean())

    def mastered(self) -> bool:
        """The mastering curriculum's test ([L21] §7.3: "a threshold of mean marginal values"):
        the visited skills' mean V̄ has stopped rising: over the last `mastery_window` policy
        updates of this refinement phase it rose by less than `mastery_threshold` of itself."""
        window, progress = self.sc.mastery_window, self.phase.progress
        if len(progress) <= window:
            return False
        then = progress[-1 - window]
        return progress[-1] - then < self.sc.mastery_threshold * abs(then)

    def update_marginal(self, layers: Layers, mu: float, iteration: int, refill: bool) -> None:
        super().update_marginal(layers, mu, iteration, refill)
        self._tick(update=True)

    ENTRY_PARTS = ("traces",)  # one entry per elite: written as the elite set changes

    def pending_parts(self) -> tuple[str, ...]:
        return ("elites",) if self.added or self.removed else ()

    def drain(self, part: str) -> tuple[dict, set[str]]:
        """Traces added (as lists) and removed since the last call."""
        if part != "traces":
            raise KeyError(part)
        added, removed = self.added, self.removed
        self.added, self.removed = {}, set()
        return {k: v.tolist() for k, v in added.items()}, removed

    def entries(self, part: str) -> dict:
        if part != "traces":
            raise KeyError(part)
        return {k: v.tolist() for k, v in self.traces.items()}

    def views(self, parts: Iterable[str], n: int = 21) -> dict:
        """Also the elites' density (Eq. 15) when the elite set changed."""
        out = super().views(parts, n)
        return out | ({"density": self.density_grid(n)} if "elites" in parts else {})

    # --- the learner's calls ------------------------------------------------------------------

    def elite_data(self) -> tuple[np.ndarray, np.ndarray]:
        """(a' [n, d], traces [n, K, D]) of the live elites: P_θ's training set."""
        live = self.elites.live()
        keys = [self.elites.keys[s] for s in live]
        traces = np.array([self.traces[k] for k in keys]).reshape(-1, *self.trace_shape)
        return self.elites.params[live].copy(), traces

    def update_motion(self, layers: Layers | None, version: int, loss: float | None, stage: str):
        """The learner's P_θ (numpy layers), its version and loss, and the bootstrap stage."""
        if stage not in STAGES:
            raise ValueError(f"stage must be one of {STAGES}, got {stage!r}")
        if layers is not None:
            self.motion_layers = float32_layers(layers)
        self.motion_version, self.motion_loss = int(version), loss
        self.stage = stage

    # --- views ----------------------------------------------------------------------------------

    def density_grid(self, n: int = 21) -> dict | None:
        """Eq. 15 over the display dims (others at the reference): values [len(ys)][len(xs)]."""
        if len(self.display_dims) != 2:
            return None
        xs, ys, pts = self.space.grid(self.display_dims, n)  # type: ignore[arg-type]
        fixed = [i for i, name in enumerate(self.space.names) if name not in self.display_dims]
        pts[:, fixed] = self.reference[fixed]
        values = self.density(pts).reshape(len(ys), len(xs))
        return {
            "dims": list(self.display_dims),
            "xs": xs.tolist(),
            "ys": ys.tolist(),
            "values": values.tolist(),
            "visited": self.sc.density_visited,
            "surrounding": self.sc.density_surrounding,
            "elites": len(self.elites),
        }

    def elites_table(self) -> dict:
        """Live elites for the API: names, params [n, d], fitness [n], keys [n]."""
        live = self.elites.live()
        return {
            "names": list(self.space.names),
            "params": self.elites.params[live].tolist(),
            "fitness": self.elites.fitness[live].tolist(),
            "keys": [self.elites.keys[s] for s in live],
        }

    def summary(self) -> CurriculumSummary:
        last = self.history[-1] if self.history else None
        phase = self.phase.phase if self.stage != "base" else "base"
        fitness = self.elites.fitness[self.elites.live()]
        return replace(
            super().summary(),
            phase="uniform" if self.sc.sampling == "uniform" else phase,
            stage=self.stage,
            explored_ratio=None if last is None else last[1],
            exploration_rate_surrounding=self.phase.rate_surrounding,
            exploration_rate_visited=self.phase.rate_visited,
            elites=len(self.elites),
            elite_mean_fitness=float(fitness.mean()) if len(self.elites) else None,
            phase_switches=self.phase.switches,
            motion_version=self.motion_version,
            motion_loss=self.motion_loss,
            batch=None if self.batch is None else self.batch["id"],
            batch_region=None if self.batch is None else self.batch["region"],
            reference=self.space.to_dict(self.reference),
            task_ranges={k: list(v) for k, v in self.space.ranges().items()},
            history=[{"episodes": n, "explored_ratio": er} for n, er in self.history[-200:]],
            achieved=self._achieved_summary(),
        )

    def _achieved_summary(self) -> dict[str, dict[str, float]]:
        """Per task parameter: mean, min and max of a' over the latest episodes."""
        if not self.achieved:
            return {}
        a = np.asarray(self.achieved)
        return {
            n: {"mean": float(a[:, i].mean()), "min": float(a[:, i].min()),
                "max": float(a[:, i].max())}
            for i, n in enumerate(self.space.names)
        }  # fmt: skip

    # --- state ----------------------------------------------------------------------------------

    def to_state(self, parts: Iterable[str] = STATE_PARTS) -> dict:
        parts = tuple(parts)
        state = super().to_state([p for p in parts if p in AdaptiveCurriculum.STATE_PARTS])
        if "core" in parts:
            b = self.batch
            state["core"] |= {
                "phase": vars(self.phase).copy(),
                "stage": self.stage,
                "batch": None if b is None else b | {"params": np.asarray(b["params"]).tolist()},
                "batches": {str(k): v for k, v in self.batches.items()},
                "batch_count": self.batch_count,
                "history": self.history,
                "improvements": self.improvements,
                "achieved": self.achieved,
            }
        if "elites" in parts:
            state["elites"] = self.elites.to_state()
        if "motion" in parts:
            state["motion"] = {
                "version": self.motion_version,
                "loss": self.motion_loss,
                "layers": None
                if self.motion_layers is None
                else [[w.tolist(), b.tolist()] for w, b in self.motion_layers],
            }
        if "traces" in parts:
            state["traces"] = {k: v.tolist() for k, v in sorted(self.traces.items())}
        return state

    def from_state(self, state: dict) -> None:
        core = dict(state["core"])
        self.phase = PhaseSwitch(**core.pop("phase"))
        self.phase.rule = self._rule()  # the config's, also for states written before rules
        self.stage = core.pop("stage")
        b = core.pop("batch")
        self.batch = None if b is None else b | {"params": np.asarray(b["params"], np.float64)}
        self.batches = {int(k): v for k, v in core.pop("batches").items()}
        self.batch_count = int(core.pop("batch_count"))
        self.history = [tuple(h) for h in core.pop("history")]
        self.improvements = int(core.pop("improvements"))
        self.achieved = core.pop("achieved", [])  # absent in older states
        super().from_state(state | {"core": core})
        self.elites.from_state(state["elites"])
        m = state["motion"]
        self.motion_version, self.motion_loss = int(m["version"]), m["loss"]
        self.motion_layers = None if m["layers"] is None else float32_layers(m["layers"])
        self.traces = {k: np.asarray(v, np.float64) for k, v in state["traces"].items()}
        self.added, self.removed = {}, set()
        self._density = None
