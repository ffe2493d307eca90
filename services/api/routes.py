"""The endpoints. They read Redis (and, for pause/resume/k with a bearer token, write the run's
control hash that the learner polls); nothing here imports torch, mujoco or ray."""

from __future__ import annotations

import hashlib
import json
import secrets
import threading
from collections import OrderedDict
from typing import Annotated

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Path, Query, Request, Response, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from redis.asyncio import Redis
from starlette.concurrency import run_in_threadpool

from paramimic.curriculum.elite_set import EliteSet
from paramimic.task_space import TaskSpace
from services.api.models import (
    Accepted,
    CharacterInfo,
    Curriculum,
    DensityGrid,
    Elite,
    Elites,
    Event,
    Health,
    HistoryPage,
    MarginalValueGrid,
    Progress,
    RunDetail,
    RunSummary,
    SetK,
    TaskBatch,
)
from services.keys import RUN_ID, RUNS, SAMPLES_LIMIT, RunKeys
from services.store import add_event


def get_redis(request: Request) -> Redis:
    return request.app.state.redis


RedisDep = Annotated[Redis, Depends(get_redis)]
RunId = Annotated[str, Path(pattern=RUN_ID.pattern, description="run id, as listed by /runs")]
STREAM_ID = r"^(0|[0-9]{1,19}-[0-9]{1,19})$"  # fits Redis' 64-bit stream id parts

RUNS_PAGE_MAX = 1000
META_FIELDS = ("name", "character", "status", "started_at", "updated_at", "total_steps")

router = APIRouter()
bearer = HTTPBearer(auto_error=False)


async def require_token(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
) -> None:
    token = request.app.state.settings.api_token
    if token is None:
        raise HTTPException(
            status.HTTP_403_FORBIDDEN,
            "changing a run is disabled: start the API with PARAMIMIC_API_TOKEN set",
        )
    if credentials is None or not secrets.compare_digest(
        credentials.credentials.encode(), token.get_secret_value().encode()
    ):
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            "a valid bearer token is required",
            headers={"WWW-Authenticate": "Bearer"},
        )


TokenDep = Depends(require_token)


def _not_found(run: str) -> HTTPException:
    return HTTPException(status.HTTP_404_NOT_FOUND, f"no run {run!r}; GET /runs lists them")


async def run_status(r: Redis, run: str) -> tuple[RunKeys, str]:
    """The run's keys and status; 404 if there is no such run."""
    keys = RunKeys(run)
    state = await r.hget(keys.meta, "status")
    if state is None:
        raise _not_found(run)
    return keys, state


def live_status(stored: str, lease: int) -> str:
    """A run stored as running or paused whose learner stopped renewing its lease (killed,
    host lost) is `stale`."""
    return "stale" if stored in ("running", "paused") and not lease else stored


def _num(value: str | None, kind=float):
    if value is None:
        return None
    v = json.loads(value)
    return None if v is None else kind(v)


@router.get("/health", response_model=Health, tags=["service"])
async def health(r: RedisDep):
    await r.ping()
    return Health(status="ok", redis="ok")


@router.get("/runs", response_model=list[RunSummary], tags=["runs"])
async def list_runs(
    r: RedisDep,
    response: Response,
    offset: Annotated[int, Query(ge=0, le=10**9, description="runs to skip")] = 0,
    limit: Annotated[int, Query(ge=1, le=RUNS_PAGE_MAX, description="runs per page")] = 100,
):
    """Runs, newest first, a page at a time (`X-Total-Count` holds how many there are)."""
    response.headers["X-Total-Count"] = str(await r.zcard(RUNS))
    ids = await r.zrevrange(RUNS, offset, offset + limit - 1)
    pipe = r.pipeline(transaction=False)
    for run in ids:
        keys = RunKeys(run)
        pipe.hmget(keys.meta, list(META_FIELDS))
        pipe.hmget(keys.progress, ["iteration", "env_steps"])
        pipe.exists(keys.lease)
    replies = await pipe.execute()
    runs = []
    for run, values, (iteration, env_steps), lease in zip(
        ids, replies[::3], replies[1::3], replies[2::3], strict=True
    ):
        meta = {k: v for k, v in zip(META_FIELDS, values, strict=True) if v is not None}
        if "status" not in meta:
            continue
        meta["status"] = live_status(meta["status"], lease)
        runs.append(
            RunSummary(
                run_id=run,
                name=meta.get("name", ""),
                character=meta.get("character", ""),
                status=meta.get("status", "unknown"),
                started_at=float(meta.get("started_at", 0)),
                updated_at=float(meta.get("updated_at", 0)),
                iteration=_num(iteration, int),
                env_steps=_num(env_steps, int),
                total_steps=_num(meta.get("total_steps"), int),
            )
        )
    return runs


