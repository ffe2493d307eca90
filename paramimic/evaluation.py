"""Evaluation of a parametric controller ([WL19] Table 4, Fig. 6).

Fall-down % within the horizon, task achievement (mean cumulative task reward), mean return,
per-parameter returns over a grid of two task dimensions, and uniformity: min/mean and the
coefficient of variation of the per-parameter returns. On a clip gait (`env.gait`) also the
imitation measures: the body position error (every body against its reference, each relative
to its own root in its own heading frame, averaged over bodies and control steps, m; on an [L21]
skill too, against m_a), the root drift (the root's mean horizontal distance from the reference
root path, m) and the forward speed against the clip's. On an [L21] skill family, each task
is performed with the motion the run deals it (m_a = P_θ(a), `Method.performer`) and counts as
achieved when every measured parameter lands within its σ_task of the goal ([L21] Eq. 8), the
clip is completed and the character does not fall.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from paramimic.envs import ParamEnv, env_for
from paramimic.rl.networks import ActorCritic
from paramimic.task_space import TaskSpace


@dataclass
class EpisodeResult:
    task: np.ndarray
    ret: float
    task_return: float  # Σ of the task reward term (Eq. 6 share of the reward)
    length: int
    fell: bool
    distance: float  # root x travelled (m)
    seconds: float
    fitness: float | None = None  # [L21] Eq. 10 of a skill episode (0 unless completed)
    body_error: float | None = None  # clip gaits: mean body position error (m)
    root_drift: float | None = None  # clip gaits: mean distance from the reference root path
    clip_speed: float | None = None  # clip gaits: the clip's speed on this body (m/s)
    target_speed: float | None = None  # [WL19] gaits: the body's target speed (Table 1, m/s)
    # [L21] skills: each measured task parameter's |a' − a| / σ_task, and whether the task was
    # achieved (every one within its σ_task, the clip completed, no fall)
    task_errors: dict[str, float] | None = None
    achieved: bool | None = None
    facing_error: float | None = None  # clip gaits: mean angle from the clip's facing (rad)


Act = Callable[[np.ndarray], np.ndarray]  # observations [n, obs] -> actions [n, A]
Motions = Callable[[np.ndarray], "np.ndarray | None"]  # tasks [n, d] -> m_a [n, K, D], or None


def deterministic(policy: ActorCritic) -> Act:
    """The policy's mean action."""
    fast = policy.numpy_policy()
    return lambda obs: fast.act(obs, None)[0]


def morph_path(path: Sequence[dict[str, float]], t: float) -> dict[str, float]:
    """Piecewise-linear interpolation along shapes `path` at t ∈ [0, 1]."""
    if len(path) == 1:
        return dict(path[0])
    x = min(max(t, 0.0), 1.0) * (len(path) - 1)
    k = min(int(x), len(path) - 2)
    u = x - k
    return {n: (1 - u) * path[k][n] + u * path[k + 1][n] for n in path[0]}


def morph_episode(
    act: Act,
    env: ParamEnv,
    task: np.ndarray,
    path: Sequence[dict[str, float]],
    seconds: float,
    seed: int = 0,
    watch: Callable[[], None] | None = None,
) -> dict:
    """[WL19] §5.2: one body whose shape follows `path` over `seconds`, `set_shape` every
    control step with the policy in control throughout; ends early if the body falls. `watch`
    is called on the start and after every step (a camera). Returns whether it fell, when, the
    shape then and the root's forward distance."""
    names = set(path[0])
    if any(set(p) != names for p in path):
        raise ValueError("every shape on a morph path must name the same parameters")
    obs, _ = env.reset(seed=seed, options={"task": task})
    obs = env.set_shape(path[0])
    x0 = float(env.data.qpos[0])
    if watch:
        watch()
    steps = int(round(seconds / env.dt))
    fell, done = False, 0
    for i in range(steps):
        obs = env.set_shape(morph_path(path, (i + 1) / steps))
        obs, _, terminated, truncated, _ = env.step(act(obs[None])[0])
        done = i + 1
        if watch:
            watch()
        if terminated or truncated:
            fell = bool(terminated)
            break
    shape = {n: float(env.task[env.task_space.names.index(n)]) for n in sorted(names)}
    return {
        "fell": fell,
        "seconds": done * env.dt,
        "shape": shape,
        "distance": float(env.data.qpos[0]) - x0,
    }


