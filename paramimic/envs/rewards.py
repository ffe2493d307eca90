"""The reward equations of both papers, one pure function each, on plain arrays.

[WL19] Eq. 4-7: every term is a bell exp(−‖x‖²_D / σ) with ‖x‖²_D = ‖x‖² / dim(x); the reward
is their weighted mean, so it lies in (0, 1]. [L21] Eq. 5-8: tracking bells exp(−‖x‖² / σ²)
mixed with fixed weights, and a task bell paid continuously or as a spike.
The environments gather the errors from the simulation and call these; the tests work them out
by hand.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

_XYZ = np.ones(3)  # sums the squared x, y, z of each end-effector error


class WL19Terms(NamedTuple):
    """The bells of one control step ([WL19] Eq. 5-7); `end_effector` has one per effector."""

    pose: float
    velocity: float
    end_effector: np.ndarray  # [n_ee]
    com_velocity: float
    direction: float
    torque: float


class WL19Weights(NamedTuple):
    """w1..w6 of Eq. 4 (w3 per end-effector), divided by their sum (see `wl19_weights`)."""

    pose: float
    velocity: float
    end_effector: float
    com_velocity: float
    direction: float
    torque: float


def wl19_imitation(
    q_err: np.ndarray,
    dq_err: np.ndarray,
    ee_err: np.ndarray,
    sigma_pose: float,
    sigma_velocity: float,
    sigma_end_effector: float,
) -> tuple[float, float, np.ndarray]:
    """[WL19] Eq. 5, R_imit: bells of the joint angle error q − q̂ [nj], the joint velocity error
    [nj] and each end-effector's position error [n_ee, 3] (root frame). Returns (pose,
    velocity, end-effectors [n_ee])."""
    nj = len(q_err)
    pose = math.exp(-q_err.dot(q_err) / (sigma_pose * nj))
    velocity = math.exp(-dq_err.dot(dq_err) / (sigma_velocity * nj))
    ee = np.exp((ee_err * ee_err).dot(_XYZ) * (-1.0 / (sigma_end_effector * 3)))
    return pose, velocity, ee


def wl19_task(
    com_velocity_err: tuple[float, float],
    direction_err: tuple[float, float],
    sigma_com_velocity: float,
    sigma_direction: float,
    direction_scale: float = 1.0,
) -> tuple[float, float]:
    """[WL19] Eq. 6, R_task: the bell of the average COM velocity against the target in the
    ground plane, v̄ − v′ [2], and of the facing direction against the target direction,
    d − d′ [2]; the direction error scaled by the body's leg symmetry ([WL19] Table 1)."""
    vx, vy = com_velocity_err
    ex, ey = direction_err
    com = math.exp(-(vx * vx + vy * vy) / (sigma_com_velocity * 2))
    direction = math.exp(-direction_scale * (ex * ex + ey * ey) / (sigma_direction * 2))
    return com, direction


def wl19_regularization(
    tau: np.ndarray, tau_limit: np.ndarray, sigma_torque: float, energy_scale: float = 1.0
) -> float:
    """[WL19] Eq. 7, R_reg: the bell of the joint torques relative to their limits [nj], the
    energy scaled by m₀/m for this body ([WL19] Table 1)."""
    x = tau / tau_limit
    return math.exp(-energy_scale * x.dot(x) / (sigma_torque * len(x)))


def wl19_weights(
    w_pose: float,
    w_velocity: float,
    w_end_effector: float,
    w_com_velocity: float,
    w_direction: float,
    w_torque: float,
    n_ee: int,
    imitation: bool = True,
) -> WL19Weights:
    """The weights of Eq. 4 divided by their sum (w3 counted once per end-effector) so that a
    step's reward lies in (0, 1]. Without a reference motion the imitation weights are 0."""
    k = 1.0 if imitation else 0.0
    w = (k * w_pose, k * w_velocity, k * w_end_effector, w_com_velocity, w_direction, w_torque)
    total = w[0] + w[1] + n_ee * w[2] + w[3] + w[4] + w[5]
    return WL19Weights(*(x / total for x in w))


def wl19_task_share(terms: WL19Terms, weights: WL19Weights) -> float:
    """The R_task part of Eq. 4: w4 r_com + w5 r_direction."""
    return weights.com_velocity * terms.com_velocity + weights.direction * terms.direction


def wl19_reward(terms: WL19Terms, weights: WL19Weights) -> float:
    """[WL19] Eq. 4: R = R_imit + R_task + R_reg as the weighted sum of the bells."""
    imit = weights.pose * terms.pose + weights.velocity * terms.velocity
    imit += weights.end_effector * float(terms.end_effector.sum())
    return imit + wl19_task_share(terms, weights) + weights.torque * terms.torque


def wl19_reward_product(terms: WL19Terms, weights: WL19Weights) -> float:
    """Eq. 4's bells multiplied instead of added: R = Π r_i over the terms whose weight is
    non-zero (every end-effector's bell a factor), in (0, 1]. The sum pays a step for whatever
    terms it meets (a body that stands still keeps the end-effector, direction and torque
    bells: about half of a walking step's reward on the walker), so that surviving pays almost
    as much as imitating; in the product a step is worth only as much as its worst term, as
    later imitation work combines them (e.g. Won, Gopinath and Hodgins 2020)."""
    r = 1.0
    for bell, w in zip(
        (terms.pose, terms.velocity, terms.com_velocity, terms.direction, terms.torque),
        (weights.pose, weights.velocity, weights.com_velocity, weights.direction, weights.torque),
        strict=True,
    ):
        if w > 0.0:
            r *= bell
    if weights.end_effector > 0.0:
        r *= float(np.prod(terms.end_effector))
    return r


def l21_tracking(
    q_err: np.ndarray,
    ee_err: np.ndarray,
    com_err: np.ndarray,
    time_err: float,
    sigma_q: float,
    sigma_ee: float,
    sigma_com: float,
    sigma_time: float,
) -> tuple[float, float, float, float]:
    """[L21] Eq. 7: r_q, r_ee, r_com, r_time, the bells exp(−‖x‖²/σ²) of the joint rotation
    error log(q̂⁻¹q) [nj] (hinges: angle differences), the end-effector error relative to the
    COM [n_ee, 3], the COM error [3], and the time-step error exp(τ) − exp(τ̂)."""
    return (
        math.exp(-float(q_err @ q_err) / sigma_q**2),
        math.exp(-float(np.sum(ee_err * ee_err)) / sigma_ee**2),
        math.exp(-float(com_err @ com_err) / sigma_com**2),
        math.exp(-(time_err * time_err) / sigma_time**2),
    )


def l21_tracking_reward(
    terms: tuple[float, float, float, float], w_q: float, w_ee: float, w_com: float, w_time: float
) -> float:
    """[L21] Eq. 6: r_tracking = w_q r_q + w_ee r_ee + w_com r_com + w_time r_time."""
    r_q, r_ee, r_com, r_time = terms
    return w_q * r_q + w_ee * r_ee + w_com * r_com + w_time * r_time


def l21_task(error: float, sigma_task: float) -> float:
    """[L21] Eq. 8: r_task = exp(−‖a_measured − a‖² / σ_task²) for one task parameter."""
    return math.exp(-(error * error) / sigma_task**2)


def l21_reward(r_tracking: float, r_task: float, w_tracking: float, w_task: float) -> float:
    """[L21] Eq. 5: r = w_tracking r_tracking + w_task r_task (§4.2: spike task rewards weigh
    (1.0, 10.0), continuous ones (0.9, 0.1))."""
    return w_tracking * r_tracking + w_task * r_task
