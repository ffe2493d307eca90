"""The API's response and request bodies (these make its OpenAPI schema)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field


class Health(BaseModel):
    status: str = Field(description="ok, or unavailable when Redis does not answer")
    redis: str


class RunSummary(BaseModel):
    run_id: str
    name: str
    character: str
    status: str = Field(
        description="running, paused, finished, stopped, failed, or stale (running or paused, "
        "but its learner stopped renewing its lease: killed or its host lost)"
    )
    started_at: float
    updated_at: float
    iteration: int | None = None
    env_steps: int | None = None
    total_steps: int | None = None


class TaskParameter(BaseModel):
    """One dimension of the run's task space and what it means ([L21] §4.2, Table 1)."""

    name: str
    range: list[float] = Field(description="[min, max]; equal ends make it a constraint")
    constraint: bool
    kind: str = Field(
        description="shape (a multiple of the base body's), condition (gravity), goal (target "
        "velocity/direction) or measured (a measure of the motion, `env.skill.measures`)"
    )
    unit: str = Field(description="unit of the range ('reference': multiples of the clip's own)")
    measure: str | None = Field(None, description="measured: its measure (motion.measures)")
    axis: str | None = None
    body: str | None = None
    window: list[float] | None = Field(None, description="share of the clip it looks at")
    reward: str | None = Field(None, description="measured: spike or continuous task reward")
    event: str | None = Field(None, description="spike: clip_end, takeoff or window_end")
    sigma: float | None = None


class RunDetail(RunSummary):
    """A run: its summary, its whole validated config and its task parameters."""

    config: dict = Field(description="the experiment config the run was started with")
    parameters: list[TaskParameter]


class CharacterInfo(BaseModel):
    """A run's character as the registry describes it."""

    run_id: str
    name: str
    planar: bool = Field(description="root slides in x, z and pitches (else a free root)")
    swims: bool = Field(description="moves in MuJoCo's fluid model")
    shape_params: dict[str, list[float]] = Field(description="b: name -> [low, high]")
    joints: list[str] = Field(description="actuated joints, in action order")
    gait: bool = Field(description="has a [WL19] reference gait")
    clips: list[str] = Field(description="[L21] clips it can imitate")
    envs: list[str] = Field(description="its gymnasium env ids")
    physics_hz: int | None = Field(None, description="its default physics rate")


class Progress(BaseModel):
    run_id: str
    status: str
    iteration: int = 0
    env_steps: int = 0
    total_steps: int | None = None
    episodes: int = 0
    steps_per_second: float | None = None
    mean_return: float | None = None
    fall_percent: float | None = None
    actors: int | None = Field(None, description="rollout actors in the pool (Ray runs)")
    nodes: int | None = Field(None, description="Ray nodes those actors run on")
    updated_at: float | None = None


class HistoryPage(BaseModel):
    run_id: str
    items: list[dict[str, Any]] = Field(description="one metrics record per iteration, in order")
    next_since: int = Field(description="pass as ?since= to get the records after these")


class Curriculum(BaseModel):
    run_id: str
    mode: str = Field(
        description="adaptive ([WL19] MCMC on exp(-k(V̄-μ)/μ)), uniform (k = 0 or [L21] uniform "
        "task sampling) or skill (the [L21] exploration/refinement curriculum)"
    )
    k: float
    mu: float | None = Field(description="μ, the running mean of V̄")
    marginal_iteration: int = Field(description="iteration of the V̄ the sampler holds")
    refills: int = Field(description="times the buffer S was refilled")
    buffer_adaptive: bool = Field(description="whether S came from MCMC (else uniform)")
    buffer_size: int
    buffer_mean: dict[str, float]
    buffer_std: dict[str, float]
    task_names: list[str]
    episodes: int = Field(description="finished episodes the sampler has ingested")
    mean_return: float | None
    fall_percent: float | None
    tasks_served: int
    range_width: float | None = Field(
        None, description="share of each task range in use (curriculum.widen; 1: all of it)"
    )
    paused: bool
    phase: str | None = Field(
        None, description="[L21] §6: base (π0), exploration, refinement, or uniform"
    )
    explored_ratio: float | None = Field(None, description="ER: share of the task space in A_h")
    exploration_rate_surrounding: float | None = Field(
        None, description="elites improved per episode in batches from A_s (§6.1)"
    )
    exploration_rate_visited: float | None = Field(
        None, description="elites improved per episode in batches from A_h (§6.1)"
    )
    stage: str | None = Field(None, description="[L21] §5.3 bootstrap: base, proxy or mixed")
    elites: int | None = Field(None, description="size of the elite set")
    elite_mean_fitness: float | None = None
    phase_switches: int | None = None
    motion_version: int | None = Field(None, description="version of P_θ the sampler holds")
    motion_loss: float | None = Field(None, description="P_θ's loss per trace entry (Eq. 12)")
    batch: int | None = None
    batch_region: str | None = None
    reference: dict[str, float] | None = Field(None, description="a0, the parameter of m0")
    task_ranges: dict[str, list[float]] | None = None
    history: list[dict[str, float]] | None = Field(
        None, description="ER against N (episodes), one point per finished batch"
    )
    achieved: dict[str, dict[str, float]] | None = Field(
        None, description="a' of the latest episodes per parameter (hindsight): mean, min, max"
    )
    updated_at: float | None = None


class Grid(BaseModel):
    """Values over the run's two display dimensions: values[i][j] at (xs[j], ys[i])."""

    run_id: str
    available: bool = Field(description="false until there is a snapshot")
    dims: list[str] = []
    xs: list[float] = []
    ys: list[float] = []
    values: list[list[float]] = []


class MarginalValueGrid(Grid):
    """V̄ over the grid; available once the learner has sent its first V̄."""

    mu: float | None = None
    iteration: int | None = None


class TaskBatch(BaseModel):
    time: float
    source: str = Field(description="who asked: actorN or learner")
    names: list[str]
    tasks: list[list[float]]
    region: str | None = Field(None, description="[L21]: where the batch was drawn")
    batch: int | None = None


class Elite(BaseModel):
    key: str = Field(description="the episode id of the elite")
    params: dict[str, float] = Field(description="a', the parameter the episode achieved")
    fitness: float
    distance: float | None = Field(None, description="normalized distance to ?near=")


class Elites(BaseModel):
    run_id: str
    names: list[str]
    total: int = Field(description="elites in the set")
    items: list[Elite]


class DensityGrid(Grid):
    """The KDE density of the elites (Eq. 15) over the grid."""

    visited: float | None = Field(None, description="D: A_h where density >= D")
    surrounding: float | None = Field(None, description="D': A_s where D' <= density < D")
    elites: int | None = None


class Event(BaseModel):
    id: str = Field(description="stream id; pass as ?since= for the events after it")
    type: str
    message: str
    time: float
    data: dict[str, Any] = {}


class Accepted(BaseModel):
    run_id: str
    requested: dict[str, Any]


class SetK(BaseModel):
    k: float = Field(ge=0, le=1e6, description="uniformity k of exp(-k(V̄-μ)/μ); 0 = uniform")
