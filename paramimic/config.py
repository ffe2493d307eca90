"""Pydantic models of a whole experiment, validated before anything starts.

Sections: `character`, `task`, `env`, `ppo`, `curriculum`, `actors`, `train`. Every field is
documented once, here; numbers from the papers name their source.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from paramimic.recipes import PRESETS, apply
from paramimic.task_space import TaskSpace

PositiveFloat = Annotated[float, Field(gt=0)]
NonNegativeFloat = Annotated[float, Field(ge=0)]
PositiveInt = Annotated[int, Field(gt=0)]
# An MLP's hidden layers: 1-8 of 1-4096 units ([L21] §7's 4x1024 policy is the largest the
# papers use); a bound, so that a typo cannot ask for a 120 GB layer after Redis and Ray are up.
Units = Annotated[int, Field(ge=1, le=4096)]
Layers = Annotated[tuple[Units, ...], Field(min_length=1, max_length=8)]
# A seed torch, numpy and Ray all take.
Seed = Annotated[int, Field(ge=0, le=2**31 - 1)]
# Bounds of the task goals a config may set (beyond them no body is meant to go).
GOAL_LIMITS = {"target_velocity": (-20.0, 20.0), "target_direction": (-4 * math.pi, 4 * math.pi),
               "gravity": (0.0, 10.0), "jump_height": (0.0, 10.0)}  # fmt: skip

# Task goals and physical conditions understood by the environments besides the character's
# shape parameters.
TASK_GOALS = {
    "target_velocity": "target average COM speed (m/s) along the target direction",
    "target_direction": "heading of the target velocity in the ground plane (rad, 0 = +x; 3D)",
    "gravity": "gravity as a multiple of 9.81 m/s² (skill env)",
    "jump_height": "peak rise of the COM above its standing height (m, skill env)",
}


def _registry():
    """The character registry (`paramimic.characters`), imported when a config is validated:
    it loads MuJoCo, which the bare config models do not need."""
    from paramimic import characters

    return characters


class Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True, allow_inf_nan=False)


class RewardConfig(Section):
    """[WL19] Eq. 4-7: the weights w1..w6 default to the character's row of Table 3
    (`Registration.reward_weights`); the sensitivities σ1..σ6 are the paper's for all bodies."""

    w_pose: float | None = Field(None, ge=0, description="w1, joint angle imitation")
    w_velocity: float | None = Field(None, ge=0, description="w2, joint velocity imitation")
    w_end_effector: float | None = Field(
        None, ge=0, description="w3, per end-effector position imitation"
    )
    w_com_velocity: float | None = Field(
        None, ge=0, description="w4, average COM velocity vs target"
    )
    w_direction: float | None = Field(
        None, ge=0, description="w5, facing direction vs target direction"
    )
    w_torque: float | None = Field(None, ge=0, description="w6, joint torque regularizer")
    sigma_pose: PositiveFloat = 0.02  # σ1
    sigma_velocity: PositiveFloat = 0.5  # σ2
    sigma_end_effector: PositiveFloat = 0.2  # σ3
    sigma_com_velocity: PositiveFloat = 0.2  # σ4
    sigma_direction: PositiveFloat = 0.05  # σ5
    sigma_torque: PositiveFloat = 0.1  # σ6
    normalize: bool = Field(
        True, description="scale velocity, direction and energy by the body ([WL19] §4.3)"
    )
    end_effector_frame: Literal["root", "heading"] = Field(
        "root",
        description="the frame of Eq. 5's end-effector positions: root, the root's own frame "
        "(the body's tilt is not imitated; [WL19]'s gaits stay upright), or heading, relative to "
        "the root in its heading frame (yaw removed, tilt kept, as DeepMimic's end-effector term): "
        "a clip that rolls the body over, the cartwheel, is then imitated as a whole",
    )
    facing: Literal["target", "clip"] = Field(
        "target",
        description="Eq. 6's d′, the direction the facing term wants: target, the target "
        "direction ([WL19]); clip, a clip gait's own root facing at this phase turned onto the "
        "target direction, for a clip that does not face where it travels (the cartwheel faces "
        "across its path and turns on the way; without it nothing holds the body's yaw)",
    )
    combine: Literal["sum", "product"] = Field(
        "sum",
        description="sum: Eq. 4, the weighted mean of the bells; product: the bells multiplied "
        "(terms of weight 0 left out), so that a step pays only as much as its worst term",
    )

    @property
    def in_place(self) -> bool:
        """No velocity task: the COM-velocity term's weight is 0 (a clip performed in place,
        [WL19] Fig. 2c's dance), so there is no speed to hold."""
        return self.w_com_velocity == 0

    def weights(self, table3: tuple[float, ...]) -> tuple[float, ...]:
        """w1..w6: the ones set here, the character's [WL19] Table 3 row for the others."""
        names = ("w_pose", "w_velocity", "w_end_effector", "w_com_velocity", "w_direction")
        mine = [getattr(self, n) for n in (*names, "w_torque")]
        return tuple(t if w is None else w for w, t in zip(mine, table3, strict=True))


