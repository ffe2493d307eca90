"""The papers, reproduced row by row: each experiment at the paper's settings and at ours, with
the paper's own number beside them. Not a timed test.

Rows (ROWS below):
- [WL19] Table 4: reward normalization on and off, biped (lower body) and quadruped; task
  achievement and falls within 30 s on 300 bodies drawn with a seed the training never used.
- [WL19] Fig. 6: k = 0 / 5 / 10 / 20 on walker_legs; the worst decile and the coefficient of
  variation of the per-shape return over a 7 x 7 grid ("the higher k, the more uniform").
- [L21] Table 2: A1 (m_a = m0), A2 (no time warp), A3 (ours) on the jump family: the share of
  the task space explored (ER, what §7.2 measures) and the range of each dimension the elites
  cover.
- [L21] §7.3: ER against episodes for the baseline, exploration-only, mastering, alternating
  and ours (the runs of `benchmarks/curriculum.py --samplings`, read from its curriculum.json;
  at the paper's settings from `--recipe l21`'s curriculum_l21.json).

Each row runs in two arms: `paper` (the paper's recipe, `recipe: wl19` or `l21`: every
departure switched to the paper's setting) and `ours` (the row's config as shipped). A run is
the serial trainer in its own run directory (runs/reproduce/..., resumed where it stopped),
evaluated once at its budget; its JSON and the table's (reproduce.json) go to
benchmarks/results/reproduce/.

    python benchmarks/reproduce.py run wl19_fig6 --arm ours --seeds 0,1,2 [--jobs 2]
    python benchmarks/reproduce.py all [--dry-run]  # every row and §7.3, both arms, 3 seeds
    python benchmarks/reproduce.py table        # docs/reproduce.md from the JSON and the recipes
    python benchmarks/reproduce.py cost         # what a run costs in each arm (cost.json)
    python benchmarks/reproduce.py backfill     # measures added since into kept runs' JSON
    python benchmarks/reproduce.py rn-falls     # where Table 4's runs fall, by RN's scale
    python benchmarks/reproduce.py list
"""

from __future__ import annotations

import argparse
import functools
import json
import multiprocessing
import time
from pathlib import Path

import numpy as np
from humanoid import metrics_rows, wall_clock  # benchmarks/humanoid.py
from tabulate import tabulate

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
OUT = RESULTS / "reproduce"
DOCS = ROOT / "docs" / "reproduce.md"
RUNS = ROOT / "runs" / "reproduce"
EVAL_SEED = 10_000  # + the training seed: shapes the training never drew
CLAIM_SEEDS = 3  # a claim is judged once every variant of its row has run on this many seeds
SEEDS = list(range(CLAIM_SEEDS))  # the seeds `all` runs
# [WL19] Table 4's evaluation: 300 bodies, falls within 30 s; Fig. 6's 7 x 7 grid of shapes
EVAL = {"bodies": 300, "seconds": 30.0, "grid": 7}

# row -> what it reproduces, the config, its variants (overrides), the paper's recipe, the
# budget per run in env steps, what is measured, and the paper's numbers per variant
ROWS: dict[str, dict] = {
    "wl19_table4": {
        "paper": "[WL19] Table 4",
        "what": "reward normalization (RN) on/off; task achievement and falls in 30 s, 300 bodies",
        "variants": {
            "biped_lower_rn": ("configs/biped_lower.yaml", {"env.reward.normalize": True}),
            "biped_lower_no_rn": ("configs/biped_lower.yaml", {"env.reward.normalize": False}),
            "quadruped_rn": ("configs/quadruped.yaml", {"env.reward.normalize": True}),
            "quadruped_no_rn": ("configs/quadruped.yaml", {"env.reward.normalize": False}),
        },
        # ours: the recipes that learn these families here (docs/results/families-that-learn.md):
        # every range shrunk halfway to the base body (x0.5), warm started from a base-body run
        # of the same seed, which RN on and off share (on the base body every RN scale is 1)
        "ours_variants": {
            "biped_lower_rn": ("configs/biped_x0.5.yaml", {"env.reward.normalize": True}),
            "biped_lower_no_rn": ("configs/biped_x0.5.yaml", {"env.reward.normalize": False}),
            "quadruped_rn": ("configs/quadruped_x0.5.yaml", {"env.reward.normalize": True}),
            "quadruped_no_rn": ("configs/quadruped_x0.5.yaml", {"env.reward.normalize": False}),
        },
        "base": {
            "configs/biped_x0.5.yaml": ("configs/biped_base.yaml", 2_000_000),
            "configs/quadruped_x0.5.yaml": ("configs/quadruped_base.yaml", 2_000_000),
        },
        # the biped's family stage: what configs/biped_x0.5.yaml ships (the families study: its
        # range has not grown to the whole family by half of it)
        "ours_steps": {"configs/biped_x0.5.yaml": 8_000_000},
        "recipe": "wl19",
        "steps": 2_000_000,
        "measure": "family",
        "paper_numbers": {
            "biped_lower_rn": "369.54 task, 20.7 % falls",
            "biped_lower_no_rn": "218.86 task, 54.1 % falls",
            "quadruped_rn": "427.51 task, 9.3 % falls",
            "quadruped_no_rn": "338.15 task, 11.1 % falls",
        },
    },
    "wl19_fig6": {
        "paper": "[WL19] Fig. 6",
        "what": "uniformity k of the shape sampling; worst decile and CV of the per-shape return",
        "variants": {
            f"k{k}": ("configs/walker_legs.yaml", {"curriculum.k": float(k)})
            for k in (0, 5, 10, 20)
        },
        "recipe": "wl19",
        "steps": 2_000_000,
        "measure": "family",
        "paper_numbers": {
            "k0": "the least uniform (Fig. 6a)",
            "k5": "no number",
            "k10": "more uniform than k = 0 (Fig. 6b)",
            "k20": "no number",
        },
    },
    "l21_table2": {
        "paper": "[L21] Table 2",
        "what": "A1 (m_a = m0) / A2 (no time warp) / A3 (ours): task ranges explored (jump)",
        "variants": {
            "A1": ("configs/walker_jump.yaml", {"curriculum.skill.motion_parameterization": False}),
            "A2": ("configs/walker_jump.yaml", {"env.skill.time_warp": False}),
            "A3": ("configs/walker_jump.yaml", {}),
        },  # fmt: skip
        "recipe": "l21",
        "steps": 2_000_000,
        "measure": "skill",
        "paper_numbers": {
            "A1": "none for a planar jump (humanoid: gravity [0.4, 1.65])",
            "A2": "none for a planar jump (humanoid: gravity [0.3, 1.65])",
            "A3": "none for a planar jump (humanoid: gravity [0.2, 1.65])",
        },
    },
}
CURRICULA = ("uniform", "exploration_only", "mastering", "alternating", "curriculum")
CURRICULA_STEPS = 1_500_000  # §7.3's budget per run (benchmarks/curriculum.py --steps)
CURRICULA_PAPER = {
    "uniform": "none for a planar jump (humanoid Jump: 43 % explored)",
    "exploration_only": "none for a planar jump (humanoid Jump: 87 %)",
    "mastering": "explores the hard examples",
    "alternating": "explores the hard examples",
    "curriculum": "the best balance in every example",
}


