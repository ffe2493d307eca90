"""SkillEnv: continuous-time imitation of one clip for a family of tasks ([L21] §3-5).

The motion to imitate is m_a = (m0 ⊕ d̂)(φ) with the time increments τ̂ of a *trace*
{(d̂, τ̂)} sampled at `trace_bins` reference times (Eq. 1-3); the caller passes it with the task
(`options={"task": a, "motion": trace}`); no trace means m_a = m0 (τ̂ = 0).
- action (d_t, τ_t): joint displacements and a log time increment; the reference advances by
  Δφ = exp(τ_t) control steps while the simulation advances by Δt, and the PD target is
  m0(φ') ⊕ d_t (§4.1);
- reward: r = w_tracking r_tracking + w_task r_task (Eq. 5), tracking = 0.28 r_q + 0.28 r_ee +
  0.28 r_com + 0.16 r_time (Eq. 6-7), continuous; the task reward (Eq. 8) compares each measured
  task parameter (`env.skill.measures`, `paramimic.motion.measures`; `jump_height` is the COM
  rise) with its goal: a spike paid at its event (the clip's end, take-off, a window's end) or a
  continuous reward in its window (§4.2). Every transition reports Δφ for variable time-step
  GAE (Eq. 9) and the spike part of its reward;
- when the episode ends it reports the trace it made (root displacement measured, joint
  displacements and τ as acted), the parameter a' it achieved (hindsight: every measured
  parameter by the same measure) and its fitness F (Eq. 10) against m0 (0 unless the clip was
  completed), with the constraint reward of its zero-range measured parameters.
Reference time φ is counted in control steps (Δφ = 1 is real time).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from paramimic.characters import Body
from paramimic.envs.core import EnvCore, bodies_in_heading_frame, body_position_error
from paramimic.envs.rewards import l21_reward, l21_task, l21_tracking, l21_tracking_reward
from paramimic.envs.skill_motion import DisplacedMotion, PoseTable, at
from paramimic.envs.skill_record import EpisodePath
from paramimic.messages import SkillOutcome, StepInfo
from paramimic.motion.fitness import EpisodeTrace, fitness
from paramimic.motion.measures import CONTACT_HEIGHT, Measure, Trajectory, default_unit
from paramimic.motion.parameterization import TAU_LIMIT
from paramimic.motion.phase import PhaseSampler

G = 9.81
SKILL_TERMS = ("q", "ee", "com", "time", "task")
# jump_height without a declaration: the COM rise as a spike at the clip's end (Eq. 8)
JUMP_HEIGHT = {"measure": "com_rise"}


@dataclass(frozen=True)
class TaskMeasure:
    """A measured task parameter of this env: its task dimension and how it is rewarded."""

    index: int
    name: str
    measure: Measure
    reward: str  # "spike" or "continuous"
    event: str  # when a spike is paid: clip_end, takeoff, window_end
    sigma: float  # σ_task of Eq. 8 in the parameter's unit


class SkillEnv(EnvCore):
    @property
    def GOALS(self) -> frozenset[str]:  # noqa: N802 (EnvCore's name)
        return frozenset({"gravity", "jump_height", *self.config.skill.measures})

    def _setup(self) -> None:
        if self.config.clip is None:
            raise ValueError("SkillEnv needs env.clip")
        self.skill = self.config.skill
        self._gravity_idx = self.goal_index("gravity")
        self.measured = self._task_measures()
        self._energy = any(t.measure.kind == "takeoff_kinetic_energy" for t in self.measured)
        # a name, or a clip file (its text carried with the run when it is there)
        self.clip = self.registration.load_clip(self.config.clip, self.config.clip_texts)
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
        self._hold_steps = int(round(self.skill.hold_seconds / self.dt))
        cfg = self.config
        self._phases = (  # RSI's start phases where episodes fail, or uniform
            PhaseSampler(cfg.phase_bins, cfg.phase_alpha, wrap=False)
            if cfg.phase_sampling == "failures" and self.skill.rsi > 0
            else None
        )
        self._max_steps = int(np.ceil(self.length * np.exp(TAU_LIMIT))) + 1 + self._hold_steps
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.nj + 1,), np.float32)
        self._task = self.task_space.center.copy()
        self.reset(seed=0)
        obs = self._observe()
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, obs.shape, np.float32)
        w = self.skill
        continuous = any(t.reward == "continuous" for t in self.measured)
        # §4.2: (1.0, 10) with spike task rewards, (0.9, 0.1) with continuous ones, 1.0 without
        self._w_tracking = w.w_tracking_continuous if continuous else 1.0
        self._w_spike = w.w_task_spike
        self._w_continuous = w.w_task_continuous

    def _task_measures(self) -> list[TaskMeasure]:
        """The measured task parameters: `env.skill.measures`, and `jump_height` as the COM rise."""
        from paramimic.config import TaskMeasureConfig

        out = []
        for i, name in enumerate(self.task_space.names):
            spec = self.skill.measures.get(name)
            if spec is None and name == "jump_height":
                spec = TaskMeasureConfig(**JUMP_HEIGHT, sigma=self.skill.sigma_task)
            if spec is None:
                continue
            width = float(self.task_space.width[i])
            sigma = spec.sigma or (width / 6 if width > 0 else 0.1 * abs(self.task_space.low[i]))
            measure = Measure(
                spec.measure, spec.unit or default_unit(spec.measure), spec.axis, spec.body,
                tuple(spec.window),
            )  # fmt: skip
            out.append(
                TaskMeasure(
                    i, name, measure, spec.reward, spec.resolved_event(), float(sigma or 0.1)
                )
            )
        return out

    # --- body and reference ------------------------------------------------------------------

    def _bind(self, c: Body) -> None:
        self.model = copy.copy(c.model)  # own copy: gravity changes per episode
        self.data = mujoco.MjData(self.model)
        self._scratch = mujoco.MjData(self.model)
        self._index_fall_geoms()
        dt = self.model.opt.timestep * self.frame_skip
        self._q0 = self._clip_qpos(c, np.arange(int(np.ceil(self.clip.duration / dt)) + 2) * dt)
        self._motion = DisplacedMotion(self.model, self._scratch, c, self._q0, self.root_nq)
        poses0 = self._kinematics(self._q0)
        ee0, low0 = poses0.ee, poses0.low
        self._feet = np.array(
            [list(c.definition.end_effectors).index(f) for f in c.definition.feet]
        )
        self._ee_height0 = ee0[:, self._feet, 2]  # m0 end-effector heights (world) for F
        self._contact0 = low0 < CONTACT_HEIGHT  # C_j of m0: foot near the ground
        self.reference = self._reference_trajectory(self.clip.duration / dt, dt)
        # every measure's SI value on m0 for this body: the unit of `reference` parameters
        self._reference_si = {t.name: t.measure.si(self.reference) for t in self.measured}
        for t in self.measured:
            if t.measure.unit == "reference" and abs(self._reference_si[t.name]) < 1e-9:
                raise ValueError(
                    f"task.{t.name}: {t.measure.kind} is 0 on the clip {self.clip.name!r}, so "
                    "`unit: reference` (multiples of it) means nothing; give an SI unit"
                )

    def _kinematics(self, qpos: np.ndarray, times: np.ndarray | None = None) -> PoseTable:
        return self._motion.kinematics(qpos, times)

    def _clip_qpos(self, c: Body, times: np.ndarray) -> np.ndarray:
        """m0 at reference times (s) as qpos rows of body c: [n, nq]."""
        pose = self.clip.sample(times)
        if self.root_nq == self.root_nv:  # planar: the clip is for the base body; feet down
            pose.root_position[:, 2] += c.hip_height - self._base_hip_height
        return self.definition.pose_qpos(c, pose)

    def _reference_trajectory(
        self, length: float, dt: float, energy: bool | None = None
    ) -> Trajectory:
        """m0 on this body as the measures read it, at φ = 0, 1, .. and the clip's end `length`;
        with `energy` (default: when a task parameter measures it) the kinetic energy, from
        velocities by finite differences of the poses."""
        energy = self._energy if energy is None else energy
        c = self.character
        phis = np.arange(int(np.floor(length + 1e-9)) + 1, dtype=np.float64)
        if length - phis[-1] > 1e-6:
            phis = np.append(phis, length)
        # the clip's own last pose at its end (a looping clip would start its next cycle there)
        qpos = self._clip_qpos(c, np.minimum(phis * dt, self.clip.duration * (1 - 1e-9)))
        t = self._kinematics(qpos, phis * dt if energy else None)
        return Trajectory(
            phis * dt, phis / length, t.com, t.rot,
            {name: t.ee[:, j] for j, name in enumerate(c.definition.end_effectors)},
            t.low, t.energy, float(mujoco.mj_getTotalmass(self.model)), t.low < CONTACT_HEIGHT,
        )  # fmt: skip

    def _set_motion(self, trace: np.ndarray | None) -> None:
        """Tabulate m_a on the reference grid: pose, end-effectors relative to the COM, COM, τ̂."""
        if trace is None:
            trace = np.zeros(self.trace_shape)
        trace = np.array(trace, np.float64)
        if not self.skill.time_warp:  # A2: every motion in real time
            trace[:, -1] = 0.0
        ma = self._motion.tables(trace, self._bins)
        self._qa, self._bodies_a, self._eea, self._coma = ma.q, ma.bodies, ma.ee, ma.com
        self._tau_hat = ma.tau

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
        rng = self.np_random
        rsi = self._trace is None and self.skill.rsi > 0 and rng.random() < self.skill.rsi
        # RSI: a phase of the clip (not its last control step; uniform, or where episodes fail:
        # `env.phase_sampling`), else the clip's start
        self._start = (self._phases.sample(rng) if self._phases else rng.random()) if rsi else 0.0
        start = float(self._start * max(self.length - 1.0, 0.0))
        self._rsi = start > 0.0
        d.qpos[:] = at(self._qa, start)
        d.qpos[c.qpos_idx] += noise * rng.standard_normal(self.nj)
        height = 1 if self.root_nq == self.root_nv else 2
        mujoco.mj_kinematics(m, d)
        lowest = d.site_xpos[c.contact_site_ids, 2].min()
        if self._rsi:  # the clip's own state: its velocity, its height (lifted off the floor)
            ahead = at(self._qa, start + 1.0)
            mujoco.mj_differentiatePos(m, d.qvel, self.dt, at(self._qa, start), ahead)
            d.qpos[height] -= min(lowest - 1e-3, 0.0)
        else:  # at rest, the lowest foot on the ground
            d.qvel[:] = 0.0
            d.qpos[height] -= lowest - 1e-3
        d.ctrl[:] = np.clip(d.qpos[c.qpos_idx], c.ctrl_low, c.ctrl_high)
        mujoco.mj_forward(m, d)
        self._phi = start
        self._steps = 0
        # the root's x offset from m_a's (0 at the clip's start): the COM reference follows it
        self._x0 = float(d.qpos[0]) - float(at(self._qa, start)[0] - self._qa[0, 0])
        self._z0 = float(d.qpos[height] - at(self._qa, start)[height])  # the lift at reset
        self._watch_stability()
        self._rec: dict[str, list] = {k: [] for k in ("phi", "d", "pose", "vel", "ee", "slide")}
        self._path = EpisodePath(m, c, self._energy, self._contact0)
        self._fired: set[str] = set()  # spikes paid this episode
        self._held: SkillOutcome | None = None  # the clip end's outcome while standing after it
        self._hold_left = 0
        self._measure_row(start)
        self._feet_xy = d.site_xpos[c.ee_site_ids[self._feet]][:, :2].copy()
        self._prev_q = d.qpos[c.qpos_idx].copy()
        obs = self._observe()
        self._last_obs = obs
        return obs, {"task": a.copy()}

    def step(self, action: np.ndarray):
        m, d, c = self.model, self.data, self.character
        action = np.clip(np.asarray(action, np.float64), -1.0, 1.0)
        d_joints = action[: self.nj] * self.config.action_scale
        tau = float(action[self.nj]) * self.skill.tau_scale if self.skill.time_warp else 0.0
        dphi = float(np.exp(tau))
        phi_next = self._phi + dphi
        # PD target m0(φ') ⊕ d_t (§4.1); the servo clamps it to the joint's control range
        d.ctrl[:] = at(self._q0, phi_next)[c.qpos_idx] + d_joints
        mujoco.mj_step(m, d, nstep=self.frame_skip)
        self._steps += 1
        self._phi = phi_next
        if self.diverging():
            info = self._info(dphi, 0.0, [0.0] * len(SKILL_TERMS), fell=False, diverged=True)
            return self._end(self._last_obs, 0.0, info, terminated=True, completed=False)
        self._record(phi_next, d_joints, tau)
        self._measure_row(phi_next)
        s = self.skill
        terms = list(self._tracking(phi_next, tau))
        r_track = l21_tracking_reward(terms, s.w_q, s.w_ee, s.w_com, s.w_time)  # Eq. 6
        obs = self._observe()
        self._last_obs = obs
        fell = self.fall_contact()
        deviated = not fell and self._deviated()
        completed = phi_next >= self.length and not (fell or deviated) and self._held is None
        r_continuous, r_spike = self._task_rewards(completed)
        reward = l21_reward(r_track, r_continuous or 0.0, self._w_tracking, self._w_continuous)
        spike = 0.0 if r_spike is None else self._w_spike * r_spike  # Eq. 5, paid at once
        r_task = r_continuous if r_continuous is not None else r_spike
        terms.append(0.0 if r_task is None else r_task)
        if self._held is not None or completed and self._hold_steps:  # standing after the end
            return self._hold(obs, reward + spike, spike, dphi, terms, fell, deviated, completed)
        ends = fell or deviated or completed
        if ends or self._steps >= self._max_steps or self._timed_out():
            info = self._info(dphi, spike, terms, fell=fell, deviated=deviated)
            self._rsi_ended(failed=fell or deviated)
            return self._end(obs, reward + spike, info, ends, completed)
        info = self._info(dphi, spike, terms, fell=False)
        return obs, reward + spike, False, False, info

    def _hold(self, obs, reward, spike, dphi, terms, fell, deviated, completed):
        """`hold_seconds` after the clip's end: the summary is the clip end's; the episode ends
        on a fall (or a deviation, in training) or when the time is up, reporting whether the
        body stood the whole time (a training time limit that cuts the stand short truncates
        it: not `held`)."""
        if completed:
            self._held, self._hold_left = self._summary(True), self._hold_steps
        self._hold_left -= 0 if completed else 1
        info = self._info(dphi, spike, terms, fell=fell, deviated=deviated)
        stop = fell or deviated
        cut = not stop and self._hold_left > 0 and self._timed_out()
        if stop or cut or self._hold_left <= 0 or self._steps >= self._max_steps:
            info["skill"] = self._held.with_held(not (stop or cut))
            self._rsi_ended(failed=stop)
            return obs, reward, not cut, cut, info
        return obs, reward, False, False, info

    def _rsi_ended(self, failed: bool) -> None:
        """An RSI episode ended: its start phase's failure rate learns whether it fell or
        deviated (`env.phase_sampling: failures`)."""
        if self._rsi and self._phases is not None:
            self._phases.update(self._start, failed)

    def _deviated(self) -> bool:
        """`deviation_limit` (a training rule, as on clip gaits): a body (relative to the root,
        in its heading frame) or the root's height farther than that from m_a's at φ (after
        the clip's end, its last pose)."""
        limit = self.config.deviation_limit
        if limit is None:
            return False
        _, worst = self.body_error()
        h = 1 if self.root_nq == self.root_nv else 2
        height = float(self.data.qpos[h]) - at(self._qa, self._phi)[h] - self._z0
        return worst > limit or abs(height) > limit

    @property
    def horizon_seconds(self) -> float:
        """The episode's nominal length (s): the clip at its own pace and the stand after it."""
        return (self.length + self._hold_steps) * self.dt

    tracks_bodies = True  # `body_error` against m_a

    def body_error(self) -> tuple[float, float]:
        """(mean, max) distance (m) between the bodies' simulated positions and m_a's at φ
        (after the clip's end, its last pose), each relative to its own root in its own
        heading frame: the measure ParamEnv's clip gaits report."""
        c, d = self.character, self.data
        sim = bodies_in_heading_frame(d.xpos, d.xmat, c.root_body_id)
        return body_position_error(sim, at(self._bodies_a, self._phi))

    # --- task parameters as measures ---------------------------------------------------------

    def _measure_row(self, phi: float) -> None:
        """One row of the episode's `Trajectory` (the state after this control step)."""
        self._path.add(self.data, self._steps * self.dt, phi / self.length, phi)

    def episode_trajectory(self) -> Trajectory:
        """The episode so far as the measures read it."""
        return self._path.trajectory()

    def measure(self, t: TaskMeasure, traj: Trajectory | None = None) -> float:
        """A measured task parameter on the episode so far (or `traj`), in its unit."""
        traj = self.episode_trajectory() if traj is None else traj
        return t.measure.value(traj, self._reference_si[t.name])

    def task_errors(self) -> dict[str, float]:
        """Each measured task parameter's distance from its goal on the episode so far, in its
        σ_task ([L21] Eq. 8): |measure − a| / σ (unclipped, so a constraint's miss shows)."""
        traj = self.episode_trajectory()
        return {
            t.name: abs(self.measure(t, traj) - float(self._task[t.index])) / t.sigma
            for t in self.measured
        }

    def _task_rewards(self, completed: bool) -> tuple[float | None, float | None]:
        """r_task of Eq. 8 for this step: over the continuous parameters in their window, and over
        the spike parameters whose event happens now (None where there is none)."""
        if not self.measured or self._rsi:  # a mid-clip start measures no whole-motion task
            return None, None
        path = self._path
        phase, prev = path.phase[-1], path.phase[-2]
        air = [bool(np.all(low > CONTACT_HEIGHT)) for low in path.low[-2:]]
        takeoff = air[1] and not air[0]
        cont, spikes = [], []
        for t in self.measured:
            lo, hi = t.measure.window
            if t.reward == "continuous":
                if lo <= phase <= hi:
                    cont.append(t)
                continue
            fires = {
                "clip_end": completed,
                "takeoff": takeoff,
                "window_end": prev < hi <= phase,
            }[t.event]
            if fires and t.name not in self._fired:
                self._fired.add(t.name)
                spikes.append(t)

        traj = self.episode_trajectory() if cont or spikes else None

        def r_task(ts: list[TaskMeasure]) -> float | None:
            if not ts:
                return None
            err = [(self.measure(t, traj) - self._task[t.index]) / t.sigma for t in ts]
            return l21_task(float(np.linalg.norm(err)), 1.0)  # Eq. 8 over the parameters

        return r_task(cont), r_task(spikes)

    def _tracking(self, phi: float, tau: float) -> tuple[float, float, float, float]:
        """r_q, r_ee, r_com, r_time of Eq. 7 against m_a at φ."""
        c, d, s = self.character, self.data, self.skill
        qa = at(self._qa, phi)
        dq = d.qpos[c.qpos_idx] - qa[c.qpos_idx]  # hinges: log(q̂⁻¹q) is the angle difference
        com = d.subtree_com[c.root_body_id]
        ee = d.site_xpos[c.ee_site_ids] - com
        com_hat = at(self._coma, phi).copy()
        com_hat[0] += self._x0
        dt_hat = float(np.exp(at(self._tau_hat, phi)))
        return l21_tracking(
            dq,
            ee - at(self._eea, phi),
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
        q0 = at(self._q0, phi)
        rec = self._rec
        rec["phi"].append(phi)
        rec["d"].append(
            np.concatenate([self._motion.root_displacement(d.qpos, q0, self._x0), d_joints, [tau]])
        )
        q = d.qpos[c.qpos_idx]
        rec["pose"].append(q - q0[c.qpos_idx])
        dq0 = (at(self._q0, phi + 0.5) - at(self._q0, phi - 0.5))[c.qpos_idx]
        rec["vel"].append(np.stack([(q - self._prev_q) / self.dt, dq0 / self.dt], axis=0))
        self._prev_q = q.copy()
        feet = c.contact_site_ids.reshape(len(c.definition.feet), 4)
        rec["ee"].append(d.site_xpos[feet, 2].min(axis=1))
        xy = d.site_xpos[c.ee_site_ids[self._feet]][:, :2]
        rec["slide"].append(np.linalg.norm(xy - self._feet_xy, axis=1))
        self._feet_xy = xy.copy()

    def reference_task(self) -> np.ndarray:
        """a0, the parameter of m0 itself: gravity 1, body scales 1 and every measured parameter
        on m0 on the current body (1 for `reference` units), clipped into the task space."""
        a = np.ones(self.task_space.dim)
        for t in self.measured:
            a[t.index] = self.measure(t, self.reference)
        return np.clip(a, self.task_space.low, self.task_space.high)

    def reference_measures(self) -> dict[str, float]:
        """Every measure of the library on m0 on the current body, in SI units (`clip info`)."""
        from paramimic.motion.measures import AXES, MEASURES

        ref = self._reference_trajectory(self.length, self.dt, energy=True)  # every measure
        out = {}
        for kind, k in MEASURES.items():
            variants: list[dict] = [{}]
            if "axis" in k.needs or "axis" in k.optional:
                variants = ([{}] if "axis" in k.optional else []) + [{"axis": a} for a in AXES]
            if "body" in k.needs:
                variants = [{"body": b} for b in self.character.definition.end_effectors]
            for v in variants:
                label = kind + "".join(f" {k}={x}" for k, x in v.items())
                out[label] = Measure(kind, default_unit(kind), v.get("axis"), v.get("body")).si(ref)
        return out

    def clip_setup(self) -> dict:
        """What the [L21] curriculum needs of the clip without building an env (the sampler
        actor's): {"trace_shape": (bins, D), "reference": a0 as a list}."""
        return {"trace_shape": self.trace_shape, "reference": self.reference_task().tolist()}

    def jump_height(self) -> float:
        """Peak rise of the COM above its height at the start of this episode so far (m)."""
        com = np.asarray(self._path.com)
        return float(com[:, 2].max() - com[0, 2])

    def _end(self, obs, reward: float, info: StepInfo, terminated: bool, completed: bool):
        """The episode's last step: its outcome in `info`; not terminated is truncated."""
        info["skill"] = self._summary(completed and not info["diverged"])
        return obs, reward, terminated, not terminated, info

    def _info(self, dphi, spike, terms, fell, diverged=False, deviated=False) -> StepInfo:
        return StepInfo(
            task=self._task.copy(), fell=fell, diverged=diverged, deviated=deviated, dphi=dphi,
            reward_spike=spike,
            reward_terms=dict(zip(SKILL_TERMS, terms, strict=True)),
        )  # fmt: skip

    def _summary(self, completed: bool) -> SkillOutcome:
        """Hindsight parameter a', fitness F (Eq. 10) and the trace of this episode."""
        if self._rsi:  # π0's RSI episode: nothing for the hindsight record or the elite set
            return SkillOutcome(None, 0.0, None, False)
        achieved = self._task.copy()
        traj = self.episode_trajectory()
        for t in self.measured:  # hindsight a' by the parameter's own measure
            achieved[t.index] = self.measure(t, traj)
        achieved = np.clip(achieved, self.task_space.low, self.task_space.high)
        rec = self._rec
        if not completed or len(rec["phi"]) < 2:
            return SkillOutcome(achieved, 0.0, None, False)
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
        # Eq. 10: zero-range measured parameters are constraints the episode should meet
        fixed = [t for t in self.measured if self.task_space.width[t.index] == 0]
        r_constraint, missed = 0.0, None
        if fixed:
            err = [(self.measure(t, traj) - self._task[t.index]) / t.sigma for t in fixed]
            r_constraint = l21_task(float(np.linalg.norm(err)), 1.0)
            missed = float(np.max(np.abs(err)))
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
        return SkillOutcome(achieved, f, trace, True, constraint_error=missed)

    def _observe(self) -> np.ndarray:
        c, d = self.character, self.data
        phi = self._phi
        root = c.root_body_id
        xmat = d.xmat[root].reshape(3, 3)
        com = d.subtree_com[root]
        ee = (d.site_xpos[c.ee_site_ids] - d.xpos[root]) @ xmat  # root frame
        nxt = phi + float(np.exp(at(self._tau_hat, phi)))
        qa = at(self._qa, nxt)
        return np.concatenate(
            [
                self.observed_task(),
                d.qpos[c.qpos_idx],
                d.qvel[c.qvel_idx],
                d.qvel[: self.root_nv],
                xmat.ravel(),
                [com[2], d.xpos[root, 2], phi / self.length],
                ee.ravel(),
                qa[c.qpos_idx],  # the next frame of m_a: joint pose, root height, COM
                [at(self._coma, nxt)[2], at(self._tau_hat, phi)],
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
