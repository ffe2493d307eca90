"""Procedural reference motions: sinusoidal keyframes authored in code ([WL19] §5.3).

Each joint follows q(φ) = c + a1·sin(2π(φ + p)) + a2·sin(4π(φ + p)), with φ in cycles. The
pose and its time derivative are evaluated for all joints at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from paramimic.characters.articulated import BIPED_LOWER, FISH, MANTA, QUADRUPED

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


def _gait(
    joints: tuple[str, ...], period: float, rows: dict[str, tuple[float, float, float, float]]
) -> SinusoidalMotion:
    """A motion over all `joints` in their order; joints without a row hold 0."""
    unknown = set(rows) - set(joints)
    if unknown:
        raise KeyError(f"gait rows for unknown joints {sorted(unknown)}")
    return _motion(period, {j: rows.get(j, (0.0, 0.0, 0.0, 0.0)) for j in joints})


def _joint_names(character) -> tuple[str, ...]:
    return tuple(j.name for j in character.joints)


# The lower-body biped walks like the planar walker: hip pitch, knee and ankle pitch per leg,
# with a little hip roll shifting the weight over the stance leg. The offsets (the mean pose)
# stand with slightly bent knees and flat feet (hip + knee + ankle = 0).
BIPED_LOWER_GAIT = _gait(
    _joint_names(BIPED_LOWER),
    1.0,
    {
        "hip_r_pitch": (0.10, 0.32, 0.00, 0.00),
        "knee_r": (-0.20, -0.30, 0.05, 0.25),
        "ankle_r_pitch": (0.10, 0.15, 0.00, -0.10),
        "hip_r_roll": (0.00, 0.04, 0.00, 0.25),
        "hip_l_pitch": (0.10, 0.32, 0.00, 0.50),
        "knee_l": (-0.20, -0.30, 0.05, 0.75),
        "ankle_l_pitch": (0.10, 0.15, 0.00, 0.40),
        "hip_l_roll": (0.00, 0.04, 0.00, 0.75),
    },
)


def _trot() -> SinusoidalMotion:
    """A trot: diagonal legs (front-right with hind-left) swing together, half a cycle apart."""
    rows = {}
    for side, phase in (("fr", 0.0), ("hl", 0.0), ("fl", 0.5), ("hr", 0.5)):
        rows[f"hip_{side}_pitch"] = (0.10, 0.30, 0.00, phase)
        rows[f"knee_{side}"] = (-0.20, -0.30, 0.00, phase + 0.25)
        rows[f"ankle_{side}_pitch"] = (0.10, 0.10, 0.00, phase - 0.10)
    return _gait(_joint_names(QUADRUPED), 0.6, rows)


QUADRUPED_GAIT = _trot()

# Carangiform swimming: a wave travels head to tail along the spine (yaw), its amplitude
# growing toward the tail ([WL19] §5.3: sinusoidal keyframes).
FISH_GAIT = _gait(
    _joint_names(FISH),
    1.0,
    {f"spine{i}_a": (0.0, 0.08 + 0.06 * i, 0.0, -0.15 * i) for i in range(1, 6)},
)

# Manta: the wings flap (roll, mirrored left and right) with a lag toward the tips and twist
# (pitch) a quarter cycle ahead, which turns the flap into thrust.
MANTA_GAIT = _gait(
    _joint_names(MANTA),
    1.5,
    {
        f"wing{i}_{side}_{dof}": (0.0, sign * amp, 0.0, lag - 0.1 * i)
        for i in range(3)
        for side, sign in (("l", 1.0), ("r", -1.0))
        for dof, amp, lag in (("a", 0.35, 0.0), ("b", 0.15 * sign, 0.25))
    },
)

REFERENCE_MOTIONS: dict[str, SinusoidalMotion] = {
    "walker": WALKER_GAIT,
    "hopper": HOPPER_GAIT,
    "biped_lower": BIPED_LOWER_GAIT,
    "quadruped": QUADRUPED_GAIT,
    "fish": FISH_GAIT,
    "manta": MANTA_GAIT,
}


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
    from scipy.interpolate import PchipInterpolator

    from paramimic.motion.clip import Clip

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
