"""Fitness of an episode against the reference motion m0, [L21] §5.1 (Eq. 10).

F = f_pose · f_velocity · f_contact · f_drag + w_constraint · r_constraint, each factor
exp(−(1/σ²)(1/T) Σ_φ ...) over the T reference-time samples of the episode. The caller gives the
per-sample quantities measured on the episode and on m0 at the same φ (joint rotations and
velocities in body-local frames, end-effector heights, contact flags, end-effector xz motion).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# [L21] §5.1 constants
SIGMA_POSE = 2.67
SIGMA_VELOCITY = 75.5
SIGMA_CONTACT = 1.3
SIGMA_DRAG = 0.7
W_CONSTRAINT = 0.1
V_FLOOR = 0.5  # V: keeps the velocity denominators away from zero


@dataclass
class EpisodeTrace:
    """Per reference-time sample φ = 0..T-1 ([T, ...] arrays); `_ref` ones are m0's."""

    pose_error: np.ndarray  # [T, J] ‖log(q̄_i⁻¹ q_i)‖ per joint (rotation angle between them)
    velocity: np.ndarray  # [T, J, k] joint velocities (body-local)
    velocity_ref: np.ndarray  # [T, J, k]
    ee_height: np.ndarray  # [T, E] end-effector heights above the ground
    ee_height_ref: np.ndarray  # [T, E]
    contact_ref: np.ndarray  # [T, E] bool, C_j(φ) of m0
    ee_slide: np.ndarray  # [T, E] ‖T_j(φ)‖: end-effector translation in the ground plane


def fitness(trace: EpisodeTrace, r_constraint: float = 0.0) -> float:
    """F of Eq. 10."""
    T = len(trace.pose_error)
    f_pose = np.exp(-np.sum(np.square(trace.pose_error)) / T / SIGMA_POSE**2)
    dv2 = np.sum(np.square(trace.velocity - trace.velocity_ref), axis=-1)  # [T, J]
    # denominator max(V, ‖v̄‖²): the reference speed (the extracted text drops the bar)
    v2 = np.maximum(V_FLOOR, np.sum(np.square(trace.velocity_ref), axis=-1))
    f_velocity = np.exp(-np.sum(dv2 / v2) / T / SIGMA_VELOCITY**2)
    c = np.asarray(trace.contact_ref, np.float64)
    dy2 = np.square(trace.ee_height - trace.ee_height_ref)
    f_contact = np.exp(-np.sum(c * dy2) / T / SIGMA_CONTACT**2)
    held = c[1:] * c[:-1]  # C_j(φ) C_j(φ − 1): feet that should stay planted
    f_drag = np.exp(-np.sum(held * np.square(trace.ee_slide[1:])) / T / SIGMA_DRAG**2)
    return float(f_pose * f_velocity * f_contact * f_drag + W_CONSTRAINT * r_constraint)