def result_path(row: str, arm: str, variant: str, seed: int, steps: int) -> Path:
    return OUT / f"{row}_{arm}_{variant}_s{seed}_{steps // 1000}k.json"


def variant_spec(row: str, arm: str, variant: str) -> tuple[str, dict, int, tuple | None]:
    """A variant in an arm: its config, its overrides, its budget in env steps and its base
    stage (a base-body config and its steps, or None): a row's `ours_variants` replace its
    variants in our arm."""
    spec = ROWS[row]
    ours = spec.get("ours_variants") if arm == "ours" else None
    config, overrides = (ours or spec["variants"])[variant]
    base = spec.get("base", {}).get(config) if arm == "ours" else None
    steps = spec.get("ours_steps", {}).get(config, spec["steps"]) if arm == "ours" else None
    return config, overrides, steps or spec["steps"], base


def base_dir(row: str, arm: str, base_config: str, seed: int) -> Path:
    return RUNS / row / arm / f"base_{Path(base_config).stem}_s{seed}"


def _config(
    row: str, arm: str, variant: str, seed: int, run_dir: Path, threads: int | None,
    warm: bool = True,
):  # fmt: skip
    """A variant's config in an arm, and the overrides that made it from the row's config
    (`warm`: started from its base stage's run, where it has one)."""
    from paramimic import recipes
    from paramimic.config import load_config

    spec = ROWS[row]
    config, overrides, _, base = variant_spec(row, arm, variant)
    overrides = (recipes.overrides(spec["recipe"]) if arm == "paper" else {}) | overrides
    if base and warm:
        overrides = overrides | {"train.init_from": str(base_dir(row, arm, base[0], seed))}
    cfg = load_config(
        ROOT / config,
        overrides
        | {"train.seed": seed, "train.run_dir": str(run_dir)}
        | ({"train.torch_threads": threads} if threads else {}),
    )
    return cfg, overrides


def run_base(row: str, arm: str, base_config: str, steps: int, seed: int,
             threads: int | None = None) -> Path:  # fmt: skip
    """A base-body stage trained to `steps` (resumed; nothing to do once there). Two runs that
    start from one base stage at once: the second waits for the first's (a lock file)."""
    import fcntl

    import torch

    from paramimic.config import load_config
    from paramimic.training.trainer import train_serial

    run_dir = base_dir(row, arm, base_config, seed)
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    with open(run_dir.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not _trained(run_dir, steps):
            cfg = load_config(
                ROOT / base_config,
                {"train.seed": seed, "train.run_dir": str(run_dir)}
                | ({"train.torch_threads": threads} if threads else {}),
            )
            torch.manual_seed(seed)
            train_serial(cfg, steps, run_dir)
            print(f"base stage {run_dir} at {steps:,} env steps")
    return run_dir


def cost(rows: list[str], iterations: int = 3) -> dict:
    """What a run of each row costs in each arm on this machine: a few policy iterations of the
    row's first variant, arm after arm in one process (compare the arms of one call only:
    speeds drift between days), as wall-clock seconds per 1,000 env steps and the hours a run
    of the row's budget would take at that rate, every core to the one run."""
    import tempfile

    import torch

    from paramimic.training.trainer import train_serial

    out = {}
    for row in rows:
        spec = ROWS[row]
        variant = next(iter(spec["variants"]))
        out[row] = {"variant": variant}
        for arm in ("paper", "ours"):
            budget = variant_spec(row, arm, variant)[2]
            with tempfile.TemporaryDirectory() as tmp:
                cfg, _ = _config(row, arm, variant, 0, Path(tmp), None, warm=False)
                steps = iterations * cfg.ppo.num_steps
                torch.manual_seed(0)
                t0 = time.perf_counter()
                trainer = train_serial(cfg, steps, Path(tmp))
                seconds = time.perf_counter() - t0
            per_k = 1000 * seconds / trainer.progress.env_steps
            out[row][arm] = {
                "env_steps": trainer.progress.env_steps,
                "seconds": seconds,
                "seconds_per_1k_steps": per_k,
                "budget": budget,
                "hours_per_run": per_k * budget / 1000 / 3600,
                "physics_hz": cfg.env.physics_hz,
                "minibatch_size": cfg.ppo.minibatch_size,
                "hidden_sizes": list(cfg.ppo.hidden_sizes),
            }
            print(f"{row} {arm}: {per_k:.2f} s per 1k env steps, "
                  f"{out[row][arm]['hours_per_run']:.1f} h per run")  # fmt: skip
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / "cost.json"
    kept = json.loads(path.read_text()) if path.exists() else {}
    path.write_text(json.dumps(kept | out, indent=1))
    return out


def scales(bodies: int = EVAL["bodies"]) -> dict:
    """What reward normalization does in each arm of [WL19] Table 4: its three scales ([WL19]
    Table 1: velocity, direction, energy) over `bodies` shapes drawn as the evaluation draws
    them, as the 5th and 95th percentiles and their ratio (how far apart RN moves the bodies'
    rewards; 1 on the base body), for reproduce.json."""
    from paramimic.config import load_config
    from paramimic.envs import env_for
    from paramimic.envs.reward_normalization import reward_scales

    out: dict = {}
    for variant in ROWS["wl19_table4"]["variants"]:
        if not variant.endswith("_no_rn"):
            continue
        body_name = variant.removesuffix("_no_rn")
        for arm in ("paper", "ours"):
            config = variant_spec("wl19_table4", arm, variant)[0]
            cfg = load_config(ROOT / config)
            env = env_for(cfg)
            space = cfg.task_space()
            base = env.body_for(space.base(env.definition.param_names()))
            tasks = space.sample(np.random.default_rng(EVAL_SEED), bodies)
            found = np.array([
                (r.velocity, r.direction, r.energy)
                for b in map(env.body_for, tasks)
                for r in [reward_scales(b.leg_lengths, base.leg_lengths, b.mass, base.mass)]
            ])  # fmt: skip
            env.close()
            low, high = np.percentile(found, [5, 95], axis=0)
            out.setdefault(body_name, {})[arm] = {
                "config": config,
                "bodies": bodies,
                **{name: {"p5": float(lo), "p95": float(hi), "ratio": float(hi / lo)}
                   for name, lo, hi in zip(("velocity", "direction", "energy"), low, high,
                                           strict=True)},
            }  # fmt: skip
    return out


def rn_falls(arm: str) -> dict:
    """Where each [WL19] Table 4 run of an arm falls (`_falls_by_scale`), into rn_falls.json by
    arm; a run measured there at the env steps it was kept at is not measured again. The thirds
    are a seed's, so RN on and off of a seed split the same bodies."""
    path = OUT / "rn_falls.json"
    kept_all = json.loads(path.read_text()) if path.exists() else {}
    before = kept_all.get(arm, {})
    found: dict = {}
    for variant in ROWS["wl19_table4"]["variants"]:
        for kept in _results("wl19_table4", arm, variant):
            seed = str(kept["seed"])
            old = before.get(variant, {}).get("seeds", {}).get(seed)
            if old is None or old.get("env_steps") != kept["env_steps"]:
                old = _falls_by_scale(arm, variant, kept)
            if old is not None:
                found.setdefault(variant, {"seeds": {}})["seeds"][seed] = old
    means = ("falls", "falls_by_third", "speed_by_third", "target_by_third")
    for v in found.values():
        v["mean"] = {k: np.mean([r[k] for r in v["seeds"].values()], axis=0).tolist()
                     for k in means}  # fmt: skip
    OUT.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(kept_all | {arm: found}, indent=1))
    print(f"wrote {path}")
    return found


