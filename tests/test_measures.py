"""The measure library worked out by hand on constructed trajectories — a body turning at
a known rate, a point rising to a known height, a body leaving the ground at a known instant."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paramimic.motion.measures import (
    Measure,
    Trajectory,
    airborne_angular_velocity,
    average_com_speed,
    com_distance,
    com_rise,
    contact_match,
    peak_end_effector_height,
    root_rotation,
    takeoff_kinetic_energy,
)

DT = 0.05
T = 21  # 1 s in 20 steps of 0.05 s


def _traj(
    rotation: Rotation | None = None,
    com: np.ndarray | None = None,
    feet: np.ndarray | None = None,
    energy: np.ndarray | None = None,
    ee: np.ndarray | None = None,
    contact_ref: np.ndarray | None = None,
    mass: float = 2.0,
) -> Trajectory:
    t = np.arange(T) * DT
    return Trajectory(
        time=t,
        phase=t / t[-1],
        com=np.zeros((T, 3)) if com is None else com,
        root_rotation=(Rotation.identity(T) if rotation is None else rotation).as_matrix(),
        end_effectors={"hand": np.zeros((T, 3)) if ee is None else ee},
        foot_height=np.zeros((T, 2)) if feet is None else feet,
        kinetic_energy=np.zeros(T) if energy is None else energy,
        mass=mass,
        contact_ref=contact_ref,
    )


def _spin(axis: np.ndarray, rate: float, start: Rotation | None = None) -> Rotation:
    """A root turning at `rate` rad/s about a world axis, from `start` (identity: facing +x)."""
    t = np.arange(T) * DT
    turn = Rotation.from_rotvec(np.outer(rate * t, axis))
    return turn * (start or Rotation.identity())


def test_root_rotation_about_each_heading_axis():
    # 2 rad/s for 1 s about the world's vertical: 2 rad of yaw, nothing about pitch or roll
    yaw = _traj(_spin(np.array([0.0, 0.0, 1.0]), 2.0))
    assert root_rotation(yaw, "yaw") == pytest.approx(2.0)
    assert root_rotation(yaw, "pitch") == pytest.approx(0.0, abs=1e-9)
    # a backflip: 2π/s for 1 s about the lateral axis (y, left of a body facing +x) is one turn,
    # a full 2π although the root ends where it started
    flip = _traj(_spin(np.array([0.0, 1.0, 0.0]), 2 * np.pi))
    assert root_rotation(flip, "pitch") == pytest.approx(2 * np.pi)
    assert root_rotation(flip) == pytest.approx(2 * np.pi)  # no axis: the main axis
    # the heading frame follows the body: facing +y (yaw 90°), a turn about world x is pitch
    facing_y = Rotation.from_euler("z", 90, degrees=True)
    side = _traj(_spin(np.array([1.0, 0.0, 0.0]), 1.5, start=facing_y))
    assert root_rotation(side, "pitch") == pytest.approx(1.5)
    assert root_rotation(side, "roll") == pytest.approx(0.0, abs=1e-9)


def test_angular_velocity_counts_airborne_steps_only():
    # 3 rad/s of pitch all along, feet off the ground (above 3 cm) in rows 5..14 only: 9 steps
    # with both ends in the air, each at 3 rad/s -> mean 3 rad/s
    feet = np.zeros((T, 2))
    feet[5:15] = 0.2
    traj = _traj(_spin(np.array([0.0, 1.0, 0.0]), 3.0), feet=feet)
    assert airborne_angular_velocity(traj, "pitch") == pytest.approx(3.0)
    assert airborne_angular_velocity(traj) == pytest.approx(3.0)
    assert airborne_angular_velocity(traj, "yaw") == pytest.approx(0.0, abs=1e-9)
    # never airborne: 0
    assert airborne_angular_velocity(_traj(_spin(np.array([0, 1.0, 0]), 3.0))) == 0.0


def test_heights_distances_and_speed():
    t = np.arange(T) * DT
    com = np.zeros((T, 3))
    com[:, 2] = 1.0 + 0.5 * np.sin(np.pi * t)  # rises 0.5 m at t = 0.5 s, back down at 1 s
    com[:, 0] = 3.0 * t  # 3 m forward
    com[:, 1] = 4.0 * t  # and 4 m to the side: 5 m in 1 s
    hand = np.zeros((T, 3))
    hand[:, 2] = 2.0 * t  # a hand rising linearly to 2 m
    traj = _traj(com=com, ee=hand)
    assert com_rise(traj) == pytest.approx(0.5)
    assert com_distance(traj) == pytest.approx(5.0)
    assert average_com_speed(traj) == pytest.approx(5.0)
    assert peak_end_effector_height(traj, "hand") == pytest.approx(2.0)
    # within the first half of the clip the hand reaches 1 m
    half = Measure("peak_end_effector_height", "m", body="hand", window=(0.0, 0.5))
    assert half.si(traj) == pytest.approx(1.0)


def test_takeoff_energy_and_contact_match():
    feet = np.zeros((T, 2))
    feet[8:] = 0.5  # both feet leave the ground at row 8
    energy = np.arange(T, dtype=float) * 10.0  # 10 J per row
    traj = _traj(feet=feet, energy=energy)
    assert takeoff_kinetic_energy(traj) == pytest.approx(80.0)
    assert takeoff_kinetic_energy(_traj(energy=energy)) == 0.0  # never leaves the ground
    # m0 says the feet leave at row 12: rows 8..11 disagree, 4 of 21
    ref = np.ones((T, 2), bool)
    ref[12:] = False
    assert contact_match(_traj(feet=feet, contact_ref=ref)) == pytest.approx(17 / 21)


def test_units_and_reference_multiples():
    flip = _traj(_spin(np.array([0.0, 1.0, 0.0]), 2 * np.pi))
    assert Measure("root_rotation", "turns", axis="pitch").value(flip) == pytest.approx(1.0)
    assert Measure("root_rotation", "deg", axis="pitch").value(flip) == pytest.approx(360.0)
    # reference: a multiple of m0's own value (here 4π on m0 -> half of it)
    ref = Measure("root_rotation", "reference", axis="pitch")
    assert ref.value(flip, reference_si=4 * np.pi) == pytest.approx(0.5)
    feet = np.zeros((T, 2))
    feet[8:] = 0.5
    jump = _traj(feet=feet, energy=np.full(T, 30.0), mass=2.0)
    assert Measure("takeoff_kinetic_energy", "J/kg").value(jump) == pytest.approx(15.0)
