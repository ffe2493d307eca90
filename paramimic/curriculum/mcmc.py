"""Adaptive sampling of task parameters by Metropolis-Hastings ([WL19] §4.2, Eq. 10, Alg. 1).

The target density is P̄(a) ∝ exp(−k (V̄(a) − μ) / μ): parameters the policy handles worse
than average are drawn more often. The proposal is uniform over the box (the parameters have
clear bounds), so the acceptance ratio is the surrogate ᾱ = P̄(a') / P̄(a). k = 0 is uniform.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from paramimic.task_space import TaskSpace

MarginalFn = Callable[[np.ndarray], np.ndarray]  # [n, d] -> V̄ [n]


def surrogate_log_density(v_bar: np.ndarray, mu: float, k: float) -> np.ndarray:
    """log P̄ = −k (V̄ − μ) / μ  ([WL19] Eq. 10). Requires μ > 0 (bell-shaped rewards)."""
    return -k * (np.asarray(v_bar) - mu) / mu


def concentration(v_bar: np.ndarray, mu: float, k: float, low: float = 0.1) -> dict[str, float]:
    """How narrowly P̄ ([WL19] Eq. 10) draws, from V̄ at points spread uniformly over the box:
    its effective sample share (Σw)² / (n Σw²) (1 for uniform draws, 1/n for a single point) and
    the share of its mass on the `low` fraction of points with the lowest V̄ (`low` if uniform)."""
    v_bar = np.asarray(v_bar, dtype=np.float64)
    log_w = surrogate_log_density(v_bar, mu, k) if k and mu and mu > 0 else np.zeros_like(v_bar)
    w = np.exp(log_w - log_w.max())
    lowest = v_bar <= np.quantile(v_bar, low)
    return {
        "effective_share": float(w.sum() ** 2 / (len(w) * (w**2).sum())),
        "low_mass": float(w[lowest].sum() / w.sum()),
    }


def metropolis_hastings(
    log_density: Callable[[np.ndarray], np.ndarray],
    space: TaskSpace,
    rng: np.random.Generator,
    n_samples: int,
    n_chains: int,
    burn_in: int,
) -> np.ndarray:
    """n_samples points from several independent chains with a uniform proposal: [n, d].

    Chains start uniformly, take `burn_in` steps, then each records one state per step until
    n_samples are collected (round-robin over chains).
    """
    x = space.sample(rng, n_chains)
    lp = log_density(x)
    steps = burn_in + -(-n_samples // n_chains)
    records = []
    for s in range(steps):
        proposal = space.sample(rng, n_chains)
        lp_new = log_density(proposal)
        accept = np.log(rng.random(n_chains)) < lp_new - lp  # ᾱ = P̄(a')/P̄(a)
        x = np.where(accept[:, None], proposal, x)
        lp = np.where(accept, lp_new, lp)
        if s >= burn_in:
            records.append(x.copy())
    return np.concatenate(records)[:n_samples]


class AdaptiveSampler:
    """The shape/task buffer S of Alg. 1: refilled by MCMC every P_MCMC iterations."""

    def __init__(
        self,
        space: TaskSpace,
        k: float,
        n_mcmc: int = 1000,
        chains: int = 16,
        burn_in: int = 20,
        seed: int = 0,
    ) -> None:
        self.space = space
        self.k = float(k)
        self.n_mcmc, self.chains, self.burn_in = n_mcmc, chains, burn_in
        self.rng = np.random.default_rng(seed)
        self.buffer = space.sample(self.rng, n_mcmc)  # before V̄ exists: uniform
        self.refills = 0
        self.adaptive = False  # whether the buffer came from MCMC (else uniform)

    def refill(self, marginal: MarginalFn | None, mu: float | None) -> None:
        """Alg. 1 l.3: S ← N_MCMC samples of P̄ given V̄ and μ (uniform when k = 0 or μ ≤ 0)."""
        self.refills += 1
        if self.k == 0 or marginal is None or mu is None or not mu > 0:
            self.buffer = self.space.sample(self.rng, self.n_mcmc)
            self.adaptive = False
            return
        k = self.k

        def log_density(a: np.ndarray) -> np.ndarray:
            return surrogate_log_density(marginal(a), mu, k)

        self.buffer = metropolis_hastings(
            log_density, self.space, self.rng, self.n_mcmc, self.chains, self.burn_in
        )
        self.adaptive = True

    def next_tasks(self, n: int) -> np.ndarray:
        """Alg. 1 l.7: n task parameters chosen from S: [n, d]."""
        return self.buffer[self.rng.integers(0, len(self.buffer), size=n)].copy()

    def to_state(self, with_buffer: bool = True) -> dict:
        state = {
            "k": self.k,
            "refills": self.refills,
            "adaptive": self.adaptive,
            "rng": self.rng.bit_generator.state,
        }
        if with_buffer:
            state["buffer"] = self.buffer.tolist()
        return state

    def from_state(self, state: dict) -> None:
        self.k = float(state["k"])
        self.buffer = np.asarray(state["buffer"], dtype=np.float64)
        self.refills = int(state["refills"])
        self.adaptive = bool(state["adaptive"])
        self.rng.bit_generator.state = state["rng"]
