"""Measures: the task parameters of a skill family as quantities of a motion ([L21] §4.2, §7.1).

[L21]'s x_task (Eq. 8) "can be any measurement taken from the simulation": a kick's height, the
rotation of a spin, the torso's angular velocity in the air, the kinetic energy at take-off.
Each measure here is a small pure function of a `Trajectory` (one row per control step) that
both the simulated episode and the reference clip m0 fill, so that the hindsight parameter a′
of an episode (§5.1) and the nominal a0 of the clip are the same computation.

Rotation axes are the episode's heading frame at its first row: yaw about the world's vertical,
roll about the root's forward (local x) axis projected on the ground, pitch about the lateral
axis (vertical x forward, pointing left).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

AXES = ("yaw", "pitch", "roll")
CONTACT_HEIGHT = 0.03  # m: a foot this close to the ground touches it (m0's C_j, [L21] §5.1)


@dataclass(frozen=True)
class Trajectory:
    """A motion sampled at control steps; every array has T rows."""

    time: np.ndarray  # [T] s since the start
    phase: np.ndarray  # [T] reference time as a share of the clip, 0 at the start, 1 at its end
    com: np.ndarray  # [T, 3] world COM (m)
    root_rotation: np.ndarray  # [T, 3, 3] world-from-root rotation matrices
    end_effectors: dict[str, np.ndarray]  # name -> [T, 3] world positions (m)
    foot_height: np.ndarray  # [T, F] each foot's lowest point above the ground (m)
    kinetic_energy: np.ndarray  # [T] whole-body kinetic energy (J)
    mass: float  # kg
    contact_ref: np.ndarray | None = None  # [T, F] m0's foot contacts at each row's φ

    def __len__(self) -> int:
        return len(self.time)

    @property
    def airborne(self) -> np.ndarray:
        """[T] bool: no foot touches the ground."""
        return np.all(self.foot_height > CONTACT_HEIGHT, axis=1)

    def window(self, start: float, end: float) -> Trajectory:
        """The rows whose phase lies in [start, end] (the first row if none does)."""
        keep = (self.phase >= start) & (self.phase <= end)
        if not keep.any():
            keep = np.zeros(len(self), bool)
            keep[0] = True
        return Trajectory(
            self.time[keep],
            self.phase[keep],
            self.com[keep],
            self.root_rotation[keep],
            {k: v[keep] for k, v in self.end_effectors.items()},
            self.foot_height[keep],
            self.kinetic_energy[keep],
            self.mass,
            None if self.contact_ref is None else self.contact_ref[keep],
        )


def heading_axes(rotation: np.ndarray) -> dict[str, np.ndarray]:
    """The yaw, pitch, roll axes (world unit vectors) of a root rotation [3, 3]'s heading frame."""
    forward = np.array([rotation[0, 0], rotation[1, 0], 0.0])
    n = np.linalg.norm(forward)
    forward = forward / n if n > 1e-9 else np.array([1.0, 0.0, 0.0])
    up = np.array([0.0, 0.0, 1.0])
    return {"yaw": up, "roll": forward, "pitch": np.cross(up, forward)}


def rotation_steps(traj: Trajectory) -> np.ndarray:
    """[T-1, 3] world rotation vectors from each row's root rotation to the next's."""
    r = Rotation.from_matrix(traj.root_rotation)
    return (r[1:] * r[:-1].inv()).as_rotvec()


def root_rotation(traj: Trajectory, axis: str | None = None) -> float:
    """Total rotation (rad) of the root about a heading axis, |Σ_t Δθ_t · axis| (a backflip is
    2π about pitch, a spin n turns about yaw), or without an axis about the motion's own main
    axis, ‖Σ_t Δθ_t‖ (a cartwheel that turns its heading on the way)."""
    if len(traj) < 2:
        return 0.0
    total = rotation_steps(traj).sum(axis=0)
    if axis is None:
        return float(np.linalg.norm(total))
    return float(abs(total @ heading_axes(traj.root_rotation[0])[axis]))


def airborne_angular_velocity(traj: Trajectory, axis: str | None = None) -> float:
    """Average angular velocity (rad/s) of the torso (the root) while no foot touches the ground
    ([L21] §7.1, Backflip): |mean ω · axis| over airborne steps, or mean |ω| without an axis;
    0 if the motion never leaves the ground."""
    if len(traj) < 2:
        return 0.0
    omega = rotation_steps(traj) / np.diff(traj.time)[:, None]  # [T-1, 3]
    air = traj.airborne[1:] & traj.airborne[:-1]  # both ends of the step in the air
    if not air.any():
        return 0.0
    if axis is None:
        return float(np.linalg.norm(omega[air], axis=1).mean())
    a = heading_axes(traj.root_rotation[0])[axis]
    return float(abs((omega[air] @ a).mean()))


