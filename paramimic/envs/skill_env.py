"""SkillEnv: continuous-time imitation of one clip for a family of tasks ([L21] §3-5).

The motion to imitate is m_a = (m0 ⊕ d̂)(φ) with the time increments τ̂ of a *trace*
{(d̂, τ̂)} sampled at `trace_bins` reference times (Eq. 1-3); the caller passes it with the task
(`options={"task": a, "motion": trace}`); no trace means m_a = m0 (τ̂ = 0).
- action (d_t, τ_t): joint displacements and a log time increment; the reference advances by
  Δφ = exp(τ_t) control steps while the simulation advances by Δt, and the PD target is
  m0(φ') ⊕ d_t (§4.1);
- reward: r = w_tracking r_tracking + w_task r_task (Eq. 5), tracking = 0.28 r_q + 0.28 r_ee +
  0.28 r_com + 0.16 r_time (Eq. 6-7), continuous; the jump-height task reward (Eq. 8) is a spike
  paid when the clip ends. Every transition reports Δφ for variable time-step GAE (Eq. 9);
- when the episode ends it reports the trace it made (root displacement measured, joint
  displacements and τ as acted), the parameter a' it achieved (hindsight) and its fitness F
  (Eq. 10) against m0 (0 unless the clip was completed).
Reference time φ is counted in control steps (Δφ = 1 is real time).
"""

from __future__ import annotations

import copy
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from paramimic.characters import Body
from paramimic.config import ExperimentConfig
from paramimic.envs.core import EnvCore
from paramimic.envs.rewards import l21_reward, l21_task, l21_tracking, l21_tracking_reward
from paramimic.motion.fitness import EpisodeTrace, fitness
from paramimic.motion.parameterization import TAU_LIMIT, displace, displace_hinges

G = 9.81
CONTACT_HEIGHT = 0.03  # m: an end-effector of m0 this close to the ground is in contact (C_j)
SKILL_TERMS = ("q", "ee", "com", "time", "task")


def clip_setup(cfg: ExperimentConfig) -> dict:
    """What the [L21] curriculum needs to know of an experiment's clip without building an env:
    {"trace_shape": (bins, D), "reference": a0 as a list}."""
    return SkillEnv(cfg.character, cfg.task, cfg.env).clip_setup()