@router.get("/runs/{run}", response_model=RunDetail, tags=["runs"])
async def run_detail(run: RunId, r: RedisDep):
    """One run: status, config and its task parameters by name, unit and meaning (measured
    parameters with their measure, reward and event)."""
    pipe = r.pipeline(transaction=False)
    keys = RunKeys(run)
    pipe.hmget(keys.meta, [*META_FIELDS, "config", "parameters"])
    pipe.hmget(keys.progress, ["iteration", "env_steps"])
    pipe.exists(keys.lease)
    values, (iteration, env_steps), lease = await pipe.execute()
    meta = dict(zip((*META_FIELDS, "config", "parameters"), values, strict=True))
    if meta["status"] is None:
        raise _not_found(run)
    config = json.loads(meta["config"] or "{}")  # damaged JSON: 409 (app.damaged_state)
    params = json.loads(meta["parameters"]) if meta["parameters"] else None
    if params is None:  # runs registered by older versions stored ranges only
        params = [{"name": n, "range": list(v), "constraint": v[0] == v[1], "kind": "unknown",
                   "unit": ""} for n, v in config.get("task", {}).items()]  # fmt: skip
    return RunDetail(
        run_id=run,
        name=meta["name"] or "",
        character=meta["character"] or "",
        status=live_status(meta["status"], lease),
        started_at=float(meta["started_at"] or 0),
        updated_at=float(meta["updated_at"] or 0),
        iteration=_num(iteration, int),
        env_steps=_num(env_steps, int),
        total_steps=_num(meta["total_steps"], int),
        config=config,
        parameters=params,
    )


@router.get("/runs/{run}/character", response_model=CharacterInfo, tags=["runs"])
async def character(run: RunId, r: RedisDep):
    """The run's character from the registry: capabilities, shape parameters, motions."""
    keys, _ = await run_status(r, run)
    info = await r.hget(keys.meta, "character_info")
    if info is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"run {run!r} recorded no character info")
    return CharacterInfo(run_id=run, **json.loads(info))


@router.get("/runs/{run}/progress", response_model=Progress, tags=["runs"])
async def progress(run: RunId, r: RedisDep):
    keys = RunKeys(run)
    pipe = r.pipeline(transaction=False)  # one round trip
    pipe.hmget(keys.meta, ["status", "total_steps"])
    pipe.hgetall(keys.progress)
    pipe.exists(keys.lease)
    (state, total_steps), p, lease = await pipe.execute()
    if state is None:
        raise _not_found(run)
    return Progress(
        run_id=run,
        status=live_status(state, lease),
        iteration=_num(p.get("iteration"), int) or 0,
        env_steps=_num(p.get("env_steps"), int) or 0,
        total_steps=_num(total_steps, int),
        episodes=_num(p.get("episodes_total"), int) or 0,
        steps_per_second=_num(p.get("steps_per_second")),
        mean_return=_num(p.get("mean_return")),
        fall_percent=_num(p.get("fall_percent")),
        actors=_num(p.get("actors"), int),
        nodes=_num(p.get("nodes"), int),
        updated_at=_num(p.get("updated_at")),
    )


@router.get("/runs/{run}/history", response_model=HistoryPage, tags=["runs"])
async def history(
    run: RunId,
    r: RedisDep,
    since: Annotated[int, Query(ge=0, le=2**53, description="records after this iteration")] = 0,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 1000,
):
    keys, _ = await run_status(r, run)
    raw = await r.zrangebyscore(keys.history, f"({since}", "+inf", start=0, num=limit)
    items = await run_in_threadpool(lambda: [json.loads(x) for x in raw])  # off the event loop
    return HistoryPage(
        run_id=run, items=items, next_since=items[-1]["iteration"] if items else since
    )


@router.get("/runs/{run}/curriculum", response_model=Curriculum, tags=["curriculum"])
async def curriculum(run: RunId, r: RedisDep):
    keys, _ = await run_status(r, run)
    summary, updated = await r.hmget(keys.curriculum, ["summary", "updated_at"])
    if summary is None:
        raise HTTPException(
            status.HTTP_404_NOT_FOUND, f"run {run!r} has no curriculum state (no sampler yet)"
        )
    paused = await r.hget(keys.control, "paused")
    return Curriculum(
        run_id=run, paused=paused == "1", updated_at=_num(updated), **json.loads(summary)
    )


