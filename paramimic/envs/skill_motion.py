"""The motion a skill episode imitates, tabulated on one body: m_a = m0 ⊕ d ([L21] Eq. 2) on the
reference grid (one row per control step of reference time φ), and the kinematics of qpos rows
that every table and measure of the skill env reads (one loop)."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from paramimic.characters import Body
from paramimic.envs.core import bodies_in_heading_frame
from paramimic.motion.parameterization import TAU_LIMIT, displace, displace_hinges


def at(table: np.ndarray, phi: float) -> np.ndarray:
    """A table's row at reference time φ, linearly between grid rows (held at both ends)."""
    x = min(max(phi, 0.0), len(table) - 1.000001)
    k = int(x)
    return table[k] + (x - k) * (table[k + 1] - table[k])


@dataclass(frozen=True)
class PoseTable:
    """Kinematics of qpos rows on a body, as the skill env's tables and measures read them."""

    ee: np.ndarray  # [n, E, 3] end-effector sites (world)
    com: np.ndarray  # [n, 3] the COM
    rot: np.ndarray  # [n, 3, 3] the root's orientation
    low: np.ndarray  # [n, F] each foot's lowest contact point (height)
    bodies: np.ndarray  # [n, B, 3] the bodies relative to the root, in its heading frame
    energy: np.ndarray  # [n] kinetic energy (with `times`; else zeros)


@dataclass(frozen=True)
class MotionTables:
    """m_a on the reference grid."""

    q: np.ndarray  # [K, nq] qpos
    ee: np.ndarray  # [K, E, 3] end-effectors relative to the COM
    com: np.ndarray  # [K, 3]
    tau: np.ndarray  # [K] τ̂, the time warp (clipped to ±TAU_LIMIT)
    bodies: np.ndarray  # [K, B, 3] bodies relative to the root, in its heading frame


class DisplacedMotion:
    """m0 on one body (`q0`, its qpos on the reference grid) and m0 ⊕ d for a motion trace d."""

    def __init__(
        self, model: mujoco.MjModel, scratch: mujoco.MjData, body: Body, q0: np.ndarray,
        root_nq: int,
    ) -> None:  # fmt: skip
        self.model, self.scratch, self.body, self.q0 = model, scratch, body, q0
        self.root_nq = root_nq
        self.root_nv = model.nv - len(body.qpos_idx)

    def kinematics(self, qpos: np.ndarray, times: np.ndarray | None = None) -> PoseTable:
        """Every row of `qpos` [n, nq] set on the scratch data. With `times` [n] (s), also the
        kinetic energy, from velocities by finite differences of neighbouring rows."""
        model, data, body = self.model, self.scratch, self.body
        n, root = len(qpos), body.root_body_id
        feet = body.contact_site_ids.reshape(len(body.definition.feet), 4)
        out = PoseTable(
            np.empty((n, len(body.ee_site_ids), 3)), np.empty((n, 3)), np.empty((n, 3, 3)),
            np.empty((n, len(feet))), np.empty((n, model.nbody - root - 1, 3)), np.zeros(n),
        )  # fmt: skip
        for i, row in enumerate(qpos):
            data.qpos[:] = row
            if times is not None:
                a, b = (i, i + 1) if i + 1 < n else (i - 1, i)
                mujoco.mj_differentiatePos(model, data.qvel, times[b] - times[a], qpos[a], qpos[b])
                mujoco.mj_forward(model, data)
                mujoco.mj_energyVel(model, data)
                out.energy[i] = data.energy[1]
            else:
                mujoco.mj_kinematics(model, data)
                mujoco.mj_comPos(model, data)
            out.ee[i] = data.site_xpos[body.ee_site_ids]
            out.com[i] = data.subtree_com[root]
            out.rot[i] = data.xmat[root].reshape(3, 3)
            out.low[i] = data.site_xpos[feet, 2].min(axis=1)
            out.bodies[i] = bodies_in_heading_frame(data.xpos, data.xmat, root)
        return out

    def displaced(self, d_root: np.ndarray, d_joints: np.ndarray) -> np.ndarray:
        """m0 ⊕ d (Eq. 2) on the grid's qpos rows: root position + d0, root rotation exp(d1),
        joints + d."""
        q0 = self.q0
        q = q0.copy()
        idx = self.body.qpos_idx
        q[:, idx] = displace_hinges(q0[:, idx], d_joints)
        if self.root_nq == self.root_nv:  # planar root: x, z and the pitch hinge add
            q[:, : self.root_nq] = displace_hinges(q0[:, : self.root_nq], d_root)
            return q
        rotations = Rotation.from_quat(q0[:, 3:7], scalar_first=True)
        q[:, :3], rotated = displace(q0[:, :3], rotations, d_root[:, :3], d_root[:, 3:])
        q[:, 3:7] = rotated.as_quat(scalar_first=True)
        return q

    def root_displacement(self, qpos: np.ndarray, q0: np.ndarray, x0: float) -> np.ndarray:
        """A simulated root relative to m0's at the same φ, the start x aligned: [root_nv]."""
        d = np.empty(self.root_nv)
        if self.root_nq == self.root_nv:
            d[:] = qpos[: self.root_nq] - q0[: self.root_nq]
            d[0] -= x0
            return d
        d[:3] = qpos[:3] - q0[:3]
        d[0] -= x0
        mujoco.mju_subQuat(d[3:], qpos[3:7], q0[3:7])
        return d

    def tables(self, trace: np.ndarray, bins: np.ndarray) -> MotionTables:
        """m_a for a motion trace [bins, root_nv + nj + 1] of (d_root, d_joints, τ) at the
        reference times `bins`, interpolated onto the grid."""
        nj = len(self.body.qpos_idx)
        shape = (len(bins), self.root_nv + nj + 1)
        if trace.shape != shape:
            raise ValueError(f"motion trace must have shape {shape}, got {trace.shape}")
        grid = np.arange(len(self.q0), dtype=np.float64)
        rows = np.stack([np.interp(grid, bins, trace[:, j]) for j in range(shape[1])], 1)
        rn = self.root_nv
        q = self.displaced(rows[:, :rn], rows[:, rn : rn + nj])
        poses = self.kinematics(q)
        return MotionTables(
            q, poses.ee - poses.com[:, None, :], poses.com,
            np.clip(rows[:, -1], -TAU_LIMIT, TAU_LIMIT), poses.bodies,
        )  # fmt: skip