def _falls_by_scale(arm: str, variant: str, kept: dict) -> dict | None:
    """A kept [WL19] Table 4 run's held-out bodies evaluated again from its run directory's
    checkpoint (the state its report was measured in: the same bodies and episode seeds, so the
    same falls), by each body's RN velocity scale ([WL19] Table 1, as `scales`): the share that
    falls in each third of the bodies, the lowest scale (shortest or most uneven legs) first,
    with the mean forward speed there and the mean target speed (RN's per body, or the base
    body's without RN). None without the checkpoint it was evaluated in."""
    from paramimic.envs import env_for
    from paramimic.envs.reward_normalization import reward_scales
    from paramimic.evaluation import deterministic, run_episodes
    from paramimic.training import checkpoint

    seed = kept["seed"]
    run_dir = RUNS / "wl19_table4" / arm / f"{variant}_s{seed}"
    if not checkpoint.checkpoint_dir(run_dir).is_dir():
        print(f"{run_dir}: no checkpoint, skipped")
        return None
    state, cfg, policy = checkpoint.load_policy(run_dir)
    if state["progress"]["env_steps"] != kept["env_steps"]:
        print(f"{run_dir}: trained on since it was evaluated, skipped")
        return None
    space = cfg.task_space()
    tasks = space.sample(np.random.default_rng(EVAL_SEED + seed), EVAL["bodies"])
    make_env = functools.partial(env_for, cfg, cfg.env.for_evaluation(EVAL["seconds"]))
    episodes = run_episodes(deterministic(policy), make_env, tasks, 8, EVAL_SEED + seed)
    env = env_for(cfg)
    base = env.body_for(space.base(env.definition.param_names()))
    velocity = np.array([
        reward_scales(b.leg_lengths, base.leg_lengths, b.mass, base.mass).velocity
        for b in map(env.body_for, tasks)
    ])  # fmt: skip
    env.close()
    fell = np.array([e.fell for e in episodes], dtype=float)
    speed = np.array([e.distance / e.seconds for e in episodes])
    target = np.array([e.target_speed for e in episodes])  # RN's, or the base's
    third = np.digitize(velocity, np.quantile(velocity, [1 / 3, 2 / 3]))
    return {
        "env_steps": kept["env_steps"],
        "falls": 100.0 * float(fell.mean()),
        "kept_falls": kept["report"]["fall_percent"],
        "velocity_scale_edges": np.quantile(velocity, [0, 1 / 3, 2 / 3, 1]).tolist(),
        "falls_by_third": [100.0 * float(fell[third == i].mean()) for i in range(3)],
        "speed_by_third": [float(speed[third == i].mean()) for i in range(3)],
        "target_by_third": [float(target[third == i].mean()) for i in range(3)],
    }


def trained_seconds(run_dir: Path, env_steps: int) -> float | None:
    """Seconds a run trained to `env_steps`, over every session it was resumed in, the pauses
    between them left out (from its metrics.jsonl); None without a logged iteration there."""
    rows = metrics_rows(run_dir) if (run_dir / "metrics.jsonl").exists() else []
    upto = next((r["iteration"] for r in rows if r.get("env_steps") == env_steps), None)
    return None if upto is None else wall_clock([r for r in rows if r.get("iteration", 0) <= upto])


def backfill() -> list[Path]:
    """Kept runs written before a measure was added get it from their run directory's
    checkpoint (the state they were evaluated in): a [WL19] run the sampler's concentration and
    the training range's width at its end, an [L21] run its elites' mean fitness. Without the
    checkpoint, a run whose config never grows its range gets its width from the config (the
    whole range, from start to end). A run's `train_seconds` is its training log's
    (`trained_seconds`, every session), where the log still reaches its env steps."""
    done = []
    for path in sorted(OUT.glob("*_s*_*k.json")):
        out = json.loads(path.read_text())
        run_dir = RUNS / out["row"] / out["arm"] / f"{out['variant']}_s{out['seed']}"
        added = _missing_measures(out, run_dir)
        seconds = trained_seconds(run_dir, out["env_steps"])
        timed = {} if seconds in (None, out.get("train_seconds")) else {"train_seconds": seconds}
        if not added and not timed:
            continue
        out["report"].update(added)
        out.update(timed)
        path.write_text(json.dumps(out, indent=2))
        done.append(path)
        print(path.name + ": " + ", ".join(f"{k} {v}" for k, v in (added | timed).items()))
    return done


