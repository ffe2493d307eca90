"""The env core that ParamEnv ([WL19]) and SkillEnv ([L21]) share.

A family env draws task parameters a from its task space at every reset (or takes
`options={"task": a}`), builds the body F(B̄, b) for the shape part of a (compiled bodies are
cached per shape), places it on the ground, ends an episode when the simulation diverges, and can
change the body mid-episode ([WL19] §5.2). The subclasses add their reference motion,
observation, reward and termination.
"""

from __future__ import annotations

import copy
import dataclasses
from abc import ABC, abstractmethod
from collections.abc import Mapping
from functools import cache, lru_cache
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from paramimic.characters import Body, registration
from paramimic.characters.body import TIMESTEP, stable_pd
from paramimic.characters.dimensions import Reshaper
from paramimic.characters.ground_fit import fit_ground_contact, lift_to_ground
from paramimic.config import EnvConfig
from paramimic.task_space import TaskSpace

# MuJoCo's warnings for a bad qpos, qvel or qacc (it resets the state when one fires)
INSTABILITY = slice(
    int(mujoco.mjtWarning.mjWARN_BADQPOS), int(mujoco.mjtWarning.mjWARN_BADQACC) + 1
)
MAX_SPEED = 100.0  # an RMS of qvel above this (m/s, rad/s) is a diverged simulation


def in_heading_frame(points: np.ndarray, origin: np.ndarray, xmat: np.ndarray) -> np.ndarray:
    """Points [N, 3] relative to `origin`, in the heading frame of the body whose rotation
    matrix (row-major [9]) is `xmat`: its x axis in the ground plane; yaw removed, tilt kept."""
    fx, fy = xmat[0], xmat[3]
    norm = float(np.hypot(fx, fy)) or 1.0
    fx, fy = fx / norm, fy / norm
    rel = points - origin
    return np.column_stack(
        [rel[:, 0] * fx + rel[:, 1] * fy, rel[:, 1] * fx - rel[:, 0] * fy, rel[:, 2]]
    )


def bodies_in_heading_frame(xpos: np.ndarray, xmat: np.ndarray, root: int) -> np.ndarray:
    """Every body after `root` [B, 3] relative to the root, in the root's heading frame:
    what the body position error compares."""
    return in_heading_frame(xpos[root + 1 :], xpos[root], xmat[root])