class TaskMeasureConfig(Section):
    """A declared task parameter of a skill family: a measure of the episode (and of the clip,
    for its nominal value a0) from `paramimic.motion.measures`, its unit and its task reward
    ([L21] §4.2, Eq. 8). In a config it is written inline: `task: {name: {measure: ..., range:
    [min, max], ...}}`; its range stays in `task`, the rest lands here."""

    measure: str = Field(description="a measure of paramimic.motion.measures.MEASURES")
    axis: Literal["yaw", "pitch", "roll"] | None = Field(
        None, description="rotation axis of the heading frame (root_rotation, angular velocity)"
    )
    body: str | None = Field(None, description="the end effector it reads (peak heights)")
    window: tuple[float, float] = Field(
        (0.0, 1.0), description="the share of the clip it looks at, [start, end] in [0, 1]"
    )
    unit: str | None = Field(
        None, description="unit of the range ('reference': multiples of the clip's own value); "
        "default: the measure's SI unit",
    )  # fmt: skip
    reward: Literal["spike", "continuous"] = Field(
        "spike", description="[L21] §4.2: paid once at `event`, or every step in the window"
    )
    event: Literal["clip_end", "takeoff", "window_end"] | None = Field(
        None, description="when a spike is paid; default: take-off for take-off measures, the "
        "window's end for a window, else the clip's end",
    )  # fmt: skip
    sigma: PositiveFloat | None = Field(
        None, description="σ_task of Eq. 8 in the parameter's unit; default: a sixth of the "
        "range (a tenth of the value for a constraint)",
    )  # fmt: skip

    @model_validator(mode="after")
    def _known(self) -> TaskMeasureConfig:
        from paramimic.motion.measures import MEASURES, REFERENCE, UNITS

        kind = MEASURES.get(self.measure)
        if kind is None:
            raise ValueError(f"measure {self.measure!r}: one of {sorted(MEASURES)}")
        if "axis" in kind.needs and self.axis is None:
            raise ValueError(f"measure {self.measure!r} needs an axis (yaw, pitch or roll)")
        if "body" in kind.needs and self.body is None:
            raise ValueError(f"measure {self.measure!r} needs a body (an end effector)")
        units = [*UNITS[kind.quantity], REFERENCE]
        if self.unit is not None and self.unit not in units:
            raise ValueError(f"unit {self.unit!r} of {self.measure!r}: one of {units}")
        lo, hi = self.window
        if not 0.0 <= lo < hi <= 1.0:
            raise ValueError(f"window {list(self.window)}: need 0 <= start < end <= 1")
        if self.event == "window_end" and self.window == (0.0, 1.0):
            raise ValueError("event window_end needs a window")
        return self

    def resolved_event(self) -> str:
        from paramimic.motion.measures import MEASURES

        if self.event is not None:
            return self.event
        if MEASURES[self.measure].takeoff:
            return "takeoff"
        return "window_end" if self.window != (0.0, 1.0) else "clip_end"


class SkillConfig(Section):
    """Continuous-time imitation of a clip ([L21] §4): rewards Eq. 5-8, action (d, τ)."""

    sigma_q: PositiveFloat = 3.16  # [L21] Eq. 7
    sigma_ee: PositiveFloat = 0.8
    sigma_com: PositiveFloat = 0.35
    sigma_time: PositiveFloat = 0.1
    w_q: float = Field(0.28, ge=0)
    w_ee: float = Field(0.28, ge=0)
    w_com: float = Field(0.28, ge=0)
    w_time: float = Field(0.16, ge=0)
    sigma_task: PositiveFloat = Field(0.1, description="σ_task of Eq. 8 (m for jump height)")
    # [L21] §4.2: spike task rewards weigh (1.0, 10.0), continuous ones (0.9, 0.1)
    w_tracking_spike: float = Field(1.0, ge=0)
    w_task_spike: float = Field(10.0, ge=0)
    w_tracking_continuous: float = Field(0.9, ge=0)
    w_task_continuous: float = Field(0.1, ge=0)
    tau_scale: PositiveFloat = Field(1.0, description="τ per unit action: Δφ in [e^-s, e^s]")
    time_warp: bool = Field(
        True, description="false: no time warp ([L21] §7.2's A2 and A1): the policy's τ is "
        "ignored and the reference advances in real time (Δφ = 1), every motion's τ̂ taken as "
        "0, so r_time pays in full and traces carry τ = 0; true: Δφ = exp(τ) (§4.1, A3)",
    )  # fmt: skip
    trace_bins: int = Field(16, ge=2, description="reference-time bins of a motion trace")
    hold_seconds: float = Field(
        0.0, ge=0, description="after the clip's end the episode goes on this long with the "
        "reference holding the clip's last frame; its summary (a', F and trace as at the clip's "
        "end) says `held`: no fall in that time. For judging one-shot skills (land and stand); "
        "0: the episode ends at the clip's end ([L21])",
    )  # fmt: skip
    rsi: float = Field(
        0.0, ge=0, le=1, description="reference state initialisation (DeepMimic): this share of "
        "the episodes that imitate m0 itself (no motion trace: [L21]'s π0) starts at a random "
        "phase of the clip in its pose and velocity. Such episodes train π0 only: they have no "
        "take-off and no whole-motion fitness, so they report no a', trace or fitness (never "
        "the hindsight record or the elite set) and pay no task reward; 0: every episode "
        "starts at the clip's start ([L21])",
    )  # fmt: skip
    measures: dict[str, TaskMeasureConfig] = Field(
        default_factory=dict,
        description="declared task parameters: name -> measure (written inline under `task`)",
    )


class HorizonGrowthConfig(Section):
    """Training episodes' time limit grown from `start_seconds` to the env's own limit
    (`max_episode_seconds`, or a skill's clip) over the first `samples` env steps, linearly
    (DeepMimic's shipped walk grows its limit from 0.5 s to 20 s over 32M samples)."""

    start_seconds: PositiveFloat = Field(0.5, description="the limit at the first update (s)")
    samples: PositiveInt = Field(
        32_000_000, description="env steps over which the limit reaches the env's own"
    )

    def seconds(self, samples_done: int, full: float) -> float:
        """The limit (s) after `samples_done` env steps, for an env whose own limit is `full`."""
        share = min(max(samples_done / self.samples, 0.0), 1.0)
        return self.start_seconds + share * (full - self.start_seconds)


