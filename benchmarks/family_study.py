"""Families that learn: what makes one controller work on most bodies of walker_legs.

Each variant is a set of config overrides on configs/walker_legs.yaml, trained with the serial
trainer (one torch thread, so two runs share the 2 cores) and evaluated with the deterministic
policy on 300 shapes drawn with a seed no training run uses (EVAL_SEED) plus a 7x7 grid of the
two leg lengths, 10 s episodes. Runs are resumable: `run` continues from the run dir's latest
checkpoint (runs/study/<variant>_s<seed>), so an interrupted study loses at most 10 iterations.

    python benchmarks/family_study.py run std_frozen --seed 0 --steps 2000000
    python benchmarks/family_study.py queue std_frozen,kl_adaptive --seeds 0 --steps 2000000
    python benchmarks/family_study.py merge
        # the table and benchmarks/results/family_study/study_curves.png
    python benchmarks/family_study.py probe base_legs --seed 0   # a run's controller on the family
    python benchmarks/family_study.py fragility biped_base_heading0.8_std0.1  # base -> family
    python benchmarks/family_study.py sensitivity biped_base_heading0.8_std0.1  # one part at a time
    python benchmarks/family_study.py fit-offsets   # how far Eq. 1 moves a body's first pose
    python benchmarks/family_study.py reference   # the pose bell of every body on its reference
    python benchmarks/family_study.py headings biped_base --seed 0   # where a 3D body turned
    python benchmarks/family_study.py stopped k0 --seed 0   # a stopped screen's training curve

Each run writes benchmarks/results/family_study/study_<variant>_s<seed>_<M>M.json (evaluation,
config, the training curve); `merge` writes study.json: per variant and budget, mean and spread over
seeds of falls, mean return, worst-decile return, forward speed and the final policy std.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results" / "family_study"
RUNS = ROOT / "runs" / "study"
EVAL_SEED = 2024  # never a training seed
EVAL_EPISODES = 300
CONFIG = "configs/walker_legs.yaml"
# The variants (benchmarks/family_study.yaml): each states the knobs the study varies, so that it
# means the same whatever the config ships (configs/walker_legs.yaml now carries the winner,
# `retarget_stall`).
STUDY = yaml.safe_load((ROOT / "benchmarks" / "family_study.yaml").read_text())
VARIANTS: dict[str, dict] = {
    name: {k: v for b in spec["uses"] for k, v in STUDY["blocks"][b].items()} | spec.get("set", {})
    for name, spec in STUDY["variants"].items()
}


def _shrunk(character: str, scale: float) -> dict[str, list[float]]:
    """Config overrides putting the character's shape ranges, shrunk by `scale`, in the task."""
    from paramimic.characters import registration

    return {f"task.{k}": list(v) for k, v in registration(character).shape_ranges(scale).items()}


def variant_config(variant: str, seed: int) -> tuple[str, dict]:
    """The config file and the overrides of a variant (the shape ranges of other configs' ones:
    every range shrunk toward the base body by the variant's `shape_scale`)."""
    spec = STUDY["variants"][variant]
    config, scale = spec.get("config", CONFIG), spec.get("shape_scale", 1.0)
    overrides = {
        k: ROOT / v.format(seed=seed) if k == "train.init_from" else v
        for k, v in (STUDY["unnamed"] | VARIANTS[variant]).items()
    }
    if scale != 1.0:
        overrides |= _shrunk(Path(config).stem, scale)
    if spec.get("global_only"):  # the parts' own scales b_l stay at the base body's
        overrides |= {k: [1.0, 1.0] for k in overrides if k.startswith("task.")
                      and not k.startswith("task.global_")}  # fmt: skip
    return config, overrides


# what a result file keeps of each training iteration (metrics.jsonl)
CURVE_KEYS = ("env_steps", "mean_return", "fall_percent", "mean_length", "std", "approx_kl",
              "clip_fraction", "policy_lr", "range_width", "edge_fall_percent")  # fmt: skip


def _report_path(variant: str, seed: int, steps: int) -> Path:
    return RESULTS / f"study_{variant}_s{seed}_{steps / 1e6:g}M.json"


