"""ParamEnv: one gymnasium environment for a family of bodies and tasks.

Each episode draws task parameters a from the task space (or takes `options={"task": a}`),
builds the body F(B̄, b) for the shape part of a, and imitates the character's reference motion
while meeting the task goals. Observation, action and reward follow [WL19] §3.2:
- observation: a, joint positions and velocities, root height, up vector and velocity,
  end-effectors in the root frame, target and average COM velocity in the heading frame, and
  with a reference motion the phase (sin, cos) and the reference poses of the next control step
  and 0.5 s and 1.0 s ahead;
- action: an offset added to the reference pose, the PD target of the stable PD servos;
- reward: Eq. 4-7, every term a bell, scaled by 1/Σw into (0, 1].
"""

from __future__ import annotations

import math
from collections import OrderedDict
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from paramimic.characters import Body
from paramimic.characters.legs import leg_chains
from paramimic.envs.core import (
    EnvCore,
    bodies_in_heading_frame,
    body_position_error,
    in_heading_frame,
)
from paramimic.envs.reward_normalization import RewardScales, reward_scales
from paramimic.envs.rewards import (
    WL19Terms,
    wl19_imitation,
    wl19_regularization,
    wl19_reward,
    wl19_reward_product,
    wl19_task,
    wl19_task_share,
    wl19_weights,
)
from paramimic.messages import StepInfo
from paramimic.motion.clip_gait import ClipGait
from paramimic.motion.phase import PhaseSampler
from paramimic.motion.retarget import RetargetedGait, retarget_pose

CLIP_GAITS = 32  # clip gait tables kept per env, as `compiled_body` keeps 32 bodies
REFERENCE_SAMPLES = 64  # phases at which end-effector reference positions are tabulated
SENSOR_OFF = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
FUTURE_POSES = (0.5, 1.0)  # s: reference postures observed ahead ([WL19] §4.1)
REWARD_TERMS = ("pose", "velocity", "end_effector", "com_velocity", "direction", "torque", "task")


