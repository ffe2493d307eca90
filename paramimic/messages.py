"""The messages that cross process boundaries, typed once.

A training run passes three things between its processes (the sampler actor, the rollout
actors, the learner, the API): the curriculum's **deal** of task parameters (and, for [L21],
the motions m_a to imitate), the **report** of each finished episode, and the **summary** of
the curriculum the API and the CLI show (`TaskDeal`, `EpisodeReport`, `CurriculumSummary`).
Each is a frozen dataclass here; Ray carries them as they are, and `to_dict` / `from_dict` turn
them into JSON-able dicts at the boundaries that need text (Redis, the API). The env's per-step
`info` stays a dict (gymnasium's contract), with its keys typed by `StepInfo`.

This module is the bottom of the library: it imports numpy only, so that the envs, the rollout
loop and the curricula all speak it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any, TypedDict

import numpy as np


def _array(x, dtype=np.float64) -> np.ndarray | None:
    return None if x is None else np.asarray(x, dtype)


def _plain(x):
    return x.tolist() if isinstance(x, np.ndarray) else x


@dataclass(frozen=True)
class TaskDeal:
    """The task parameters of the next episodes, in order, from the curriculum.

    [WL19] deals tasks only. [L21] adds the motions m_a = m0 ⊕ d to imitate (None: m0 itself,
    π0's stage) and tags that come back in each episode's report: the batch the tasks belong to,
    its region of the task space and the version of P_θ that made the motions."""

    tasks: np.ndarray  # [n, d]
    motions: np.ndarray | None = None  # [n, K, D] motion traces, or None (m0)
    batch: int | None = None
    region: str | None = None
    motion_version: int | None = None

    def __post_init__(self) -> None:
        tasks = np.asarray(self.tasks, np.float64)
        if tasks.ndim != 2:
            raise ValueError(f"a deal's tasks are [n, d], got shape {tasks.shape}")
        object.__setattr__(self, "tasks", tasks)
        if self.motions is not None:
            motions = np.asarray(self.motions, np.float64)
            if motions.ndim != 3 or len(motions) != len(tasks):
                raise ValueError(
                    f"a deal's motions are [n, K, D] with n = {len(tasks)} tasks, got shape "
                    f"{motions.shape}"
                )
            object.__setattr__(self, "motions", motions)

    def __len__(self) -> int:
        return len(self.tasks)

    def take(self, idx: np.ndarray) -> TaskDeal:
        """The deal's rows `idx` (any order, repeats allowed), tags kept."""
        motions = None if self.motions is None else self.motions[idx]
        return replace(self, tasks=self.tasks[idx], motions=motions)

    def tags(self) -> DealTags:
        return DealTags(self.batch, self.region, self.motion_version)

    def to_dict(self) -> dict[str, Any]:
        return {f.name: _plain(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TaskDeal:
        return cls(
            np.asarray(d["tasks"], np.float64),
            _array(d.get("motions")),
            d.get("batch"),
            d.get("region"),
            d.get("motion_version"),
        )


@dataclass(frozen=True)
class DealTags:
    """What of a deal an episode carries back to the curriculum ([L21]; None for [WL19])."""

    batch: int | None = None
    region: str | None = None
    motion_version: int | None = None


@dataclass(frozen=True)
class SkillOutcome:
    """What an [L21] episode reports besides its return: the achieved task parameters a'
    (hindsight, None for a π0 episode started mid-clip), the fitness F (Eq. 10), the motion
    trace it performed (None unless the clip was completed) and whether it completed the clip
    (and, with `env.skill.hold_seconds`, stood after it: `held`)."""

    achieved: np.ndarray | None
    fitness: float
    trace: np.ndarray | None
    completed: bool
    held: bool | None = None
    # the largest miss of a constraint (a zero-range measured parameter) in its σ_task, on a
    # completed episode of a family with constraints (None otherwise)
    constraint_error: float | None = None

    def with_held(self, held: bool) -> SkillOutcome:
        return replace(self, held=held)

    def to_dict(self) -> dict[str, Any]:
        return {f.name: _plain(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SkillOutcome:
        return cls(
            _array(d.get("achieved")),
            float(d["fitness"]),
            _array(d.get("trace")),
            bool(d["completed"]),
            d.get("held"),
            d.get("constraint_error"),
        )


@dataclass(frozen=True)
class EpisodeReport:
    """One finished training episode, as the rollouts report it to the curriculum and the
    learner's metrics."""

    episode_id: str
    task: np.ndarray  # [d]
    ret: float  # undiscounted sum of rewards
    length: int  # control steps
    fell: bool
    diverged: bool
    reward_terms: dict[str, float]  # per-term sums over the episode
    # the env ended it before its time limit (a fall, a stall, off course, a divergence, ...)
    ended_early: bool
    # ended by the training rule `env.deviation_limit` (a clip gait, a skill; never a fall)
    deviated: bool = False
    skill: SkillOutcome | None = None  # [L21] episodes
    tags: DealTags = field(default_factory=DealTags)

    def to_dict(self) -> dict[str, Any]:
        out = {f.name: _plain(getattr(self, f.name)) for f in fields(self)}
        out["skill"] = None if self.skill is None else self.skill.to_dict()
        out["tags"] = vars(self.tags).copy()
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EpisodeReport:
        skill = d.get("skill")
        return cls(
            str(d["episode_id"]),
            np.asarray(d["task"], np.float64),
            float(d["ret"]),
            int(d["length"]),
            bool(d["fell"]),
            bool(d["diverged"]),
            {k: float(v) for k, v in d["reward_terms"].items()},
            bool(d["ended_early"]),
            bool(d.get("deviated", False)),
            None if skill is None else SkillOutcome.from_dict(skill),
            DealTags(**d.get("tags", {})),
        )


@dataclass(frozen=True)
class CurriculumSummary:
    """The curriculum's public state: what the API serves under /curriculum (its response
    model has these fields, described) and the CLI's `status` shows. The [L21] fields are None
    for the [WL19] curriculum."""

    mode: str  # adaptive, uniform or skill
    k: float
    mu: float | None
    marginal_iteration: int
    refills: int
    buffer_adaptive: bool
    buffer_size: int
    buffer_mean: dict[str, float]
    buffer_std: dict[str, float]
    task_names: list[str]
    episodes: int
    mean_return: float | None
    fall_percent: float | None
    tasks_served: int
    range_width: float | None
    # [L21] §5-6
    phase: str | None = None
    explored_ratio: float | None = None
    exploration_rate_surrounding: float | None = None
    exploration_rate_visited: float | None = None
    stage: str | None = None
    elites: int | None = None
    elite_mean_fitness: float | None = None
    phase_switches: int | None = None
    motion_version: int | None = None
    motion_loss: float | None = None
    batch: int | None = None
    batch_region: str | None = None
    reference: dict[str, float] | None = None
    task_ranges: dict[str, list[float]] | None = None
    history: list[dict[str, float]] | None = None
    achieved: dict[str, dict[str, float]] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CurriculumSummary:
        return cls(**{f.name: d[f.name] for f in fields(cls) if f.name in d})


class StepInfo(TypedDict, total=False):
    """The keys of a family env's per-step `info` (both envs; the rollout loop reads them)."""

    task: np.ndarray  # the episode's task parameters [d]
    fell: bool
    diverged: bool
    dphi: float  # reference time advanced this step ([L21]; 1.0 for [WL19])
    reward_spike: float  # the part of the reward paid at once (Eq. 5's spike)
    reward_terms: dict[str, float]
    stalled: bool  # [WL19] training rules: the episode ended by one of them
    off_course: bool
    deviated: bool
    skill: SkillOutcome  # [L21]: at the episode's end
