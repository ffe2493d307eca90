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
    status: str = Field(description="running, paused, finished, stopped or failed")
    started_at: float
    updated_at: float
    iteration: int | None = None
    env_steps: int | None = None
    total_steps: int | None = None


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
    updated_at: float | None = None


class HistoryPage(BaseModel):
    run_id: str
    items: list[dict[str, Any]] = Field(description="one metrics record per iteration, in order")
    next_since: int = Field(description="pass as ?since= to get the records after these")


class Curriculum(BaseModel):
    run_id: str
    mode: str = Field(description="adaptive ([WL19] MCMC on exp(-k(V̄-μ)/μ)) or uniform (k = 0)")
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
    paused: bool
    phase: str | None = Field(None, description="[L21] §6 phase (Part 4)")
    explored_ratio: float | None = None
    exploration_rate_surrounding: float | None = None
    exploration_rate_visited: float | None = None
    updated_at: float | None = None


class MarginalValueGrid(BaseModel):
    run_id: str
    available: bool = Field(description="false until the learner has sent its first V̄")
    dims: list[str] = []
    xs: list[float] = []
    ys: list[float] = []
    values: list[list[float]] = Field([], description="V̄ at (xs[j], ys[i]) in values[i][j]")
    mu: float | None = None
    iteration: int | None = None


class TaskBatch(BaseModel):
    time: float
    source: str = Field(description="who asked: actorN or learner")
    names: list[str]
    tasks: list[list[float]]


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
