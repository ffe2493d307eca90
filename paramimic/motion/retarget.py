"""A gait retargeted to a body whose legs differ from the base body's.

A symmetric reference gait asks every body for the same joint angles. On a body whose left and
right legs differ, those angles put the two feet at different heights under the hip: following
the reference, the body stands high on its long leg and drops onto its short one, and no
controller can both imitate and walk (the pose bell of the walker 0.8/1.2 is 0.06 under the
reference's own PD targets, against 0.39 for the base body). Retargeted, every leg follows the
base leg's hip-to-ankle path scaled by the body's *shortest* leg (the scale every leg can reach):
a long leg bends its knee more, and each foot keeps its angle to the torso (hip + knee +
ankle). On a body whose legs are all scaled alike the retargeted gait is the reference itself,
except where the reference overextends a knee beyond the side it bends to (the biped's knee
target reaches +0.1 rad against a range of -2.4-0): there the knee bends as far the other way
and the hip puts the ankle where the reference does.

Legs are hinge chains hip - knee - ankle in the sagittal plane whose angles add up (a leg
hanging straight at 0, the knee bending one way only); the ankle position relative to the hip
is T u(h) + S u(h + k) with u(θ) = (sin θ, -cos θ), thigh T, shin S. A planar character's legs
are such chains; a 3D character's are its hip pitch, knee and ankle pitch hinges (its hip roll
and yaw, and the ankle's roll, keep the reference's angles). A character's legs as chains:
`paramimic.characters.legs.leg_chains`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PHASE_STEP = 1e-4  # of a cycle: the central difference of the retargeted joint velocities


@dataclass(frozen=True)
class PlanarLeg:
    """One leg: the indices of its hip, knee and ankle in the gait's pose vector, the body's
    thigh and shin lengths and the base body's."""

    hip: int
    knee: int
    ankle: int
    thigh: float
    shin: float
    base_thigh: float
    base_shin: float
    knee_sign: float = -1.0  # the side the knee bends to (its joint range's sign)

    @property
    def scale(self) -> float:
        return (self.thigh + self.shin) / (self.base_thigh + self.base_shin)


def ankle_position(
    hip: np.ndarray, knee: np.ndarray, thigh: float, shin: float
) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics: the ankle's (x, z) relative to the hip."""
    x = thigh * np.sin(hip) + shin * np.sin(hip + knee)
    z = -thigh * np.cos(hip) - shin * np.cos(hip + knee)
    return x, z


def leg_ik(
    x: np.ndarray, z: np.ndarray, thigh: float, shin: float, knee_sign: float = -1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Hip and knee angles that put the ankle at (x, z) from the hip, the knee bent to the side
    of `knee_sign`; a point out of reach gets the straight leg pointing at it."""
    d2 = x * x + z * z
    cos_knee = np.clip((d2 - thigh * thigh - shin * shin) / (2.0 * thigh * shin), -1.0, 1.0)
    knee = knee_sign * np.arccos(cos_knee)
    along = np.arctan2(x, -z)  # the direction of the ankle from the hip, 0 straight down
    hip = along - np.arctan2(shin * np.sin(knee), thigh + shin * np.cos(knee))
    return hip, knee


def retarget_pose(pose: np.ndarray, legs: tuple[PlanarLeg, ...], scale: float) -> np.ndarray:
    """Each leg's base hip-to-ankle path scaled by `scale`, solved for this body's leg, the
    foot's angle (hip + knee + ankle) kept: pose [J] or [n, J] -> the same shape."""
    out = np.array(pose, dtype=float, copy=True)
    q = np.atleast_2d(out)
    for leg in legs:
        h, k, a = q[:, leg.hip], q[:, leg.knee], q[:, leg.ankle]
        x, z = ankle_position(h, k, leg.base_thigh, leg.base_shin)
        # the knee bends to the side it is built to, also where the reference overextends it
        h2, k2 = leg_ik(scale * x, scale * z, leg.thigh, leg.shin, leg.knee_sign)
        q[:, leg.ankle] = h + k + a - h2 - k2
        q[:, leg.hip], q[:, leg.knee] = h2, k2
    return out


class RetargetedGait:
    """A periodic reference motion (`pose`, `velocity`, `period`, `joints`) retargeted to a body
    by `retarget_pose` with the shortest leg's scale; velocities by central differences."""

    def __init__(self, motion, legs: tuple[PlanarLeg, ...]) -> None:
        self.motion = motion
        self.legs = legs
        self.scale = min(leg.scale for leg in legs)
        self.period = motion.period
        self.joints = motion.joints

    def pose(self, phi: float | np.ndarray) -> np.ndarray:
        return retarget_pose(self.motion.pose(phi), self.legs, self.scale)

    def velocity(self, phi: float | np.ndarray) -> np.ndarray:
        phi = np.asarray(phi, dtype=float)
        ahead, behind = self.pose(phi + PHASE_STEP), self.pose(phi - PHASE_STEP)
        return (ahead - behind) / (2.0 * PHASE_STEP * self.period)
