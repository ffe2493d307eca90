"""Procedural reference motions: sinusoidal keyframes authored in code ([WL19] §5.3).

Each joint follows q(φ) = c + a1·sin(2π(φ + p)) + a2·sin(4π(φ + p)), with φ in cycles. The
pose and its time derivative are evaluated for all joints at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class SinusoidalMotion:
    """A periodic reference motion over named joints; `period` is seconds per cycle."""

    joints: tuple[str, ...]
    period: float
    offset: np.ndarray  # [J]
    amp1: np.ndarray  # [J] first harmonic
    amp2: np.ndarray  # [J] second harmonic
    phase: np.ndarray  # [J] phase shift in cycles

    def pose(self, phi: float) -> np.ndarray:
        x = TWO_PI * (phi + self.phase)
        return self.offset + self.amp1 * np.sin(x) + self.amp2 * np.sin(2.0 * x)

    def velocity(self, phi: float) -> np.ndarray:
        """dq/dt in rad/s when φ advances at 1/period cycles per second."""
        x = TWO_PI * (phi + self.phase)
        return (TWO_PI / self.period) * (self.amp1 * np.cos(x) + 2.0 * self.amp2 * np.cos(2.0 * x))


def _motion(period: float, rows: dict[str, tuple[float, float, float, float]]) -> SinusoidalMotion:
    names = tuple(rows)
    cols = np.array([rows[n] for n in names], dtype=np.float64).T
    return SinusoidalMotion(names, period, *cols)


# Walking at about 1 m/s: two steps of ~0.5 m per 1 s cycle. The right leg swings forward around
# φ = 0, the left half a cycle later. Hip flexion is positive forward, knees flex negative and
# bend most in mid-swing, ankles roll heel to toe.
WALKER_GAIT = _motion(
    1.0,
    {
        #            offset  a1     a2    phase
        "hip_r": (0.20, 0.32, 0.00, 0.00),
        "knee_r": (-0.45, -0.35, 0.05, 0.25),
        "ankle_r": (0.00, 0.15, 0.00, -0.10),
        "hip_l": (0.20, 0.32, 0.00, 0.50),
        "knee_l": (-0.45, -0.35, 0.05, 0.75),
        "ankle_l": (0.00, 0.15, 0.00, 0.40),
    },
)

# Hopping: crouch and extend twice a second, the leg swinging slightly forward in flight.
HOPPER_GAIT = _motion(
    0.5,
    {
        "hip": (0.35, 0.20, 0.00, 0.00),
        "knee": (-0.55, -0.35, 0.00, 0.25),
        "ankle": (0.15, 0.20, 0.00, 0.25),
    },
)

REFERENCE_MOTIONS: dict[str, SinusoidalMotion] = {"walker": WALKER_GAIT, "hopper": HOPPER_GAIT}