def com_rise(traj: Trajectory) -> float:
    """Peak rise (m) of the COM above its height at the first row (jump height, [L21] Eq. 8)."""
    return float(traj.com[:, 2].max() - traj.com[0, 2])


def peak_end_effector_height(traj: Trajectory, body: str) -> float:
    """Peak height (m) of an end effector above the ground (a kick's height)."""
    return float(traj.end_effectors[body][:, 2].max())


def com_distance(traj: Trajectory) -> float:
    """Horizontal distance (m) between the COM at the first and the last row."""
    return float(np.linalg.norm(traj.com[-1, :2] - traj.com[0, :2]))


def average_com_speed(traj: Trajectory) -> float:
    """Horizontal COM distance over elapsed time (m/s)."""
    elapsed = float(traj.time[-1] - traj.time[0])
    return com_distance(traj) / elapsed if elapsed > 0 else 0.0


def takeoff_kinetic_energy(traj: Trajectory) -> float:
    """Whole-body kinetic energy (J) at the first row in the air after a row on the ground (the
    onset of a jump, [L21] §7.1 Jump); 0 if the motion never takes off."""
    air = traj.airborne
    off = np.flatnonzero(air[1:] & ~air[:-1])
    return float(traj.kinetic_energy[off[0] + 1]) if len(off) else 0.0


def contact_match(traj: Trajectory) -> float:
    """Share of rows whose foot contacts (each foot on the ground or not) are m0's at the same
    reference time: 1 for m0 itself; the Jump family's foot-contact constraint ([L21] Table 1)."""
    if traj.contact_ref is None:
        return 1.0
    mine = traj.foot_height <= CONTACT_HEIGHT
    return float(np.all(mine == traj.contact_ref, axis=1).mean())


@dataclass(frozen=True)
class MeasureKind:
    fn: Callable[..., float]
    quantity: str  # the SI quantity of its value: what units it can be declared in
    needs: tuple[str, ...] = ()  # spec fields the measure reads: "axis", "body"
    optional: tuple[str, ...] = ()
    takeoff: bool = False  # its value is fixed at take-off (the natural event for a spike)


MEASURES: dict[str, MeasureKind] = {
    "com_rise": MeasureKind(com_rise, "length"),
    "root_rotation": MeasureKind(root_rotation, "angle", optional=("axis",)),
    "airborne_angular_velocity": MeasureKind(
        airborne_angular_velocity, "angular_velocity", optional=("axis",)
    ),
    "peak_end_effector_height": MeasureKind(peak_end_effector_height, "length", needs=("body",)),
    "com_distance": MeasureKind(com_distance, "length"),
    "average_com_speed": MeasureKind(average_com_speed, "speed"),
    "takeoff_kinetic_energy": MeasureKind(takeoff_kinetic_energy, "energy", takeoff=True),
    "contact_match": MeasureKind(contact_match, "fraction"),
}

# value in a unit = value in SI / factor; "reference": a multiple of the clip's own value
# ([L21] §7.1: "the unit of each task parameter is a multiple of that in the reference data")
UNITS: dict[str, dict[str, float]] = {
    "length": {"m": 1.0, "cm": 0.01},
    "angle": {"rad": 1.0, "deg": np.pi / 180, "turns": 2 * np.pi},
    "angular_velocity": {"rad/s": 1.0, "deg/s": np.pi / 180, "turns/s": 2 * np.pi},
    "speed": {"m/s": 1.0},
    "energy": {"J": 1.0, "J/kg": None},  # J/kg: divided by the body's mass
    "fraction": {"1": 1.0},
}
REFERENCE = "reference"


@dataclass(frozen=True)
class Measure:
    """One declared task parameter's measure: what it reads and in which unit it reports."""

    kind: str
    unit: str
    axis: str | None = None
    body: str | None = None
    window: tuple[float, float] = (0.0, 1.0)  # share of the clip the measure looks at

    def si(self, traj: Trajectory) -> float:
        """The measure's value in SI units on the rows of its window."""
        k = MEASURES[self.kind]
        args = {n: getattr(self, n) for n in (*k.needs, *k.optional)}
        if self.window != (0.0, 1.0):
            traj = traj.window(*self.window)
        return k.fn(traj, **args)

    def value(self, traj: Trajectory, reference_si: float | None = None) -> float:
        """The measure in its declared unit; `reference` needs m0's value (SI) on this body."""
        v = self.si(traj)
        if self.unit == REFERENCE:
            if not reference_si:
                return 0.0
            return v / reference_si
        factor = UNITS[MEASURES[self.kind].quantity][self.unit]
        return v / traj.mass if factor is None else v / factor


def default_unit(kind: str) -> str:
    """The SI unit a measure reports in when the config names none."""
    return next(iter(UNITS[MEASURES[kind].quantity]))
