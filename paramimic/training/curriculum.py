"""What the learner and the rollouts ask of a curriculum, as Protocols: the calls every
curriculum answers, and the capabilities only some have. The same interface is met in-process
(`paramimic.curriculum`'s classes) and over Ray (the services forward every call to the sampler
actor that owns the curriculum)."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from paramimic.messages import CurriculumSummary, EpisodeReport, TaskDeal
from paramimic.rl.numpy_mlp import Layers


class Curriculum(Protocol):
    """Deal tasks, take the episodes' reports and the learner's V̄, show and save its state."""

    def next_tasks(self, n: int) -> np.ndarray: ...

    def next_deal(self, n: int) -> TaskDeal: ...

    def ingest(self, episodes: list[EpisodeReport]) -> int: ...

    def update_marginal(self, layers: Layers, mu: float, iteration: int, refill: bool) -> None: ...

    def set_k(self, k: float) -> None: ...

    def summary(self) -> CurriculumSummary: ...

    def to_state(self) -> dict: ...

    def from_state(self, state: dict) -> None: ...


class WideningCurriculum(Curriculum, Protocol):
    """`curriculum.widen`: a task range grown from the base body when the policy masters it."""

    def edge_tasks(self, n: int, seed: int) -> np.ndarray | None: ...

    def judge_edge(self, episodes: int, falls: int) -> float: ...


class MotionCurriculum(Curriculum, Protocol):
    """[L21]: an elite set to fit P_θ on, and the learner's P_θ and bootstrap stage back."""

    def elite_data(self) -> tuple[np.ndarray, np.ndarray]: ...

    def update_motion(
        self, layers: Layers | None, version: int, loss: float | None, stage: str
    ) -> None: ...

    def performed_motions(self, tasks: np.ndarray) -> np.ndarray | None: ...
