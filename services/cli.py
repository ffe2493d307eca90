"""`paramimic` command line: train and evaluate parametric controllers."""

from __future__ import annotations

import json
import signal
from pathlib import Path
from typing import Annotated

import typer
import yaml
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from paramimic.config import ConfigError, ExperimentConfig, load_config

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Train and evaluate parametric physics-based character controllers.",
)
console = Console()


def _fail(message: str) -> None:
    console.print(f"[bold red]error:[/] {message}")
    raise typer.Exit(code=2)


@app.command()
def train(
    config: Annotated[Path, typer.Argument(help="experiment YAML, e.g. configs/walker_legs.yaml")],
    serial: Annotated[
        bool, typer.Option("--serial", help="run everything in this process, without Ray")
    ] = False,
    ray_address: Annotated[
        str | None,
        typer.Option(help="join this Ray cluster (default: $RAY_ADDRESS, else start a local one)"),
    ] = None,
    total_steps: Annotated[int | None, typer.Option(help="override train.total_steps")] = None,
    run_dir: Annotated[Path | None, typer.Option(help="override train.run_dir")] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="continue from the run's latest checkpoint")
    ] = False,
    seed: Annotated[int | None, typer.Option(help="override train.seed")] = None,
) -> None:
    """Train a controller for CONFIG: rollouts on Ray actors, or in-process with --serial."""
    overrides = {
        k: v
        for k, v in {
            "train.total_steps": total_steps,
            "train.seed": seed,
            "train.run_dir": str(run_dir) if run_dir else None,
        }.items()
        if v is not None
    }
    try:
        cfg = load_config(config, overrides)
    except ConfigError as e:
        _fail(str(e))
    _train(cfg, resume, serial, ray_address)


def _train(cfg: ExperimentConfig, resume: bool, serial: bool, ray_address: str | None) -> None:
    from services.learner import checkpoint
    from services.learner.trainer import SerialBackend, Trainer

    run_dir = cfg.resolved_run_dir()
    if not resume and (checkpoint.checkpoint_dir(run_dir) / checkpoint.LATEST).exists():
        _fail(f"{run_dir} already holds a run; pass --resume or another --run-dir")
    run_dir.mkdir(parents=True, exist_ok=True)
    trainer = Trainer(cfg, run_dir)
    if resume:
        try:
            state = checkpoint.load(run_dir)
        except FileNotFoundError as e:
            _fail(str(e))
        trainer.load_state_dict(state)
        console.print(
            f"resumed at iteration {trainer.progress.iteration}, "
            f"{trainer.progress.env_steps} env steps"
        )
    (run_dir / "config.yaml").write_text(
        yaml.safe_dump(cfg.model_dump(mode="json"), sort_keys=False)
    )
    started_ray = False
    fatal: tuple[type[Exception], ...] = ()  # errors that end the run with a message
    if serial:
        backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.sampler.next_tasks)
    else:
        import ray

        from services.learner.cluster import connect
        from services.learner.ray_backend import AllActorsLost, RayBackend

        fatal = (AllActorsLost,)
        started_ray = connect(ray_address)
        backend = RayBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.sampler.next_tasks)
        console.print(
            f"Ray: {backend.num_actors} rollout actors x {cfg.actors.num_envs} envs, "
            f"{backend.steps} steps per fragment, {cfg.actors.mode} mode"
        )
    stop = {"flag": False}

    def on_sigint(signum, frame):  # first Ctrl-C: finish the iteration, checkpoint, exit
        stop["flag"] = True
        console.print("[yellow]stopping after this iteration...[/]")

    previous = signal.signal(signal.SIGINT, on_sigint)
    total = cfg.train.total_steps
    console.print(f"run directory: {run_dir}")
    code = 0
    try:
        with Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            TextColumn("{task.completed:,.0f}/{task.total:,.0f} steps"),
            TextColumn("{task.fields[info]}"),
            TimeElapsedColumn(),
            console=console,
        ) as bar:
            task = bar.add_task(
                "training", total=total, completed=trainer.progress.env_steps, info=""
            )

            def show(m: dict) -> None:
                info = (
                    f"it {m['iteration']}  {m['steps_per_second']:,.0f} steps/s  "
                    f"return {m.get('mean_return', float('nan')):.2f}  "
                    f"fall {m.get('fall_percent', float('nan')):.0f}%"
                )
                if m.get("actor_restarts"):
                    info += f"  restarts {m['actor_restarts']}"
                bar.update(task, completed=m["env_steps"], info=info)

            trainer.train(backend, total, on_metrics=show, should_stop=lambda: stop["flag"])
    except fatal as e:  # the checkpoint was written by Trainer.train on the way out
        console.print(f"[bold red]stopped:[/] {e}; checkpoint saved, resume with --resume")
        code = 3
    finally:
        signal.signal(signal.SIGINT, previous)
        backend.close()
        if started_ray:
            ray.shutdown()
    console.print(f"checkpoint: {run_dir / 'checkpoints' / 'latest.pt'}")
    if code:
        raise typer.Exit(code=code)


@app.command("eval")
def evaluate_cmd(
    run: Annotated[Path, typer.Argument(help="run directory or checkpoint file")],
    episodes: Annotated[int, typer.Option(help="random tasks to evaluate")] = 300,
    seed: Annotated[int, typer.Option()] = 0,
    out: Annotated[Path | None, typer.Option(help="write the report as JSON here")] = None,
    grid: Annotated[int, typer.Option(help="grid size per displayed dimension")] = 5,
    seconds: Annotated[
        float | None, typer.Option(help="episode horizon (default: the config's)")
    ] = None,
    num_envs: Annotated[int, typer.Option(help="environments stepped together")] = 8,
) -> None:
    """Fall %, task achievement, returns and uniformity of a trained controller."""
    from paramimic.envs import make_env
    from paramimic.evaluation import deterministic, evaluate
    from paramimic.rl.networks import ActorCritic
    from services.learner import checkpoint

    if episodes < 1 or grid < 1 or num_envs < 1:
        _fail("--episodes, --grid and --num-envs must be positive")
    try:
        state = checkpoint.load(run)
    except FileNotFoundError as e:
        _fail(str(e))
    cfg = ExperimentConfig.model_validate(state["config"])
    if seconds is not None:
        cfg.env.max_episode_seconds = seconds
    policy = ActorCritic(state["obs_dim"], state["act_dim"], cfg.ppo.hidden_sizes, 0.0)
    policy.load_state_dict(state["learner"]["policy"])
    policy.eval()
    probe = make_env(cfg.character, cfg.task, cfg.env)
    report = evaluate(
        deterministic(policy),
        lambda: make_env(cfg.character, cfg.task, cfg.env),
        probe.task_space,
        episodes,
        seed,
        cfg.grid_dims(),
        grid,
        num_envs,
    )
    report.update(
        {
            "checkpoint": str(checkpoint.resolve(run)),
            "config": cfg.name,
            "iteration": state["progress"]["iteration"],
            "env_steps": state["progress"]["env_steps"],
            "seed": seed,
            "horizon_seconds": cfg.env.max_episode_seconds,
        }
    )
    text = json.dumps(report, indent=2)
    if out:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
        console.print(f"wrote {out}")
    keys = (
        "mean_return",
        "worst_decile_return",
        "task_achievement",
        "fall_percent",
        "mean_forward_speed",
    )
    console.print({k: round(report[k], 3) for k in keys} | {"uniformity": report["uniformity"]})


if __name__ == "__main__":
    app()