class EnvConfig(Section):
    """Simulation, observation, reward and termination of ParamEnv."""

    physics_hz: int | None = Field(
        None,
        ge=30,
        description="physics rate (Hz); default: the character's (its registration, chosen by "
        "benchmarks/physics_rate.py; [WL19] Table 2 used 600 Hz)",
    )
    control_hz: int = Field(30, ge=1, description="policy rate ([WL19] Table 2: 30 Hz)")
    frame_skip: int | None = Field(
        None, ge=1, description="physics steps per control step: physics_hz / control_hz"
    )
    max_episode_seconds: PositiveFloat = Field(30.0, description="time limit ([WL19] Table 2)")
    action_scale: PositiveFloat = Field(0.5, description="rad of PD target offset per unit action")
    pd_gain: PositiveFloat | None = Field(
        None,
        description="one k_p (N·m/rad) for every joint, k_d = 2√k_p ([L21] §7: k_p 600, k_d 49); "
        "None: each joint's own gains (the character's, DeepMimic's for the humanoid)",
    )
    stable_pd: bool = Field(
        False,
        description="servos as the stable PD controller of [WL19] Eq. 3 (the stiffness acting on "
        "the position predicted one physics step ahead); off: only the damping is implicit "
        "(docs/reproduce.md, 'Stable PD')",
    )
    imitation: bool = Field(True, description="follow the character's procedural reference motion")
    retarget: bool = Field(
        False,
        description="characters with legs: each leg follows the base leg's hip-to-ankle path "
        "(in the sagittal plane) scaled by the body's shortest leg "
        "(paramimic/motion/retarget.py), so that bodies with legs of unequal length get a "
        "reference they can follow",
    )
    target_velocity: float | None = Field(
        None, ge=-20.0, le=20.0, description="target speed (m/s, within ±20) when the task "
        "space has none; default: the gait's own, 1.0 for a procedural gait, the clip's speed "
        "for a clip gait (env.gait)",
    )  # fmt: skip
    target_direction: float = Field(
        0.0, ge=-4 * math.pi, le=4 * math.pi,
        description="target heading (rad, within ±4π) when the task space has none (3D)",
    )  # fmt: skip
    ground_fit: bool = Field(
        True, description="fit a new body's feet to the base's contacts ([WL19] Eq. 1) at reset"
    )
    ground_fit_max_change: PositiveFloat | None = Field(
        None, description="rad: a ground fit that moves a joint farther than this from the "
        "pose falls back to lifting the body (the humanoid mid-stride crouches to reach the "
        "base's swing-foot points); None: no limit",
    )  # fmt: skip
    com_velocity_window: PositiveFloat = Field(
        2.0, description="seconds over which the COM velocity is averaged ([WL19] Eq. 6)"
    )
    fall_height_ratio: float = Field(
        0.55, gt=0, lt=1, description="fall when the hip is below this share of its standing height"
    )
    max_pitch: PositiveFloat = Field(1.0, description="fall when the torso tilts more (rad)")
    stall_speed_ratio: float | None = Field(
        None, gt=0, le=1, description="end the episode when the COM's average velocity along "
        "the target direction (over com_velocity_window) is below this share of the target "
        "speed: standing still stops paying (a training device; evaluation runs without it)",
    )  # fmt: skip
    heading_error_limit: float | None = Field(
        None, gt=0, le=math.pi, description="3D characters: end the episode when the facing "
        "direction is farther than this from the target direction (rad): a body that has "
        "turned away stops collecting the imitation terms (a training device like "
        "stall_speed_ratio; evaluation runs without it)",
    )  # fmt: skip
    deviation_limit: float | None = Field(
        None, gt=0, description="a clip's early termination (a clip gait's or an [L21] "
        "skill's): end the episode when a body is farther than this (m) from its reference "
        "position (both relative to the root, in the root's heading frame) or the root's "
        "height is; a training device like "
        "stall_speed_ratio, reported as `deviated`, never a fall (evaluation runs without it)",
    )  # fmt: skip
    phase_sampling: Literal["uniform", "failures"] = Field(
        "uniform", description="where reference state initialisation starts a cycle (a clip "
        "gait) or a skill's RSI episode (env.skill.rsi): uniform phases ([WL19] Alg. 1), or "
        "phases drawn where episodes fail "
        "(paramimic/motion/phase.py; evaluation always draws uniform phases)",
    )  # fmt: skip
    phase_bins: int = Field(10, ge=1, description="phase_sampling failures: bins per cycle")
    phase_alpha: float = Field(
        0.02, gt=0, le=1, description="phase_sampling failures: EMA rate per episode and bin"
    )
    init_noise: float = Field(0.05, ge=0, description="noise on the initial reference state")
    observe_shape: bool = Field(
        True, description="false: the observation's shape parameters stay at the base body's "
        "(1.0), so the policy does not know the body it controls (domain randomization: a "
        "study's control for [WL19]'s shape-aware policy)",
    )  # fmt: skip
    horizon_growth: HorizonGrowthConfig | None = Field(
        None, description="training only: episodes start short and their time limit grows to "
        "the full horizon over the first samples (env steps counted as policy updates x "
        "ppo.num_steps); None: every training episode has the full horizon",
    )  # fmt: skip
    reward: RewardConfig = RewardConfig()
    clip: str | None = Field(
        None, description="imitate this clip in continuous time ([L21]); None: [WL19] gaits"
    )
    gait: str | None = Field(
        None, description="a looping clip of the character (a name or a clip file) as the "
        "[WL19] reference gait of ParamEnv: imitated cycle after cycle under the locomotion "
        "task; None: the character's procedural gait",
    )  # fmt: skip
    skill: SkillConfig = SkillConfig()
    clip_texts: dict[str, str] = Field(
        default_factory=dict, description="the content of the clip files `clip` or `gait` "
        "names (path -> text), carried with the run so that its actors, evaluation and play "
        "need not see the file; `paramimic train` fills it",
    )  # fmt: skip

    @model_validator(mode="before")
    @classmethod
    def _rates(cls, data: Any) -> Any:
        """physics_hz and frame_skip, each from the other (configs before physics_hz give
        frame_skip); both unset: the character's rate, filled in by the experiment."""
        if not isinstance(data, dict):
            return data
        control = data.get("control_hz", cls.model_fields["control_hz"].default)
        physics, skip = data.get("physics_hz"), data.get("frame_skip")
        if not all(isinstance(v, int | None) for v in (physics, skip, control)) or control < 1:
            return data  # the field's own type error names it
        if physics is None and skip is not None:
            return data | {"physics_hz": skip * control}
        if physics is not None and skip is None and physics % control == 0:
            return data | {"frame_skip": physics // control}
        return data  # a rate that is not a multiple of control_hz fails below, naming both

    @model_validator(mode="after")
    def _consistent_rates(self) -> EnvConfig:
        if self.physics_hz is None:
            return self
        steps = self.physics_hz // self.control_hz
        if self.physics_hz % self.control_hz:
            raise ValueError(
                f"physics_hz ({self.physics_hz}) must be a multiple of control_hz "
                f"({self.control_hz})"
            )
        if self.frame_skip != steps:
            raise ValueError(
                f"frame_skip {self.frame_skip} != physics_hz / control_hz = {steps}; "
                "set physics_hz and control_hz instead"
            )
        return self

    def for_evaluation(self, max_episode_seconds: float | None = None) -> EnvConfig:
        """This section as evaluation, rendering and play run it: whole episodes, without the
        training devices that end an episode early (stall_speed_ratio, heading_error_limit,
        deviation_limit, horizon_growth), starting at uniform phases (a clip gait) or at the
        clip's start (a skill: no RSI)."""
        update = {"stall_speed_ratio": None, "heading_error_limit": None, "deviation_limit": None}
        update["horizon_growth"] = None
        update["phase_sampling"] = "uniform"
        update["skill"] = self.skill.model_copy(update={"rsi": 0.0})
        if max_episode_seconds is not None:
            update["max_episode_seconds"] = max_episode_seconds
        return self.model_copy(update=update)

    def with_rate(self, physics_hz: int) -> EnvConfig:
        """This section with `physics_hz` (and its frame_skip) filled in, validated."""
        return EnvConfig.model_validate(self.model_dump() | {"physics_hz": physics_hz})


class PPOConfig(Section):
    """PPO ([WL19] §3.2, Table 2; [L21] §4.3, §7)."""

    num_steps: int = Field(
        4096, ge=64, le=2**22, description="T, transitions per policy update (at most 4M)"
    )
    num_epochs: int = Field(10, ge=1, le=100, description="N, passes over the batch per update")
    minibatch_size: int = Field(512, ge=8, description="n, transitions per gradient step")
    policy_lr: PositiveFloat = Field(2e-4, description="policy learning rate ([L21] §7)")
    value_lr: PositiveFloat = Field(1e-3, description="value learning rate ([L21] §7)")
    gamma: float = Field(0.95, gt=0, lt=1, description="discount γ ([WL19] Table 2)")
    gae_lambda: float = Field(0.95, ge=0, le=1, description="GAE λ ([WL19] Table 2)")
    clip_coef: PositiveFloat = Field(0.2, description="clip ε ([WL19] Table 2)")
    ent_coef: float = Field(0.0, ge=0, description="entropy bonus")
    vf_coef: PositiveFloat = Field(0.5, description="value loss weight")
    max_grad_norm: PositiveFloat = Field(0.5, description="gradient clipping")
    hidden_sizes: Layers = Field((128, 128, 128), description="3 layers of 128 ([WL19] §5)")
    value_hidden_sizes: Layers | None = Field(
        None,
        description="the value network's layers ([L21] §7: 2 x 512 beside a 4 x 1024 policy); "
        "None: the policy's",
    )
    init_log_std: float = Field(
        -1.0, ge=-20.0, le=2.0, description="initial log std of the Gaussian policy (-20 to 2)"
    )
    learn_std: bool = Field(
        True,
        description="false: the policy std stays at exp(init_log_std), as imitation "
        "controllers keep it (DeepMimic; docs/results/families-that-learn.md)",
    )
    desired_kl: PositiveFloat | None = Field(
        None,
        description="adapt the policy learning rate per minibatch to this approx. KL: /1.5 "
        "above 2x, x1.5 below 1/2 (rsl_rl's rule), within [1e-5, 1e-2]; none: fixed lr",
    )
    update_precision: Literal["float32", "bfloat16", "auto"] = Field(
        "float32",
        description="the number format of the update's matrix products: bfloat16 runs the "
        "forward and backward passes under torch's CPU autocast (weights, optimizer, log-probs "
        "and losses stay float32; faster on CPUs with AMX or AVX512-BF16 (docs/humanoid.md), "
        "far slower without); auto: bfloat16 where the CPU has either, else float32",
    )
    obs_clip: PositiveFloat = Field(10.0, description="clip of normalized observations")
    obs_std_floor: NonNegativeFloat = Field(
        0.0,
        description="least std the observation normalizer divides by (observation units: m, "
        "rad, m/s): an input that hardly varied in training, such as a part held on a stiff "
        "joint (the biped's torso: 0.2-0.7 mm), otherwise turns a body 2 % taller into an "
        "input 7-24 sigma off; 0: the experience's std",
    )


class SkillCurriculumConfig(Section):
    """Elites, P_θ, bootstrap and the exploration/refinement curriculum of [L21] §5-6.

    Distances in the task space are measured on the box normalized to [0, 1] per free dimension
    (A = diag(1/width²); the paper's A = I on its normalized parameters)."""

    sampling: Literal["curriculum", "uniform", "exploration_only", "mastering", "alternating"] = (
        Field(
            "curriculum",
            description="the curricula of [L21] §7.3: curriculum (ours, §6's phase rule), "
            "uniform (the baseline: random task parameters), exploration_only (explore until "
            "ER reaches `exploration_complete`, then refine), mastering (refine until the "
            "visited region's mean V̄ stops rising (`mastery_threshold`, `mastery_window`) or "
            "`phase_timeout` updates pass), alternating (`phase_updates` policy updates per "
            "phase)",
        )
    )
    phase_updates: int = Field(
        20, ge=1, description="alternating: policy updates per phase ([L21] §7.3: 20)"
    )
    mastery_threshold: float = Field(
        0.01,
        gt=0,
        description="mastering: refinement ends once the mean V̄ over the live elites (the "
        "visited skills) rose by less than this share of itself over the last "
        "`mastery_window` policy updates (ours; [L21] §7.3 gives no number)",
    )
    mastery_window: int = Field(
        10, ge=1, description="mastering: policy updates over which the rise is measured (ours)"
    )
    phase_timeout: int = Field(
        100, ge=1, description="mastering: policy updates a phase lasts at most (ours; "
        "[L21] §7.3 gives no number)",
    )  # fmt: skip
    exploration_complete: float = Field(
        1.0, gt=0, le=1, description="exploration_only: the ER that ends exploration ([L21] "
        "§7.3: ER = 1)",
    )  # fmt: skip
    motion_parameterization: bool = Field(
        True, description="false: m_a = m0 for every task ([L21] §7.2's A1, DeepMimic's "
        "baseline: the policy sees a and imitates the clip itself; no kNN proxy, no P_θ fits); "
        "elites are still kept, so ER is measured as for the others",
    )  # fmt: skip
    reference: dict[str, float] = Field(
        default_factory=dict,
        description="a of the reference motion m0 (default: gravity 1, body scales 1, the "
        "clip's own jump height), where the base policy π0 trains",
    )
    batch_size: int = Field(20, ge=1, description="task parameters per batch ([L21] §6)")
    episodes_per_param: int = Field(30, ge=1, description="episodes per parameter ([L21] §6)")
    elite_radius: PositiveFloat = Field(0.1, description="r of Eq. 13 ([L21] §5.2)")
    fitness_threshold: float = Field(0.1, ge=0, description="elites need F above it (§5.2)")
    constraint_tolerance: PositiveFloat | None = Field(
        None,
        description="elites must also hold every constraint (a zero-range measured parameter) "
        "within this many σ_task (ours); None: [L21] §5.2's rule, where a constraint only "
        "adds w_constraint · r_constraint (Eq. 10, at most 0.1) to F, so a performance that "
        "breaks it still enters",
    )
    improvement: float = Field(0.02, ge=0, description="exploration-rate margin (§6.1)")
    density_visited: PositiveFloat = Field(0.8, description="D: A_h where density >= D (§6.2)")
    density_surrounding: PositiveFloat = Field(0.2, description="D': A_s from D' (§6.2)")
    bandwidth: PositiveFloat = Field(0.1, description="kernel width h of Eq. 15 (normalized)")
    probe_every: int = Field(4, ge=2, description="every n-th batch samples the other region")
    knn_k: int = Field(5, ge=1, description="k of the kNN proxy (Eq. 14, §5.3)")
    knn_sigma: PositiveFloat = Field(0.28, description="σ_k of Eq. 14 (§5.3)")
    p_every: int = Field(10, ge=1, description="policy updates between P_θ fits (§7)")
    p_steps: int = Field(10, ge=1, description="P_θ minibatch updates per fit (§7)")
    p_hidden: Layers = Field((512, 512), description="P_θ layers (§7)")
    p_lr: PositiveFloat = Field(1e-3, description="P_θ learning rate (§7)")
    p_batch: int = Field(128, ge=1, description="P_θ minibatch (§7)")
    p_loss_threshold: PositiveFloat = Field(
        0.01, description="P_θ mean squared error per trace entry below which P_θ is used (§5.3)"
    )
    base_min_iterations: int = Field(5, ge=0, description="π0 trains at least this long")
    base_max_iterations: int = Field(200, ge=0, description="π0 stops here even without plateau")
    plateau_window: int = Field(10, ge=2, description="iterations compared for a plateau")
    plateau_tolerance: float = Field(
        0.02, ge=0, description="plateau: mean return grew by less than this share over a window"
    )

    @model_validator(mode="after")
    def _bands(self) -> SkillCurriculumConfig:
        if not self.density_surrounding < self.density_visited:
            raise ValueError("density_surrounding (D') must be below density_visited (D)")
        if self.base_max_iterations < self.base_min_iterations:
            raise ValueError("base_max_iterations must be >= base_min_iterations")
        return self


class WidenConfig(Section):
    """A task range that grows from the base body (`origin`) as the controller masters it:
    automatic domain randomization's rule (OpenAI 2019) on one width for all free dims. Tasks
    drawn from S are pulled toward the origin to `width` of their offset (V̄ sampling runs
    inside the current range); the width grows by `step` when fewer than `promote_below` of
    `window` episodes failed. Which episodes, and what fails one (`promote_on`):
    - `early_ends`: the training episodes, ended early for any reason the env has (a fall, a
      stall, off course, a divergence);
    - `falls`: the training episodes, ended by a fall only (the walker study's recorded runs: an
      episode ended by the stall or heading rule counts as mastered there);
    - `edge`: every `check_every` iterations, `window` episodes of the deterministic policy on
      bodies at the range's edge (ADR's boundary test), at the evaluation's horizon, failed by a
      fall. Training episodes of an exploring policy fall far more often than its mean action
      does (the base biped: 40 % in training, 2 % held out), so they judge it by its noise."""

    start: float = Field(0.2, ge=0, le=1, description="initial width, a share of each range")
    step: float = Field(0.1, gt=0, le=1, description="width added on a promotion")
    window: int = Field(256, ge=1, description="episodes per promotion decision")
    promote_below: float = Field(
        0.5,
        gt=0,
        le=1,
        description="grow when fewer than this share of the window's episodes failed",
    )
    promote_on: Literal["early_ends", "falls", "edge"] = Field(
        "early_ends",
        description="which episodes judge the range and what fails one: any early end or a "
        "fall of training episodes, or a fall of deterministic episodes at the range's edge",
    )
    check_every: int = Field(
        10, ge=1, description="`edge` only: iterations between two tests of the range's edge"
    )
    origin: Literal["base", "center"] = Field(
        "base",
        description="where the range grows from: the base body (every shape parameter at 1.0, "
        "clipped into its range; other dims at their centre) or the box's centre (the two agree "
        "on a box centred on 1.0)",
    )


class CurriculumConfig(Section):
    """Adaptive sampling of task parameters ([WL19] §4.2, Alg. 1, Table 2)."""

    k: float = Field(
        10.0,
        ge=0,
        description="uniformity k of exp(-k(V̄-μ)/μ) ([WL19] Eq. 10; [L21] Eq. 17 in refinement)",
    )
    k_ramp_iterations: int | None = Field(
        None, ge=1, description="k rises linearly from 0 to `k` over this many policy updates "
        "([WL19] §6: 'gradually increasing the degree of uniformity k'); a k set through the "
        "API ends the ramp; None: `k` from the first update",
    )  # fmt: skip
    n_mcmc: int = Field(1000, ge=1, description="N_MCMC, samples per buffer refill")
    p_mcmc: int = Field(20, ge=1, description="P_MCMC, iterations between refills")
    chains: int = Field(16, ge=1, description="Metropolis-Hastings chains")
    burn_in: int = Field(20, ge=0, description="steps each chain takes before it records")
    marginal_lr: PositiveFloat = Field(1e-3, description="α_V̄ ([WL19] Table 2)")
    mu_lr: PositiveFloat = Field(1e-3, description="α_μ ([WL19] Table 2)")
    marginal_hidden: Layers = Field((64, 64), description="V̄ MLP layers")
    marginal_batch: int = Field(128, ge=1, description="minibatch of (a, v) pairs ([L21] §7)")
    display_dims: tuple[str, ...] | None = Field(
        None, description="two task dims for grids (default: the first two free)"
    )
    widen: WidenConfig | None = Field(
        None, description="grow the task range from its centre as it is mastered (none: all of it)"
    )
    skill: SkillCurriculumConfig = SkillCurriculumConfig()

    def k_at(self, iteration: int) -> float:
        """k at a policy update: `k`, or on its linear ramp from 0 (`k_ramp_iterations`)."""
        if self.k_ramp_iterations is None:
            return self.k
        return self.k * min(max(iteration, 0) / self.k_ramp_iterations, 1.0)


class ActorsConfig(Section):
    """Rollout workers: in-process for --serial, Ray actors otherwise."""

    num_actors: int | Literal["auto"] = Field(
        "auto", description="N Ray rollout actors; auto = one per CPU of the cluster"
    )
    num_envs: int = Field(
        16, ge=1, le=1024, description="M, environments stepped together per worker"
    )
    steps_per_fragment: int | None = Field(
        None, ge=1, description="T per env per fragment; default: ppo.num_steps / (N M)"
    )
    mode: Literal["sync", "pipelined"] = Field(
        "sync",
        description="pipelined: actors sample the next fragment during the update (one "
        "policy version of lag, corrected by the PPO ratio); sync: they wait",
    )
    lost_timeout: PositiveFloat = Field(
        120.0, description="seconds without any live actor before the learner checkpoints and exits"
    )
    fragment_timeout: PositiveFloat = Field(
        300.0,
        description="seconds a fragment may take; an actor past it is hung: killed, restarted by "
        "Ray, its fragment dropped",
    )
    sampler_timeout: PositiveFloat = Field(
        60.0,
        description="seconds the learner and the actors wait for one answer of the sampler actor "
        "(it is restarted by Ray and reloads from Redis meanwhile) before it counts as failed",
    )
    max_fragment_errors: int = Field(
        20,
        ge=1,
        description="fragment errors in a row (no fragment arriving in between) that make a "
        "persistent failure: the learner checkpoints and exits with the reason",
    )

    @field_validator("num_actors")
    @classmethod
    def _positive_actors(cls, v: int | str) -> int | str:
        if isinstance(v, int) and v < 1:
            raise ValueError("num_actors must be a positive int or 'auto'")
        return v


class TrainConfig(Section):
    total_steps: int = Field(2_000_000, ge=1, description="environment steps to train for")
    seed: Seed = 0
    checkpoint_every: int = Field(10, ge=1, description="iterations between checkpoints")
    tensorboard: bool = Field(
        True,
        description="TensorBoard event files in the run's tensorboard/ folder: every metric per "
        "env step, the curriculum's state and the V̄ map (`tensorboard --logdir runs`)",
    )
    wandb: Literal["off", "online", "offline"] = Field(
        "off",
        description="Weights & Biases (the `wandb` extra): the same curves in a W&B run, its files "
        "in the run's wandb/ folder; offline needs no network or account (`wandb sync` later)",
    )
    wandb_project: str = Field("paramimic", description="the W&B project of `train.wandb`")
    keep_checkpoints: int | None = Field(
        5, ge=1, description="ckpt_*.pt files kept (older ones are pruned); null: keep all"
    )
    max_bad_updates: int = Field(
        3,
        ge=1,
        description="updates in a row with non-finite losses or gradients (their steps are "
        "skipped) before the run stops with a checkpoint of the last finite weights",
    )
    run_dir: Path | None = Field(None, description="default: runs/<config name>")
    init_from: Path | None = Field(
        None,
        description="warm start: the policy, value and normalizer of this checkpoint (a run dir, "
        "a .pt or a shipped controller's name) of the same character and env, e.g. the base "
        "body's controller for its family; its task dims in the same order, more may follow; "
        "inputs constant there that vary here, and added ones, start ignored (`adopt_controller`)",
    )
    torch_threads: int | Literal["auto"] = Field(
        "auto",
        description="torch intra-op threads of the learner's update; auto: every core with "
        "--serial (nothing else runs then), 1 on Ray (the rollout actors use the cores)",
    )

    @field_validator("torch_threads")
    @classmethod
    def _positive_threads(cls, v: int | str) -> int | str:
        if v != "auto" and v < 1:
            raise ValueError("torch_threads must be >= 1 or 'auto'")
        return v


class ExperimentConfig(Section):
    name: str = Field(
        "experiment",
        pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$",
        description="experiment name: letters, digits, '_', '.', '-' (it starts the run id)",
    )
    character: str = "walker"
    task: dict[str, tuple[float, float]] = Field(
        default_factory=dict, description="the task space A: name -> [min, max]"
    )
    shape_space: Literal["task", "full"] = Field(
        "task",
        description="'full' adds the character's documented shape family at its ranges "
        "(b_g 0.5-1.5, b_l 0.7-1.2 for the [WL19] §5.3 characters; the humanoid's Fig. 2a/c "
        "parameters) to the task space; entries in `task` override single ranges or add more",
    )
    shape_scale: float = Field(
        1.0,
        ge=0.0,
        le=1.0,
        description="with shape_space 'full': every documented shape range shrunk toward the "
        "base body, [1 - s(1 - lo), 1 + s(hi - 1)] (0.5: the x0.5 families of the study; 0: the "
        "base body alone)",
    )
    recipe: Literal["wl19", "l21", "paramimic_walker", "paramimic_humanoid"] | None = Field(
        None,
        description="a preset that sets every field where a paper's settings and ours part "
        "ways (paramimic/recipes.py; `paramimic config show` says where each value comes "
        "from): wl19, l21, paramimic_walker, paramimic_humanoid; a field the config sets wins",
    )
    env: EnvConfig = EnvConfig()
    ppo: PPOConfig = PPOConfig()
    curriculum: CurriculumConfig = CurriculumConfig()
    actors: ActorsConfig = ActorsConfig()
    train: TrainConfig = TrainConfig()

    @model_validator(mode="before")
    @classmethod
    def _inline_measures(cls, data: Any) -> Any:
        return inline_measures(data)

    @field_validator("character")
    @classmethod
    def _known_character(cls, v: str) -> str:
        known = _registry().REGISTRY
        if v not in known:
            raise ValueError(f"unknown character {v!r}; known: {sorted(known)}")
        return v

    @model_validator(mode="before")
    @classmethod
    def _character_defaults(cls, data: Any) -> Any:
        """What the character fills in: its physics rate when `env` sets none, and with
        `shape_space: full` every documented shape range (shrunk by `shape_scale`) that `task`
        does not set. An unknown character is left to the field's own error."""
        if (
            not isinstance(data, dict)
            or data.get("character", "walker") not in _registry().REGISTRY
        ):
            return data
        registration = _registry().registration(data.get("character", "walker"))
        data = dict(data)
        env = data.get("env")
        if isinstance(env, EnvConfig) and env.physics_hz is None:
            data["env"] = env.with_rate(registration.physics_hz)
        elif env is None or isinstance(env, dict) and env.get("physics_hz") is None:
            env = dict(env or {})
            if env.get("frame_skip") is None:
                data["env"] = env | {"physics_hz": registration.physics_hz}
        if data.get("shape_space") == "full" and isinstance(data.get("task", {}), dict):
            if not registration.shape_ranges():
                raise ValueError(f"shape_space: {registration.name!r} has no shape parameters")
            s = data.get("shape_scale", 1.0)
            if isinstance(s, int | float) and 0 <= s <= 1:
                data["task"] = registration.shape_ranges(s) | dict(data.get("task") or {})
        return data

    @model_validator(mode="after")
    def _shape_scale_needs_full(self) -> ExperimentConfig:
        if self.shape_space != "full" and self.shape_scale != 1.0:
            raise ValueError(
                "shape_scale: shrinks the documented shape ranges of shape_space 'full'"
            )
        return self

    @model_validator(mode="after")
    def _valid_task(self) -> ExperimentConfig:
        registration = _registry().registration(self.character)
        character = registration.character
        if self.env.retarget and not character.legs:
            raise ValueError(
                f"env.retarget: retargets a character's legs; {self.character!r} has none"
            )
        if self.env.heading_error_limit is not None and character.planar:
            raise ValueError(
                f"env.heading_error_limit: {self.character!r} is planar and cannot turn away "
                "from its target; the rule is for 3D characters"
            )
        measures = self.env.skill.measures
        self._valid_measures(character)
        allowed = set(character.param_names()) | set(TASK_GOALS) | set(measures)
        shape_ranges = {p.name: (p.low, p.high) for p in character.shape_params}
        for name, (lo, hi) in self.task.items():
            if name not in allowed:
                raise ValueError(
                    f"task.{name}: not a parameter of {self.character!r}; "
                    f"allowed: {sorted(allowed)}"
                )
            if lo > hi:
                raise ValueError(f"task.{name}: min {lo} > max {hi}")
            if name in GOAL_LIMITS:
                low, high = GOAL_LIMITS[name]
                if lo < low or hi > high:
                    raise ValueError(f"task.{name}: [{lo}, {hi}] leaves [{low:g}, {high:g}]")
            if name in measures or name in TASK_GOALS and name != "gravity":
                continue
            if lo <= 0:
                raise ValueError(f"task.{name}: scales must be positive, got min {lo}")
            if name in shape_ranges:
                low, high = shape_ranges[name]
                if lo < low or hi > high:
                    raise ValueError(
                        f"task.{name}: [{lo}, {hi}] leaves the range {self.character!r} "
                        f"supports, [{low}, {high}]"
                    )
        if self.env.clip is not None and self.env.gait is not None:
            raise ValueError(
                "env.gait and env.clip: a clip is either the [WL19] reference gait "
                "(env.gait, ParamEnv) or an [L21] skill (env.clip, SkillEnv), not both"
            )
        for field in ("clip", "gait"):
            _check_clip_name(field, getattr(self.env, field), registration)
        if self.env.gait is not None and character.planar:
            raise ValueError(f"env.gait: clip gaits need a free root; {self.character!r} is planar")
        if self.env.reward.end_effector_frame == "heading" and self.env.gait is None:
            raise ValueError(
                "env.reward.end_effector_frame: heading needs a clip gait (env.gait), whose "
                "reference has a root orientation to imitate"
            )
        if self.env.reward.facing == "clip" and self.env.gait is None:
            raise ValueError(
                "env.reward.facing: clip needs a clip gait (env.gait), whose root facing the "
                "facing term then follows"
            )
        if "target_direction" in self.task and character.planar:
            raise ValueError(
                f"task.target_direction: {self.character!r} moves in the sagittal plane only"
            )
        for name, value in self.curriculum.skill.reference.items():
            if name not in self.task:
                raise ValueError(f"curriculum.skill.reference.{name}: not a task parameter")
            lo, hi = self.task[name]
            if not lo <= value <= hi:
                raise ValueError(
                    f"curriculum.skill.reference.{name}: {value} is outside [{lo}, {hi}]"
                )
        dims = self.curriculum.display_dims
        if dims is not None and (len(dims) != 2 or any(d not in self.task for d in dims)):
            raise ValueError(
                f"curriculum.display_dims must name two task parameters, got {list(dims)}"
            )
        if self.ppo.minibatch_size > self.ppo.num_steps:
            raise ValueError("ppo.minibatch_size must not exceed ppo.num_steps")
        return self

    def _valid_measures(self, character) -> None:
        """Declared parameters: in the task space, not a body or physics name, reading an end
        effector the character has."""
        reserved = (set(character.param_names()) | set(TASK_GOALS)) - {"jump_height"}
        for name, m in self.env.skill.measures.items():
            where = f"task.{name}"
            if name not in self.task:
                raise ValueError(f"env.skill.measures.{name}: not in task (give it a range)")
            if name in reserved:
                raise ValueError(f"{where}: {name!r} is a body or physics parameter, not a measure")
            if m.body is not None and m.body not in character.end_effectors:
                raise ValueError(
                    f"{where}.body {m.body!r}: not an end effector of {self.character!r}; "
                    f"one of {list(character.end_effectors)}"
                )

    def parameters(self) -> list[dict[str, Any]]:
        """The task space as a reader sees it (the API, the dashboard): per parameter its range,
        unit and kind — shape (a multiple of the base body's), condition (gravity), goal
        (target velocity, direction) or measured (with its measure, reward and event) — and
        whether a zero range makes it a constraint."""
        from paramimic.motion.measures import default_unit

        shapes = set(_registry().registration(self.character).character.param_names())
        measures = dict(self.env.skill.measures)
        if "jump_height" in self.task and "jump_height" not in measures:
            measures["jump_height"] = TaskMeasureConfig(measure="com_rise")
        units = {"gravity": "G", "target_velocity": "m/s", "target_direction": "rad"}
        out = []
        for name, (lo, hi) in self.task.items():
            p: dict[str, Any] = {"name": name, "range": [lo, hi], "constraint": lo == hi}
            if name in measures:
                m = measures[name]
                p |= {"kind": "measured", "unit": m.unit or default_unit(m.measure)}
                p |= m.model_dump(exclude={"unit", "event"}, exclude_none=True)
                p["event"] = m.resolved_event() if m.reward == "spike" else None
            elif name in shapes:
                p |= {"kind": "shape", "unit": "x base"}
            else:
                p |= {"kind": "condition" if name == "gravity" else "goal", "unit": units[name]}
            out.append(p)
        return out

    def display_dims(self) -> tuple[str, ...]:
        """The task dimensions the curriculum's maps, the evaluation's grid and the heatmaps
        show: `curriculum.display_dims`, else the first two free ones (fewer if there are
        fewer; a grid needs two)."""
        if self.curriculum.display_dims is not None:
            return tuple(self.curriculum.display_dims)
        return tuple(n for n, (lo, hi) in self.task.items() if hi > lo)[:2]

    def task_space(self) -> TaskSpace:
        """The task space A (the envs' own, without building one)."""
        return TaskSpace.from_ranges(self.task)

    def resolved_run_dir(self) -> Path:
        return self.train.run_dir or Path("runs") / self.name

    @model_validator(mode="before")
    @classmethod
    def _recipe(cls, data: Any) -> Any:
        """The named recipe's fields beneath what the config sets (paramimic/recipes.py).
        Defined last: pydantic runs `before` validators last-defined first, so the character's
        defaults and the inline measures see the recipe's values."""
        if not isinstance(data, dict) or data.get("recipe") is None:
            return data
        if data["recipe"] not in PRESETS:
            return data  # the field's own error names the known recipes
        return apply(data)


def inline_measures(data: Any) -> Any:
    """`task: {name: {measure: ..., range: [lo, hi], ...}}`: the range stays in `task`, the
    measure goes to `env.skill.measures` (a config as written, before validation)."""
    if not isinstance(data, dict) or not isinstance(data.get("task"), dict):
        return data
    inline = {k: v for k, v in data["task"].items() if isinstance(v, dict)}
    if not inline:
        return data
    data = dict(data)
    data["task"] = dict(data["task"])
    env = dict(data.get("env") or {})
    skill = dict(env.get("skill") or {})
    measures = dict(skill.get("measures") or {})
    for name, spec in inline.items():
        spec = dict(spec)
        if "range" not in spec:
            raise ValueError(f"task.{name}: a declared parameter needs a range: [min, max]")
        data["task"][name] = spec.pop("range")
        measures[name] = spec
    data["env"] = env | {"skill": skill | {"measures": measures}}
    return data


class ConfigError(ValueError):
    """A config that cannot run; the message names the field and the reason."""


def _check_clip_name(field: str, name: str | None, registration) -> None:
    """`env.clip` / `env.gait` names one of the character's clips or a clip file; which file,
    and whether it parses, is the train preflight's to check (validation reads no files)."""
    if name is None or name in registration.clips:
        return
    owners = _registry().clip_owners()
    is_file = registration.clip_file is not None and (Path(name).suffix or "/" in name)
    if name in owners or not is_file:
        raise ValueError(
            f"env.{field} {name!r} does not fit character {registration.name!r}; clips: "
            + ", ".join(f"{k} ({'/'.join(v)})" for k, v in owners.items())
            + (", or a clip file (a path)" if registration.clip_file is not None else "")
        )


def format_validation_error(err: ValidationError) -> str:
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"]) or "(config)"
        lines.append(f"{loc}: {e['msg']}")
    return "; ".join(lines)


def raw_config(path: str | Path, overrides: dict[str, Any] | None = None) -> dict:
    """A YAML experiment as written, with its name and the dotted `overrides` set."""
    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text()) or {}
    except (OSError, yaml.YAMLError) as e:
        raise ConfigError(f"{path}: cannot read config: {e}") from e
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: top level must be a mapping")
    raw.setdefault("name", path.stem)
    for dotted, value in (overrides or {}).items():
        node = raw
        *parents, leaf = dotted.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    return raw


