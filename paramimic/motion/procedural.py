"""Procedural reference motions: sinusoidal keyframes authored in code ([WL19] §5.3).

Each joint follows q(φ) = c + a1·sin(2π(φ + p)) + a2·sin(4π(φ + p)), with φ in cycles. The
pose and its time derivative are evaluated for all joints at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.spatial.transform import Rotation

from paramimic.motion.clip import Clip

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

    def rest_pose(self) -> np.ndarray:
        """The mean pose of the cycle (the offsets): the posture a body stands or floats in."""
        return self.offset.copy()

    def pose(self, phi: float | np.ndarray) -> np.ndarray:
        """q(φ) [J], or [n, J] for n phases."""
        x = TWO_PI * (np.asarray(phi)[..., None] + self.phase)
        return self.offset + self.amp1 * np.sin(x) + self.amp2 * np.sin(2.0 * x)

    def velocity(self, phi: float | np.ndarray) -> np.ndarray:
        """dq/dt in rad/s when φ advances at 1/period cycles per second: [J] or [n, J]."""
        x = TWO_PI * (np.asarray(phi)[..., None] + self.phase)
        return (TWO_PI / self.period) * (self.amp1 * np.cos(x) + 2.0 * self.amp2 * np.cos(2.0 * x))


Rows = dict[str, tuple[float, float, float, float]]  # joint -> (offset, a1, a2, phase)


def alternating(rows: Rows, sides: tuple[str, str] = ("r", "l")) -> Rows:
    """The rows of a two-legged gait from one leg's: joint names hold `{side}`; the first side
    moves as given, the second half a cycle later."""
    return {
        name.format(side=side): (c, a1, a2, phase + 0.5 * k)
        for k, side in enumerate(sides)
        for name, (c, a1, a2, phase) in rows.items()
    }


def gait(joints: tuple[str, ...], period: float, rows: Rows) -> SinusoidalMotion:
    """A motion over all `joints` in their order (a character's actuated joints); joints
    without a row hold 0."""
    unknown = set(rows) - set(joints)
    if unknown:
        raise KeyError(f"gait rows for unknown joints {sorted(unknown)}")
    cols = np.array([rows.get(j, (0.0, 0.0, 0.0, 0.0)) for j in joints], dtype=np.float64).T
    return SinusoidalMotion(tuple(joints), period, *cols)


# --- planar jump clip ([L21] Jump at laptop scale) --------------------------------------------

GRAVITY = 9.81
JUMP_APEX = 0.12  # m the hip rises above its take-off height in the reference jump
JUMP_FPS = 60.0
# Keyframes (time s, torso pitch, hip, knee, ankle), both legs alike. Pitch and hip flexion are
# positive about -y (pitch > 0 leans back, hip > 0 swings the thigh forward); a foot is flat on
# the ground when pitch + hip + knee + ankle = 0.
_TAKE_OFF, _FLIGHT = 0.8, 2.0 * np.sqrt(2.0 * JUMP_APEX / GRAVITY)
_LAND = _TAKE_OFF + _FLIGHT
JUMP_KEYS = np.array(
    [
        (0.00, 0.00, 0.00, 0.00, 0.00),  # stand
        (0.20, -0.10, 0.25, -0.30, 0.15),
        (0.50, -0.50, 1.20, -1.40, 0.70),  # crouch
        (_TAKE_OFF, 0.00, 0.00, 0.00, -0.35),  # take-off: extended, on the toes
        (_TAKE_OFF + _FLIGHT / 2, -0.10, 0.50, -0.70, 0.10),  # apex: a slight tuck
        (_LAND, 0.00, 0.15, -0.20, 0.05),  # landing
        (_LAND + 0.25, -0.40, 1.00, -1.20, 0.60),  # absorb
        (_LAND + 0.70, 0.00, 0.00, 0.00, 0.00),  # stand
        (_LAND + 0.90, 0.00, 0.00, 0.00, 0.00),
    ]
)


def planar_jump_clip(
    joints: tuple[str, ...], thigh: float, shin: float, foot: float, apex: float = JUMP_APEX
):
    """A jump in place for a planar character whose joints are (hip, knee, ankle) per leg:
    crouch, take-off, a ballistic flight of `apex` m, landing and recovery, at 60 fps.

    Angles interpolate with monotone cubics between the keyframes; the root height keeps the
    flat feet on the ground in stance and follows the parabola of gravity in flight."""
    t = np.arange(0.0, JUMP_KEYS[-1, 0] + 1e-9, 1.0 / JUMP_FPS)
    angles = PchipInterpolator(JUMP_KEYS[:, 0], JUMP_KEYS[:, 1:], axis=0)(t)
    pitch, hip, knee, ankle = angles.T
    stance_z = foot + thigh * np.cos(pitch + hip) + shin * np.cos(pitch + hip + knee)
    z = stance_z.copy()
    take_off_z = np.interp(_TAKE_OFF, t, stance_z)
    v0 = np.sqrt(2.0 * GRAVITY * apex)
    flight = (t > _TAKE_OFF) & (t < _TAKE_OFF + 2.0 * v0 / GRAVITY)
    s = t[flight] - _TAKE_OFF
    z[flight] = take_off_z + v0 * s - 0.5 * GRAVITY * s**2
    legs = len(joints) // 3
    revolute = np.tile(np.stack([hip, knee, ankle], axis=1), (1, legs))
    n = len(t)
    durations = np.full(n, 1.0 / JUMP_FPS)
    durations[-1] = 0.0
    return Clip(
        name="planar_jump",
        durations=durations,
        root_position=np.stack([np.zeros(n), np.zeros(n), z], axis=1),
        root_quat=Rotation.from_rotvec(np.outer(pitch, PITCH_AXIS)).as_quat(),
        spherical_names=(),
        spherical=np.zeros((n, 0, 4)),
        revolute_names=tuple(joints),
        revolute=revolute,
        loop="none",
    )


PITCH_AXIS = np.array([0.0, -1.0, 0.0])  # planar root pitch axis (the characters' PLANAR_AXIS)