def run_episodes(
    act: Act,
    make_env: Callable[[], ParamEnv],
    tasks: np.ndarray,
    num_envs: int,
    seed: int,
    motions: Motions | None = None,
) -> list[EpisodeResult]:
    """One episode per task, `num_envs` at a time with one batched `act` call per step;
    `motions` deals each task the motion it is performed with ([L21]: m_a = P_θ(a))."""
    envs = [make_env() for _ in range(min(num_envs, len(tasks)))]
    dealt = None if motions is None else motions(np.asarray(tasks))
    rng = np.random.default_rng(seed)
    results: list[EpisodeResult | None] = [None] * len(tasks)
    queue = list(range(len(tasks)))
    slots: list[dict | None] = [None] * len(envs)
    obs = np.zeros((len(envs), envs[0].observation_space.shape[0]), np.float32)

    def start(j: int) -> None:
        if not queue:
            slots[j] = None
            return
        k = queue.pop(0)
        options = {"task": tasks[k]} | ({} if dealt is None else {"motion": dealt[k]})
        o, _ = envs[j].reset(seed=int(rng.integers(2**31 - 1)), options=options)
        obs[j] = o
        slots[j] = {"k": k, "ret": 0.0, "task": 0.0, "len": 0, "x0": float(envs[j].data.qpos[0])}
        slots[j] |= {"error": 0.0, "drift": 0.0, "facing": 0.0}

    for j in range(len(envs)):
        start(j)
    while any(s is not None for s in slots):
        actions = act(obs)
        for j, env in enumerate(envs):
            s = slots[j]
            if s is None:
                continue
            o, r, te, tr, info = env.step(actions[j])
            obs[j] = o
            s["ret"] += r
            s["task"] += info["reward_terms"]["task"]
            s["len"] += 1
            bodies = getattr(env, "tracks_bodies", False)
            path = getattr(env, "clip_speed", None) is not None
            if not info["diverged"]:
                s["error"] += env.body_error()[0] if bodies else 0.0
                s["drift"] += env.root_drift() if path else 0.0
                s["facing"] += env.facing_error() if path else 0.0
            if te or tr:
                fell = bool(info["fell"] or info["diverged"])  # a completed clip also ends
                errors = env.task_errors() if getattr(env, "measured", None) else None
                achieved = None
                if errors is not None:
                    done = "skill" in info and info["skill"].completed
                    achieved = done and not fell and all(e <= 1.0 for e in errors.values())
                results[s["k"]] = EpisodeResult(
                    tasks[s["k"]],
                    s["ret"],
                    s["task"],
                    s["len"],
                    fell,
                    float(env.data.qpos[0]) - s["x0"],
                    s["len"] * env.dt,
                    info["skill"].fitness if "skill" in info else None,
                    s["error"] / s["len"] if bodies else None,
                    s["drift"] / s["len"] if path else None,
                    env.clip_speed if path else None,
                    getattr(env, "target_speed", None),
                    errors,
                    achieved,
                    facing_error=s["facing"] / s["len"] if path else None,
                )
                start(j)
    return [r for r in results if r is not None]


def uniformity(returns: np.ndarray) -> dict[str, float]:
    """min/mean and coefficient of variation (std/mean) of per-parameter returns."""
    r = np.asarray(returns, dtype=np.float64)
    mean = float(r.mean())
    return {
        "min_over_mean": float(r.min() / mean) if mean else 0.0,
        "coefficient_of_variation": float(r.std() / mean) if mean else 0.0,
    }


