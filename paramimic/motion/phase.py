"""Start phases drawn where the policy fails: [WL19]'s idea of sampling what the controller does
badly (§4.3, V̄ over shapes), applied to the phase of a cyclic reference.

Reference state initialisation starts each episode at a phase of the reference cycle. Uniform
phases spend most episodes on the parts of the cycle the policy has mastered; this sampler keeps,
per phase bin, an exponential moving average of how often an episode started there failed (a
fall or a deviation before its time limit), smooths it over neighbouring bins (the cycle wraps),
and draws bins in proportion, with a uniform floor so that no phase is forgotten — the rule of
mjlab's motion-tracking command (failure counts per bin of the clip, EMA, a uniform share, a
small smoothing kernel), here per cycle of a looping gait, or over a one-shot clip's
reference state initialisation ([L21]'s π0).
"""

from __future__ import annotations

import numpy as np

KERNEL = (0.25, 0.5, 0.25)  # weights of the bin before, the bin, the bin after


class PhaseSampler:
    """`wrap`: the phase is a cycle's (a looping gait: the last bin borders the first); else a
    one-shot clip's, whose first and last bins border only their inner neighbour."""

    def __init__(
        self, bins: int = 10, alpha: float = 0.02, uniform: float = 0.1, wrap: bool = True
    ) -> None:
        if bins < 1 or not 0 < alpha <= 1 or not 0 <= uniform <= 1:
            raise ValueError(
                f"bins >= 1, alpha in (0, 1], uniform in [0, 1]: {bins, alpha, uniform}"
            )
        self.bins, self.alpha, self.uniform, self.wrap = bins, alpha, uniform, wrap
        self.failure = np.zeros(bins)  # EMA of the failure rate of episodes started in each bin

    def probabilities(self) -> np.ndarray:
        """p(bin) = (1 - u) s / Σs + u / bins, s the failure rates smoothed over the circle
        (over the line, each end its own outer neighbour, without `wrap`); uniform until
        something failed."""
        f = self.failure
        if self.wrap:
            before, after = np.roll(f, 1), np.roll(f, -1)
        else:
            before, after = np.r_[f[:1], f[:-1]], np.r_[f[1:], f[-1:]]
        smooth = KERNEL[0] * before + KERNEL[1] * f + KERNEL[2] * after
        total = smooth.sum()
        if total <= 0:
            return np.full(self.bins, 1.0 / self.bins)
        return (1.0 - self.uniform) * smooth / total + self.uniform / self.bins

    def sample(self, rng: np.random.Generator) -> float:
        """A start phase in [0, 1): a bin by `probabilities`, uniform within it."""
        b = rng.choice(self.bins, p=self.probabilities())
        return float((b + rng.random()) / self.bins)

    def update(self, phase: float, failed: bool) -> None:
        """An episode that started at `phase` (cycles) ended: failed, or reached its limit."""
        b = int((phase % 1.0) * self.bins) % self.bins
        self.failure[b] += self.alpha * (float(failed) - self.failure[b])
