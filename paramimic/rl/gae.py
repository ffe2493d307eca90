"""Generalized advantage estimation with variable time steps ([L21] Eq. 9).

A transition that advances reference time by Δφ is discounted by γ^Δφ, and its GAE trace by
λ^Δφ. Continuous rewards are integrated over the step with the discount inside the integral;
spike rewards count at once:

    δ(φ) = ∫₀^Δφ γ^υ R_c dυ + R_s + γ^Δφ V(φ + Δφ) − V(φ)
    A(φ) = δ(φ) + γ^Δφ λ^Δφ A(φ + Δφ)

R_c is held constant over the step, and the integral is taken in the units in which a unit step
collects exactly R_c: ∫₀^Δφ γ^υ dυ / ∫₀^1 γ^υ dυ = (1 − γ^Δφ) / (1 − γ). Splitting a step in two
adds up to the same (time-warp invariance, [L21] Fig. 4), and with Δφ = 1 everything is
standard GAE.
"""

from __future__ import annotations

import numpy as np


def compute_gae(
    rewards: np.ndarray,
    spike_rewards: np.ndarray,
    values: np.ndarray,
    next_values: np.ndarray,
    terminated: np.ndarray,
    truncated: np.ndarray,
    dphi: np.ndarray,
    gamma: float,
    gae_lambda: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Advantages and value targets for a fragment of T steps of B environments.

    Args:
      rewards: [T, B] continuous reward of each step (its rate per unit of reference time).
      spike_rewards: [T, B] reward received at once at the end of each step.
      values: [T, B] V(s_t) under the policy that collected the data.
      next_values: [T, B] V(s_{t+1}) of the true next state: for a truncated step the value of
        its final observation (not of the reset state); ignored where terminated.
      terminated: [T, B] the episode ended in a terminal state (no bootstrap).
      truncated: [T, B] the episode was cut off (bootstrap from next_values, then stop the trace).
      dphi: [T, B] reference time Δφ advanced by each step (1 for a plain discrete step).
      gamma, gae_lambda: per unit of reference time.

    Returns:
      (advantages [T, B], returns [T, B]) with returns = advantages + values.
    """
    rewards = np.asarray(rewards, dtype=np.float64)
    terminated = np.asarray(terminated, dtype=bool)
    truncated = np.asarray(truncated, dtype=bool)
    dphi = np.asarray(dphi, dtype=np.float64)
    discount = np.power(gamma, dphi)  # γ^Δφ
    trace = discount * np.power(gae_lambda, dphi)  # γ^Δφ λ^Δφ
    integral = (1.0 - discount) / (1.0 - gamma)  # ∫₀^Δφ γ^υ dυ in unit-step units
    bootstrap = np.where(terminated, 0.0, next_values)
    deltas = integral * rewards + spike_rewards + discount * bootstrap - values
    carry = np.where(terminated | truncated, 0.0, trace)  # the trace stops at every episode end
    advantages = np.empty_like(deltas)
    last = np.zeros(deltas.shape[1:], dtype=np.float64)
    for t in range(deltas.shape[0] - 1, -1, -1):
        last = deltas[t] + carry[t] * last
        advantages[t] = last
    return advantages, advantages + values