def _missing_measures(out: dict, run_dir: Path) -> dict:
    """The report keys a kept run lacks, from the checkpoint it was evaluated in (`backfill`)."""
    from paramimic.config import ExperimentConfig
    from paramimic.curriculum.adaptive import AdaptiveCurriculum
    from paramimic.training import checkpoint

    family = ROWS[out["row"]]["measure"] == "family"
    keys = ("sampling", "range_width") if family else ("elite_mean_fitness",)
    missing = [k for k in keys if k not in out["report"]]
    if not missing:
        return {}
    state = checkpoint.load(run_dir) if checkpoint.checkpoint_dir(run_dir).is_dir() else None
    if state is not None and state["progress"]["env_steps"] != out["env_steps"]:
        state = None  # trained on since: not the state that was evaluated
    if state is None:
        cfg, _ = _config(out["row"], out["arm"], out["variant"], out["seed"], run_dir, None,
                         warm=False)  # fmt: skip
        measures = {"range_width": 1.0} if family and cfg.curriculum.widen is None else {}
    elif family:
        curriculum = AdaptiveCurriculum.from_config(
            ExperimentConfig.model_validate(state["config"])
        )
        curriculum.from_state(state["curriculum"])
        measures = _family_state(curriculum)
    else:
        measures = {"elite_mean_fitness": _mean_or_none(state["curriculum"]["elites"]["fitness"])}
    return {k: measures[k] for k in missing if k in measures}


def _family_state(curriculum) -> dict:
    """Where a [WL19] run's sampler stood at its end: how narrowly it drew
    (`mcmc.concentration`) and the share of the shape ranges it trained on (1 unless the config
    grows its range from the base body, `curriculum.widen`; the evaluation draws from all of it)."""
    return {"sampling": curriculum.concentration(), "range_width": float(curriculum.width)}


def _mean_or_none(values) -> float | None:
    return float(np.mean(values)) if len(values) else None


def run_one(
    row: str, arm: str, variant: str, seed: int, steps: int, threads: int | None = None
) -> dict:
    """Train one variant of a row in one arm to `steps` (resumed from its run directory), then
    evaluate it; the JSON is kept and not run again. `threads`: the learner's torch threads
    (one per run when runs share the machine; default: the config's)."""
    import torch

    from paramimic.evaluation import evaluate_config
    from paramimic.training.trainer import train_serial

    spec = ROWS[row]
    run_dir = RUNS / row / arm / f"{variant}_s{seed}"
    config, _, _, base = variant_spec(row, arm, variant)
    if base:
        run_base(row, arm, *base, seed, threads)
    cfg, overrides = _config(row, arm, variant, seed, run_dir, threads)
    torch.manual_seed(seed)
    trainer = train_serial(cfg, steps, run_dir)
    seconds = trained_seconds(run_dir, trainer.progress.env_steps)
    out = {"row": row, "arm": arm, "variant": variant, "seed": seed,
           "config": config, "overrides": overrides,
           "base": {"config": base[0], "env_steps": base[1]} if base else None,
           "env_steps": trainer.progress.env_steps, "train_seconds": seconds}  # fmt: skip
    if spec["measure"] == "family":
        report = evaluate_config(trainer.learner.policy, cfg, EVAL["bodies"], EVAL_SEED + seed,
                                 EVAL["grid"], EVAL["seconds"])  # fmt: skip
        grid = report.pop("grid")
        out["report"] = report | {"grid_uniformity": grid["uniformity"],
                                  **_family_state(trainer.curriculum)}  # fmt: skip
    else:
        c = trainer.curriculum
        live = c.elites.live()
        params = c.elites.params[live]
        out["report"] = {
            "explored_ratio": c.explored_ratio(),
            "episodes": int(c.stats["episodes"]),
            "elites": int(len(live)),
            "elite_mean_fitness": _mean_or_none(c.elites.fitness[live]),  # [L21] Eq. 10's F
            "ranges": {
                n: [float(params[:, i].min()), float(params[:, i].max())] if len(params) else None
                for i, n in enumerate(c.space.names)
            },
        }
    path = result_path(row, arm, variant, seed, steps)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=2))
    print(f"wrote {path}")
    return out


def _cell(row: str, results: list[dict]) -> str:
    """Mean over seeds (each seed in brackets) of a row's measure."""
    if not results:
        return "not run yet"
    reps = [r["report"] for r in results]
    seeds = ", ".join(str(r["seed"]) for r in results)
    if ROWS[row]["measure"] == "family":
        falls = [x["fall_percent"] for x in reps]
        task = [x["task_achievement"] for x in reps]
        worst = [x["worst_decile_return"] for x in reps]
        cv = [x["grid_uniformity"]["coefficient_of_variation"] for x in reps]
        widths = [x.get("range_width") for x in reps]
        grown = ("" if None in widths or min(widths) >= 1.0 else "; trained on "
                 + " / ".join(f"{100 * w:.0f}" for w in widths) + " % of the ranges")  # fmt: skip
        return (f"{np.mean(task):.1f} task, {np.mean(falls):.1f} % falls, worst decile "
                f"{np.mean(worst):.1f}, CV {np.mean(cv):.2f} (seeds {seeds}; falls "
                + " / ".join(f"{f:.1f}" for f in falls) + grown + ")")  # fmt: skip
    er = [x["explored_ratio"] for x in reps]
    spans = "; ".join(f"{dim} [{lo:.2f}, {hi:.2f}]" for dim, (lo, hi) in _ranges(reps).items())
    return (f"ER {np.mean(er):.2f} ({' / '.join(f'{e:.2f}' for e in er)}); {spans or 'no elites'}"
            f" (seeds {seeds})")  # fmt: skip


def _ranges(reports: list[dict]) -> dict[str, tuple[float, float]]:
    """Per task dimension, the range the elites covered, its ends averaged over the runs that
    have elites."""
    dims = dict.fromkeys(d for x in reports for d, r in x["ranges"].items() if r)
    return {d: tuple(float(np.mean([x["ranges"][d][i] for x in reports if x["ranges"].get(d)]))
                     for i in (0, 1))
            for d in dims}  # fmt: skip


def _summary(row: str, results: list[dict]) -> dict:
    """A variant's measure per seed and its mean over the seeds (reproduce.json; the docs' text
    reads its numbers from here)."""
    reps = [r["report"] for r in results]
    if ROWS[row]["measure"] == "family":
        per_seed = {
            "task": [x["task_achievement"] for x in reps],
            "falls": [x["fall_percent"] for x in reps],
            "worst_decile": [x["worst_decile_return"] for x in reps],
            "cv": [x["grid_uniformity"]["coefficient_of_variation"] for x in reps],
            "length_seconds": [x["mean_length_seconds"] for x in reps],  # of EVAL's 30 s
            "speed": [x["mean_forward_speed"] for x in reps],
            # how narrowly the sampler drew at the end (`mcmc.concentration`)
            "effective_share": [(x.get("sampling") or {}).get("effective_share") for x in reps],
            "low_mass": [(x.get("sampling") or {}).get("low_mass") for x in reps],
            "range_width": [x.get("range_width") for x in reps],
        }
    else:
        per_seed = {
            "explored_ratio": [x["explored_ratio"] for x in reps],
            "elite_mean_fitness": [x.get("elite_mean_fitness") for x in reps],
            **{f"{d}_{end}": [(x["ranges"].get(d) or [None, None])[i] for x in reps]
               for d in _ranges(reps) for i, end in enumerate(("low", "high"))},
        }  # fmt: skip
    means = {k: float(np.mean(v)) if v and None not in v else None for k, v in per_seed.items()}
    return {"seeds": [r["seed"] for r in results], "per_seed": per_seed, "mean": means}


