"""[L21] Fig. 8 at laptop scale: explored ratio ER against episodes N for the exploration/
refinement curriculum and for uniform random task sampling at the same episode budget, on
configs/walker_jump.yaml. Everything but `curriculum.skill.sampling` is the same (the bootstrap
with π0, hindsight elites, P_θ); ER is measured the same way for both (share of the task box
whose elite density is at least D = 0.8, on 2,048 fixed probe points).

    pip install -e ".[bench]"
    python benchmarks/curriculum.py [--steps 400000] [--seeds 0] [--jobs 2]
        [--config configs/walker_jump.yaml]

Writes benchmarks/results/curriculum/curriculum.json (per run: N, ER, elites, phase per iteration;
the ER of each run at common N; the ratio curriculum / uniform) and
benchmarks/results/curriculum/curriculum.png.
Each run is the serial backend in its own process; --jobs runs that many at once (default 2,
one per core; with more than one job each learner uses one torch thread). Each finished run is
kept in benchmarks/results/curriculum/runs/<sampling>_s<seed>_<steps>.json and not run again,
so seeds can be added later (`--seeds 0,1,2` reruns only the missing ones) and the comparison
covers them.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results" / "curriculum"


def kept_run(sampling: str, seed: int, steps: int, recipe: str | None = None) -> Path:
    """Where a finished run is kept (and found, so that it is not run again)."""
    prefix = f"{recipe}_" if recipe else ""
    return RESULTS / "runs" / f"{prefix}{sampling}_s{seed}_{steps}.json"


def run(
    config: str,
    sampling: str,
    steps: int,
    seed: int,
    run_dir: Path,
    threads: int | None = None,
    recipe: str | None = None,
) -> dict:
    """One serial run of `sampling`; `threads`: the learner's torch threads (one per run when
    runs share the machine; default: the config's, every core for a serial trainer); `recipe`:
    the config at a paper's settings (every field of the recipe over the config's own)."""
    import torch

    from paramimic import recipes
    from paramimic.config import load_config
    from paramimic.training.trainer import SerialBackend, Trainer

    cfg = load_config(
        ROOT / config,
        (recipes.overrides(recipe) if recipe else {})
        | {
            "curriculum.skill.sampling": sampling,
            "train.seed": seed,
            "train.run_dir": str(run_dir),
            "train.checkpoint_every": 1_000_000,
        }
        | ({"train.torch_threads": threads} if threads else {}),
    )
    torch.manual_seed(seed)
    run_dir.mkdir(parents=True, exist_ok=True)
    trainer = Trainer(cfg, run_dir)
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    curve = []
    t0 = time.perf_counter()

    def record(m: dict) -> None:
        c = trainer.curriculum
        s = c.summary()
        curve.append(
            {
                "iteration": m["iteration"],
                "env_steps": m["env_steps"],
                "episodes": int(c.stats["episodes"]),
                "explored_ratio": c.explored_ratio(),
                "elites": s.elites,
                "phase": s.phase,
                "stage": s.stage,
                "mean_return": m.get("mean_return"),
                "fall_percent": m.get("fall_percent"),
                "elite_mean_fitness": s.elite_mean_fitness,
            }
        )
        last = curve[-1]
        print(
            f"{sampling:10s} s{seed} it {last['iteration']:4d} N {last['episodes']:6d} "
            f"ER {last['explored_ratio']:.3f} elites {last['elites']:4d} {last['phase']}",
            flush=True,
        )

    trainer.train(backend, steps, on_metrics=record)
    return {
        "sampling": sampling,
        "seed": seed,
        "recipe": recipe,
        "steps": steps,
        "seconds": time.perf_counter() - t0,
        "phase_switches": trainer.curriculum.phase.switches,
        "curve": curve,
        "elites": final_elites(run_dir),
    }


def _run_job(job: tuple) -> dict:
    return run(*job)


def final_elites(run_dir: Path) -> dict:
    """The elite set in the run's last checkpoint: names, params a', fitness, and per task
    dimension the range the elites cover."""
    from paramimic.training import checkpoint

    state = checkpoint.load(checkpoint.resolve(run_dir))
    table = state["curriculum"]["elites"]
    names = list(state["config"]["task"])
    params = np.asarray(table["params"]).reshape(-1, len(names))
    return {
        "names": names,
        "params": params.tolist(),
        "fitness": table["fitness"],
        "ranges": {
            n: [float(params[:, i].min()), float(params[:, i].max())] for i, n in enumerate(names)
        }
        if len(params)
        else {},
    }


def compare(runs: list[dict]) -> dict:
    """ER at common episode counts (linear interpolation), per mode averaged over seeds."""
    n_max = min(r["curve"][-1]["episodes"] for r in runs)
    grid = np.linspace(0, n_max, 21)[1:]
    per_mode: dict[str, list[np.ndarray]] = {}
    for r in runs:
        n = [p["episodes"] for p in r["curve"]]
        er = [p["explored_ratio"] for p in r["curve"]]
        per_mode.setdefault(r["sampling"], []).append(np.interp(grid, n, er))
    mean = {k: np.mean(v, axis=0) for k, v in per_mode.items()}
    out = {"episodes": grid.tolist(), "explored_ratio": {k: v.tolist() for k, v in mean.items()}}
    # the share of the policy updates after π0's base stage spent refining, per mode
    refining: dict[str, list[float]] = {}
    for r in runs:
        after = [p["phase"] for p in r["curve"] if p["stage"] != "base"]
        share = sum(p == "refinement" for p in after) / len(after) if after else 0.0
        refining.setdefault(r["sampling"], []).append(share)
    out["refinement_share"] = {k: float(np.mean(v)) for k, v in refining.items()}
    if {"curriculum", "uniform"} <= set(mean):
        c, u = mean["curriculum"], mean["uniform"]
        out["final_ratio"] = float(c[-1] / u[-1]) if u[-1] > 0 else None
        out["area_ratio"] = float(c.sum() / u.sum()) if u.sum() > 0 else None
        out["target"] = "ER(curriculum) >= 1.5 x ER(uniform) at equal episodes"
        out["target_met"] = out["final_ratio"] is not None and out["final_ratio"] >= 1.5
    return out


def plot(runs: list[dict], path: Path, config: str, recipe: str | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    colors = {"curriculum": "tab:red", "uniform": "tab:blue", "exploration_only": "tab:green",
              "mastering": "tab:purple", "alternating": "tab:orange"}  # fmt: skip
    for r in runs:  # each seed thin, the mean over the seeds at common N thick
        n = [p["episodes"] for p in r["curve"]]
        er = [p["explored_ratio"] for p in r["curve"]]
        ax.plot(n, er, color=colors[r["sampling"]], alpha=0.3, linewidth=0.8)
    mean = compare(runs)
    for sampling, er in mean["explored_ratio"].items():
        seeds = sum(r["sampling"] == sampling for r in runs)
        ax.plot(mean["episodes"], er, color=colors[sampling], linewidth=2,
                label=f"{sampling} (mean of {seeds})")  # fmt: skip
    ax.set_xlabel("episodes N")
    ax.set_ylabel("explored ratio ER")
    at = f" at recipe {recipe}" if recipe else ""
    ax.set_title(f"{Path(config).stem}{at}: the curricula of [L21] §7.3 (Fig. 8)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default="configs/walker_jump.yaml")
    p.add_argument("--steps", type=int, default=400_000)
    p.add_argument("--seeds", default="0")
    p.add_argument(
        "--samplings",
        default="curriculum,uniform",
        help="curriculum.skill.sampling values compared: curriculum (ours), uniform (the "
        "baseline), exploration_only, mastering, alternating ([L21] §7.3)",
    )
    p.add_argument("--jobs", type=int, default=2, help="runs at once, one process each")
    p.add_argument(
        "--recipe",
        default=None,
        help="run the config at a paper's settings (l21: [L21] §7's), kept apart from the "
        "shipped config's runs; default out: curriculum_<recipe>.json",
    )
    p.add_argument("--out", default=None, help="default: curriculum.json (or per --recipe)")
    p.add_argument(
        "--add-elites",
        action="store_true",
        help="only add the final elite sets of the runs in --out from their checkpoints",
    )
    args = p.parse_args()
    out = Path(args.out or RESULTS / f"curriculum{'_' + args.recipe if args.recipe else ''}.json")
    prefix = f"{args.recipe}_" if args.recipe else ""
    if args.add_elites:
        result = json.loads(out.read_text())
        for r in result["runs"]:
            run_dir = ROOT / "runs" / "bench_curriculum" / f"{prefix}{r['sampling']}_s{r['seed']}"
            r["elites"] = final_elites(run_dir)
            print(r["sampling"], r["seed"], r["elites"]["ranges"])
        out.write_text(json.dumps(result, indent=1))
        return
    seeds = [int(s) for s in args.seeds.split(",")]
    samplings = args.samplings.split(",")
    (RESULTS / "runs").mkdir(parents=True, exist_ok=True)

    def kept_path(sampling: str, seed: int) -> Path:
        return kept_run(sampling, seed, args.steps, args.recipe)

    jobs = [
        (
            args.config,
            sampling,
            args.steps,
            seed,
            ROOT / "runs" / "bench_curriculum" / f"{prefix}{sampling}_s{seed}",
            1 if args.jobs > 1 else None,
            args.recipe,
        )
        for seed in seeds
        for sampling in samplings
        if not kept_path(sampling, seed).exists()
    ]
    with multiprocessing.get_context("spawn").Pool(max(1, args.jobs)) as pool:
        for r in pool.imap_unordered(_run_job, jobs):  # each kept as soon as it finishes
            kept_path(r["sampling"], r["seed"]).write_text(json.dumps(r))
    runs = [
        json.loads(kept_path(sampling, seed).read_text())
        for seed in seeds
        for sampling in samplings
    ]
    result = {
        "config": args.config,
        "recipe": args.recipe,
        "steps": args.steps,
        "seeds": seeds,
        "comparison": compare(runs),
        "runs": runs,
        "command": "python benchmarks/curriculum.py " + " ".join(sys.argv[1:]),
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))
    plot(runs, out.with_suffix(".png"), args.config, args.recipe)
    print(json.dumps(result["comparison"], indent=1))


if __name__ == "__main__":
    main()
