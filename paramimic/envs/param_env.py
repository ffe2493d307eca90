"""ParamEnv: one gymnasium environment for a family of bodies and tasks.

Each episode draws task parameters a from the task space (or takes `options={"task": a}`),
builds the body F(B̄, b) for the shape part of a, and imitates the character's reference motion
while meeting the task goals. Observation, action and reward follow [WL19] §3.2:
- observation: a, joint positions and velocities, root height, up vector and velocity,
  end-effectors in the root frame, target and average COM velocity, and with a reference motion
  the phase (sin, cos) and the next reference pose;
- action: an offset added to the reference pose, the PD target of the stable PD servos;
- reward: Eq. 4-7, every term a bell, scaled by 1/Σw into (0, 1].
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import lru_cache
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from paramimic.characters import Character, compile_character, get_character
from paramimic.characters.ground_fit import fit_ground_contact, lift_to_ground
from paramimic.config import TASK_GOALS, EnvConfig
from paramimic.curriculum.task_space import TaskSpace
from paramimic.envs.reward_normalization import RewardScales, reward_scales
from paramimic.motion import REFERENCE_MOTIONS

REFERENCE_SAMPLES = 64  # phases at which end-effector reference positions are tabulated
SENSOR_OFF = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
# MuJoCo's warnings for a bad qpos, qvel or qacc (it resets the state when one fires)
INSTABILITY = slice(
    int(mujoco.mjtWarning.mjWARN_BADQPOS), int(mujoco.mjtWarning.mjWARN_BADQACC) + 1
)
MAX_SPEED = 100.0  # an RMS of qvel above this (m/s, rad/s) is a diverged simulation


@lru_cache(maxsize=32)
def _compiled(character: str, shape: tuple[tuple[str, float], ...]) -> Character:
    return compile_character(get_character(character), dict(shape))


class ParamEnv(gym.Env):
    metadata = {"render_modes": [], "render_fps": 30}

    def __init__(
        self,
        character: str = "walker",
        task: Mapping[str, tuple[float, float]] | None = None,
        config: EnvConfig | Mapping[str, Any] | None = None,
    ) -> None:
        self.definition = get_character(character)
        self.config = (
            config if isinstance(config, EnvConfig) else EnvConfig.model_validate(config or {})
        )
        task = dict(task or {})
        allowed = set(self.definition.param_names()) | set(TASK_GOALS)
        unknown = set(task) - allowed
        if unknown:
            raise ValueError(
                f"unknown task parameters {sorted(unknown)} for {character!r}; "
                f"allowed: {sorted(allowed)}"
            )
        self.task_space = TaskSpace.from_ranges(task)
        self._shape_idx = [
            (n, i)
            for i, n in enumerate(self.task_space.names)
            if n in self.definition.param_names()
        ]
        names = self.task_space.names
        self._velocity_idx = names.index("target_velocity") if "target_velocity" in names else None
        self._direction_idx = (
            names.index("target_direction") if "target_direction" in names else None
        )
        self.motion = REFERENCE_MOTIONS[character] if self.config.imitation else None
        joint_names = tuple(j.name for j in self.definition.joints)
        if self.motion is not None and self.motion.joints != joint_names:
            raise ValueError(f"reference motion joints {self.motion.joints} != {joint_names}")
        self.frame_skip = self.config.frame_skip
        self._action_scale = self.config.action_scale
        self._min_up = math.cos(self.config.max_pitch)  # the root's z axis may tilt this far
        self.character: Character
        self.model: mujoco.MjModel
        self.data: mujoco.MjData
        self._load(self.task_space.center)
        self._layout()
        self.dt = self.model.opt.timestep * self.frame_skip
        self._max_steps = int(round(self.config.max_episode_seconds / self.dt))
        self._window = max(1, int(round(self.config.com_velocity_window / self.dt)))
        self._task = self.task_space.center.copy()
        nu = len(joint_names)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (nu,), np.float32)
        self._init_state(np.random.default_rng(0), phase=0.0)
        self._last_obs = None
        obs = self._observe()
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, obs.shape, np.float32)

    # --- body ---------------------------------------------------------------------------------

    def _load(self, task: np.ndarray) -> None:
        shape = tuple((n, round(float(task[i]), 9)) for n, i in self._shape_idx)
        c = _compiled(self.definition.name, shape)
        if getattr(self, "character", None) is c:
            return
        self.character = c
        self.model = c.model
        # Sensors are evaluated once per control step (`_sense`), not in each of the physics steps.
        c.model.opt.disableflags |= SENSOR_OFF
        self._flags_sensing = c.model.opt.disableflags & ~SENSOR_OFF
        self._flags_stepping = c.model.opt.disableflags
        self._opt = c.model.opt
        self.data = mujoco.MjData(c.model)
        # Root: planar (slide x, slide z relative to the build height, pitch) or free (x y z, quat)
        self._free = c.model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
        self._height_adr, self._height_offset = (2, 0.0) if self._free else (1, c.hip_height)
        self._swims = bool(getattr(self.definition, "swims", False))
        self._fall_height = self.config.fall_height_ratio * c.hip_height
        self._height_joint = 0 if self._free else c.model.joint("rootz").id
        base = _compiled(self.definition.name, ())
        if getattr(self, "_base", None) is not base:
            self._base, self._base_data = base, mujoco.MjData(base.model)
        self._scales = (
            reward_scales(c.leg_lengths, base.leg_lengths, c.mass, base.mass)
            if self.config.reward.normalize
            else RewardScales.identity()
        )
        if hasattr(self, "_block_exponent_base"):
            self._scale_energy()
        self._max_qvel_sq = c.model.nv * MAX_SPEED**2
        self._reference = self._tabulate_reference() if self.motion is not None else None

    def _layout(self) -> None:
        """Index and weight arrays of the reward and observation; the same for every shape."""
        c = self.character
        n_ee = len(c.ee_site_ids)
        rc = self.config.reward
        nj = len(c.qpos_idx)
        # Bells of Eq. 5-7 in sensordata order: pose, joint velocity, each end-effector, torque,
        # then COM velocity and direction. Weights w1..w6 (Table 3) and 1/(σ dim(x)).
        w = np.array(
            [
                rc.w_pose,
                rc.w_velocity,
                *[rc.w_end_effector] * n_ee,
                rc.w_torque,
                rc.w_com_velocity,
                rc.w_direction,
            ]
        )
        if self.motion is None:
            w[: 2 + n_ee] = 0.0
        sigma = np.array(
            [
                rc.sigma_pose,
                rc.sigma_velocity,
                *[rc.sigma_end_effector] * n_ee,
                rc.sigma_torque,
                rc.sigma_com_velocity,
                rc.sigma_direction,
            ]
        )
        dims = np.array([nj, nj, *[3] * n_ee, nj, 2, 2], dtype=np.float64)
        w = w / w.sum()  # every step's reward lies in (0, 1]
        exponent = -1.0 / (sigma * dims)  # bell = exp(‖x‖² · exponent) = exp(-‖x‖²_D / σ)
        self._nj = nj
        # The sensordata block q, dq, ee, τ: squared entries -> exponent of each of its bells
        # (torques relative to their limits), one matrix product per step.
        self._block = slice(0, c.tau_sensor.stop)
        groups = [0] * nj + [1] * nj + [2 + i for i in range(n_ee) for _ in range(3)]
        groups += [2 + n_ee] * nj
        nb = 3 + n_ee
        scale_sq = np.concatenate([np.ones(2 * nj + 3 * n_ee), 1.0 / c.torque_limit**2])
        block_exponent = np.zeros((len(groups), nb))
        block_exponent[np.arange(len(groups)), groups] = scale_sq * exponent[groups]
        self._block_exponent_base = block_exponent
        self._torque_rows = slice(len(groups) - nj, len(groups))
        self._scale_energy()
        self._w_block = w[:nb]
        self._zero_reference = np.zeros(len(groups))
        # block bells -> reported terms: pose, velocity, Σ end-effector, (COM velocity,
        # direction: set per step), torque, (task)
        tm = np.zeros((nb, len(REWARD_TERMS)))
        tm[0, 0] = tm[1, 1] = 1.0
        tm[2 : 2 + n_ee, 2] = 1.0
        tm[2 + n_ee, 5] = 1.0
        self._term_matrix = tm
        self._w_com, self._w_dir = float(w[nb]), float(w[nb + 1])
        self._exp_com, self._exp_dir = float(exponent[nb]), float(exponent[nb + 1])
        # sensordata entries the observation reads: joints, end-effectors and the up vector, in
        # the sagittal plane (x, z) for planar bodies, all of x, y, z for free ones
        axes = [0, 1, 2] if self._free else [0, 2]
        ee = np.arange(c.ee_sensor.start, c.ee_sensor.stop).reshape(n_ee, 3)[:, axes].ravel()
        up = c.up_sensor.start + np.array(axes)
        self._obs_sensors = np.concatenate([np.arange(2 * nj), ee, up])
        self._root_velocity = slice(0, 6) if self._free else slice(0, 3)

    def _scale_energy(self) -> None:
        """[WL19] Table 1: the torque (energy) bell's exponent × m0/m for this body."""
        e = self._block_exponent_base.copy()
        e[self._torque_rows] *= self._scales.energy
        self._block_exponent = e

    def _tabulate_reference(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Reference pose, joint velocity and end-effectors (root frame) over one cycle.

        Rows k = 0..K sample φ = k/K; returns (rows [K+1] of [P], row differences [K] of [P]) as
        lists, so that a lookup is one multiply-add (indexing a list is cheaper per step).
        """
        c, d, m = self.character, self.data, self.model
        rows = []
        for k in range(REFERENCE_SAMPLES + 1):
            phi = k / REFERENCE_SAMPLES
            mujoco.mj_resetData(m, d)
            d.qpos[c.qpos_idx] = self.motion.pose(phi)
            mujoco.mj_fwdPosition(m, d)
            self._sense()
            rows.append(
                np.concatenate(
                    [
                        self.motion.pose(phi),
                        self.motion.velocity(phi),
                        d.sensordata[c.ee_sensor],
                        np.zeros(len(c.qpos_idx)),
                    ]
                )
            )
        table = np.array(rows)
        return list(table), list(np.diff(table, axis=0))

    def _reference_at(self, phase: float) -> np.ndarray:
        """Linear interpolation in the tabulated reference: [pose, joint velocity, ee, 0]."""
        x = (phase % 1.0) * REFERENCE_SAMPLES
        k = int(x)
        rows, slopes = self._reference
        return rows[k] + (x - k) * slopes[k]

    # --- episode ------------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        task = (options or {}).get("task")
        if task is None:
            a = self.task_space.sample(self.np_random, 1)[0]
        else:
            a = (
                self.task_space.from_dict(task)
                if isinstance(task, Mapping)
                else np.asarray(task, dtype=np.float64).reshape(-1)
            )
            if a.shape != (self.task_space.dim,) or not self.task_space.contains(a)[0]:
                raise ValueError(
                    f"task {a} is not inside the task space {self.task_space.ranges()}"
                )
        self._task = a
        self._load(a)
        self._init_state(self.np_random, phase=float(self.np_random.random()))
        obs = self._observe()
        self._last_obs = obs
        return obs, {"task": self._task.copy()}

    def _init_state(self, rng: np.random.Generator, phase: float) -> None:
        """Reference state at a random phase with noise ([WL19] Alg. 1 l.8), feet on the floor."""
        c, d, m = self.character, self.data, self.model
        mujoco.mj_resetData(m, d)
        self._set_targets()
        self._phase = phase
        self._dphase = self.dt / self.motion.period if self.motion is not None else 0.0
        noise = self.config.init_noise
        nj = len(c.qpos_idx)
        if self.motion is not None:
            d.qpos[c.qpos_idx] = self.motion.pose(phase) + noise * rng.standard_normal(nj)
            d.qvel[c.qvel_idx] = self.motion.velocity(phase) + noise * rng.standard_normal(nj)
        d.qpos[c.qpos_idx] = np.clip(d.qpos[c.qpos_idx], c.ctrl_low, c.ctrl_high)
        d.qvel[0] = self._target_vel[0]  # root velocity along the target
        if self._free:
            d.qvel[1] = self._target_vel[1]
        if len(c.contact_site_ids):
            d.qpos[:] = self.ground_posture(d.qpos.copy())
            d.qpos[self._height_adr] += 1e-3
        d.ctrl[:] = d.qpos[c.qpos_idx]
        mujoco.mj_forward(m, d)
        self._sense()
        self._steps = 0
        self._unstable = int(d.warning.number[INSTABILITY].sum())
        self._com = [tuple(d.sensordata[c.com_sensor].tolist())] * (self._window + 1)
        self._com_vel = (0.0, 0.0, 0.0)
        self._next_reference = None

    def _set_targets(self) -> None:
        """Target speed and direction of the task, normalized for the body ([WL19] Table 1)."""
        base_v = (
            float(self._task[self._velocity_idx])
            if self._velocity_idx is not None
            else self.config.target_velocity
        )
        self._target_v = self._scales.velocity * base_v
        heading = (
            float(self._task[self._direction_idx])
            if self._direction_idx is not None
            else self.config.target_direction
        )
        # d′: the target direction in the ground plane (a negative speed means backwards)
        sign = 1.0 if self._target_v >= 0 else -1.0
        self._target_dir = (sign * math.cos(heading), sign * math.sin(heading))
        self._target_vel = (self._target_v * math.cos(heading), self._target_v * math.sin(heading))

    def ground_posture(self, qpos: np.ndarray) -> np.ndarray:
        """The initial posture on the ground. A body other than the base is fitted by [WL19]
        Eq. 1 to the base body's contact points in the same pose; the base (or a failed fit)
        is moved vertically until its lowest foot point touches."""
        c = self.character
        if self.config.ground_fit and c.shape != self._base.shape:
            base, bd = self._base, self._base_data
            bd.qpos[:] = lift_to_ground(
                base.model, bd, qpos, base.contact_site_ids, self._height_adr
            )
            mujoco.mj_kinematics(base.model, bd)
            targets = bd.site_xpos[base.contact_site_ids]
            joints = c.model.actuator_trnid[:, 0]
            return fit_ground_contact(
                c.model, self.data, qpos, targets, c.contact_site_ids, self._height_joint, joints
            ).qpos
        return lift_to_ground(c.model, self.data, qpos, c.contact_site_ids, self._height_adr)

    def set_shape(self, shape: Mapping[str, float]) -> np.ndarray:
        """Change the body mid-episode ([WL19] §5.2): rebuild the model for the new shape, copy
        joint positions, velocities and controls, lift the body out of the ground if its limbs
        grew, and carry on from the same state and phase. The shape parameters must be task
        dimensions (the policy observes them). Returns the new observation."""
        a = self._task.copy()
        shape_dims = dict(self._shape_idx)
        for name, value in shape.items():
            if name not in shape_dims:
                raise ValueError(
                    f"{name!r} is not a shape dimension of this task space; "
                    f"shape dimensions: {sorted(shape_dims)}"
                )
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"shape parameter {name!r} must be a positive number, got {value}")
            a[shape_dims[name]] = float(value)
        old, c = self.data, self.character
        com_before = old.sensordata[c.com_sensor].copy()
        self._task = a
        self._load(a)
        c, d, m = self.character, self.data, self.model
        d.qpos[:], d.qvel[:], d.ctrl[:] = old.qpos, old.qvel, old.ctrl
        d.time = old.time
        mujoco.mj_forward(m, d)
        depth = -min((d.contact.dist[i] for i in range(d.ncon)), default=0.0)
        if depth > 0:  # lift until no penetration
            d.qpos[self._height_adr] += depth + 1e-4
            mujoco.mj_forward(m, d)
        self._sense()
        self._unstable = int(d.warning.number[INSTABILITY].sum())
        self._set_targets()
        # the average COM velocity continues: shift its history by the COM's jump
        shift = d.sensordata[c.com_sensor] - com_before
        self._com = [tuple((np.array(p) + shift).tolist()) for p in self._com]
        obs = self._observe()
        self._last_obs = obs
        return obs

    # --- step ---------------------------------------------------------------------------------

    def step(self, action: np.ndarray):
        c, d = self.character, self.data
        self._phase += self._dphase
        # PD target = reference pose + offset; MuJoCo clamps ctrl to the joint range.
        a = np.minimum(np.maximum(action, -1.0), 1.0) * self._action_scale
        ref = None
        if self._reference is not None:
            ref = self._next_reference  # looked up by the previous observation at this phase
            a += ref[: self._nj]
        d.ctrl[:] = a
        mujoco.mj_step(self.model, d, nstep=self.frame_skip)
        self._sense()
        self._steps += 1

        # [WL19] Eq. 6 uses the COM velocity averaged over the last `com_velocity_window` seconds.
        cx, cy, cz = com = d.sensordata[c.com_sensor].tolist()
        ring = self._com
        elapsed = self._steps if self._steps < self._window else self._window
        ox, oy, oz = ring[(self._steps - elapsed) % len(ring)]
        inv = 1.0 / (elapsed * self.dt)
        self._com_vel = ((cx - ox) * inv, (cy - oy) * inv, (cz - oz) * inv)
        ring[self._steps % len(ring)] = com

        # A diverging simulation ends the episode, never the run: NaN or exploding velocities,
        # or MuJoCo's own reset of the state on a bad qpos, qvel or qacc.
        qvel = d.qvel
        if (
            not qvel @ qvel < self._max_qvel_sq
            or d.warning.number[INSTABILITY].sum() > self._unstable
        ):
            return self._diverged()
        reward, terms = self._reward(ref)
        obs = self._observe()
        self._last_obs = obs
        height = d.qpos[self._height_adr] + self._height_offset
        tilted = d.sensordata[c.up_sensor.start + 2] < self._min_up
        fell = not self._swims and bool(height < self._fall_height or tilted)
        truncated = self._steps >= self._max_steps and not fell
        info = {
            "task": self._task.copy(),
            "fell": fell,
            "diverged": False,
            "dphi": 1.0,
            "reward_spike": 0.0,
            "reward_terms": terms,
        }
        return obs, reward, fell, truncated, info

    def _diverged(self) -> tuple:
        info = {
            "task": self._task.copy(),
            "fell": False,
            "diverged": True,
            "dphi": 1.0,
            "reward_spike": 0.0,
            "reward_terms": dict.fromkeys(REWARD_TERMS, 0.0),
        }
        return self._last_obs, 0.0, True, False, info

    def _sense(self) -> None:
        """Evaluate the sensor block for the current state of the control step."""
        m, d, opt = self.model, self.data, self._opt
        opt.disableflags = self._flags_sensing
        mujoco.mj_sensorPos(m, d)
        mujoco.mj_sensorVel(m, d)
        mujoco.mj_sensorAcc(m, d)
        opt.disableflags = self._flags_stepping

    def _reward(self, ref: np.ndarray | None) -> tuple[float, dict[str, float]]:
        """[WL19] Eq. 4-7: R = R_imit + R_task + R_reg, ‖x‖²_D = ‖x‖²/dim(x), each term a bell."""
        d = self.data
        sq = d.sensordata[self._block] - (self._zero_reference if ref is None else ref)
        sq *= sq
        bells = np.exp(sq @ self._block_exponent)  # Eq. 5 pose, velocity, each ee; Eq. 7 τ
        terms = (bells @ self._term_matrix).tolist()
        vx, vy, _ = self._com_vel
        vx -= self._target_vel[0]
        vy -= self._target_vel[1]
        terms[3] = math.exp((vx * vx + vy * vy) * self._exp_com)  # Eq. 6: COM velocity
        # Eq. 6: facing direction d (the root's x axis in the ground plane) against d′, the
        # error scaled by the body's leg symmetry ([WL19] Table 1)
        xmat = d.xmat[self.character.root_body_id]
        fx, fy = xmat[0], xmat[3]
        norm = math.hypot(fx, fy) or 1.0
        ex, ey = fx / norm - self._target_dir[0], fy / norm - self._target_dir[1]
        terms[4] = math.exp(self._scales.direction * (ex * ex + ey * ey) * self._exp_dir)
        terms[6] = self._w_com * terms[3] + self._w_dir * terms[4]  # task share of the reward
        reward = float(bells @ self._w_block) + terms[6]
        return reward, dict(zip(REWARD_TERMS, terms, strict=True))

    def _observe(self) -> np.ndarray:
        c, d = self.character, self.data
        phase = self._phase
        vx, _, vz = self._com_vel
        height = d.qpos[self._height_adr] + self._height_offset
        parts = [
            self._task,
            d.sensordata[self._obs_sensors],  # joint q, dq, end-effectors, up vector
            d.qvel[self._root_velocity],  # root velocity (planar: x, z, pitch rate)
            (height, self._target_v, vx, vz),  # root height, target speed, average COM vel.
        ]
        if self._free:  # heading: the root's x axis, the target direction, COM velocity y
            xmat = d.xmat[c.root_body_id]
            parts.append((xmat[0], xmat[3], xmat[6], *self._target_dir, self._com_vel[1]))
        if self._reference is not None:
            x = 2.0 * math.pi * phase
            parts.append((math.sin(x), math.cos(x)))
            self._next_reference = self._reference_at(phase + self._dphase)
            parts.append(self._next_reference[: self._nj])  # next reference pose
        return np.concatenate(parts, dtype=np.float32)

    # --- accessors ----------------------------------------------------------------------------

    @property
    def task(self) -> np.ndarray:
        return self._task.copy()

    @property
    def sim_time(self) -> float:
        return self._steps * self.dt


REWARD_TERMS = ("pose", "velocity", "end_effector", "com_velocity", "direction", "torque", "task")