def falls_against_sampling(arm: str) -> dict | None:
    """Fig. 6's adaptive runs (k > 0) in an arm: the rank correlation (Spearman) of a run's
    falls with how widely its sampler drew at the end (`mcmc.concentration`'s effective share)."""
    from scipy.stats import spearmanr

    pairs = [(r["report"]["fall_percent"], r["report"]["sampling"]["effective_share"])
             for v in ROWS["wl19_fig6"]["variants"] if v != "k0"
             for r in _results("wl19_fig6", arm, v) if r["report"].get("sampling")]  # fmt: skip
    if len(pairs) < 3:
        return None
    rho, p = spearmanr(*zip(*pairs, strict=True))
    return {"runs": len(pairs), "spearman": float(rho), "p_value": float(p)}


def departures() -> str:
    """Every field a paper's recipe sets, beside ours (the library default or our recipes')."""
    from paramimic.config import ExperimentConfig
    from paramimic.recipes import PRESETS, flatten

    default = flatten(ExperimentConfig().model_dump(mode="json"))
    names = ("wl19", "l21", "paramimic_walker", "paramimic_humanoid")
    fields = sorted({f for n in names for f in PRESETS[n]})

    def shown(name: str, field: str) -> str:
        s = PRESETS[name].get(field)
        return "" if s is None else json.dumps(list(s.value) if isinstance(s.value, tuple)
                                               else s.value)  # fmt: skip

    rows = [[f, json.dumps(default.get(f)), *(shown(n, f) for n in names)] for f in fields]
    return tabulate(rows, ["field", "library default", *names], tablefmt="github")


def _by_budget(row: str, arm: str, variant: str) -> dict[int, list[dict]]:
    """A variant's kept runs in an arm by their budget in env steps, the smallest first."""
    found: dict[int, list[dict]] = {}
    for p in sorted(OUT.glob(f"{row}_{arm}_{variant}_s*_*k.json")):
        steps = int(p.stem.rsplit("_", 1)[1].removesuffix("k")) * 1000
        found.setdefault(steps, []).append(json.loads(p.read_text()))
    return dict(sorted(found.items()))


def _results(row: str, arm: str, variant: str) -> list[dict]:
    """A variant's runs at the largest budget it has kept runs of (a budget raised later
    supersedes the runs kept at the old one; they stay in reproduce.json's `earlier`)."""
    found = _by_budget(row, arm, variant)
    return found[max(found)] if found else []


def _short_of_budget(row: str, arm: str, variants: list[str]) -> str:
    """ "at 4M of 8M" where the latest kept runs of any of the variants are short of its budget
    (kept before the budget was raised; "" otherwise)."""
    for variant in variants:
        budgets = _by_budget(row, arm, variant)
        target = variant_spec(row, arm, variant)[2]
        if budgets and max(budgets) < target:
            return f"at {max(budgets) / 1e6:g}M of {target / 1e6:g}M"
    return ""


def _kept_summary(row: str, budgets: dict[int, list[dict]]) -> dict:
    """`_summary` of a variant's runs at its largest budget (`_by_budget`), with those kept at
    smaller ones under `earlier` (by budget: "4000k")."""
    budgets = dict(budgets)
    latest = _summary(row, budgets.pop(max(budgets)))
    earlier = {f"{b // 1000}k": _summary(row, r) for b, r in budgets.items()}
    return latest | ({"earlier": earlier} if earlier else {})


def _seeded(row: str, arm: str, variants: list[str]) -> list[list[dict]]:
    """The runs of the variants a claim compares, once each has run on every seed the claim is
    judged on, all at one budget (a budget raised for some: not until they all reach it);
    empty lists before."""
    found = [_by_budget(row, arm, v) for v in variants]
    latest = {max(b) for b in found if b}
    if len(latest) != 1 or any(len(b.get(max(latest), [])) < CLAIM_SEEDS for b in found):
        return [[] for _ in variants]
    return [b[max(latest)] for b in found]


def _mean(results: list[dict], key) -> float:
    return float(np.mean([key(r["report"]) for r in results]))


def _on_seeds(groups: list[list[dict]], holds) -> str:
    """The seeds on which a claim holds, paired by seed across the groups of runs it compares
    (`holds` takes one report per group): "on seeds 0, 2 of 0, 1, 2". A claim agrees on the
    mean over the seeds; like a 3-seed target, it stands only where it holds on every seed."""
    by = [{r["seed"]: r["report"] for r in g} for g in groups]
    seeds = sorted(set.intersection(*(set(b) for b in by)))
    wins = [seed for seed in seeds if holds(*(b[seed] for b in by))]
    won = ", ".join(map(str, wins))
    where = f"on seed{'s' if len(wins) > 1 else ''} {won}" if wins else "on no seed"
    return f"{where} of {', '.join(map(str, seeds))}"


def _claim_rn(arm: str, body: str) -> tuple[str, str]:
    """[WL19] Table 4: reward normalization raises task achievement and lowers falls ("cannot
    say" where every body of both variants falls: the claim is about families that walk)."""
    on, off = _seeded("wl19_table4", arm, [f"{body}_rn", f"{body}_no_rn"])
    if not on or not off:
        return "not run yet", ""
    task = [_mean(x, lambda r: r["task_achievement"]) for x in (on, off)]
    falls = [_mean(x, lambda r: r["fall_percent"]) for x in (on, off)]
    short = _short_of_budget("wl19_table4", arm, [f"{body}_rn", f"{body}_no_rn"])
    if min(falls) >= 100.0:  # no body of either variant stays up: a claim about walkers
        up = [_mean(x, lambda r: r["mean_length_seconds"]) for x in (on, off)]
        return "cannot say", (f"every body falls with RN and without, after {up[0]:.1f} and "
                              f"{up[1]:.1f} s on the mean; task {task[0]:.1f} vs {task[1]:.1f}"
                              + (f"; {short}" if short else ""))  # fmt: skip
    verdict = "agrees" if task[0] > task[1] and falls[0] < falls[1] else "disagrees"
    seeds = _on_seeds([on, off], lambda a, b: a["task_achievement"] > b["task_achievement"]
                      and a["fall_percent"] < b["fall_percent"])  # fmt: skip
    return verdict, (f"task {task[0]:.1f} vs {task[1]:.1f}, falls {falls[0]:.1f} % vs "
                     f"{falls[1]:.1f} % (RN on vs off); both {seeds}"
                     + (f"; {short}" if short else ""))  # fmt: skip