def run(variant: str, seed: int, steps: int) -> dict:
    """Train (or continue) one variant and seed to `steps` env steps, then evaluate."""
    warnings.filterwarnings("ignore")
    from paramimic.config import load_config
    from paramimic.evaluation import evaluate_config
    from paramimic.training.trainer import train_serial

    run_dir = RUNS / f"{variant}_s{seed}"
    config, variant_overrides = variant_config(variant, seed)
    overrides = variant_overrides | {
        "train.run_dir": str(run_dir),
        "train.seed": seed,
        "train.torch_threads": 1,
    }
    cfg = load_config(ROOT / config, overrides)
    t0 = time.perf_counter()
    trainer = train_serial(cfg, steps, run_dir)
    report = evaluate_config(trainer.learner.policy, cfg, EVAL_EPISODES, EVAL_SEED, 7, seconds=10.0)
    curve = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    report |= {
        "variant": variant,
        "overrides": VARIANTS[variant],
        "config": config,
        "seed": seed,
        "env_steps": trainer.progress.env_steps,
        "seconds_this_session": time.perf_counter() - t0,
        "final_std": float(np.exp(trainer.learner.policy.log_std.detach().numpy()).mean()),
        "curve": [{k: m[k] for k in CURVE_KEYS if k in m} for m in curve],
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    _report_path(variant, seed, steps).write_text(json.dumps(report, indent=2))
    return report


def _run_state(variant: str, seed: int) -> tuple[dict, dict]:
    """A study run's latest checkpoint and its config's env section."""
    from paramimic.config import ExperimentConfig
    from paramimic.training import checkpoint

    state = checkpoint.load(RUNS / f"{variant}_s{seed}")
    return state, ExperimentConfig.model_validate(state["config"]).env.model_dump()


def _adopted(state: dict, cfg):
    """The checkpoint's controller warm started on `cfg`'s family as `train.init_from` does
    (adopt_controller: inputs constant in its training start ignored)."""
    import torch

    from paramimic.config import ExperimentConfig
    from paramimic.rl.ppo import PPOLearner, adopt_controller
    from paramimic.training.trainer import reset_observations

    source = ExperimentConfig.model_validate(state["config"])
    learner = PPOLearner(state["obs_dim"], state["act_dim"], source.ppo)
    adopt_controller(learner, state["learner"], reset_observations(cfg))
    torch.set_num_threads(1)
    return learner.policy


def probe(variant: str, seed: int, episodes: int = 100) -> dict:
    """A study run's controller (its latest checkpoint) on the whole family of CONFIG: e.g. how
    far the base body's controller (`base_legs`) carries, blind to the shape as a warm start
    begins. Writes study_probe_<variant>_s<seed>.json."""
    warnings.filterwarnings("ignore")
    from paramimic.config import load_config
    from paramimic.evaluation import evaluate_config

    state, env = _run_state(variant, seed)
    cfg = load_config(ROOT / CONFIG, {"env": env})
    policy = _adopted(state, cfg)
    report = evaluate_config(policy, cfg, episodes, EVAL_SEED, 7, seconds=10.0)
    report |= {"variant": variant, "seed": seed, "family": CONFIG}
    (RESULTS / f"study_probe_{variant}_s{seed}.json").write_text(json.dumps(report, indent=2))
    return report


# (shape scale, shape parameters that vary: a prefix of their names, "" for all of them)
FRAGILITY_FAMILIES = (
    (0.05, ""), (0.25, ""), (0.5, ""),
    (0.05, "global_"), (0.05, "global_z"), (0.02, "global_z"), (0.05, "hip_"), (0.05, "torso_"),
    (0.05, "thigh_"), (0.05, "shin_"), (0.05, "foot_"),
)  # fmt: skip


def fragility(variant: str, seed: int, episodes: int = 40) -> dict:
    """How far a run's controller (warm started as `train.init_from` does, which changes
    nothing for a controller trained on varying shapes) carries into its config's family:
    falls and return on random bodies of the shape ranges shrunk by s, with all shape
    parameters varying or only one group. Writes study_fragility_<variant>_s<seed>_<M>M.json
    (M: the checkpoint's env steps)."""
    warnings.filterwarnings("ignore")
    from paramimic.config import load_config
    from paramimic.envs import env_for

    config = variant_config(variant, seed)[0]
    state, env = _run_state(variant, seed)
    rows = []
    for scale, prefix in FRAGILITY_FAMILIES:
        ranges = _shrunk(Path(config).stem, scale)
        ranges = {k: r if k.startswith(f"task.{prefix}") else [1.0, 1.0] for k, r in ranges.items()}
        cfg = load_config(ROOT / config, {"env": env} | ranges)
        policy = _adopted(state, cfg)
        env_cfg = cfg.env.for_evaluation(10.0)
        space = env_for(cfg, env_cfg).task_space
        tasks = space.sample(np.random.default_rng(EVAL_SEED), episodes)
        summary = _on_bodies(policy, cfg, env_cfg, tasks)
        rows.append({"shape_scale": scale, "varying": prefix or "all"} | summary)
        print(f"shape scale {scale:g}, varying {prefix or 'all'}: falls "
              f"{summary['fall_percent']:.1f} %, return {summary['mean_return']:.0f}")  # fmt: skip
    return _controller_report("fragility", variant, seed, state, episodes, {"families": rows})


def _episodes_on(policy, cfg, env_cfg, tasks: np.ndarray) -> list:
    """The deterministic controller, one episode per task of `cfg`'s env, as `run`'s
    evaluation runs them (8 at a time, EVAL_SEED): EpisodeResults in the tasks' order."""
    from paramimic.envs import env_for
    from paramimic.evaluation import deterministic, run_episodes

    return run_episodes(
        deterministic(policy), lambda: env_for(cfg, env_cfg), tasks, 8,
        EVAL_SEED,
    )  # fmt: skip


def _on_bodies(policy, cfg, env_cfg, tasks: np.ndarray) -> dict:
    """`_episodes_on`, summarized (`summarize`'s dict)."""
    from paramimic.evaluation import summarize

    return summarize(_episodes_on(policy, cfg, env_cfg, tasks))


RIM_BINS = ((0, 2), (3, 4), (5, 6), (7, 99))  # parameters beyond the range's width


def rim(variant: str, seed: int) -> dict:
    """Where a grown family's controller falls: the held-out evaluation of `run` (the same 300
    bodies and seeds, so the same falls) split by how many shape parameters of a body lie
    beyond the width the run's range reached (curriculum.widen; one width for all 27 of the
    biped's, so nearly every held-out body has some). Writes
    study_rim_<variant>_s<seed>_<M>M.json."""
    warnings.filterwarnings("ignore")
    from paramimic.config import ExperimentConfig
    from paramimic.envs import env_for
    from paramimic.evaluation import summarize

    state, _ = _run_state(variant, seed)
    cfg = ExperimentConfig.model_validate(state["config"])
    width = float(state["curriculum"]["core"]["width"])
    env_cfg = cfg.env.for_evaluation(10.0)
    space = env_for(cfg, env_cfg).task_space
    tasks = space.sample(np.random.default_rng(EVAL_SEED), EVAL_EPISODES)
    results = _episodes_on(_adopted(state, cfg), cfg, env_cfg, tasks)
    free = space.free
    offset = np.abs(tasks - space.center)[:, free] / (0.5 * space.width[free])
    beyond = (offset > width).sum(axis=1)
    rets = np.array([r.ret for r in results])
    worst = np.argsort(rets)[: len(rets) // 10]
    groups = []
    for lo, hi in RIM_BINS:
        mask = (beyond >= lo) & (beyond <= hi)
        chosen = [r for r, m in zip(results, mask, strict=True) if m]
        row = {"beyond": [lo, hi], "bodies": int(mask.sum()),
               "worst_decile_share": float(np.mean(mask[worst]))}  # fmt: skip
        groups.append(row | (summarize(chosen) if chosen else {}))
        falls = f"{groups[-1]['fall_percent']:.1f} %" if chosen else "-"
        print(f"{lo}-{hi} of {free.sum()} parameters beyond the range's {100 * width:.0f} %: "
              f"{row['bodies']} bodies, falls {falls}, "
              f"{100 * row['worst_decile_share']:.0f} % of the worst decile")  # fmt: skip
    overall = summarize(results)
    print(f"all: falls {overall['fall_percent']:.1f} % (the run's report: the same bodies)")
    return _controller_report(
        "rim", variant, seed, state, EVAL_EPISODES,
        {"range_width": width, "all": overall, "groups": groups,
         "parameters_beyond": beyond.tolist(), "fell": [r.fell for r in results]},
    )  # fmt: skip


# the reports of a run's controller measured elsewhere (study_<kind>_...), which `merge` skips
CONTROLLER_KINDS = ("fragility", "rim", "sensitivity")


def _controller_report(
    kind: str, variant: str, seed: int, state: dict, episodes: int, rows: dict
) -> dict:
    """benchmarks/results/family_study/study_<kind>_<variant>_s<seed>_<M>M.json (M: the
    checkpoint's env steps) of a run's controller measured on other bodies, `episodes` per body or
    family."""
    assert kind in CONTROLLER_KINDS, kind
    steps = int(state["progress"]["env_steps"])
    report = {"variant": variant, "seed": seed, "config": variant_config(variant, seed)[0],
              "env_steps": steps, "episodes": episodes} | rows  # fmt: skip
    name = f"study_{kind}_{variant}_s{seed}_{round(steps / 1e6):g}M.json"
    (RESULTS / name).write_text(json.dumps(report, indent=2))
    return report


# one shape parameter moved at a time (the others at the base body's 1.0): which part of the
# body a controller's gait hinges on
SENSITIVITY_PARAMETERS = ("global_x", "global_z", "hip_z", "torso_z", "thigh_r_z", "shin_r_z",
                          "foot_r_z")  # fmt: skip
SENSITIVITY_VALUES = (0.98, 1.02)


def sensitivity(variant: str, seed: int, episodes: int = 10) -> dict:
    """A run's controller (as `fragility` adopts it) on bodies that differ from the base body
    in one shape parameter by 2 %: falls and forward speed per parameter and value, the base
    body first. Writes study_sensitivity_<variant>_s<seed>_<M>M.json."""
    warnings.filterwarnings("ignore")
    from paramimic.config import load_config
    from paramimic.envs import env_for
    from paramimic.rl.ppo import CONSTANT

    config = variant_config(variant, seed)[0]
    state, env = _run_state(variant, seed)
    # ranges wide enough to hold every value moved (x0.2: global 0.9-1.1, parts 0.94-1.04)
    cfg = load_config(ROOT / config, {"env": env} | _shrunk(Path(config).stem, 0.2))
    policy = _adopted(state, cfg)
    env_cfg = cfg.env.for_evaluation(10.0)
    probe_env = env_for(cfg, env_cfg)
    names = list(probe_env.task_space.names)
    # the inputs that varied least in the run's training (its normalizer's std; inputs that never
    # varied, such as the fixed shape parameters, aside), and how far each body moves them at
    # its first step, in those standard deviations (the same reset seed: the same phase)
    layout = probe_env.observation_layout()
    inputs = [f"{segment}[{i}]" for segment, size in layout for i in range(size)]
    std = np.sqrt(np.asarray(state["learner"]["normalizer"]["var"], dtype=float))
    least = [k for k in np.argsort(std) if std[k] ** 2 > CONSTANT][:5]
    first = {}
    cases = [("base", 1.0)] + [(p, v) for p in SENSITIVITY_PARAMETERS for v in SENSITIVITY_VALUES]
    rows = []
    for name, value in cases:
        task = np.array([1.0 if n != name else value for n in names])
        task[names.index("target_velocity")] = cfg.task["target_velocity"][0]
        first[name, value] = probe_env.reset(seed=EVAL_SEED, options={"task": task})[0][least]
        shift = (first[name, value] - first["base", 1.0]) / std[least]
        summary = _on_bodies(policy, cfg, env_cfg, np.repeat(task[None], episodes, axis=0))
        moved = {inputs[k]: float(x) for k, x in zip(least, shift, strict=True)}
        rows.append(
            {"parameter": name, "value": value} | summary | {"least_varied_shift_sigma": moved}
        )
        print(f"{name} {value:g}: falls {summary['fall_percent']:.0f} %, speed "
              f"{summary['mean_forward_speed']:.2f} m/s")  # fmt: skip
    extra = {"bodies": rows, "least_varied_inputs": {inputs[k]: float(std[k]) for k in least}}
    return _controller_report("sensitivity", variant, seed, state, episodes, extra)


def stopped(variant: str, seed: int) -> dict:
    """A run stopped before its budget and not evaluated (a screen that lost): its training
    curve as it stands, benchmarks/results/family_study/study_<variant>_s<seed>_stopped.json, for
    the record and the curves figure. (`run` continues it and writes the evaluated report.)"""
    run_dir = RUNS / f"{variant}_s{seed}"
    curve = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    tail = curve[-10:]
    report = {
        "variant": variant,
        "overrides": VARIANTS[variant],
        "config": variant_config(variant, seed)[0],
        "seed": seed,
        "env_steps": curve[-1]["env_steps"],
        "evaluated": False,
        "last_10_iterations": {
            k: float(np.mean([m[k] for m in tail])) for k in ("mean_return", "fall_percent")
        },
        "curve": [{k: m[k] for k in CURVE_KEYS if k in m} for m in curve],
    }
    (RESULTS / f"study_{variant}_s{seed}_stopped.json").write_text(json.dumps(report, indent=2))
    return report


def _spread(values: list[float]) -> dict:
    a = np.array(values, dtype=float)
    return {"mean": float(a.mean()), "min": float(a.min()), "max": float(a.max()), "n": len(a)}


def merge() -> dict:
    groups: dict[tuple[str, float], list[dict]] = {}
    for path in sorted(RESULTS.glob("study_*_s*_*M.json")):
        if path.name.startswith(tuple(f"study_{k}_" for k in ("probe", *CONTROLLER_KINDS))):
            continue  # evaluations of a run's controller elsewhere, not runs
        r = json.loads(path.read_text())
        millions = float(path.stem.rsplit("_", 1)[1].removesuffix("M"))  # the run's budget
        groups.setdefault((r["variant"], millions), []).append(r)
    table = {}
    for (variant, millions), runs in sorted(groups.items()):
        table[f"{variant}@{millions:g}M"] = {
            "seeds": [r["seed"] for r in runs],
            "config": runs[0]["config"],
            "overrides": VARIANTS.get(variant, runs[0]["overrides"]),
            "fall_percent": _spread([r["fall_percent"] for r in runs]),
            "mean_return": _spread([r["mean_return"] for r in runs]),
            "worst_decile_return": _spread([r["worst_decile_return"] for r in runs]),
            "worst_decile_over_mean": _spread(
                [r["worst_decile_return"] / max(r["mean_return"], 1e-9) for r in runs]
            ),
            "forward_speed": _spread([r["mean_forward_speed"] for r in runs]),
            "final_std": _spread([r["final_std"] for r in runs]),
            "grid_fall_percent": _spread(
                [100 * float(np.mean(r["grid"]["fall"])) for r in runs if "grid" in r]
            ),
        }
    (RESULTS / "study.json").write_text(json.dumps(table, indent=2))
    curves = dict(groups)  # the figures also draw the stopped screens' curves
    for path in sorted(RESULTS.glob("study_*_s*_stopped.json")):
        r = json.loads(path.read_text())
        if not any(v == r["variant"] for v, _ in groups):
            curves.setdefault((r["variant"], 0), []).append(r)
    _plot(curves)
    for name, row in table.items():
        f, w = row["fall_percent"], row["worst_decile_return"]
        print(
            f"{name:34s} seeds {row['seeds']}  falls {f['mean']:5.1f} % [{f['min']:.1f}-"
            f"{f['max']:.1f}]  return {row['mean_return']['mean']:6.1f}  worst decile "
            f"{w['mean']:5.1f}  speed {row['forward_speed']['mean']:.2f}  "
            f"std {row['final_std']['mean']:.2f}"
        )
    return table


# the training curves the study draws, per figure: its main steps on walker_legs, and the 3D rows
STD_PANEL = ("std", "policy std")
WIDTH_PANEL = ("range_width", "share of the shape ranges in use (curriculum.widen)")
CURVES = {
    "study_curves.png": (
        "walker_legs (each leg 0.7-1.3x): training curves per variant and seed",
        (
            "learned_std",
            "std_frozen",
            "std_frozen_gamma99",
            "std_frozen_gamma99_stall_widen",
            "retarget",
            "retarget_stall",
            "retarget_stall_k0",
        ),
        STD_PANEL,
    ),
    "study_curves_3d.png": (
        "biped_lower (base body, x0.5 ranges) and quadruped (x0.5): training curves per seed",
        (
            "biped_base_heading0.8",
            "biped_base_heading0.8_std0.1",
            "biped_x0.5_std0.1",
            "quadruped_x0.5",
            "quadruped_x0.5_std0.1_heading",
            "quadruped_x0.5_std0.1_heading_stall",
        ),
        STD_PANEL,
    ),
    "study_curves_biped_x0.5.png": (
        "biped_lower at x0.5 ranges: the recipe and its screens, training curves per seed",
        (
            "biped_x0.5_std0.1",
            "biped_x0.5_std0.1_global",
            "biped_x0.5_std0.1_retarget",
            "biped_x0.5_std0.1_lr5e-5",
            "biped_x0.5_std0.05",
            "biped_x0.5_std0.1_blind",
            "biped_x0.5_std0.1_nofit",
            "biped_x0.5_std0.1_warm_widen",
            "biped_x0.5_std0.1_warm_widen0.7",
            "biped_x0.5_std0.1_floor",
            "biped_x0.5_std0.1_floor_warm",
            "biped_x0.5_std0.1_floor_warm_kl",
            "biped_x0.5_std0.1_floor_warm_widen_kl",
            "biped_x0.5_std0.1_floor_warm_widen0.6_kl",
            "biped_x0.5_std0.1_floor_warm_edge_kl",
        ),
        WIDTH_PANEL,
    ),
    "study_curves_quadruped.png": (
        "quadruped: the x0.5 family from scratch, the base body and the family from its "
        "controller, training curves per seed",
        (
            "quadruped_x0.5",
            "quadruped_x0.5_retarget",
            "quadruped_x0.5_retarget_stall",
            "quadruped_base_stall",
            "quadruped_x0.5_warm_stall",
            "quadruped_x0.5_warm_stall_lr5e-5",
            "quadruped_x0.5_warm_stall_kl",
        ),
        ("mean_length", "training episode length (control steps, 30 per s)"),
    ),
}


def _plot(groups: dict) -> None:
    for name, (title, variants, panel) in CURVES.items():
        _plot_curves(groups, variants, title, panel, RESULTS / name)


def _plot_curves(
    groups: dict, variants: tuple[str, ...], title: str, panel: tuple[str, str], path: Path
) -> None:
    """Training falls, return and `panel` (a curve key, its title) per variant and seed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    colors = plt.get_cmap("tab20").colors  # up to 20 variants a figure, each its own colour
    variants = [v for v in variants if any(v == g for g, _ in groups)]
    for i, variant in enumerate(variants):
        # per seed its longest run (a longer run's curve holds the shorter's)
        longest = {}
        for _, g in sorted((m, g) for (v, m), g in groups.items() if v == variant):
            longest |= {r["seed"]: r for r in g}
        runs = [longest[seed] for seed in sorted(longest)]
        for j, r in enumerate(runs):
            x = [m["env_steps"] / 1e6 for m in r["curve"]]
            for ax, key in zip(axes, ("fall_percent", "mean_return", panel[0]), strict=True):
                y = np.array([m.get(key, np.nan) for m in r["curve"]], dtype=float)
                if key != panel[0] and len(y) >= 10:  # noisy episodes: a moving average of 10
                    y = np.convolve(y, np.ones(10) / 10, mode="valid")
                ax.plot(x[len(x) - len(y) :], y, color=colors[i % len(colors)], alpha=0.8,
                        label=variant if j == 0 else None)  # fmt: skip
    for ax, label in zip(axes, ("training falls (%)", "training return", panel[1]), strict=True):
        ax.set_title(label)
        ax.set_xlabel("env steps (M)")
    # below the panels, where it hides no curve: one entry per variant
    handles, labels = axes[0].get_legend_handles_labels()
    columns = min(len(labels), 5) or 1
    fig.legend(handles, labels, loc="lower center", ncol=columns, fontsize=7, frameon=False)
    fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.04 + 0.05 * -(-len(labels) // columns), 1, 1))
    fig.savefig(path, dpi=90)
    plt.close(fig)


def headings(variant: str, seed: int, episodes: int = 20) -> dict:
    """A study run's controller (latest checkpoint) on its own config's env, whole episodes
    from random initial states: per episode whether and when it fell and the largest angle
    between its facing direction and the target direction. Writes
    study_headings_<variant>_s<seed>.json."""
    warnings.filterwarnings("ignore")
    from paramimic.envs import env_for
    from paramimic.evaluation import deterministic
    from paramimic.training import checkpoint

    _, cfg, policy = checkpoint.load_policy(RUNS / f"{variant}_s{seed}")
    act = deterministic(policy)
    env = env_for(cfg, cfg.env.for_evaluation(10.0))
    rows = []
    for i in range(episodes):
        obs, _ = env.reset(seed=EVAL_SEED + i)
        worst = 0.0
        while True:
            obs, _, terminated, truncated, info = env.step(act(obs[None])[0])
            worst = max(worst, env.unwrapped.heading_error() or 0.0)
            if terminated or truncated:
                break
        rows.append(
            {"fell": bool(info["fell"]), "seconds": env.sim_time, "max_heading_error": worst}
        )
    fallen = [r for r in rows if r["fell"]]
    report = {
        "variant": variant,
        "seed": seed,
        "episodes": rows,
        "max_heading_error_fallen": [r["max_heading_error"] for r in fallen],
        "max_heading_error_standing": [r["max_heading_error"] for r in rows if not r["fell"]],
    }
    (RESULTS / f"study_headings_{variant}_s{seed}.json").write_text(json.dumps(report, indent=2))
    return report


def fit_offsets(resets: int = 10) -> dict:
    """How far [WL19] Eq. 1's ground fit moves a biped_lower body's initial posture off its
    reference pose (init_noise 0): per shape scale, the largest joint offset (rad) of each
    reset. Writes study_fit_offsets.json."""
    warnings.filterwarnings("ignore")
    from paramimic.config import load_config
    from paramimic.envs import env_for

    rows = []
    for scale in (0.0, 0.05, 0.5):
        overrides = _shrunk("biped_lower", scale) | {"env.init_noise": 0.0}
        cfg = load_config(ROOT / "configs/biped_lower.yaml", overrides)
        env = env_for(cfg).unwrapped
        offsets = []
        for i in range(resets):
            env.reset(seed=i)
            c = env.character
            reference = np.clip(env.motion.pose(env._phase), c.ctrl_low, c.ctrl_high)
            offsets.append(float(np.abs(reference - env.data.qpos[c.qpos_idx]).max()))
        rows.append({"shape_scale": scale, "max_joint_offset_rad": offsets})
        print(f"shape scale {scale:g}: largest joint offset from the reference "
              f"{max(offsets):.3f} rad (mean over resets {np.mean(offsets):.3f})")  # fmt: skip
    report = {"config": "configs/biped_lower.yaml", "resets": resets, "scales": rows}
    (RESULTS / "study_fit_offsets.json").write_text(json.dumps(report, indent=2))
    return report


REFERENCE_BODIES = ((1.0, 1.0), (0.8, 0.8), (1.2, 1.2), (0.8, 1.2), (1.2, 0.8), (0.7, 1.3))


def reference(resets: int = 10, steps: int = 10) -> dict:
    """How well each body can follow its reference at all: the servos' PD targets on the
    reference pose (zero action) for `steps` control steps from `resets` resets, the mean [WL19]
    pose bell (Eq. 5), with and without env.retarget. Writes study_reference_pose.json."""
    from paramimic.config import load_config
    from paramimic.envs import env_for

    rows = []
    for left, right in REFERENCE_BODIES:
        row = {"left_leg_length": left, "right_leg_length": right}
        for retarget in (False, True):
            cfg = load_config(ROOT / CONFIG, {"env.retarget": retarget})
            env = env_for(cfg)
            task = {"left_leg_length": left, "right_leg_length": right, "target_velocity": 1.0}
            bells = []
            for seed in range(resets):
                env.reset(seed=seed, options={"task": task})
                for _ in range(steps):
                    bells.append(env.step(np.zeros(env.action_space.shape))[4]["reward_terms"])
            key = "retargeted" if retarget else "reference"
            row[f"pose_bell_{key}"] = float(np.mean([b["pose"] for b in bells]))
        rows.append(row)
    report = {"resets": resets, "steps": steps, "config": CONFIG, "bodies": rows}
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "study_reference_pose.json").write_text(json.dumps(report, indent=2))
    return report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument(
        "command",
        choices=[
            "run",
            "queue",
            "merge",
            "probe",
            "fragility",
            "sensitivity",
            "fit-offsets",
            "reference",
            "headings",
            "stopped",
            "rim",
        ],  # fmt: skip
    )
    ap.add_argument("variants", nargs="?", default="std_frozen_gamma99", help="comma-separated")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--seeds", default="0", help="comma-separated, for `queue`")
    ap.add_argument("--steps", type=int, default=2_000_000)
    ap.add_argument("--parallel", type=int, default=2)
    args = ap.parse_args()
    for v in args.variants.split(","):
        if v not in VARIANTS:
            raise SystemExit(f"unknown variant {v!r}; variants: {sorted(VARIANTS)}")
    if args.command == "merge":
        merge()
    elif args.command == "headings":
        r = headings(args.variants, args.seed)
        for row in r["episodes"]:
            print(f"{'fell' if row['fell'] else 'up  '} at {row['seconds']:5.2f} s, largest "
                  f"heading error {row['max_heading_error']:.2f} rad")  # fmt: skip
    elif args.command == "reference":
        for row in reference()["bodies"]:
            print(f"legs {row['left_leg_length']}/{row['right_leg_length']}: pose bell "
                  f"{row['pose_bell_reference']:.3f} on the reference, "
                  f"{row['pose_bell_retargeted']:.3f} retargeted")  # fmt: skip
    elif args.command == "probe":
        r = probe(args.variants, args.seed)
        print(f"{args.variants} s{args.seed} on {CONFIG}: falls {r['fall_percent']:.1f} %")
        for y, row in zip(r["grid"]["y"], r["grid"]["returns"], strict=True):
            print(f"{y:4.2f}", " ".join(f"{v:5.0f}" for v in row))
    elif args.command == "fit-offsets":
        fit_offsets()
    elif args.command == "fragility":
        fragility(args.variants, args.seed)
    elif args.command == "sensitivity":
        sensitivity(args.variants, args.seed)
    elif args.command == "rim":
        rim(args.variants, args.seed)
    elif args.command == "stopped":
        r = stopped(args.variants, args.seed)
        last = r["last_10_iterations"]
        print(f"{args.variants} s{args.seed} stopped at {r['env_steps']:,} steps: training "
              f"return {last['mean_return']:.1f}, falls {last['fall_percent']:.0f} % (last 10 "
              "iterations)")  # fmt: skip
    elif args.command == "run":
        r = run(args.variants, args.seed, args.steps)
        print(f"{args.variants} s{args.seed}: falls {r['fall_percent']:.1f} %")
    else:  # every (variant, seed) without a report at this budget, `parallel` at a time
        jobs = [
            (v, int(s))
            for s in args.seeds.split(",")
            for v in args.variants.split(",")
            if not _report_path(v, int(s), args.steps).exists()
        ]

        def sub(job: tuple[str, int]) -> int:
            v, s = job
            cmd = [sys.executable, __file__, "run", v, "--seed", str(s), "--steps", str(args.steps)]
            return subprocess.call(cmd)

        with ThreadPoolExecutor(args.parallel) as pool:
            codes = list(pool.map(sub, jobs))
        merge()
        if any(codes):
            raise SystemExit(f"{sum(1 for c in codes if c)} runs failed")


if __name__ == "__main__":
    main()