def summarize(results: list[EpisodeResult]) -> dict:
    rets = np.array([r.ret for r in results])
    speeds = np.array([r.distance / r.seconds for r in results])
    decile = np.sort(rets)[: max(1, len(rets) // 10)]
    return (
        {
            "episodes": len(results),
            "mean_return": float(rets.mean()),
            "worst_decile_return": float(decile.mean()),
            "task_achievement": float(np.mean([r.task_return for r in results])),
            "fall_percent": 100.0 * float(np.mean([r.fell for r in results])),
            "mean_length_seconds": float(np.mean([r.seconds for r in results])),
            "mean_forward_speed": float(speeds.mean()),
            "uniformity": uniformity(rets),
        }
        | _fitness(results)
        | _achieved(results)
        | _tracking(results, speeds)
        | _on_target(results, speeds)
    )


SPEED_TOLERANCE = 0.15  # a body is on target within 15 % of its own target speed


def _on_target(results: list[EpisodeResult], speeds: np.ndarray) -> dict:
    """[WL19] gaits: the forward speed over each body's own target speed (its Table 1
    normalization), the mean and the share of bodies within SPEED_TOLERANCE of it."""
    targets = np.array([r.target_speed or 0.0 for r in results])
    if not results or results[0].target_speed is None or (targets <= 0).any():
        return {}
    ratio = speeds / targets
    within = np.abs(ratio - 1.0) <= SPEED_TOLERANCE
    return {"speed_over_target": float(ratio.mean()), "on_target_share": float(within.mean())}


def _fitness(results: list[EpisodeResult]) -> dict:
    f = [r.fitness for r in results if r.fitness is not None]
    return {"mean_fitness": float(np.mean(f))} if f else {}


def _achieved(results: list[EpisodeResult]) -> dict:
    """[L21] skills: the share of tasks achieved, and each measured parameter's mean error in
    its σ_task."""
    done = [r for r in results if r.achieved is not None]
    if not done:
        return {}
    names = list(done[0].task_errors or {})
    return {
        "achieved_share": float(np.mean([r.achieved for r in done])),
        "task_error_sigmas": {n: float(np.mean([r.task_errors[n] for r in done])) for n in names},
    }


def _tracking(results: list[EpisodeResult], speeds: np.ndarray) -> dict:
    """The clip-gait measures over episodes (each episode's per-step mean, then the mean)."""
    if not results or results[0].body_error is None:
        return {}
    out = {"mean_body_error": float(np.mean([r.body_error for r in results]))}
    if results[0].clip_speed is None:  # a skill: no root path to follow
        return out
    clip = np.array([r.clip_speed for r in results])
    return out | {
        "mean_root_drift": float(np.mean([r.root_drift for r in results])),
        "mean_facing_error": float(np.mean([r.facing_error for r in results])),
        "clip_speed": float(clip.mean()),
        "speed_ratio": float(np.mean(speeds / clip)),
    }


def evaluate(
    act: Act,
    make_env: Callable[[], ParamEnv],
    space: TaskSpace,
    episodes: int,
    seed: int,
    grid_dims: tuple[str, str] | None,
    grid_size: int,
    num_envs: int = 8,
    motions: Motions | None = None,
) -> dict:
    """Random tasks (uniform over A) for the headline numbers, plus a grid over two dims;
    `motions`: what each task is performed with (`run_episodes`)."""
    rng = np.random.default_rng(seed)
    tasks = space.sample(rng, episodes)
    report = summarize(run_episodes(act, make_env, tasks, num_envs, seed, motions))
    if grid_dims is not None:
        xs, ys, pts = space.grid(grid_dims, grid_size)
        grid = run_episodes(act, make_env, pts, num_envs, seed + 1, motions)
        rets = np.array([r.ret for r in grid]).reshape(grid_size, grid_size)
        report["grid"] = {
            "dims": list(grid_dims),
            "x": xs.tolist(),
            "y": ys.tolist(),
            "returns": rets.tolist(),  # [y][x]
            "fall": np.array([r.fell for r in grid]).reshape(grid_size, grid_size).tolist(),
            "uniformity": uniformity(rets.ravel()),
        }
    return report


def evaluate_config(
    policy: ActorCritic,
    cfg,
    episodes: int,
    seed: int,
    grid_size: int,
    seconds: float | None = None,
    motions: Motions | None = None,
) -> dict:
    """`evaluate` of the deterministic `policy` on an experiment config's env and task space
    (`cfg`: an ExperimentConfig), episodes of `seconds` (default: the config's horizon), the
    grid over the config's display dims; `motions` as `evaluate`'s (a run's: `Method.performer`)."""

    env_cfg = cfg.env.for_evaluation(seconds)
    dims = cfg.display_dims()
    return evaluate(
        deterministic(policy),
        lambda: env_for(cfg, env_cfg),
        cfg.task_space(),
        episodes,
        seed,
        dims if len(dims) == 2 else None,
        grid_size,
        motions=motions,
    )