def _claim_k(arm: str) -> tuple[str, str]:
    """[WL19] Fig. 6: the higher k, the more uniform the per-shape returns (a lower CV at
    k = 10 than at k = 0, Fig. 6a/b)."""
    found = dict(zip((0, 5, 10, 20), _seeded("wl19_fig6", arm, ["k0", "k5", "k10", "k20"]),
                     strict=True))  # fmt: skip
    if not all(found.values()):
        return "not run yet", ""
    cv = [_mean(x, _cv) for x in found.values()]
    # Fig. 6a against 6b: k = 0 against k = 10; and whether the CV falls at every step of k
    verdict = "agrees" if cv[0] > cv[2] else "disagrees"
    monotone = all(a > b for a, b in zip(cv, cv[1:], strict=False))
    steps = "falling at every step" if monotone else "not falling at every step"
    seeds = _on_seeds([found[0], found[10]], lambda a, b: _cv(a) > _cv(b))
    return verdict, ("CV " + " / ".join(f"{c:.3f}" for c in cv)
                     + f" at k = 0 / 5 / 10 / 20, {steps}; k = 10 below k = 0 {seeds}")  # fmt: skip


def _cv(report: dict) -> float:
    return report["grid_uniformity"]["coefficient_of_variation"]


def _claim_ablation(arm: str) -> tuple[str, str]:
    """[L21] Table 2 (§7.2): A3 explores wider task ranges than A2 and A1, as the share of the
    task space explored that §7.2 measures (ER), with the range of each dimension beside it."""
    variants = ["A1", "A2", "A3"]
    found = dict(zip(variants, _seeded("l21_table2", arm, variants), strict=True))
    if not all(found.values()):
        return "not run yet", ""
    er = [_mean(x, lambda r: r["explored_ratio"]) for x in found.values()]
    verdict = "agrees" if er[2] > er[1] > er[0] else "disagrees"
    spans = {v: _ranges([r["report"] for r in x]) for v, x in found.items()}
    dims = "; ".join(
        f"{d} " + " / ".join(f"[{s[d][0]:.2f}, {s[d][1]:.2f}]" if d in s else "none"
                             for s in spans.values())
        for d in dict.fromkeys(d for s in spans.values() for d in s)
    )  # fmt: skip
    seeds = _on_seeds(list(found.values()),
                      lambda a1, a2, a3: a3["explored_ratio"] > a2["explored_ratio"]
                      > a1["explored_ratio"])  # fmt: skip
    return verdict, (f"ER {' / '.join(f'{e:.2f}' for e in er)}; {dims} (A1 / A2 / A3); "
                     f"in that order {seeds}")  # fmt: skip


def _curricula_runs(arm: str) -> dict[str, list[dict]]:
    """§7.3's runs per curriculum in an arm, in seed order: the ones `benchmarks/curriculum.py`'s
    comparison was made of (curriculum.json; at [L21]'s settings, its `--recipe l21` run's)."""
    path = RESULTS / "curriculum" / ("curriculum_l21.json" if arm == "paper" else "curriculum.json")
    runs = json.loads(path.read_text())["runs"] if path.exists() else []
    return {s: sorted((r for r in runs if r["sampling"] == s), key=lambda r: r["seed"])
            for s in CURRICULA}  # fmt: skip


def _curricula_cell(runs: list[dict]) -> str:
    if not runs:
        return "not run yet"
    er = [r["curve"][-1]["explored_ratio"] for r in runs]
    n = [r["curve"][-1]["episodes"] for r in runs]
    return (f"ER {np.mean(er):.2f} at N = {np.mean(n):,.0f} (seeds "
            + ", ".join(str(r["seed"]) for r in runs) + ": "
            + " / ".join(f"{x:.2f}" for x in er) + ")")  # fmt: skip


def _claim_curricula(arm: str) -> tuple[str, str]:
    """[L21] §7.3: the curriculum explores more than each other curriculum at equal episodes
    (on the mean over the seeds; the seeds on which it does are named)."""
    er = {s: {r["seed"]: r for r in runs} for s, runs in _curricula_runs(arm).items() if runs}
    if set(er) != set(CURRICULA) or min(map(len, er.values())) < CLAIM_SEEDS:
        return "not run yet", ""
    n = min(r["curve"][-1]["episodes"] for runs in er.values() for r in runs.values())

    def at_n(r: dict) -> float:
        curve = r["curve"]
        return float(np.interp(n, [c["episodes"] for c in curve],
                               [c["explored_ratio"] for c in curve]))  # fmt: skip

    mean = {s: float(np.mean([at_n(r) for r in runs.values()])) for s, runs in er.items()}
    seeds = sorted(set.intersection(*(set(runs) for runs in er.values())))
    wins = [seed for seed in seeds
            if max(er, key=lambda s: at_n(er[s][seed])) == "curriculum"]  # fmt: skip
    verdict = "agrees" if max(mean, key=mean.get) == "curriculum" else "disagrees"
    return verdict, (f"ER at N = {n:,}: " + ", ".join(f"{s} {v:.2f}" for s, v in mean.items())
                     + f"; the most on seeds {', '.join(map(str, wins)) or 'none'} of "
                     + ", ".join(map(str, seeds)))  # fmt: skip


def claims() -> list[list[str]]:
    """Each paper's claim, checked on each arm's runs: agrees / disagrees, with the numbers."""
    rows = []
    checks = [
        ("[WL19] Table 4", "RN raises task achievement and lowers falls: biped",
         lambda arm: _claim_rn(arm, "biped_lower")),
        ("[WL19] Table 4", "RN raises task achievement and lowers falls: quadruped",
         lambda arm: _claim_rn(arm, "quadruped")),
        ("[WL19] Fig. 6", "the higher k, the more uniform (a lower CV at k = 10 than 0)", _claim_k),
        ("[L21] Table 2", "A3 explores wider task ranges than A2, A2 than A1 (ER)",
         _claim_ablation),
        ("[L21] §7.3", "the curriculum explores the most at equal episodes", _claim_curricula),
    ]  # fmt: skip
    for paper, claim, check in checks:
        cells = [check(arm) for arm in ("paper", "ours")]
        rows.append([paper, claim, *(": ".join(x for x in c if x) for c in cells)])
    return rows


