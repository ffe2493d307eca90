"""The bootstrap of [L21] §5.3 as a stage machine the learner advances once per iteration.

`base`: π0 tracks m0 at the reference parameter until its learning curve plateaus (the mean
return of the last `plateau_window` iterations grew by less than `plateau_tolerance` of the
window before; at least `base_min_iterations`, at most `base_max_iterations`);
`proxy`: the curriculum runs and m_a is the kNN proxy (Eq. 14) until P_θ's regression loss is
below `p_loss_threshold`; `mixed`: m_a is P_θ(a) or the proxy at random.
"""

from __future__ import annotations

import math

import numpy as np

from paramimic.config import SkillCurriculumConfig


class Bootstrap:
    def __init__(self, config: SkillCurriculumConfig) -> None:
        self.config = config
        self.stage = "base"
        self.returns: list[float] = []  # mean return per base-stage iteration
        self.switched_at: dict[str, int] = {}

    def observe(self, iteration: int, mean_return: float | None, p_loss: float | None) -> str:
        """Advance with one iteration's mean return and P_θ's latest loss; returns the stage."""
        c = self.config
        if self.stage == "base":
            if mean_return is not None and math.isfinite(mean_return):
                self.returns.append(float(mean_return))
            n, w = len(self.returns), c.plateau_window
            if n >= c.base_max_iterations or (
                n >= max(c.base_min_iterations, 2 * w) and self._plateau()
            ):
                self._switch("proxy", iteration)
        elif self.stage == "proxy" and p_loss is not None and p_loss < c.p_loss_threshold:
            self._switch("mixed", iteration)
        return self.stage

    def _plateau(self) -> bool:
        w = self.config.plateau_window
        last = float(np.mean(self.returns[-w:]))
        before = float(np.mean(self.returns[-2 * w : -w]))
        return last - before <= self.config.plateau_tolerance * abs(before)

    def _switch(self, stage: str, iteration: int) -> None:
        self.stage = stage
        self.switched_at[stage] = iteration

    def to_state(self) -> dict:
        return {"stage": self.stage, "returns": self.returns, "switched_at": self.switched_at}

    def from_state(self, state: dict) -> None:
        self.stage = state["stage"]
        self.returns = list(state["returns"])
        self.switched_at = dict(state["switched_at"])