@router.get(
    "/runs/{run}/curriculum/marginal-value", response_model=MarginalValueGrid, tags=["curriculum"]
)
async def marginal_value(run: RunId, r: RedisDep):
    """V̄ over the two task dimensions the config displays (the others at the box centre)."""
    keys, _ = await run_status(r, run)
    grid = await r.hget(keys.curriculum, "grid")
    data = json.loads(grid) if grid else None
    if not data:
        return MarginalValueGrid(run_id=run, available=False)
    return MarginalValueGrid(run_id=run, available=True, **data)


def _floats(name: str, text: str | None, dim: int) -> np.ndarray | None:
    if text is None:
        return None
    try:
        values = np.array([float(x) for x in text.split(",")])
    except ValueError:
        values = np.array([])
    if values.shape != (dim,) or not np.all(np.isfinite(values)):
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_ENTITY,
            f"{name} must be {dim} comma-separated finite numbers, one per task parameter",
        )
    return values


async def _skill_state(r: Redis, run: str, field: str) -> tuple[RunKeys, dict, str | None]:
    """The run's [L21] curriculum summary and one of its JSON fields, unparsed; 404 for other
    runs."""
    keys, _ = await run_status(r, run)
    summary, value = await r.hmget(keys.curriculum, ["summary", field])
    s = json.loads(summary) if summary else {}
    if s.get("task_ranges") is None:
        raise HTTPException(
            status.HTTP_404_NOT_FOUND,
            f"run {run!r} has no [L21] skill curriculum (no elite set or density)",
        )
    return keys, s, value


class EliteCache:
    """The last parsed elite set (and its k-d tree) of each run, reused until the sampler
    writes another: a dashboard polling a 300k-entry set parses and builds it once, not per
    request. Keyed by the stored text's digest; holds the `size` most recent runs."""

    def __init__(self, size: int = 8):
        self.size = size
        self.entries: OrderedDict[str, tuple[bytes, TaskSpace, EliteSet]] = OrderedDict()
        self.builds = 0
        self.lock = threading.Lock()

    def get(self, run: str, summary: dict, text: str | None) -> tuple[TaskSpace, EliteSet]:
        raw = (text or "").encode()
        digest = (
            hashlib.blake2b(raw, digest_size=16).digest()
            + json.dumps(summary["task_ranges"], sort_keys=True).encode()
        )
        with self.lock:
            hit = self.entries.get(run)
            if hit is not None and hit[0] == digest:
                self.entries.move_to_end(run)
                return hit[1], hit[2]
        space = TaskSpace.from_ranges(summary["task_ranges"])
        elites = EliteSet(space.dim, space.metric)  # distances on the normalized box
        elites.from_state(json.loads(text) if text else {"params": [], "fitness": [], "keys": []})
        with self.lock:
            self.builds += 1
            self.entries[run] = (digest, space, elites)
            self.entries.move_to_end(run)
            while len(self.entries) > self.size:
                self.entries.popitem(last=False)
        return space, elites


def elite_cache(request: Request) -> EliteCache:
    return request.app.state.elite_cache


@router.get("/runs/{run}/curriculum/elites", response_model=Elites, tags=["curriculum"])
async def elites(
    run: RunId,
    r: RedisDep,
    cache: Annotated[EliteCache, Depends(elite_cache)],
    near: Annotated[
        str | None, Query(max_length=2000, description="a point 'x1,x2,...': its k nearest")
    ] = None,
    k: Annotated[int, Query(ge=1, le=1000, description="how many nearest to ?near=")] = 5,
    low: Annotated[str | None, Query(max_length=2000, description="box corner 'x1,...'")] = None,
    high: Annotated[str | None, Query(max_length=2000, description="box corner 'x1,...'")] = None,
    limit: Annotated[int, Query(ge=1, le=100_000)] = 1000,
    spread: Annotated[
        bool,
        Query(
            description="more matches than `limit`: an evenly spaced subset (for plots), "
            "not the first `limit`"
        ),
    ] = False,
):
    """The elite set ([L21] §5.2): all, those within the box [low, high], or the k nearest to
    a point (distance on the task box normalized per dimension), with their fitness."""
    _, summary, table = await _skill_state(r, run, "elites")
    # parsing the set, building its k-d tree and querying it is CPU work: a worker thread, not
    # the event loop
    return await run_in_threadpool(
        _elites, cache, run, summary, table, near, k, low, high, limit, spread
    )