def _budget(row: str, variant: str, costs: dict) -> str:
    """A variant's budget in each arm (ours with its base stage, which a seed's variants share),
    with the hours a run takes at the rate `cost` timed for the row's arm, where it has."""
    paper, ours = (variant_spec(row, arm, variant) for arm in ("paper", "ours"))
    text = f"{paper[2] / 1e6:.0f}M per run"
    if ours[2] != paper[2] or ours[3]:
        base = f"{ours[3][1] / 1e6:.0f}M base + " if ours[3] else ""
        text = f"paper's {paper[2] / 1e6:.0f}M, ours {base}{ours[2] / 1e6:.0f}M per run"
    if row not in costs:
        return text
    hours = [costs[row][arm]["seconds_per_1k_steps"] * spec[2] / 1000 / 3600
             for arm, spec in (("paper", paper), ("ours", ours))]  # fmt: skip
    arms = "paper's / ours" + (" without its base" if ours[3] else "")
    return f"{text}: {hours[0]:.1f} / {hours[1]:.1f} h ({arms})"


def _curricula_budget(found: list[list[dict]], costs: dict) -> str:
    """A §7.3 curriculum's budget (the steps its runs were given), with the hours a run takes
    at the rates `cost` timed for [L21] Table 2, whose arms train the same config and recipes."""
    steps = [runs[0]["steps"] if runs else CURRICULA_STEPS for runs in found]
    text = " / ".join(dict.fromkeys(f"{s / 1e6:.1f}M" for s in steps)) + " per run"
    if "l21_table2" not in costs:
        return text
    hours = [costs["l21_table2"][arm]["seconds_per_1k_steps"] * s / 1000 / 3600
             for arm, s in zip(("paper", "ours"), steps, strict=True)]  # fmt: skip
    return f"{text}: {hours[0]:.1f} / {hours[1]:.1f} h (paper's / ours, at Table 2's rates)"


def total_hours(costs: dict) -> dict[str, float] | None:
    """Hours every row of the table takes on CLAIM_SEEDS seeds in each arm, one run after the
    other with both cores to each, at the rates `cost` timed (a base stage at its family's rate,
    §7.3 at Table 2's); None until every row is timed."""
    if set(costs) < set(ROWS):
        return None
    total = {}
    for arm in ("paper", "ours"):
        steps: dict[str, int] = {}
        bases = {}
        for row, spec in ROWS.items():
            for variant in spec["variants"]:
                _, _, budget, base = variant_spec(row, arm, variant)
                steps[row] = steps.get(row, 0) + budget
                if base:
                    bases[base[0]] = (row, base[1])
        for row, budget in bases.values():
            steps[row] += budget
        steps["l21_table2"] += len(CURRICULA) * CURRICULA_STEPS
        total[arm] = sum(CLAIM_SEEDS * costs[row][arm]["seconds_per_1k_steps"] * n / 1000 / 3600
                         for row, n in steps.items())  # fmt: skip
    return total


def table() -> str:
    rows = []
    cost_file = OUT / "cost.json"
    costs = json.loads(cost_file.read_text()) if cost_file.exists() else {}
    summary = {}
    for row, spec in ROWS.items():
        for variant in spec["variants"]:
            cells = {}
            for arm in ("paper", "ours"):
                budgets = _by_budget(row, arm, variant)
                found = budgets[max(budgets)] if budgets else []
                short = _short_of_budget(row, arm, [variant]) if found else ""
                cells[arm] = _cell(row, found) + (f", {short}" if short else "")
                if found:
                    summary.setdefault(row, {}).setdefault(arm, {})[variant] = _kept_summary(
                        row, budgets
                    )
            rows.append([spec["paper"], variant, spec["paper_numbers"][variant],
                         cells["paper"], cells["ours"], _budget(row, variant, costs)])  # fmt: skip
    arms = {arm: _curricula_runs(arm) for arm in ("paper", "ours")}
    for sampling in CURRICULA:
        found = [arms[arm][sampling] for arm in ("paper", "ours")]
        rows.append(["[L21] §7.3", sampling, CURRICULA_PAPER[sampling],
                     *map(_curricula_cell, found), _curricula_budget(found, costs)])  # fmt: skip
    header = ["paper", "variant", "the paper's number", "paper's settings", "ours", "budget"]
    body = tabulate(rows, header, tablefmt="github")
    text = DOCS.read_text()
    checked = claims()
    claims_header = ["paper", "claim", "paper's settings", "ours"]
    sections = {
        "rows": body,
        "claims": tabulate(checked, claims_header, tablefmt="github"),
        "departures": departures(),
    }
    for name, part in sections.items():
        marks = (f"<!-- {name} -->", f"<!-- /{name} -->")
        head, rest = text.split(marks[0], 1)
        _, tail = rest.split(marks[1], 1)
        text = f"{head}{marks[0]}\n{part}\n{marks[1]}{tail}"
    DOCS.write_text(text)
    OUT.mkdir(parents=True, exist_ok=True)
    out = {"rows": rows, "header": header, "claims": checked, "claims_header": claims_header,
           "variants": summary, "rn_scales": scales(), "total_hours": total_hours(costs),
           "fig6_falls_against_sampling": {a: falls_against_sampling(a)
                                           for a in ("paper", "ours")}}  # fmt: skip
    (OUT / "reproduce.json").write_text(json.dumps(out, indent=1))
    return body


def _jobs(row: str, arm: str, variants: list[str] | None, seeds: list[int],
          steps: int | None = None) -> list[tuple]:  # fmt: skip
    """The runs of a row in an arm not kept yet: (row, arm, variant, seed, steps)."""
    spec = ROWS[row]
    jobs = []
    for variant in variants or spec["variants"]:
        if variant not in spec["variants"]:
            raise SystemExit(f"{row}: no variant {variant!r}; known: {list(spec['variants'])}")
        budget = steps or variant_spec(row, arm, variant)[2]
        jobs += [(row, arm, variant, seed, budget) for seed in seeds
                 if not result_path(row, arm, variant, seed, budget).exists()]  # fmt: skip
    return jobs


def run_row(row: str, arm: str, variants: list[str] | None, seeds: list[int],
            steps: int | None = None, jobs: int = 1) -> None:  # fmt: skip
    """Every run of a row in an arm that is not kept yet, `jobs` at once."""
    _train(_jobs(row, arm, variants, seeds, steps), jobs)


def _train(todo: list[tuple], jobs: int) -> None:
    """`run_one` on each job, `jobs` at once (one torch thread each when more than one)."""
    listed = "".join(
        f"\n  {row} {arm} {variant} seed {seed}" for row, arm, variant, seed, _ in todo
    )
    print(f"{len(todo)} runs to train{listed}")
    if jobs <= 1:
        for job in todo:
            run_one(*job)
        return
    with multiprocessing.get_context("spawn").Pool(jobs) as pool:
        pool.starmap(run_one, [(*job, 1) for job in todo], chunksize=1)