def body_position_error(simulated: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """(mean, max) distance (m) between bodies [B, 3] simulated and their reference."""
    err = np.linalg.norm(simulated - reference, axis=1)
    return float(err.mean()), float(err.max())


@lru_cache(maxsize=1)
def _size_names() -> tuple[str, ...]:
    model = mujoco.MjModel.from_xml_string("<mujoco/>")
    return tuple(n for n in dir(model) if n.startswith("n") and isinstance(getattr(model, n), int))


def _layout(model: mujoco.MjModel) -> tuple[int, ...]:
    """Every size of a model (nq, nv, nbody, ..., narena): equal for all shapes of a body."""
    return tuple(getattr(model, n) for n in _size_names())


def reusable_data(model: mujoco.MjModel, data: mujoco.MjData | None) -> mujoco.MjData:
    """`data` reset for `model` when it was made for a model of the same sizes (another shape of
    the same body), else a new MjData. MuJoCo's mjData holds no pointer to its model (the Python
    object's `.model` keeps the first one, read here only for its sizes), and allocating one
    costs more than the rest of a reset; stepping reused data is bit-identical."""
    if data is not None and _layout(data.model) == _layout(model):
        mujoco.mj_resetData(model, data)
        return data
    return mujoco.MjData(model)


def _penetration(data: mujoco.MjData) -> float:
    """The deepest penetration among `data`'s contacts (m, >= 0)."""
    return max(0.0, -float(data.contact.dist[: data.ncon].min(initial=0.0)))


@cache
def _reshaper(character: str) -> Reshaper:
    return Reshaper(registration(character).character)


@lru_cache(maxsize=32)
def compiled_body(
    character: str,
    shape: tuple[tuple[str, float], ...],
    timestep: float = TIMESTEP,
    pd_gain: float | None = None,
    stable: bool = False,
) -> Body:
    """F(B̄, b) compiled (by editing the character's one spec) for a physics time step, cached
    per (character, shape, time step, gain, servo): shared by the envs of a process. `pd_gain`:
    one k_p for every servo, k_d = 2√k_p ([L21] §7: 600 and 49), on a copy of the model;
    `stable`: the servos as stable PD ([WL19] Eq. 3, `stable_pd`)."""
    body = _reshaper(character)(dict(shape), timestep)
    if pd_gain is None and not stable:
        return body
    model = copy.copy(body.model)
    if pd_gain is not None:
        model.actuator_gainprm[:, 0] = pd_gain
        model.actuator_biasprm[:, 1] = -pd_gain
        model.actuator_biasprm[:, 2] = -2.0 * np.sqrt(pd_gain)
    if stable:
        model = stable_pd(model, timestep)
    return dataclasses.replace(body, model=model)


class EnvCore(gym.Env, ABC):
    metadata = {"render_modes": [], "render_fps": 30}
    GOALS: frozenset[str] = frozenset()  # task parameters besides the shape this env reads

    def __init__(
        self,
        character: str = "walker",
        task: Mapping[str, tuple[float, float]] | None = None,
        config: EnvConfig | Mapping[str, Any] | None = None,
    ) -> None:
        """A registered character's family over the task space `task` (name -> [min, max]),
        with the env section of an experiment's config."""
        self.registration = registration(character)
        self.definition = self.registration.character
        config = config if isinstance(config, EnvConfig) else EnvConfig.model_validate(config or {})
        if config.physics_hz is None:  # the character's rate
            config = config.with_rate(self.registration.physics_hz)
        self.config = config
        task = dict(task or {})
        shape_names = self.definition.param_names()
        unknown = set(task) - set(shape_names) - self.GOALS
        if unknown:
            raise ValueError(
                f"unknown task parameters {sorted(unknown)} for {character!r} in "
                f"{type(self).__name__}; allowed: {sorted(set(shape_names) | self.GOALS)}"
            )
        self.task_space = TaskSpace.from_ranges(task)
        names = self.task_space.names
        self._shape_idx = [(n, i) for i, n in enumerate(names) if n in shape_names]
        self._task = self.task_space.center.copy()
        self.frame_skip = self.config.frame_skip
        self._timestep = 1.0 / self.config.physics_hz  # the body is compiled at this rate
        self._base = self._compiled(())
        self._base_data = mujoco.MjData(self._base.model)
        self.character: Body | None = None
        self._height_adr = 1 if self.definition.planar else 2  # qpos of the root height
        self._time_limit: int | None = None  # control steps; set_time_limit
        self._setup()

    @abstractmethod
    def _setup(self) -> None:
        """The subclass's own set-up: reference motion, spaces, reward weights."""

    def set_time_limit(self, seconds: float | None) -> None:
        """Episodes from now on end (truncated) after `seconds` if that comes before the env's
        own end (`env.horizon_growth` during training); None: the env's own limit only."""
        self._time_limit = None if seconds is None else max(1, int(round(seconds / self.dt)))

    def _timed_out(self) -> bool:
        return self._time_limit is not None and self._steps >= self._time_limit

    def goal_index(self, name: str) -> int | None:
        """The task dimension of a goal or condition, None when the task space has none."""
        names = self.task_space.names
        return names.index(name) if name in names else None

    # --- task and body --------------------------------------------------------------------------

    def task_from_options(self, options: Mapping[str, Any] | None) -> np.ndarray:
        """The task of a reset: `options["task"]` (a mapping or an array, checked against the
        task space) or a uniform draw from it."""
        task = (options or {}).get("task")
        if task is None:
            return self.task_space.sample(self.np_random, 1)[0]
        a = (
            self.task_space.from_dict(task)
            if isinstance(task, Mapping)
            else np.array(task, dtype=np.float64).reshape(-1)  # a copy: the caller keeps theirs
        )
        if a.shape != (self.task_space.dim,) or not self.task_space.contains(a)[0]:
            raise ValueError(f"task {a} is not inside the task space {self.task_space.ranges()}")
        return a

    def observed_task(self) -> np.ndarray:
        """The task as the policy observes it: with `env.observe_shape` false, the shape
        parameters at the base body's 1.0 (the policy is blind to the body)."""
        if self.config.observe_shape or not self._shape_idx:
            return self._task
        task = self._task.copy()
        task[[i for _, i in self._shape_idx]] = 1.0
        return task

    def _compiled(self, shape: tuple[tuple[str, float], ...]) -> Body:
        c = self.config
        return compiled_body(self.definition.name, shape, self._timestep, c.pd_gain, c.stable_pd)

    def body_for(self, task: np.ndarray) -> Body:
        """The compiled body of the shape part of `task`."""
        shape = tuple((n, round(float(task[i]), 9)) for n, i in self._shape_idx)
        return self._compiled(shape)

    def _load(self, task: np.ndarray) -> bool:
        """Make the body of `task` current (its model and data); False if it already was."""
        body = self.body_for(task)
        if self.character is body:
            return False
        self.character = body
        self._bind(body)
        return True

    def _bind(self, body: Body) -> None:
        """Set up model, data and what depends on the body (subclasses extend it)."""
        self.model = body.model
        self.data = reusable_data(body.model, getattr(self, "data", None))

    # --- ground, divergence, falls ----------------------------------------------------------------

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
            height_joint = 0 if not self.definition.planar else c.model.joint("rootz").id
            return fit_ground_contact(
                c.model, self.data, qpos, targets, c.contact_site_ids, height_joint, joints,
                max_change=self.config.ground_fit_max_change,
            ).qpos  # fmt: skip
        return lift_to_ground(c.model, self.data, qpos, c.contact_site_ids, self._height_adr)

    def _watch_stability(self) -> None:
        """Remember the instability warnings so far: `diverging` looks for new ones."""
        self._unstable = int(self.data.warning.number[INSTABILITY].sum())
        self._max_qvel_sq = self.model.nv * MAX_SPEED**2

    def diverging(self) -> bool:
        """NaN or exploding velocities, or MuJoCo's own reset of the state on a bad qpos, qvel
        or qacc: the episode ends, never the run."""
        qvel = self.data.qvel
        return (
            not qvel @ qvel < self._max_qvel_sq
            or self.data.warning.number[INSTABILITY].sum() > self._unstable
        )

    def fall_contact(self) -> bool:
        """A fall body (root, torso, head, ...) touches the floor."""
        d = self.data
        for i in range(d.ncon):
            g1, g2 = d.contact.geom1[i], d.contact.geom2[i]
            if (g1 == self._floor and self._fall_geoms[g2]) or (
                g2 == self._floor and self._fall_geoms[g1]
            ):
                return True
        return False

    def _index_fall_geoms(self) -> None:
        m = self.model
        fall = [m.body(b).id for b in self.definition.fall_bodies]
        self._fall_geoms = np.isin(m.geom_bodyid, fall)
        self._floor = m.geom("floor").id if not self.definition.swims else -1

    # --- shape change on the fly ([WL19] §5.2) ----------------------------------------------------

    def set_shape(self, shape: Mapping[str, float]) -> np.ndarray:
        """Change the body mid-episode ([WL19] §5.2): rebuild the model for the new shape, copy
        joint positions, velocities and controls, lift the body by what its grown limbs sink
        into the ground, and carry on from the same state and phase (the body's own shape:
        nothing changes). The shape parameters must be task dimensions (the policy observes
        them). Returns the new observation."""
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
        if self.body_for(a) is self.character:  # the same body: nothing to carry over
            return self._last_obs
        old = self.data  # its state, kept before the data may be reset for the new body
        qpos, qvel, ctrl, time = old.qpos.copy(), old.qvel.copy(), old.ctrl.copy(), old.time
        warmstart = old.qacc_warmstart.copy()
        com_before = old.sensordata[self.character.com_sensor].copy()
        mujoco.mj_kinematics(self.model, old)  # the contacts at the state's own positions
        mujoco.mj_collision(self.model, old)
        depth_before = _penetration(old)
        self._task = a
        self._load(a)
        d = self.data
        d.qpos[:], d.qvel[:], d.ctrl[:] = qpos, qvel, ctrl
        d.qacc_warmstart[:], d.time = warmstart, time
        mujoco.mj_forward(self.model, d)
        # Lift by what the new limbs sink deeper than the old ones rested: MuJoCo's soft contacts
        # rest slightly inside the ground, and lifting a changing body out of it every control
        # step would leave it hovering on its toes.
        lift = _penetration(d) - depth_before  # (mj_forward found the contacts)
        if lift > 0:
            d.qpos[self._height_adr] += lift
            mujoco.mj_forward(self.model, d)
        self._watch_stability()
        self._shape_changed(com_before)
        obs = self._observe()
        self._last_obs = obs
        return obs

    def _shape_changed(self, com_before: np.ndarray) -> None:
        """What a subclass carries over to the new body after `set_shape` (the whole-body COM
        before the change [3] given)."""

    @abstractmethod
    def _observe(self) -> np.ndarray:
        """The observation of the current state [obs_dim] (float32)."""

    # --- accessors ------------------------------------------------------------------------------

    @property
    def task(self) -> np.ndarray:
        return self._task.copy()