def _elites(cache, run, summary, table, near, k, low, high, limit, spread) -> Elites:
    space, elites = cache.get(run, summary, table)
    point = _floats("near", near, space.dim)
    box_low, box_high = _floats("low", low, space.dim), _floats("high", high, space.dim)
    rows = elites.within_box(box_low, box_high)
    distance = None
    if point is not None:
        rows = elites.nearest(point, k, among=rows)
        distance = elites.distance(rows, point)
    if spread and len(rows) > limit:
        pick = np.linspace(0, len(rows) - 1, limit).round().astype(int)
        rows = rows[pick]
        distance = None if distance is None else distance[pick]
    rows = rows[:limit]
    items = [
        Elite(
            key=elites.keys[i],
            params=space.to_dict(elites.params[i]),
            fitness=float(elites.fitness[i]),
            distance=None if distance is None else float(distance[j]),
        )
        for j, i in enumerate(rows)
    ]
    return Elites(run_id=run, names=list(space.names), total=len(elites), items=items)


@router.get("/runs/{run}/curriculum/density", response_model=DensityGrid, tags=["curriculum"])
async def density(run: RunId, r: RedisDep):
    """The KDE density of the elites (Eq. 15) over the two display dimensions (the others at
    the reference), with the thresholds that split A_h, A_s and the unvisited rest."""
    _, _, grid = await _skill_state(r, run, "density")
    if not grid:
        return DensityGrid(run_id=run, available=False)
    return DensityGrid(run_id=run, available=True, **json.loads(grid))


@router.get("/runs/{run}/curriculum/samples", response_model=list[TaskBatch], tags=["curriculum"])
async def samples(
    run: RunId, r: RedisDep, limit: Annotated[int, Query(ge=1, le=SAMPLES_LIMIT)] = 20
):
    """The latest task batches the sampler handed out, newest first."""
    keys, _ = await run_status(r, run)
    return [json.loads(x) for x in await r.lrange(keys.samples, 0, limit - 1)]


@router.get("/runs/{run}/events", response_model=list[Event], tags=["runs"])
async def events(
    run: RunId,
    r: RedisDep,
    since: Annotated[
        str, Query(pattern=STREAM_ID, description="events after this id (0: from the start)")
    ] = "0",
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
):
    """Restarts, checkpoints, pauses, k changes, ... oldest first."""
    keys, _ = await run_status(r, run)
    start = "-" if since == "0" else f"({since}"
    entries = await r.xrange(keys.events, min=start, max="+", count=limit)
    return [
        Event(
            id=eid,
            type=f.get("type", ""),
            message=f.get("message", ""),
            time=float(f.get("time", 0)),
            data=json.loads(f.get("data", "{}")),
        )
        for eid, f in entries
    ]


# what every request that changes a run shares: the bearer token, 202 and the answer
CONTROL = dict(response_model=Accepted, status_code=202, dependencies=[TokenDep], tags=["control"])


async def _request(r: Redis, run: str, field: str, value, kind: str, message: str) -> Accepted:
    keys, state = await run_status(r, run)
    if state not in ("running", "paused"):
        raise HTTPException(status.HTTP_409_CONFLICT, f"run {run!r} is {state}")
    pipe = r.pipeline(transaction=True)
    pipe.hset(keys.control, field, value)
    add_event(pipe, keys, kind, message)
    await pipe.execute()
    return Accepted(run_id=run, requested={field: value})


@router.post("/runs/{run}/pause", **CONTROL)
async def pause(run: RunId, r: RedisDep):
    """Ask the learner to pause after its current iteration (needs the bearer token)."""
    return await _request(r, run, "paused", 1, "pause_requested", "pause requested via the API")


@router.post("/runs/{run}/resume", **CONTROL)
async def resume(run: RunId, r: RedisDep):
    """Ask a paused learner to go on (needs the bearer token)."""
    return await _request(r, run, "paused", 0, "resume_requested", "resume requested via the API")


@router.put("/runs/{run}/curriculum/k", **CONTROL)
async def set_k(run: RunId, body: SetK, r: RedisDep):
    """Set the uniformity k of the adaptive sampling from the next iteration (needs the token)."""
    message = f"k = {body.k:g} requested via the API"
    return await _request(r, run, "k", body.k, "k_requested", message)