def _curricula_command(arm: str, jobs: int) -> list[str]:
    """§7.3's runs in an arm: `benchmarks/curriculum.py`, our config as shipped or at [L21]'s."""
    return (["--samplings", ",".join(CURRICULA), "--seeds", ",".join(map(str, SEEDS)),
             "--steps", str(CURRICULA_STEPS), "--jobs", str(jobs)]
            + (["--recipe", "l21"] if arm == "paper" else []))  # fmt: skip


@functools.cache
def curriculum_benchmark():
    """benchmarks/curriculum.py, which runs and keeps §7.3's curricula, as a module."""
    import importlib.util

    path = ROOT / "benchmarks" / "curriculum.py"
    spec = importlib.util.spec_from_file_location("curriculum_bench", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def pending(arms: list[str]) -> list[tuple[str, float | None]]:
    """What `all` has left to run, with the hours each takes at cost.json's rates (both cores
    to it; §7.3 at Table 2's rates; a base stage not trained yet adds its own)."""
    curriculum = curriculum_benchmark()
    cost_file = OUT / "cost.json"
    costs = json.loads(cost_file.read_text()) if cost_file.exists() else {}

    def hours(row: str, arm: str, steps: int) -> float | None:
        rate = costs.get(row, {}).get(arm, {}).get("seconds_per_1k_steps")
        return None if rate is None else rate * steps / 1000 / 3600

    left = []
    for arm in arms:
        bases = set()
        for row in ROWS:
            for _, _, variant, seed, steps in _jobs(row, arm, None, SEEDS):
                base = variant_spec(row, arm, variant)[3]
                done = _trained_steps(RUNS / row / arm / f"{variant}_s{seed}")  # resumed there
                h = hours(row, arm, max(0, steps - done))
                if base and (base[0], seed) not in bases and not _trained(
                        base_dir(row, arm, base[0], seed), base[1]):  # fmt: skip
                    bases.add((base[0], seed))
                    h = None if h is None else h + hours(row, arm, base[1])
                left.append((f"{row} {arm} {variant} seed {seed}", h))
        for sampling in CURRICULA:
            for seed in SEEDS:
                recipe = "l21" if arm == "paper" else None
                if not curriculum.kept_run(sampling, seed, CURRICULA_STEPS, recipe).exists():
                    left.append((f"§7.3 {arm} {sampling} seed {seed}",
                                 hours("l21_table2", arm, CURRICULA_STEPS)))  # fmt: skip
    return left


def _trained_steps(run_dir: Path) -> int:
    """The env steps a run directory's checkpoint holds (0 without one)."""
    from paramimic.training import checkpoint

    if not checkpoint.checkpoint_dir(run_dir).is_dir():
        return 0
    return int(checkpoint.load(run_dir)["progress"]["env_steps"])


def _trained(run_dir: Path, steps: int) -> bool:
    return _trained_steps(run_dir) >= steps


def run_all(arms: list[str], jobs: int) -> None:
    """Every row in each arm on the claims' seeds, then §7.3's curricula and where Table 4's
    runs fall (`rn_falls`), then the table: what is kept is skipped, what was stopped resumes."""
    import subprocess
    import sys

    # one pool over the rows and arms: a row's odd last run shares the cores with the next's
    _train([job for arm in arms for row in ROWS for job in _jobs(row, arm, None, SEEDS)], jobs)
    script = str(ROOT / "benchmarks" / "curriculum.py")
    for arm in arms:
        subprocess.run([sys.executable, script, *_curricula_command(arm, jobs)], check=True)
        rn_falls(arm)
    print(table())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("row", choices=sorted(ROWS))
    r.add_argument("--arm", choices=("paper", "ours"), default="ours")
    r.add_argument("--variants", default=None, help="comma-separated; default: every variant")
    r.add_argument("--seeds", default="0,1,2")
    r.add_argument("--steps", type=int, default=None, help="default: the variant's budget")
    r.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="runs at once, one process and one torch thread each (2 on a 2-core machine)",
    )
    c = sub.add_parser("cost", help="time a few iterations of each row in each arm")
    c.add_argument("--rows", default=",".join(ROWS), help="comma-separated; default: every row")
    c.add_argument("--iterations", type=int, default=3)
    a = sub.add_parser("all", help="every row and §7.3 in each arm on the claims' seeds, then "
                       "the table (kept runs skipped, stopped ones resumed)")  # fmt: skip
    a.add_argument("--arms", default="ours,paper")
    a.add_argument("--jobs", type=int, default=2, help="runs at once (2 on a 2-core machine)")
    a.add_argument("--dry-run", action="store_true", help="list what is left, with its hours")
    f = sub.add_parser("rn-falls", help="where each [WL19] Table 4 run falls, by RN's velocity "
                       "scale (its bodies evaluated again from its checkpoint)")  # fmt: skip
    f.add_argument("--arm", choices=("paper", "ours"), default="ours")
    sub.add_parser("table")
    sub.add_parser("backfill", help="measures added since into kept runs, from their checkpoints")
    sub.add_parser("list")
    args = ap.parse_args()
    if args.cmd == "list":
        for row, spec in ROWS.items():
            print(f"{row:12s} {spec['paper']:16s} {spec['what']}; variants "
                  f"{', '.join(spec['variants'])}; {spec['steps']:,} steps per run")  # fmt: skip
        return
    if args.cmd == "cost":
        cost(args.rows.split(","), args.iterations)
        return
    if args.cmd == "backfill":
        backfill()
        return
    if args.cmd == "rn-falls":
        rn_falls(args.arm)
        return
    if args.cmd == "table":
        print(table())
        return
    if args.cmd == "all":
        arms = args.arms.split(",")
        if set(arms) - {"paper", "ours"}:
            raise SystemExit(f"--arms: {args.arms!r}; each arm is paper or ours")
        if args.dry_run:
            left = pending(arms)
            for what, hours in left:
                print(f"{what}: {hours:.1f} h" if hours is not None else what)
            known = [h for _, h in left if h is not None]
            print(f"{len(left)} runs left, {sum(known):.0f} h at cost.json's rates")
            return
        run_all(arms, args.jobs)
        return
    variants = args.variants.split(",") if args.variants else None
    seeds = [int(s) for s in args.seeds.split(",")]
    run_row(args.row, args.arm, variants, seeds, args.steps, args.jobs)


if __name__ == "__main__":
    main()