def load_config(path: str | Path, overrides: dict[str, Any] | None = None) -> ExperimentConfig:
    """Load and validate a YAML experiment; raise ConfigError naming the field on any problem."""
    path = Path(path)
    raw = raw_config(path, overrides)
    try:
        return ExperimentConfig.model_validate(raw)
    except ValidationError as e:
        raise ConfigError(f"{path}: {format_validation_error(e)}") from e


# What a resumed run cannot change: the body and task space, the env (observations, rewards,
# rates) and the networks' shapes; anything else (budget, actors, step sizes, k) may change.
RESUME_FIXED = (
    "character",
    "task",
    "shape_space",
    "shape_scale",
    "env",
    "ppo.hidden_sizes",
    "ppo.value_hidden_sizes",
    "ppo.learn_std",
    "curriculum.marginal_hidden",
    "curriculum.skill.p_hidden",
)


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and k != "task":
            out |= _flat(v, key + ".")
        else:
            out[key] = v
    return out


def resume_conflicts(saved: dict, cfg: ExperimentConfig) -> list[str]:
    """Fields where `cfg` differs from a checkpoint's config (`saved`, as dumped) in a way a
    resumed run cannot accept (RESUME_FIXED), as 'field: saved -> given'."""
    old = _flat(ExperimentConfig.model_validate(saved).model_dump(mode="json"))
    new = _flat(cfg.model_dump(mode="json"))
    return [
        f"{key}: {old.get(key)!r} -> {new.get(key)!r}"
        for key in sorted(old.keys() | new.keys())
        if old.get(key) != new.get(key)
        and any(key == f or key.startswith(f + ".") for f in RESUME_FIXED)
        and not key.startswith("env.clip_texts.")  # the same file's text, carried or not
    ]


def field_descriptions(model: type[BaseModel] | None = None, prefix: str = "") -> dict[str, str]:
    """Dotted field name -> its description (sections walked, optional ones too)."""
    model = model or ExperimentConfig
    out: dict[str, str] = {}
    for name, info in model.model_fields.items():
        key = f"{prefix}{name}"
        section = next(
            (t for t in (info.annotation, *getattr(info.annotation, "__args__", ()))
             if isinstance(t, type) and issubclass(t, BaseModel)),
            None,
        )  # fmt: skip
        if section is not None:
            out |= field_descriptions(section, key + ".")
        out[key] = info.description or ""
    return out
