"""A looping clip as a [WL19] reference gait: the humanoid's walk and run for ParamEnv.

[WL19] §3.2 imitates a cyclic reference gait under a locomotion task. For the planar characters
that gait is procedural (`procedural.SinusoidalMotion`); the humanoid has clips. A `ClipGait`
tabulates one cycle of a "wrap" clip on a body and answers what ParamEnv asks of a gait — the
joint pose and joint velocity at a phase φ in cycles — and what a free root needs besides: the
root's height, orientation and velocities at φ (reference state initialisation) and the root's
path over several cycles (root drift).

The clip is turned about the vertical so that it travels along +x (its heading then follows the
task's target direction), and a cycle's net turn is spread evenly over the cycle (the walk turns
0.12 rad per cycle; looped as recorded, the heading would jump at every cycle's end). Joint
velocities are central differences on the periodic table with angle differences wrapped, so a
joint's Euler angle crossing ±π is no velocity spike.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from paramimic.motion.clip import Clip, ClipPose

SAMPLES = 256  # table rows per cycle
IN_PLACE = 0.1  # m/s: a clip travelling slower is in place (it faces its first frame's way)


def _wrap(x: np.ndarray) -> np.ndarray:
    """Angles into [-π, π)."""
    return (x + np.pi) % (2.0 * np.pi) - np.pi


@dataclass(frozen=True)
class ClipGait:
    """One cycle of a looping clip on one body, with φ in cycles (0 = the clip's first frame)."""

    name: str
    joints: tuple[str, ...]
    period: float  # s per cycle
    speed: float  # m/s: the root's horizontal travel per cycle / period
    _q: np.ndarray  # [K+1, J] joint angles, unwrapped along φ
    _dq: np.ndarray  # [K+1, J] rad/s
    _root_z: np.ndarray  # [K+1]
    _root_quat: np.ndarray  # [K+1, 4] x, y, z, w; travel along +x, net turn removed
    _root_facing: np.ndarray  # [K+1, 2] the root's x axis on the ground (unit), travel frame
    _root_vel: np.ndarray  # [K+1, 3] world (travel frame), m/s
    _root_omega: np.ndarray  # [K+1, 3] local frame, rad/s (a free joint's qvel[3:6])
    _root_xy: np.ndarray  # [K+1, 2] in the travel frame, from the first frame's root
    _drift: np.ndarray  # [2]: the travel of one cycle

    @classmethod
    def from_clip(
        cls,
        clip: Clip,
        joints: tuple[str, ...],
        to_qpos: Callable[[ClipPose], np.ndarray],
        qpos_idx: np.ndarray,
        samples: int = SAMPLES,
    ) -> ClipGait:
        """Tabulate `clip` through `to_qpos` (clip poses -> qpos rows of a body with a free root:
        position, w-first quaternion, hinges) at `samples` phases per cycle."""
        if clip.loop != "wrap":
            raise ValueError(
                f"clip {clip.name!r} does not loop (its file says Loop {clip.loop!r}); a [WL19] "
                "reference gait must be cyclic: imitate it as an [L21] skill (env.clip) instead"
            )
        T = clip.duration
        h = 1.0 / samples
        phis = np.arange(samples + 1) * h
        qpos = to_qpos(clip.sample(phis * T))
        if qpos.shape[1] < 7:
            raise ValueError(f"clip gaits need a free root; qpos has {qpos.shape[1]} entries")
        rot = Rotation.from_quat(qpos[:, 3:7], scalar_first=True)
        drift = qpos[-1, :2] - qpos[0, :2]
        if np.hypot(*drift) < IN_PLACE * T:  # in place: its first frame's facing is forward
            travel = float(rot[0].as_euler("ZYX")[0])
        else:
            travel = float(np.arctan2(drift[1], drift[0]))
        # the root's orientation within the cycle: row K is the clip's own last frame (the
        # wrapped sample there is the next cycle's first); the cycle's net turn spread over it
        last = to_qpos(clip.sample(np.array([T * (1.0 - 1e-9)])))[0]
        rot = Rotation.concatenate([rot[:-1], Rotation.from_quat(last[3:7], scalar_first=True)])
        yaw = rot.as_euler("ZYX")[:, 0]
        turn = float(_wrap(np.array(yaw[-1] - yaw[0])))
        align = Rotation.from_euler("z", (-travel - turn * phis)[:, None])
        root_rot = align * rot
        root_xy = Rotation.from_euler("z", -travel).apply(
            np.column_stack([qpos[:, :2] - qpos[0, :2], np.zeros(len(phis))])
        )[:, :2]
        # joints: unwrapped along φ for interpolation; velocities by periodic central differences
        q = qpos[:, qpos_idx]
        q = np.unwrap(q, axis=0)
        core = q[:-1]  # K distinct rows (row K is row 0 of the next cycle)
        dq_core = _wrap(np.roll(core, -1, axis=0) - np.roll(core, 1, axis=0)) / (2.0 * h * T)
        dq = np.vstack([dq_core, dq_core[:1]])
        # root velocities: the root path differentiated (the wrap's drift keeps it continuous)
        ext = to_qpos(clip.sample(np.array([-h, 1.0 + h]) * T))
        xy = np.vstack([ext[:1, :2], qpos[:, :2], ext[1:, :2]])
        z = np.concatenate([ext[:1, 2], qpos[:, 2], ext[1:, 2]])
        rotate = Rotation.from_euler("z", -travel)
        lin = np.column_stack([(xy[2:] - xy[:-2]) / (2 * h * T), (z[2:] - z[:-2]) / (2 * h * T)])
        lin = rotate.apply(lin)
        # angular velocity in the root's own frame, of the aligned rotation (central differences,
        # row K is row 0 of the next cycle)
        ring = Rotation.concatenate([root_rot[-2:-1], root_rot, root_rot[1:2]])
        omega = (ring[:-2].inv() * ring[2:]).as_rotvec() / (2.0 * h * T)
        facing = root_rot.apply([1.0, 0.0, 0.0])[:, :2]
        facing /= np.maximum(np.hypot(facing[:, 0], facing[:, 1]), 1e-9)[:, None]
        names = tuple(joints)
        if len(names) != q.shape[1]:
            raise ValueError(f"{len(names)} joint names for {q.shape[1]} joint angles")
        return cls(
            name=clip.name,
            joints=names,
            period=T,
            speed=float(np.hypot(*drift) / T),
            _q=q,
            _dq=dq,
            _root_z=qpos[:, 2].copy(),
            _root_quat=root_rot.as_quat(),
            _root_facing=facing,
            _root_vel=lin,
            _root_omega=omega,
            _root_xy=root_xy,
            _drift=np.array([np.hypot(*drift), 0.0]),
        )

    # --- the gait interface of ParamEnv (φ in cycles) --------------------------------------------

    def _lookup(self, table: np.ndarray, phi: float | np.ndarray) -> np.ndarray:
        x = (np.asarray(phi, np.float64) % 1.0) * (len(table) - 1)
        k = np.minimum(x.astype(int), len(table) - 2)
        u = np.reshape(x - k, np.shape(x) + (1,) * (table.ndim - 1))
        return table[k] + u * (table[k + 1] - table[k])

    def pose(self, phi: float | np.ndarray) -> np.ndarray:
        """Joint angles (rad) at φ: [J] or [n, J]."""
        return _wrap(self._lookup(self._q, phi))

    def velocity(self, phi: float | np.ndarray) -> np.ndarray:
        """Joint velocities (rad/s) at φ: [J] or [n, J]."""
        return self._lookup(self._dq, phi)

    # --- the free root --------------------------------------------------------------------------

    def root_height(self, phi: float) -> float:
        return float(self._lookup(self._root_z, phi))

    def root_rotation(self, phi: float) -> Rotation:
        """The root's orientation at φ, travelling along +x (slerp between table rows)."""
        x = (phi % 1.0) * (len(self._root_quat) - 1)
        k = min(int(x), len(self._root_quat) - 2)
        a, b = self._root_quat[k], self._root_quat[k + 1]
        b = -b if a @ b < 0 else b
        q = a + (x - k) * (b - a)
        return Rotation.from_quat(q / np.linalg.norm(q))

    def root_facing(self, phi: float) -> tuple[float, float]:
        """The root's facing at φ (its x axis on the ground, unit length) in the travel frame:
        (1, 0) for a clip that faces where it travels; the cartwheel faces across its path."""
        fx, fy = self._lookup(self._root_facing, phi)
        norm = math.hypot(fx, fy) or 1.0
        return fx / norm, fy / norm

    def root_velocity(self, phi: float) -> tuple[np.ndarray, np.ndarray]:
        """(linear velocity in the travel frame [3], angular velocity in the root's frame [3])."""
        return self._lookup(self._root_vel, phi), self._lookup(self._root_omega, phi)

    def root_path(self, phi: float | np.ndarray) -> np.ndarray:
        """The root's horizontal position at φ (cycles, may exceed 1: it advances by one cycle's
        travel per cycle) in the travel frame, from the first frame's root: [2] or [n, 2]."""
        phi = np.asarray(phi, np.float64)
        cycles = np.floor(phi)
        local = self._lookup(self._root_xy, phi)
        if np.ndim(phi) == 0:
            return local + cycles * self._drift
        return local + cycles[:, None] * self._drift

    def root_qpos(self, phi: float | np.ndarray) -> np.ndarray:
        """The free root's qpos (x, y from `root_path`, z, w-first quaternion) at φ: [7] or
        [n, 7]."""
        phis = np.atleast_1d(np.asarray(phi, np.float64))
        out = np.empty((len(phis), 7))
        out[:, :2] = self.root_path(phis)
        out[:, 2] = self._lookup(self._root_z, phis)
        for i, p in enumerate(phis):
            out[i, 3:] = self.root_rotation(float(p)).as_quat(scalar_first=True)
        return out[0] if np.ndim(phi) == 0 else out
