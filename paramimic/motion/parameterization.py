"""Motion parameterization of [L21] §3: displacement mapping m0 ⊕ d (Eq. 2) and the time warp
φ (Eq. 3). Rotations are scipy `Rotation`s (quaternions stored x, y, z, w)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

TAU_LIMIT = 3.0  # |τ| bound: a step advances the reference by 0.05x to 20x the sim step


def time_warp(tau: np.ndarray) -> np.ndarray:
    """φ_i = Σ_{0≤k≤i-1} exp(τ_k), φ_0 = 0 (Eq. 3): [T] -> [T+1], strictly increasing.

    τ is clipped to ±TAU_LIMIT, so that every increment stays representable next to φ (an
    exp(τ) of 1e-40 would vanish in floating point and stall the warp)."""
    tau = np.clip(np.asarray(tau, np.float64), -TAU_LIMIT, TAU_LIMIT)
    return np.concatenate([[0.0], np.cumsum(np.exp(tau))])


def warp_at(phi: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """φ(t) by linear interpolation of the samples φ_i at t = i (piecewise linear, monotone)."""
    steps = np.arange(len(phi), dtype=np.float64)
    return np.interp(t, steps, phi)


def displace(
    root_position: np.ndarray,
    rotations: Rotation,
    d_root: np.ndarray,
    d_rotations: np.ndarray,
) -> tuple[np.ndarray, Rotation]:
    """m0 ⊕ d = (p0 + d0, q1 exp(d1), ..., qL exp(dL)) (Eq. 2).

    root_position [3], rotations: L rotations (root first), d_root [3], d_rotations [L, 3]
    (rotation vectors, applied in each joint's local frame: q exp(d)).
    """
    d_rotations = np.asarray(d_rotations, np.float64).reshape(len(rotations), 3)
    return (
        np.asarray(root_position, np.float64) + d_root,
        rotations * Rotation.from_rotvec(d_rotations),
    )


def displace_hinges(angles: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Eq. 2 for 1-DOF hinge joints (planar characters): q exp(d) is angle + d."""
    return np.asarray(angles, np.float64) + d
