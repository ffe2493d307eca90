"""Visited regions of the task space and the phase switch of [L21] §6.

density(a) ∝ Σ_{a_k ∈ neighbour(a)} exp(−(a_k − a)ᵀA(a_k − a)) (Eq. 15) over the elite
parameters, here with A = I/h² on the box normalized to [0, 1] per free dimension, so that one
elite exactly at a gives density 1. The paper leaves the scale of A to the user; h (the kernel
bandwidth) is our default. Regions: visited A_h (density ≥ D = 0.8), surrounding A_s
(D' = 0.2 ≤ density < D) and unvisited; the explored ratio ER is the share of A in A_h.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from paramimic.task_space import TaskSpace

VISITED, SURROUNDING, UNVISITED = "visited", "surrounding", "unvisited"


class Density:
    """KDE over a fixed set of points (rebuild it when the elite set changes)."""

    def __init__(self, space: TaskSpace, points: np.ndarray, bandwidth: float = 0.1) -> None:
        self.space, self.h = space, bandwidth
        self.free = space.width > 0
        self.tree = cKDTree(self._normalized(np.asarray(points).reshape(-1, space.dim)))

    def _normalized(self, a: np.ndarray) -> np.ndarray:
        return self.space.normalize(a)[:, self.free]

    def __call__(self, a: np.ndarray) -> np.ndarray:
        """density at each row of a: [n]. Neighbours beyond 3h add < e⁻⁹ each and are skipped."""
        x = self._normalized(a)
        if self.tree.n == 0 or len(x) == 0:
            return np.zeros(len(x))
        pairs = cKDTree(x).sparse_distance_matrix(self.tree, 3.0 * self.h, output_type="ndarray")
        # Eq. 15: Σ exp(−‖a_k − a‖² / h²) over the neighbours of each query point
        weights = np.exp(-(pairs["v"] ** 2) / self.h**2)
        return np.bincount(pairs["i"], weights=weights, minlength=len(x))


def regions(density: np.ndarray, visited: float = 0.8, surrounding: float = 0.2) -> np.ndarray:
    """A_h where density ≥ D, A_s where D' ≤ density < D, else unvisited ([L21] §6.2)."""
    return np.where(
        density >= visited, VISITED, np.where(density >= surrounding, SURROUNDING, UNVISITED)
    )


def explored_ratio(density: Density, probe: np.ndarray, visited: float = 0.8) -> float:
    """ER: the share of the task space in A_h, estimated on fixed probe points."""
    return float(np.mean(density(probe) >= visited))


def sample_band(
    space: TaskSpace,
    density: Density,
    rng: np.random.Generator,
    n: int,
    low: float,
    high: float = np.inf,
    candidates: int = 4096,
    rounds: int = 8,
) -> np.ndarray:
    """Up to n points drawn uniformly from {a : low ≤ density(a) < high} by rejection from the
    box: [m, d] with m ≤ n (fewer, possibly none, if the band is too thin to hit).
    Exploration batches take (D', D): A_s; refinement restricts its MCMC to [D, ∞): A_h."""
    found: list[np.ndarray] = []
    for _ in range(rounds):
        x = space.sample(rng, candidates)
        rho = density(x)
        found.append(x[(rho >= low) & (rho < high)])
        if sum(len(f) for f in found) >= n:
            break
    return np.concatenate(found)[:n]


@dataclass
class PhaseSwitch:
    """When to explore and when to refine: the curricula of [L21] §7.3 beside ours.

    - `curriculum` (ours, §6.3): exploration until the exploration rate in A_s falls below the
      one in A_h, refinement until it rises above it again. Rates are smoothed over the
      occasional samples taken in each region (exponential moving average with `smoothing`).
    - `exploration_only`: exploration until ER reaches the config's `exploration_complete`,
      then refinement for good.
    - `mastering`: exploration ends as ours does; refinement ends once the skills of the
      visited region are mastered (the caller's test, on `progress`: the caller's measure of
      them at each policy update of the phase) — each phase ends at its timeout at the latest.
    - `alternating`: a fixed number of policy updates per phase.
    `started` is the policy update (the learner's iteration) at which the phase began."""

    phase: str = "exploration"
    rate_surrounding: float | None = None
    rate_visited: float | None = None
    smoothing: float = 0.5
    switches: int = 0
    rule: str = "curriculum"
    started: int = 0
    progress: list[float] = field(default_factory=list)

    def observe(self, region: str, rate: float, iteration: int = 0) -> str:
        """Record the exploration rate of a batch drawn in `region`; returns the phase."""
        if region == SURROUNDING:
            self.rate_surrounding = _ema(self.rate_surrounding, rate, self.smoothing)
        elif region == VISITED:
            self.rate_visited = _ema(self.rate_visited, rate, self.smoothing)
        else:
            raise ValueError(
                f"rates are measured in {VISITED!r} or {SURROUNDING!r}, not {region!r}"
            )
        s, h = self.rate_surrounding, self.rate_visited
        if s is None or h is None or self.rule not in ("curriculum", "mastering"):
            return self.phase
        explored = self.phase == "exploration" and s < h
        refined = self.phase == "refinement" and s > h and self.rule == "curriculum"
        if explored or refined:
            self.switch(iteration)
        return self.phase

    def tick(
        self,
        iteration: int,
        explored_ratio: float | None = None,
        mastered: bool = False,
        phase_updates: int = 20,
        timeout: int = 100,
        complete: float = 1.0,
    ) -> str:
        """The rules on the clock, on ER and on mastery, at policy update `iteration`."""
        age = iteration - self.started
        if self.rule == "alternating" and age >= phase_updates:
            self.switch(iteration)
        elif self.rule == "exploration_only":
            if self.phase == "exploration" and (explored_ratio or 0.0) >= complete:
                self.switch(iteration)
        elif self.rule == "mastering" and (
            age >= timeout or (self.phase == "refinement" and mastered)
        ):
            self.switch(iteration)
        return self.phase

    def switch(self, iteration: int) -> None:
        self.phase = "refinement" if self.phase == "exploration" else "exploration"
        self.switches += 1
        self.started = iteration
        self.progress = []


def _ema(old: float | None, new: float, smoothing: float) -> float:
    return new if old is None else smoothing * old + (1.0 - smoothing) * new
