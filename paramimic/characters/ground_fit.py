"""Ground-contact fitting of a new body ([WL19] Eq. 1).

q* = argmin_q Σ_i Σ_j ‖c_ij(q) − c̄_ij‖² + w_q ‖q − q0‖²: the contact points c_ij (the four
lower corners of each box foot) of the scaled character should land where the base character's
are, in a posture near q0. Only the root's height and the actuated joints move (the paper fixes
the other root DOFs). Points that touch the ground on the base stay exactly on it (equality
constraints), which SLSQP handles; the gradient comes from MuJoCo's site Jacobians. When the
optimizer fails the body is lifted (or lowered) vertically until its lowest point touches.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.linalg import qr
from scipy.optimize import minimize
from threadpoolctl import ThreadpoolController

# SLSQP and the QR run in scipy's BLAS, whose sums change in the last bit with its thread
# count; these problems are tiny, so one thread makes a fit identical in every process
# (the learner's and a Ray worker's, which runs with one).
_BLAS = ThreadpoolController()

W_Q = 0.01  # w_q: posture regularizer weight
ON_GROUND = 2e-3  # m: a base contact point this low is on the ground
TOLERANCE = 1e-3  # m: accepted violation of the ground constraints


@dataclass
class GroundFit:
    qpos: np.ndarray  # the fitted posture (full qpos)
    method: str  # "slsqp" or "lift"
    objective: float  # Eq. 1 at qpos


def lift_to_ground(model: mujoco.MjModel, data: mujoco.MjData, qpos, sites, height_adr: int):
    """qpos moved vertically so that the lowest of `sites` touches the ground (z = 0)."""
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    out = np.array(qpos, dtype=np.float64)
    out[height_adr] -= data.site_xpos[sites, 2].min()
    return out


class _Problem:
    """Eq. 1 over x = (root height, joint angles), evaluated once per x."""

    def __init__(self, model, data, q0, targets, sites, qadr, dofs, weight):
        self.model, self.data = model, data
        self.q0 = np.array(q0, dtype=np.float64)
        self.targets, self.sites, self.weight = targets, sites, weight
        self.qadr, self.dofs = qadr, dofs  # x -> qpos addresses and dof columns
        self.sites = [int(s) for s in sites]
        self.on_ground = np.flatnonzero(targets[:, 2] < ON_GROUND)
        self.off_ground = np.flatnonzero(targets[:, 2] >= ON_GROUND)
        self._key: bytes | None = None  # the x of the cached evaluation
        self._jac = np.zeros((len(sites), 3, model.nv))  # every site's full Jacobian
        self.on_ground = self._independent(self.on_ground)

    def _independent(self, points: np.ndarray) -> np.ndarray:
        """A subset of on-ground points whose height constraints are independent at q0 (the
        corners of a rigid flat sole are coplanar: three fix the fourth; a planar body's left
        and right corners coincide). SLSQP fails on redundant equality constraints."""
        if not len(points):
            return points
        self._eval(self.x0())
        rows = self.jac[points, 2, :]
        _, r, pivots = qr(rows.T, pivoting=True, mode="economic")
        diag = np.abs(np.diag(r))
        rank = int((diag > 1e-8 * max(diag.max(), 1e-12)).sum())
        return np.sort(points[pivots[:rank]])

    def x0(self) -> np.ndarray:
        return self.q0[self.qadr].copy()

    def qpos(self, x: np.ndarray) -> np.ndarray:
        q = self.q0.copy()
        q[self.qadr] = x
        return q

    def _eval(self, x: np.ndarray) -> None:
        key = np.asarray(x, np.float64).tobytes()
        if key == self._key:
            return
        m, d = self.model, self.data
        d.qpos[:] = self.qpos(x)
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        self.points = d.site_xpos[self.sites]  # [P, 3] (a copy: fancy indexing)
        for k, s in enumerate(self.sites):
            mujoco.mj_jacSite(m, d, self._jac[k], None, s)
        self.jac = self._jac[:, :, self.dofs]  # [P, 3, X]
        self._key = key

    def objective(self, x: np.ndarray) -> float:
        self._eval(x)
        r = self.points - self.targets
        dq = x[1:] - self.q0[self.qadr[1:]]  # the root height is not regularized
        return float((r * r).sum() + self.weight * dq @ dq)

    def gradient(self, x: np.ndarray) -> np.ndarray:
        self._eval(x)
        r = self.points - self.targets
        g = 2.0 * np.einsum("pc,pcx->x", r, self.jac)
        g[1:] += 2.0 * self.weight * (x[1:] - self.q0[self.qadr[1:]])
        return g

    def ground(self, x: np.ndarray) -> np.ndarray:
        self._eval(x)
        return self.points[self.on_ground, 2] - self.targets[self.on_ground, 2]

    def ground_jac(self, x: np.ndarray) -> np.ndarray:
        self._eval(x)
        return self.jac[self.on_ground, 2, :]

    def above(self, x: np.ndarray) -> np.ndarray:
        """Heights of the points the base has in the air: they must not go below the ground
        (the on-ground ones are equality constraints; repeating them makes SLSQP's
        linearized constraints incompatible)."""
        self._eval(x)
        return self.points[self.off_ground, 2]

    def above_jac(self, x: np.ndarray) -> np.ndarray:
        self._eval(x)
        return self.jac[self.off_ground, 2, :]


def fit_ground_contact(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    q0: np.ndarray,
    targets: np.ndarray,
    sites: np.ndarray,
    height_joint: int,
    joints: np.ndarray,
    weight: float = W_Q,
    maxiter: int = 50,
    max_change: float | None = None,
) -> GroundFit:
    """Solve Eq. 1 by SLSQP from q0; `targets` [P, 3] are the base's contact points c̄ for the
    contact `sites` [P]; `height_joint` is the root's vertical DOF (a slide, or a free joint
    whose third coordinate is the height), `joints` the actuated hinge joint ids. Falls back to
    `lift_to_ground` when SLSQP fails, leaves a ground point off by more than 1 mm, or moves a
    joint more than `max_change` rad from q0 (None: no limit)."""
    with _BLAS.limit(limits=1, user_api="blas"):
        return _fit(
            model, data, q0, targets, sites, height_joint, joints, weight, maxiter, max_change
        )


def _fit(
    model, data, q0, targets, sites, height_joint, joints, weight, maxiter, max_change
) -> GroundFit:
    targets = np.asarray(targets, dtype=np.float64)
    sites = np.asarray(sites)
    joints = np.asarray(joints)
    free = model.jnt_type[height_joint] == mujoco.mjtJoint.mjJNT_FREE
    height = model.jnt_qposadr[height_joint] + (2 if free else 0)  # a free joint's z
    qadr = np.array([height, *model.jnt_qposadr[joints]])
    dofs = np.array(
        [model.jnt_dofadr[height_joint] + (2 if free else 0), *model.jnt_dofadr[joints]]
    )
    problem = _Problem(model, data, q0, targets, sites, qadr, dofs, weight)
    # a joint's range bounds it only where the joint is limited (an unlimited hinge's range is
    # [0, 0]: the humanoid's ball joints, three hinges each)
    limited = model.jnt_limited[joints].astype(bool)
    ranges = model.jnt_range[joints]
    bounds = [(None, None), *[(lo, hi) if on else (None, None)
                              for (lo, hi), on in zip(ranges, limited, strict=True)]]  # fmt: skip
    x0 = np.clip(
        problem.x0(),
        [b[0] if b[0] is not None else -np.inf for b in bounds],
        [b[1] if b[1] is not None else np.inf for b in bounds],
    )
    constraints = []
    if len(problem.off_ground):
        constraints.append({"type": "ineq", "fun": problem.above, "jac": problem.above_jac})
    if len(problem.on_ground):
        constraints.append({"type": "eq", "fun": problem.ground, "jac": problem.ground_jac})
    try:
        res = minimize(
            problem.objective,
            x0,
            jac=problem.gradient,
            bounds=bounds,
            constraints=constraints,
            method="SLSQP",
            options={"maxiter": maxiter, "ftol": 1e-6},
        )
        x = res.x
        # A feasible iterate is kept even at the iteration limit: it touches the ground as the
        # base does, and is at least as close to Eq. 1's optimum as where it started.
        ok = res.status in (0, 9) and bool(np.all(np.isfinite(x)))
        if ok:
            problem._eval(x)
            z = problem.points[:, 2]
            ok = z.min() > -TOLERANCE and (
                not len(problem.on_ground) or np.abs(problem.ground(x)).max() < TOLERANCE
            )
            # a fit that bends the joints far from the pose is no longer the pose (a long-legged
            # humanoid reaching the base's swing-foot points crouches 17 cm)
            if max_change is not None:
                ok = ok and np.abs(x[1:] - problem.x0()[1:]).max() <= max_change
    except (ValueError, np.linalg.LinAlgError):
        ok = False
    if ok:
        return GroundFit(problem.qpos(x), "slsqp", problem.objective(x))
    lifted = lift_to_ground(model, data, q0, sites, height)
    return GroundFit(lifted, "lift", problem.objective(lifted[problem.qadr]))
