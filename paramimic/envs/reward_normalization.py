"""Reward normalization of [WL19] §4.3, Table 1.

Goals and penalties tuned on the base character are rescaled by what a body can achieve
compared to the base: target speed by the mean leg length and the legs' asymmetry, the direction
error by the asymmetry, and the energy term by the mass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RewardScales:
    velocity: float  # multiplies the base target velocity v̄0
    direction: float  # multiplies ‖d − d′‖²_D
    energy: float  # multiplies Σ‖τ_i‖²_D

    @classmethod
    def identity(cls) -> RewardScales:
        return cls(1.0, 1.0, 1.0)


def reward_scales(
    legs: np.ndarray, base_legs: np.ndarray, mass: float, base_mass: float
) -> RewardScales:
    """[WL19] Table 1: with l_µ, l_σ the mean and standard deviation of the leg lengths and
    l⁰_µ the base's mean, velocity × (l_µ / l⁰_µ)·max(0.5, 1 − l_σ/l_µ), direction error ×
    max(0.5, 1 − l_σ/l_µ), energy × m₀/m. A body without legs (a swimmer) keeps velocity and
    direction as they are; only its energy term is scaled."""
    energy = base_mass / mass
    legs = np.asarray(legs, dtype=np.float64)
    if legs.size == 0:
        return RewardScales(1.0, 1.0, energy)
    mean = float(legs.mean())
    symmetry = max(0.5, 1.0 - float(legs.std()) / mean)  # l_σ: population std (1/N)
    base_mean = float(np.mean(base_legs))
    return RewardScales(mean / base_mean * symmetry, symmetry, energy)