class SkillEnv(EnvCore):
    GOALS = frozenset({"gravity", "jump_height"})

    def _setup(self) -> None:
        if self.config.clip is None:
            raise ValueError("SkillEnv needs env.clip")
        self.skill = self.config.skill
        self._gravity_idx = self.goal_index("gravity")
        self._height_idx = self.goal_index("jump_height")
        self.clip = self.registration.load_clip(self.config.clip)  # a name or a clip file
        base = self._base
        self.nj = len(base.qpos_idx)
        self.root_nq = base.model.nq - self.nj  # 3 (planar x, z, pitch) or 7 (free joint)
        self.root_nv = base.model.nv - self.nj
        self._base_hip_height = base.hip_height
        self._trace = None
        self._load(self.task_space.center)
        self.dt = self.model.opt.timestep * self.frame_skip
        # reference grid: one row per control step of reference time, φ = 0..n_ref-1
        self.length = self.clip.duration / self.dt  # φ at which the clip ends
        self.trace_dim = self.root_nv + self.nj + 1  # (d_root, d_joints, τ) per bin
        self.trace_shape = (self.skill.trace_bins, self.trace_dim)
        self._bins = (np.arange(self.skill.trace_bins) + 0.5) * self.length / self.skill.trace_bins
        self._max_steps = int(np.ceil(self.length * np.exp(TAU_LIMIT))) + 1
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.nj + 1,), np.float32)
        self._task = self.task_space.center.copy()
        self.reset(seed=0)
        obs = self._observe()
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, obs.shape, np.float32)
        w = self.skill
        spike = self._height_idx is not None
        self._w_tracking = w.w_tracking_spike if spike else 1.0  # §4.2: 1.0 without a task
        self._w_task = w.w_task_spike if spike else 0.0

    # --- body and reference ------------------------------------------------------------------

    def _bind(self, c: Body) -> None:
        self.model = copy.copy(c.model)  # own copy: gravity changes per episode
        self.data = mujoco.MjData(self.model)
        self._scratch = mujoco.MjData(self.model)
        self._index_fall_geoms()
        dt = self.model.opt.timestep * self.frame_skip
        phis = np.arange(int(np.ceil(self.clip.duration / dt)) + 2) * dt
        pose = self.clip.sample(phis)
        if self.root_nq == self.root_nv:  # planar: the clip is for the base body; feet down
            pose.root_position[:, 2] += c.hip_height - self._base_hip_height
        self._q0 = self.definition.pose_qpos(c, pose)  # m0 on the grid [n_ref, nq]
        ee0, com0, low0 = self._kinematics(self._q0)
        self._feet = np.array(
            [list(c.definition.end_effectors).index(f) for f in c.definition.feet]
        )
        self._ee_height0 = ee0[:, self._feet, 2]  # m0 end-effector heights (world) for F
        self._contact0 = low0 < CONTACT_HEIGHT  # C_j of m0: foot near the ground
        self._standing_com = com0[0, 2]
        self._m0_rise = float(com0[:, 2].max() - com0[0, 2])

    def _kinematics(self, qpos: np.ndarray):
        """World end-effectors [n, E, 3], COM [n, 3] and each foot's lowest point [n, F]."""
        m, d, c = self.model, self._scratch, self.character
        ee = np.empty((len(qpos), len(c.ee_site_ids), 3))
        com = np.empty((len(qpos), 3))
        feet = c.contact_site_ids.reshape(len(c.definition.feet), 4)
        low = np.empty((len(qpos), len(feet)))
        for i, row in enumerate(qpos):
            d.qpos[:] = row
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            ee[i] = d.site_xpos[c.ee_site_ids]
            com[i] = d.subtree_com[c.root_body_id]
            low[i] = d.site_xpos[feet, 2].min(axis=1)
        return ee, com, low

    def _displaced(self, q0: np.ndarray, d_root: np.ndarray, d_joints: np.ndarray) -> np.ndarray:
        """m0 ⊕ d (Eq. 2) on qpos rows: root position + d0, root rotation exp(d1), joints + d."""
        q = q0.copy()
        idx = self.character.qpos_idx
        q[:, idx] = displace_hinges(q0[:, idx], d_joints)
        if self.root_nq == self.root_nv:  # planar root: x, z and the pitch hinge add
            q[:, : self.root_nq] = displace_hinges(q0[:, : self.root_nq], d_root)
            return q
        rotations = Rotation.from_quat(q0[:, 3:7], scalar_first=True)
        q[:, :3], rotated = displace(q0[:, :3], rotations, d_root[:, :3], d_root[:, 3:])
        q[:, 3:7] = rotated.as_quat(scalar_first=True)
        return q

    def _root_displacement(self, qpos: np.ndarray, q0: np.ndarray, x0: float) -> np.ndarray:
        """The simulated root relative to m0's, the start x aligned: [root_nv]."""
        d = np.empty(self.root_nv)
        if self.root_nq == self.root_nv:
            d[:] = qpos[: self.root_nq] - q0[: self.root_nq]
            d[0] -= x0
            return d
        d[:3] = qpos[:3] - q0[:3]
        d[0] -= x0
        mujoco.mju_subQuat(d[3:], qpos[3:7], q0[3:7])
        return d

    def _set_motion(self, trace: np.ndarray | None) -> None:
        """Tabulate m_a on the reference grid: pose, end-effectors relative to the COM, COM, τ̂."""
        grid = np.arange(len(self._q0), dtype=np.float64)
        if trace is None:
            trace = np.zeros(self.trace_shape)
        trace = np.asarray(trace, np.float64)
        if trace.shape != self.trace_shape:
            raise ValueError(f"motion trace must have shape {self.trace_shape}, got {trace.shape}")
        rows = np.stack(
            [np.interp(grid, self._bins, trace[:, j]) for j in range(self.trace_dim)], 1
        )
        rn, nj = self.root_nv, self.nj
        qa = self._displaced(self._q0, rows[:, :rn], rows[:, rn : rn + nj])
        ee, com, _ = self._kinematics(qa)
        self._qa = qa
        self._eea = ee - com[:, None, :]  # end-effectors relative to the COM
        self._coma = com
        self._tau_hat = np.clip(rows[:, -1], -TAU_LIMIT, TAU_LIMIT)

    def _at(self, table: np.ndarray, phi: float) -> np.ndarray:
        x = min(max(phi, 0.0), len(table) - 1.000001)
        k = int(x)
        return table[k] + (x - k) * (table[k + 1] - table[k])

    # --- episode ------------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = options or {}
        self._task = a = self.task_from_options(options)
        self._load(a)
        self._set_gravity()
        self._trace = options.get("motion")
        self._set_motion(self._trace)
        m, d, c = self.model, self.data, self.character
        mujoco.mj_resetData(m, d)
        noise = self.config.init_noise
        d.qpos[:] = self._qa[0]
        d.qpos[c.qpos_idx] += noise * self.np_random.standard_normal(self.nj)
        d.qvel[:] = 0.0
        mujoco.mj_kinematics(m, d)
        lowest = d.site_xpos[c.contact_site_ids, 2].min()
        d.qpos[1 if self.root_nq == self.root_nv else 2] -= (
            lowest - 1e-3
        )  # the lowest foot on the ground
        d.ctrl[:] = np.clip(d.qpos[c.qpos_idx], c.ctrl_low, c.ctrl_high)
        mujoco.mj_forward(m, d)
        self._phi = 0.0
        self._steps = 0
        self._x0 = float(d.qpos[0])
        self._watch_stability()
        self._peak_com = float(d.subtree_com[c.root_body_id, 2])
        self._rec: dict[str, list] = {k: [] for k in ("phi", "d", "pose", "vel", "ee", "slide")}
        self._feet_xy = d.site_xpos[c.ee_site_ids[self._feet]][:, :2].copy()
        self._prev_q = d.qpos[c.qpos_idx].copy()
        obs = self._observe()
        self._last_obs = obs
        return obs, {"task": a.copy()}

    def step(self, action: np.ndarray):
        m, d, c = self.model, self.data, self.character
        action = np.clip(np.asarray(action, np.float64), -1.0, 1.0)
        d_joints = action[: self.nj] * self.config.action_scale
        tau = float(action[self.nj]) * self.skill.tau_scale
        dphi = float(np.exp(tau))
        phi_next = self._phi + dphi
        # PD target m0(φ') ⊕ d_t (§4.1); the servo clamps it to the joint's control range
        d.ctrl[:] = self._at(self._q0, phi_next)[c.qpos_idx] + d_joints
        mujoco.mj_step(m, d, nstep=self.frame_skip)
        self._steps += 1
        self._phi = phi_next
        if self.diverging():
            return self._end(self._last_obs, 0.0, 0.0, dphi, terminated=True, diverged=True)
        com = d.subtree_com[c.root_body_id]
        self._peak_com = max(self._peak_com, float(com[2]))
        self._record(phi_next, d_joints, tau)
        s = self.skill
        terms = list(self._tracking(phi_next, tau))
        r_track = l21_tracking_reward(terms, s.w_q, s.w_ee, s.w_com, s.w_time)  # Eq. 6
        reward = l21_reward(r_track, 0.0, self._w_tracking, self._w_task)  # Eq. 5, continuous
        obs = self._observe()
        self._last_obs = obs
        fell = self.fall_contact()
        completed = phi_next >= self.length and not fell
        if fell or completed or self._steps >= self._max_steps:
            spike = 0.0
            if completed and self._height_idx is not None:
                # Eq. 8, a spike paid when the clip (the duration of the jump) ends
                r_task = l21_task(self.jump_height() - self._task[self._height_idx], s.sigma_task)
                spike = l21_reward(0.0, r_task, self._w_tracking, self._w_task)
                terms.append(r_task)
            return self._end(
                obs,
                reward + spike,
                spike,
                dphi,
                terminated=fell or completed,
                terms=terms,
                fell=fell,
                completed=completed,
            )
        terms.append(0.0)
        info = self._info(dphi, 0.0, terms, fell=False)
        return obs, reward, False, False, info

    def _tracking(self, phi: float, tau: float) -> tuple[float, float, float, float]:
        """r_q, r_ee, r_com, r_time of Eq. 7 against m_a at φ."""
        c, d, s = self.character, self.data, self.skill
        qa = self._at(self._qa, phi)
        dq = d.qpos[c.qpos_idx] - qa[c.qpos_idx]  # hinges: log(q̂⁻¹q) is the angle difference
        com = d.subtree_com[c.root_body_id]
        ee = d.site_xpos[c.ee_site_ids] - com
        com_hat = self._at(self._coma, phi).copy()
        com_hat[0] += self._x0
        dt_hat = float(np.exp(self._at(self._tau_hat, phi)))
        return l21_tracking(
            dq,
            ee - self._at(self._eea, phi),
            com - com_hat,
            float(np.exp(tau)) - dt_hat,
            s.sigma_q,
            s.sigma_ee,
            s.sigma_com,
            s.sigma_time,
        )

    def _record(self, phi: float, d_joints: np.ndarray, tau: float) -> None:
        """Per-step samples for the trace and the fitness against m0 at φ."""
        c, d = self.character, self.data
        q0 = self._at(self._q0, phi)
        rec = self._rec
        rec["phi"].append(phi)
        rec["d"].append(
            np.concatenate([self._root_displacement(d.qpos, q0, self._x0), d_joints, [tau]])
        )
        q = d.qpos[c.qpos_idx]
        rec["pose"].append(q - q0[c.qpos_idx])
        dq0 = (self._at(self._q0, phi + 0.5) - self._at(self._q0, phi - 0.5))[c.qpos_idx]
        rec["vel"].append(np.stack([(q - self._prev_q) / self.dt, dq0 / self.dt], axis=0))
        self._prev_q = q.copy()
        feet = c.contact_site_ids.reshape(len(c.definition.feet), 4)
        rec["ee"].append(d.site_xpos[feet, 2].min(axis=1))
        xy = d.site_xpos[c.ee_site_ids[self._feet]][:, :2]
        rec["slide"].append(np.linalg.norm(xy - self._feet_xy, axis=1))
        self._feet_xy = xy.copy()

    def reference_task(self) -> np.ndarray:
        """a0, the parameter of m0 itself: gravity 1, body scales 1 and the clip's own jump
        height (the COM rise of m0 on the current body), clipped into the task space."""
        a = np.ones(self.task_space.dim)
        if self._height_idx is not None:
            a[self._height_idx] = self._m0_rise
        return np.clip(a, self.task_space.low, self.task_space.high)

    def clip_setup(self) -> dict:
        """{"trace_shape": (bins, D), "reference": a0 as a list}: see `clip_setup`."""
        return {"trace_shape": self.trace_shape, "reference": self.reference_task().tolist()}

    def jump_height(self) -> float:
        """Peak rise of the COM above its standing height so far in this episode."""
        return self._peak_com - self._standing_com

    def _end(
        self,
        obs,
        reward,
        spike,
        dphi,
        terminated,
        terms=None,
        fell=False,
        completed=False,
        diverged=False,
    ):
        terms = terms if terms is not None else [0.0] * len(SKILL_TERMS)
        if len(terms) < len(SKILL_TERMS):
            terms = terms + [0.0]
        info = self._info(dphi, spike, terms, fell=fell, diverged=diverged)
        info["skill"] = self._summary(completed and not diverged)
        truncated = not terminated
        return obs, reward, terminated, truncated, info

    def _info(self, dphi, spike, terms, fell, diverged=False) -> dict:
        return {
            "task": self._task.copy(),
            "fell": fell,
            "diverged": diverged,
            "dphi": dphi,
            "reward_spike": spike,
            "reward_terms": dict(zip(SKILL_TERMS, terms, strict=True)),
        }

    def _summary(self, completed: bool) -> dict:
        """Hindsight parameter a', fitness F (Eq. 10) and the trace of this episode."""
        achieved = self._task.copy()
        if self._height_idx is not None:
            achieved[self._height_idx] = self.jump_height()
        achieved = np.clip(achieved, self.task_space.low, self.task_space.high)
        rec = self._rec
        if not completed or len(rec["phi"]) < 2:
            return {"achieved": achieved, "fitness": 0.0, "trace": None, "completed": False}
        phi = np.asarray(rec["phi"])
        d = np.asarray(rec["d"])
        trace = np.stack([np.interp(self._bins, phi, d[:, j]) for j in range(d.shape[1])], 1)
        vel = np.asarray(rec["vel"])  # [T, 2, J]
        ee0 = np.stack(
            [np.interp(phi, np.arange(len(self._ee_height0)), h) for h in self._ee_height0.T], 1
        )
        c0 = np.stack(
            [
                np.interp(phi, np.arange(len(self._contact0)), f.astype(float)) > 0.5
                for f in self._contact0.T
            ],
            1,
        )
        # Eq. 10: a zero-range parameter is a constraint the episode should meet
        r_constraint = 0.0
        h = self._height_idx
        if h is not None and self.task_space.width[h] == 0:
            err = self.jump_height() - self._task[h]
            r_constraint = float(np.exp(-(err**2) / self.skill.sigma_task**2))
        f = fitness(
            EpisodeTrace(
                pose_error=np.abs(np.asarray(rec["pose"])),
                velocity=vel[:, 0, :, None],
                velocity_ref=vel[:, 1, :, None],
                ee_height=np.asarray(rec["ee"]),
                ee_height_ref=ee0,
                contact_ref=c0,
                ee_slide=np.asarray(rec["slide"]),
            ),
            r_constraint,
        )
        return {"achieved": achieved, "fitness": f, "trace": trace, "completed": True}

    def _observe(self) -> np.ndarray:
        c, d = self.character, self.data
        phi = self._phi
        root = c.root_body_id
        xmat = d.xmat[root].reshape(3, 3)
        com = d.subtree_com[root]
        ee = (d.site_xpos[c.ee_site_ids] - d.xpos[root]) @ xmat  # root frame
        nxt = phi + float(np.exp(self._at(self._tau_hat, phi)))
        qa = self._at(self._qa, nxt)
        return np.concatenate(
            [
                self._task,
                d.qpos[c.qpos_idx],
                d.qvel[c.qvel_idx],
                d.qvel[: self.root_nv],
                xmat.ravel(),
                [com[2], d.xpos[root, 2], phi / self.length],
                ee.ravel(),
                qa[c.qpos_idx],  # the next frame of m_a: joint pose, root height, COM
                [self._at(self._coma, nxt)[2], self._at(self._tau_hat, phi)],
            ],
            dtype=np.float32,
        )

    def _set_gravity(self) -> None:
        a = self._task
        g = G * (a[self._gravity_idx] if self._gravity_idx is not None else 1.0)
        self.model.opt.gravity[:] = (0.0, 0.0, -g)

    def _shape_changed(self, com_before: np.ndarray) -> None:
        """m_a is tabulated again on the new body, under the episode's gravity."""
        self._set_gravity()
        self._set_motion(self._trace)