class ParamEnv(EnvCore):
    GOALS = frozenset({"target_velocity", "target_direction"})

    def _setup(self) -> None:
        self._velocity_idx = self.goal_index("target_velocity")
        self._direction_idx = self.goal_index("target_direction")
        self._clip = None  # a clip gait's clip (env.gait), tabulated per body in `_bind`
        self._clip_gaits: OrderedDict[tuple, ClipGait] = OrderedDict()
        gait = self.registration.gait
        if self.config.gait is not None:
            if self.definition.planar:
                raise ValueError(f"env.gait: clip gaits need a free root; {self.definition.name!r}")
            self._clip = self.registration.load_clip(self.config.gait, self.config.clip_texts)
            gait = self._clip_gait(self._base)
        if self.config.reward.end_effector_frame == "heading" and self._clip is None:
            raise ValueError("env.reward.end_effector_frame: heading needs a clip gait (env.gait)")
        if self.config.reward.facing == "clip" and self._clip is None:
            raise ValueError("env.reward.facing: clip needs a clip gait (env.gait)")
        if self.config.imitation and gait is None:
            raise ValueError(f"character {self.definition.name!r} has no [WL19] gait to imitate")
        self._gait = self.motion = gait if self.config.imitation else None
        cfg = self.config
        self._phases = (  # start phases where episodes fail, or uniform
            PhaseSampler(cfg.phase_bins, cfg.phase_alpha)
            if cfg.phase_sampling == "failures" and gait is not None
            else None
        )
        # the speed the gait moves at on the base body: the target when none is given
        self._gait_speed = gait.speed if isinstance(gait, ClipGait) else 1.0
        self._action_scale = self.config.action_scale
        self._min_up = math.cos(self.config.max_pitch)  # the root's z axis may tilt this far
        self._free = not self.definition.planar
        self._height_offset = 0.0  # set per body: planar roots slide relative to build height
        self._scales = RewardScales.identity()
        self._layout()
        self._load(self.task_space.center)
        self.dt = self.model.opt.timestep * self.frame_skip
        self._max_steps = int(round(self.config.max_episode_seconds / self.dt))
        self._window = max(1, int(round(self.config.com_velocity_window / self.dt)))
        nu = len(self.definition.joints)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (nu,), np.float32)
        self._init_state(np.random.default_rng(0), phase=0.0)
        obs = self._observe()
        self._last_obs = obs
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, obs.shape, np.float32)

    # --- body ---------------------------------------------------------------------------------

    def _layout(self) -> None:
        """Sensor indices of the reward and observation and the weights of Eq. 4: the same for
        every shape (sensordata: q [nj], dq [nj], end-effectors [3 n_ee], τ [nj], up, COM)."""
        base, rc = self._base, self.config.reward
        nj, n_ee = len(base.qpos_idx), len(base.ee_site_ids)
        self._nj, self._n_ee = nj, n_ee
        self._q = slice(0, nj)
        self._dq = slice(nj, 2 * nj)
        self._ee = slice(2 * nj, 2 * nj + 3 * n_ee)
        self._weights = wl19_weights(
            *rc.weights(self.registration.reward_weights),
            n_ee,
            imitation=self.motion is not None,
        )
        # observed sensordata: joints, end-effectors and the up vector, in the sagittal plane
        # (x, z) for planar bodies, all of x, y, z for free ones
        axes = [0, 1, 2] if self._free else [0, 2]
        ee = np.arange(base.ee_sensor.start, base.ee_sensor.stop).reshape(n_ee, 3)[:, axes]
        self._up = base.up_sensor.start + np.array(axes)
        self._obs_sensors = np.concatenate([np.arange(2 * nj), ee.ravel()])
        self._zero_reference = np.zeros(2 * nj + 3 * n_ee)
        self._ee_heading = rc.end_effector_frame == "heading" and self.motion is not None

    def _bind(self, body: Body) -> None:
        super()._bind(body)
        # Sensors are evaluated once per control step (`_sense`), not in each physics step.
        body.model.opt.disableflags |= SENSOR_OFF
        self._flags_sensing = body.model.opt.disableflags & ~SENSOR_OFF
        self._flags_stepping = body.model.opt.disableflags
        self._opt = body.model.opt
        self._height_offset = 0.0 if self._free else body.hip_height
        base = self._base
        self._scales = (
            reward_scales(body.leg_lengths, base.leg_lengths, body.mass, base.mass)
            if self.config.reward.normalize
            else RewardScales.identity()
        )
        if self._clip is not None:
            self._gait = self._clip_gait(body)
            self.motion = self._gait if self.config.imitation else None
            self._index_fall_geoms()
        elif self.motion is not None and self.config.retarget:
            legs = leg_chains(self.definition, body.segment_lengths, base.segment_lengths)
            self.motion = RetargetedGait(self._gait, legs)
        self._reference = self._tabulate_reference() if self.motion is not None else None

    def _clip_gait(self, body: Body) -> ClipGait:
        """The clip gait on `body` (its root path scaled by the body's hip height; with
        `env.retarget`, each leg on the base leg's hip-to-ankle path scaled by the shortest
        leg, and the root path by that scale), cached for the last `CLIP_GAITS` bodies (a
        family draws a new body at nearly every reset)."""
        key = tuple(sorted(body.shape.items()))
        gait = self._clip_gaits.pop(key, None)
        if gait is None:
            joints = tuple(j.name for j in self.definition.joints)
            to_qpos = lambda pose: self.definition.pose_qpos(body, pose)  # noqa: E731
            if self.config.retarget:
                to_qpos = self._retargeted(body, to_qpos)
            gait = ClipGait.from_clip(self._clip, joints, to_qpos, body.qpos_idx)
        self._clip_gaits[key] = gait
        while len(self._clip_gaits) > CLIP_GAITS:
            self._clip_gaits.popitem(last=False)
        return gait

    def _retargeted(self, body: Body, to_qpos):
        """`to_qpos` of a clip on `body` with its legs retargeted (`retarget_pose`)."""
        base = self._base
        legs = leg_chains(self.definition, body.segment_lengths, base.segment_lengths)
        scale = min(leg.scale for leg in legs)
        root = scale * base.hip_height / body.hip_height  # pose_qpos scaled it by the hip height
        idx = np.asarray(body.qpos_idx)

        def retargeted(pose) -> np.ndarray:
            qpos = to_qpos(pose)
            qpos[:, :3] *= root
            qpos[:, idx] = retarget_pose(qpos[:, idx], legs, scale)
            return qpos

        return retargeted

    def _tabulate_reference(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Reference pose, joint velocity and end-effectors (root frame) over one cycle.

        Rows k = 0..K sample φ = k/K; returns (rows [K+1] of [P], row differences [K] of [P]) as
        lists, so that a lookup is one multiply-add (indexing a list is cheaper per step).
        """
        c, d, m = self.character, self.data, self.model
        phis = np.arange(REFERENCE_SAMPLES + 1) / REFERENCE_SAMPLES
        poses = self.motion.pose(phis)
        ee = np.empty((len(phis), len(c.ee_site_ids), 3))
        d.qpos[:] = m.qpos0
        heading = self._ee_heading
        for k, pose in enumerate(poses):
            if heading:  # the clip's own root orientation: its tilt is imitated
                d.qpos[:7] = self.motion.root_qpos(float(phis[k]))
            d.qpos[c.qpos_idx] = pose
            mujoco.mj_kinematics(m, d)
            if heading:
                ee[k] = self._end_effectors_in_heading_frame()
                continue
            # what the end-effector sensors measure: sites in the root's inertial frame (a
            # FRAMEPOS sensor's body reference); kinematics alone, no dynamics or collisions
            rot = d.ximat[c.root_body_id].reshape(3, 3)
            ee[k] = (d.site_xpos[c.ee_site_ids] - d.xipos[c.root_body_id]) @ rot
        velocities = self.motion.velocity(phis)
        torques = np.zeros_like(poses)
        table = np.concatenate([poses, velocities, ee.reshape(len(phis), -1), torques], axis=1)
        if isinstance(self.motion, ClipGait):
            self._bodies = self._tabulate_bodies(phis)
        return list(table), list(np.diff(table, axis=0))

    def _target_facing(self) -> tuple[float, float]:
        """Eq. 6's d′: the target direction, or with `reward.facing: clip` the clip's root
        facing at this phase turned onto the target direction (unit length)."""
        if self.config.reward.facing == "target":
            return self._target_dir
        return self.clip_facing()

    def clip_facing(self) -> tuple[float, float]:
        """A clip gait's root facing at this phase turned onto the target direction (unit
        length): where its reference faces now."""
        fx, fy = self._gait.root_facing(self._phase)
        hx, hy = self._heading
        dx, dy = hx * fx - hy * fy, hy * fx + hx * fy
        norm = math.hypot(dx, dy) or 1.0
        return dx / norm, dy / norm

    def _tabulate_bodies(self, phis: np.ndarray) -> tuple[list, list]:
        """A clip gait's reference root height and body positions relative to the root, in the
        root's heading frame (the body position error's reference): rows [1 + 3B] at φ = k/K,
        and their differences, as `_tabulate_reference`'s table."""
        c, d, m = self.character, self.data, self.model
        out = np.empty((len(phis), 1 + 3 * (m.nbody - 2)))
        for k, phi in enumerate(phis):
            d.qpos[:] = m.qpos0
            d.qpos[:7] = self.motion.root_qpos(float(phi))
            d.qpos[c.qpos_idx] = self.motion.pose(float(phi))
            mujoco.mj_kinematics(m, d)
            out[k, 0] = d.qpos[2]
            out[k, 1:] = self._bodies_in_heading_frame().ravel()
        return list(out), list(np.diff(out, axis=0))

    def _bodies_reference(self) -> np.ndarray:
        x = (self._phase % 1.0) * REFERENCE_SAMPLES
        k = int(x)
        rows, slopes = self._bodies
        return rows[k] + (x - k) * slopes[k]

    def _end_effectors_in_heading_frame(self) -> np.ndarray:
        """The end-effector sites [n_ee, 3] relative to the root, in its heading frame (yaw
        removed, tilt kept): `reward.end_effector_frame: heading`."""
        d, c = self.data, self.character
        return in_heading_frame(
            d.site_xpos[c.ee_site_ids], d.xpos[c.root_body_id], d.xmat[c.root_body_id]
        )

    def _bodies_in_heading_frame(self) -> np.ndarray:
        """Every body but the root [B, 3] relative to the root, in its heading frame (yaw
        removed), for the current kinematics."""
        return bodies_in_heading_frame(self.data.xpos, self.data.xmat, self.character.root_body_id)

    def body_error(self) -> tuple[float, float]:
        """A clip gait's (mean, max) distance (m) between the bodies' simulated and reference
        positions, each relative to its own root in its own heading frame, at this phase."""
        ref = self._bodies_reference()[1:].reshape(-1, 3)
        return body_position_error(self._bodies_in_heading_frame(), ref)

    def root_drift(self) -> float:
        """A clip gait's horizontal distance (m) between the root and the reference root path:
        the clip's root from the episode's start, advancing cycle by cycle along the target."""
        g = self._gait
        path = g.root_path(self._phase) - g.root_path(self._phase0)
        hx, hy = self._heading
        ref_x = self._origin[0] + hx * path[0] - hy * path[1]
        ref_y = self._origin[1] + hy * path[0] + hx * path[1]
        return math.hypot(self.data.qpos[0] - ref_x, self.data.qpos[1] - ref_y)

    def _reference_at(self, phase: float) -> np.ndarray:
        """Linear interpolation in the tabulated reference: [pose, joint velocity, ee, 0]."""
        x = (phase % 1.0) * REFERENCE_SAMPLES
        k = int(x)
        rows, slopes = self._reference
        return rows[k] + (x - k) * slopes[k]

    # --- episode ------------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self._task = self.task_from_options(options)
        self._load(self._task)
        rng = self.np_random
        phase = self._phases.sample(rng) if self._phases is not None else float(rng.random())
        self._init_state(rng, phase=phase)
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
        if isinstance(self._gait, ClipGait):  # the clip's root state too, facing the target
            self._root_state(phase)
        if len(c.contact_site_ids):
            d.qpos[:] = self.ground_posture(d.qpos.copy())
            d.qpos[self._height_adr] += 1e-3
        self._stand(self.root_height())  # (after the fit: its standing height in this pose)
        d.ctrl[:] = d.qpos[c.qpos_idx]
        mujoco.mj_forward(m, d)
        self._sense()
        self._steps = 0
        self._watch_stability()
        self._com = [tuple(d.sensordata[c.com_sensor].tolist())] * (self._window + 1)
        self._com_vel = (0.0, 0.0, 0.0)
        self._phase0 = phase
        self._origin = (float(d.qpos[0]), float(d.qpos[1]))
        self._look_ahead()

    def _root_state(self, phase: float) -> None:
        """Reference state initialisation of a clip gait's free root: the clip's orientation
        (its travel turned onto the target direction) and its linear and angular velocity."""
        d, g = self.data, self._gait
        hx, hy = self._heading
        turn = Rotation.from_euler("z", math.atan2(hy, hx))
        d.qpos[3:7] = (turn * g.root_rotation(phase)).as_quat(scalar_first=True)
        linear, angular = g.root_velocity(phase)
        d.qvel[0:3] = turn.apply(linear)
        d.qvel[3:6] = angular

    def root_height(self) -> float:
        """The root's height above the ground (m)."""
        return float(self.data.qpos[self._height_adr] + self._height_offset)

    def _stand(self, height: float) -> None:
        """The fall rule: a fall is the root below `fall_height_ratio` of `height`, the body's
        own standing height, i.e. its root height placed on the ground by [WL19] Eq. 1 in its
        reference pose at the episode's start. Not the straight legs' hip height: a body with
        legs 0.7/1.3 stands on its short leg, so a threshold from the longest leg counted
        bodies as fallen that stand (tests/test_family_rules.py)."""
        self._standing = (height, self.character.hip_height)
        self._fall_height = self.config.fall_height_ratio * height

    def _look_ahead(self) -> None:
        """The reference at the next control step's phase: observed now, the PD target and
        the imitation reward of the next step (one lookup per step)."""
        self._ref_next = (
            self._reference_at(self._phase + self._dphase) if self._reference is not None else None
        )

    def _set_targets(self) -> None:
        """Target speed and direction of the task, normalized for the body ([WL19] Table 1)."""
        base_v = (
            float(self._task[self._velocity_idx])
            if self._velocity_idx is not None
            else self.config.target_velocity
        )
        if base_v is None:  # the gait's own speed
            base_v = self._gait_speed
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
        self._heading = (math.cos(heading), math.sin(heading))  # where a clip gait faces

    def set_goal(self, name: str, value: float) -> np.ndarray:
        """Change a goal of the task mid-episode (target_velocity, target_direction): the targets
        follow at once, the body and its state stay. Returns the new observation."""
        index = self.goal_index(name)
        if index is None or name in dict(self._shape_idx):
            raise ValueError(f"{name!r} is not a goal dimension of this task space")
        if not np.isfinite(value):
            raise ValueError(f"goal {name!r} must be a finite number, got {value}")
        self._task = self._task.copy()
        self._task[index] = float(value)
        self._set_targets()
        self._last_obs = self._observe()
        return self._last_obs

    def _shape_changed(self, com_before: np.ndarray) -> None:
        """Targets follow the new body; the average COM velocity continues: its history shifts
        by the COM's jump."""
        self._sense()
        self._set_targets()
        shift = self.data.sensordata[self.character.com_sensor] - com_before
        self._com = [tuple((np.array(p) + shift).tolist()) for p in self._com]
        height, hip = self._standing  # the new body stands as much higher as its legs are
        self._stand(height * self.character.hip_height / hip)
        self._look_ahead()  # the reference table is the new body's

    # --- step ---------------------------------------------------------------------------------

    def step(self, action: np.ndarray):
        c, d = self.character, self.data
        self._phase += self._dphase
        # PD target = reference pose + offset; MuJoCo clamps ctrl to the joint range.
        a = np.minimum(np.maximum(action, -1.0), 1.0) * self._action_scale
        ref = self._ref_next  # the reference at this phase
        if ref is not None:
            a += ref[: self._nj]
        d.ctrl[:] = a
        mujoco.mj_step(self.model, d, nstep=self.frame_skip)
        self._sense()
        self._steps += 1
        self._update_com_velocity()
        if self.diverging():
            return self._diverged()
        reward, terms = self._reward(ref)
        self._look_ahead()
        obs = self._observe()
        self._last_obs = obs
        if self._clip is not None:  # DeepMimic's rule: root, chest or neck on the ground
            fell = self.fall_contact()
        else:
            tilted = d.sensordata[c.up_sensor.start + 2] < self._min_up
            fell = not self.definition.swims and bool(
                self.root_height() < self._fall_height or tilted
            )
        stalled = not fell and self._stalled()
        off_course = not (fell or stalled) and self._off_course()
        deviated = not (fell or stalled or off_course) and self._deviated()
        ended = fell or stalled or off_course or deviated
        truncated = (self._steps >= self._max_steps or self._timed_out()) and not ended
        if self._phases is not None and (ended or truncated):
            self._phases.update(self._phase0, failed=fell or deviated)
        info = self._step_info(
            terms, fell=fell, stalled=stalled, off_course=off_course, deviated=deviated
        )
        return obs, reward, ended, truncated, info

    def _step_info(
        self, terms: dict, *, fell=False, stalled=False, off_course=False, deviated=False,
        diverged=False,
    ) -> StepInfo:  # fmt: skip
        return StepInfo(
            task=self._task.copy(), fell=fell, stalled=stalled, off_course=off_course,
            deviated=deviated, diverged=diverged, dphi=1.0, reward_spike=0.0, reward_terms=terms,
        )  # fmt: skip

    def _deviated(self) -> bool:
        """`deviation_limit`: a body (relative to the root, in its heading frame) or the root's
        height is farther than that from the clip gait's reference."""
        limit = self.config.deviation_limit
        if limit is None or self._clip is None:
            return False
        _, worst = self.body_error()
        height = abs(self.data.qpos[2] - self._bodies_reference()[0])
        return worst > limit or height > limit

    def _stalled(self) -> bool:
        """`stall_speed_ratio`: after a full velocity window, the average COM velocity along the
        target direction is below that share of the target speed."""
        ratio = self.config.stall_speed_ratio
        speed = abs(self._target_v)
        if ratio is None or self._steps < self._window or speed < 1e-6:
            return False
        (dx, dy), (vx, vy, _) = self._target_dir, self._com_vel  # the direction carries the sign
        return vx * dx + vy * dy < ratio * speed

    def _off_course(self) -> bool:
        """`heading_error_limit`: a free body faces farther than that from its target."""
        limit = self.config.heading_error_limit
        if limit is None:
            return False
        error = self.heading_error()
        return error is not None and error > limit

    def heading_error(self) -> float | None:
        """The angle (rad, 0-π) between a free body's facing direction (the root's x axis in the
        ground plane) and the one it should face (Eq. 6's d′, `_target_facing`); None for a
        planar body or one facing straight up or down."""
        return self._angle_to(*self._target_facing()) if self._free else None

    def facing_error(self) -> float:
        """A clip gait's angle (rad, 0-π) between the body's facing and the clip's own facing
        at this phase (`clip_facing`), whatever the reward's facing term wants: how far the
        body's yaw has turned from its reference's (0 for a body facing straight up or down)."""
        return self._angle_to(*self.clip_facing()) or 0.0

    def _angle_to(self, dx: float, dy: float) -> float | None:
        """The angle (rad, 0-π) between the facing direction and the unit vector (dx, dy);
        None when the root's x axis is vertical."""
        fx, fy = self._facing()
        if fx == fy == 0.0:
            return None
        return math.acos(max(-1.0, min(1.0, fx * dx + fy * dy)))

    def _facing(self) -> tuple[float, float]:
        """The facing direction d: the root's x axis in the ground plane, of unit length ((0, 0)
        when the root's x axis is vertical)."""
        xmat = self.data.xmat[self.character.root_body_id]
        fx, fy = xmat[0], xmat[3]
        norm = math.hypot(fx, fy) or 1.0
        return fx / norm, fy / norm

    def _update_com_velocity(self) -> None:
        """[WL19] Eq. 6 uses the COM velocity averaged over the last `com_velocity_window` s."""
        cx, cy, cz = com = self.data.sensordata[self.character.com_sensor].tolist()
        ring = self._com
        elapsed = self._steps if self._steps < self._window else self._window
        ox, oy, oz = ring[(self._steps - elapsed) % len(ring)]
        inv = 1.0 / (elapsed * self.dt)
        self._com_vel = ((cx - ox) * inv, (cy - oy) * inv, (cz - oz) * inv)
        ring[self._steps % len(ring)] = com

    def _diverged(self) -> tuple:
        info = self._step_info(dict.fromkeys(REWARD_TERMS, 0.0), diverged=True)
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
        """[WL19] Eq. 4-7 on this step's sensors (`rewards.py`); reports each term."""
        c, d, rc = self.character, self.data, self.config.reward
        s = d.sensordata
        n = self._ee.stop
        err = s[:n] - (self._zero_reference[:n] if ref is None else ref[:n])
        if self._ee_heading:
            err[self._ee] = self._end_effectors_in_heading_frame().ravel() - ref[self._ee]
        pose, velocity, ee = wl19_imitation(
            err[self._q],
            err[self._dq],
            err[self._ee].reshape(self._n_ee, 3),
            rc.sigma_pose,
            rc.sigma_velocity,
            rc.sigma_end_effector,
        )
        fx, fy = self._facing()  # d, against d′
        dx, dy = self._target_facing()
        vx, vy, _ = self._com_vel
        com, direction = wl19_task(
            (vx - self._target_vel[0], vy - self._target_vel[1]),
            (fx - dx, fy - dy),
            rc.sigma_com_velocity,
            rc.sigma_direction,
            self._scales.direction,
        )
        torque = wl19_regularization(
            s[c.tau_sensor], c.torque_limit, rc.sigma_torque, self._scales.energy
        )
        terms = WL19Terms(pose, velocity, ee, com, direction, torque)
        combine = wl19_reward if rc.combine == "sum" else wl19_reward_product
        reward = combine(terms, self._weights)
        reported = {
            "pose": pose,
            "velocity": velocity,
            "end_effector": float(ee.sum()),
            "com_velocity": com,
            "direction": direction,
            "torque": torque,
            "task": wl19_task_share(terms, self._weights),
        }
        return reward, reported

    def _observe(self) -> np.ndarray:
        """[WL19] §4.1: s = (b, (q, q̇, e_1..e_K), s_s), with the sensory state s_s: the
        reference postures 0.0, 0.5 and 1.0 s ahead and the target and average COM velocity
        in the root's heading frame. Free bodies see the world's horizontal directions (up
        vector, root velocity, target direction, COM velocity) in the heading frame: turning
        the whole scene about the vertical leaves the observation unchanged."""
        c, d = self.character, self.data
        vx, vy, vz = self._com_vel
        parts = [self.observed_task(), d.sensordata[self._obs_sensors]]  # joints, end-effectors
        if self._free:  # the heading frame: the root's x axis projected on the ground
            xmat = d.xmat[c.root_body_id]
            hx, hy = self._facing()

            def heading(x: float, y: float) -> tuple[float, float]:
                return hx * x + hy * y, hx * y - hy * x

            up = d.sensordata[c.up_sensor]
            root_v = d.qvel[0:3]
            tx, ty = heading(*self._target_dir)
            vx, vy = heading(vx, vy)
            parts += [
                (*heading(up[0], up[1]), up[2]),
                (*heading(root_v[0], root_v[1]), root_v[2]),
                d.qvel[3:6],  # angular velocity: the free joint's is in the root's frame
                (xmat[6], tx, ty, vy),
            ]
        else:  # planar: the sagittal plane is the heading frame
            parts += [d.sensordata[self._up], d.qvel[0:3]]  # up (x, z); root x, z, pitch rate
        parts.append((self.root_height(), self._target_v, vx, vz))
        if self._reference is not None:
            x = 2.0 * math.pi * self._phase
            parts.append((math.sin(x), math.cos(x)))
            parts.append(self._ref_next[: self._nj])  # the next control step's reference pose
            period = self.motion.period
            for ahead in FUTURE_POSES:
                parts.append(self._reference_at(self._phase + ahead / period)[: self._nj])
        return np.concatenate(parts, dtype=np.float32)

    def observation_layout(self) -> list[tuple[str, int]]:
        """The observation's segments in order, (name, size), as `_observe` builds them."""
        nj, n_ee, axes = self._nj, self._n_ee, 3 if self._free else 2
        layout = [("task", len(self._task)), ("q", nj), ("dq", nj), ("end_effectors", axes * n_ee)]
        if self._free:
            layout += [("up_heading", 3), ("root_velocity_heading", 3)]
            layout += [("root_angular_velocity", 3), ("root_up_z_target_direction_com_vy", 4)]
        else:
            layout += [("up_xz", 2), ("root_velocity_x_z_pitch", 3)]
        layout.append(("root_height_target_speed_com_vx_vz", 4))
        if self._reference is not None:
            layout += [("phase_sin_cos", 2), ("reference_pose_next", nj)]
            layout += [(f"reference_pose_{ahead:g}s", nj) for ahead in FUTURE_POSES]
        return [(name, size) for name, size in layout if size > 0]  # no task: no task segment

    @property
    def tracks_bodies(self) -> bool:
        """Whether `body_error` has a reference: a clip gait's."""
        return self._clip is not None

    @property
    def target_speed(self) -> float:
        """The target speed on this body (m/s), after [WL19] Table 1's normalization."""
        return float(self._target_v)

    @property
    def clip_speed(self) -> float | None:
        """A clip gait's speed on this body (m/s; the clip's root path scaled by the body's hip
        height); None for a procedural gait."""
        return self._gait.speed if self._clip is not None else None

    @property
    def horizon_seconds(self) -> float:
        """The env's own episode limit (s)."""
        return self._max_steps * self.dt

    @property
    def sim_time(self) -> float:
        return self._steps * self.dt
