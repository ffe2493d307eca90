"""`paramimic` command line: train and evaluate parametric controllers."""

from __future__ import annotations

import json
import re
import secrets
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from paramimic.config import ConfigError, load_config

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Train and evaluate parametric physics-based character controllers.",
)
console = Console()


def _headless_gl() -> None:
    """MuJoCo's offscreen renderer on a machine without a display: EGL (Mesa's software
    rasterizer where there is no GPU) unless MUJOCO_GL says otherwise. MuJoCo reads MUJOCO_GL
    when it is first imported, so the commands that render call this before importing it."""
    import os

    os.environ.setdefault("MUJOCO_GL", "egl")
    if os.environ["MUJOCO_GL"] in ("egl", "osmesa"):
        os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])


def _fail(message: str) -> None:
    console.print(f"[bold red]error:[/] {message}")
    raise typer.Exit(code=2)


@app.command()
def train(
    config: Annotated[Path, typer.Argument(help="experiment YAML, e.g. configs/walker_legs.yaml")],
    serial: Annotated[
        bool,
        typer.Option("--serial", help="run everything in this process, without Ray/Redis/API"),
    ] = False,
    ray_address: Annotated[
        str | None,
        typer.Option(help="join this Ray cluster (default: $RAY_ADDRESS, else start a local one)"),
    ] = None,
    node_ip_address: Annotated[
        str | None,
        typer.Option(
            help="with --ray-address: this machine's address in the cluster, if it has several "
            "(the learner attaches to the Ray node there)"
        ),
    ] = None,
    redis_url: Annotated[
        str | None,
        typer.Option(
            envvar="REDIS_URL",
            help="use this Redis (redis://[:password@]host:port/db; a password not in the URL "
            "comes from $REDIS_PASSWORD_FILE or $REDIS_PASSWORD); default: start an embedded "
            "one with its data in the run directory",
        ),
    ] = None,
    api: Annotated[bool, typer.Option("--api/--no-api", help="serve the progress API")] = True,
    api_host: Annotated[str, typer.Option(help="API address")] = "127.0.0.1",
    api_port: Annotated[int, typer.Option(help="API port (0: any free port)")] = 8000,
    api_token: Annotated[
        str | None,
        typer.Option(
            envvar="PARAMIMIC_API_TOKEN",
            help="bearer token for pause/resume/k over the API (none: those are disabled)",
        ),
    ] = None,
    total_steps: Annotated[int | None, typer.Option(help="override train.total_steps")] = None,
    wandb: Annotated[
        str | None,
        typer.Option(
            help="online or offline: also log to Weights & Biases (pip install '.[wandb]'); "
            "offline needs no network ('wandb sync RUN_DIR/wandb/offline-run-*' uploads it)"
        ),
    ] = None,
    run_dir: Annotated[Path | None, typer.Option(help="override train.run_dir")] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="continue from the run's latest checkpoint")
    ] = False,
    resume_if_exists: Annotated[
        bool,
        typer.Option(
            "--resume-if-exists",
            help="continue from the latest checkpoint if the run has one, else start it "
            "(for a supervisor that restarts the learner)",
        ),
    ] = False,
    seed: Annotated[int | None, typer.Option(help="override train.seed")] = None,
    init_from: Annotated[
        Path | None,
        typer.Option(help="override train.init_from: warm start from this run's controller"),
    ] = None,
    sets: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            help="override any field: KEY=VALUE (YAML value), e.g. --set curriculum.k=0 "
            "--set name=fig2a_uniform (give them again with --resume)",
        ),
    ] = None,
) -> None:
    """Train a controller for CONFIG: Redis, Ray actors, the sampler and the API, or --serial."""
    from services.launch.training import LaunchError, LaunchOptions, run_training
    from services.store import with_password

    _warn_secrets_on_argv()
    overrides = _parse_sets(sets) | {
        k: v
        for k, v in {
            "train.total_steps": total_steps,
            "train.seed": seed,
            "train.wandb": wandb,
            "train.run_dir": str(run_dir) if run_dir else None,
            "train.init_from": str(init_from) if init_from else None,
        }.items()
        if v is not None
    }
    from paramimic.training.preflight import PreflightError, preflight

    try:
        cfg = load_config(config, overrides)
        cfg = preflight(cfg)  # once, before anything starts: what the run carries
    except (ConfigError, PreflightError) as e:
        _fail(str(e))
    if not 0 <= api_port < 65536:
        _fail(f"--api-port must be in 0..65535, got {api_port}")
    if resume_if_exists:
        from paramimic.training import checkpoint

        resume = (checkpoint.checkpoint_dir(cfg.resolved_run_dir()) / checkpoint.LATEST).exists()
    options = LaunchOptions(
        resume=resume,
        serial=serial,
        ray_address=ray_address,
        node_ip=node_ip_address,
        redis_url=None if redis_url is None else with_password(redis_url),
        api=api,
        api_host=api_host,
        api_port=api_port,
        api_token=api_token or None,
    )
    try:
        code = run_training(cfg, options, console)
    except LaunchError as e:
        _fail(str(e))
    if code:
        raise typer.Exit(code=code)


def _parse_sets(sets: list[str] | None) -> dict:
    """--set KEY=VALUE items as dotted config overrides, each VALUE parsed as YAML."""
    import yaml

    overrides = {}
    for item in sets or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            _fail(f"--set {item!r}: KEY=VALUE, e.g. ppo.num_epochs=5")
        try:
            overrides[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError as e:
            _fail(f"--set {item!r}: the value is not YAML: {e}")
    return overrides


def _warn_secrets_on_argv() -> None:
    """A token or a Redis password given on the command line is visible to every user of the
    machine (`ps`); the environment variables carry them unseen."""
    argv = " ".join(sys.argv)
    if "--api-token" in argv:
        console.print("[yellow]--api-token on the command line shows in `ps`: set "
                      "PARAMIMIC_API_TOKEN instead[/]")  # fmt: skip
    if re.search(r"--redis-url[ =]\S*://[^@\s]*:[^@\s]+@", argv):
        console.print("[yellow]a password in --redis-url shows in `ps`: set REDIS_URL or "
                      "REDIS_PASSWORD instead[/]")  # fmt: skip


@app.command("api")
def api_cmd(
    redis_url: Annotated[
        str, typer.Option(envvar="REDIS_URL", help="the Redis that holds the runs")
    ] = "redis://127.0.0.1:6379/0",
    host: Annotated[str, typer.Option()] = "127.0.0.1",
    port: Annotated[int, typer.Option()] = 8000,
) -> None:
    """Serve the progress API alone (token for the mutating endpoints: $PARAMIMIC_API_TOKEN;
    a Redis password not in the URL: $REDIS_PASSWORD_FILE or $REDIS_PASSWORD)."""
    from services.api.app import serve
    from services.api.settings import Settings
    from services.store import with_password

    serve(Settings(redis_url=with_password(redis_url)), host, port)


@app.command()
def status(
    api: Annotated[str, typer.Option(help="the API's URL")] = "http://127.0.0.1:8000",
    run: Annotated[str | None, typer.Option(help="run id (default: the newest run)")] = None,
) -> None:
    """Print a run's progress and curriculum state, read from the API."""
    import httpx
    from rich.table import Table

    try:
        with httpx.Client(base_url=api, timeout=10.0) as client:
            if run is None:
                runs = client.get("/runs").raise_for_status().json()
                if not runs:
                    _fail(f"no runs at {api}")
                run = runs[0]["run_id"]
            progress = client.get(f"/runs/{run}/progress")
            if progress.status_code == 404:
                _fail(progress.json()["detail"])
            progress = progress.raise_for_status().json()
            cur = client.get(f"/runs/{run}/curriculum")
            curriculum = cur.json() if cur.status_code == 200 else None
    except httpx.HTTPError as e:
        _fail(f"cannot reach the API at {api}: {e}")
    table = Table(title=f"run {run}", show_header=False)
    for key in ("status", "iteration", "env_steps", "total_steps", "episodes",
                "steps_per_second", "mean_return", "fall_percent"):  # fmt: skip
        table.add_row(key, _fmt(progress.get(key)))
    if curriculum:
        keys = ["mode", "k", "mu", "refills", "buffer_adaptive", "buffer_size", "episodes",
                "tasks_served", "phase", "explored_ratio", "paused"]  # fmt: skip
        if curriculum.get("stage") is not None:  # [L21]
            keys += ["stage", "elites", "elite_mean_fitness", "exploration_rate_surrounding",
                     "exploration_rate_visited", "phase_switches", "motion_version"]  # fmt: skip
        for key in keys:
            table.add_row(f"curriculum.{key}", _fmt(curriculum.get(key)))
        table.add_row("curriculum.buffer_mean", _fmt(curriculum["buffer_mean"]))
    console.print(table)


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:,.4g}"
    if isinstance(v, dict):
        return ", ".join(f"{k} {x:.3g}" for k, x in v.items())
    return "-" if v is None else str(v)


@app.command("eval")
def evaluate_cmd(
    run: Annotated[
        Path, typer.Argument(help="run directory, checkpoint file or shipped controller name")
    ],
    episodes: Annotated[int, typer.Option(help="random tasks to evaluate")] = 300,
    seed: Annotated[int, typer.Option()] = 0,
    out: Annotated[Path | None, typer.Option(help="write the report as JSON here")] = None,
    grid: Annotated[int, typer.Option(help="grid size per displayed dimension")] = 5,
    seconds: Annotated[
        float | None, typer.Option(help="episode horizon (default: the config's)")
    ] = None,
    num_envs: Annotated[int, typer.Option(help="environments stepped together")] = 8,
    heatmap: Annotated[
        Path | None,
        typer.Option(help="write a PNG heatmap of return over the two displayed task dims"),
    ] = None,
) -> None:
    """Fall %, task achievement, returns and uniformity of a trained controller; for an [L21]
    skill run also the share of tasks achieved, each performed with m_a = P_θ(a)."""
    from paramimic.envs import env_for
    from paramimic.evaluation import deterministic, evaluate
    from paramimic.training import checkpoint
    from paramimic.training.method import method_for

    if episodes < 1 or grid < 1 or num_envs < 1:
        _fail("--episodes, --grid and --num-envs must be positive")
    if heatmap is not None and heatmap.suffix.lower() != ".png":
        _fail(f"--heatmap must be a .png file, got {heatmap.name!r}")
    cfg, policy, state = _load_policy(run, seconds)
    dims = cfg.display_dims()
    report = evaluate(
        deterministic(policy),
        lambda: env_for(cfg),
        cfg.task_space(),
        episodes,
        seed,
        dims if len(dims) == 2 else None,
        grid,
        num_envs,
        method_for(cfg).performer(state),  # [L21]: each task performed with m_a = P_θ(a)
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
        "mean_fitness",  # [L21] skill runs
        "achieved_share",
        "mean_body_error",  # clip gaits (env.gait)
        "mean_root_drift",
        "mean_facing_error",
        "speed_ratio",
    )
    shown = {k: round(report[k], 3) for k in keys if k in report}
    console.print(shown | {"uniformity": report["uniformity"]})
    if heatmap is not None:
        from services.media import write_heatmap

        if "grid" not in report:
            _fail("the task space has fewer than two free dimensions: no heatmap")
        title = f"{cfg.name}: return per task, {cfg.env.max_episode_seconds:g} s episodes"
        console.print(f"wrote {write_heatmap(report['grid'], heatmap, title)}")


def _load_policy(run: Path, seconds: float | None = None):
    """(config, policy in eval mode, checkpoint state) of a run directory, a checkpoint or the
    name of a shipped controller (`paramimic controllers list`)."""
    from paramimic.training import checkpoint

    try:
        state, cfg, policy = checkpoint.load_policy(run)
    except (FileNotFoundError, checkpoint.CheckpointError) as e:
        _fail(str(e))
    cfg.env = cfg.env.for_evaluation(seconds)  # whole episodes: no training-only stall rules
    return cfg, policy, state


def _parse_shapes(text: str, names: tuple[str, ...]) -> list[dict[str, float]]:
    """'a=1,b=0.8;a=1.2' -> [{a: 1, b: 0.8}, {a: 1.2}], names checked against the task."""
    shapes = []
    for chunk in filter(None, (c.strip() for c in text.split(";"))):
        shape = {}
        for item in chunk.split(","):
            name, sep, value = item.partition("=")
            name = name.strip()
            if not sep or name not in names:
                _fail(f"--shapes: {item!r} is not NAME=VALUE with NAME one of {list(names)}")
            try:
                shape[name] = float(value)
            except ValueError:
                _fail(f"--shapes: {value!r} is not a number")
        shapes.append(shape)
    if not shapes:
        _fail("--shapes: give at least one shape, e.g. 'global_z=0.6;global_z=1.4'")
    return shapes


def _default_bodies(space, dims: tuple[str, ...]) -> list[dict[str, float]]:
    """The base body first, then the corners of the display dims (the ends of one dim)."""
    ranges = space.ranges()
    if not dims:
        return [{}]
    if len(dims) == 1:
        return [{}, *({dims[0]: v} for v in ranges[dims[0]])]
    (x0, x1), (y0, y1) = ranges[dims[0]], ranges[dims[1]]
    return [{}, *({dims[0]: x, dims[1]: y} for y in (y0, y1) for x in (x0, x1))]


@app.command()
def render(
    run: Annotated[
        Path, typer.Argument(help="run directory, checkpoint file or shipped controller name")
    ],
    shapes: Annotated[
        str | None,
        typer.Option(
            help="bodies as task parameters, ';' between bodies: 'global_z=0.6;global_z=1.4' "
            "(unnamed parameters sit at the base body, or the task space's centre); default: "
            "the base body and the four corners of the config's two display dims"
        ),
    ] = None,
    out: Annotated[Path, typer.Option(help="family.gif or family.mp4")] = Path("family.gif"),
    seconds: Annotated[float, typer.Option(help="length of the clip")] = 4.0,
    width: Annotated[int, typer.Option(help="pixels per body")] = 320,
    height: Annotated[int, typer.Option()] = 240,
    morph: Annotated[
        bool,
        typer.Option(help="one body whose shape morphs along the given shapes ([WL19] §5.2)"),
    ] = False,
    seed: Annotated[int, typer.Option()] = 0,
    fps: Annotated[
        float | None,
        typer.Option(help="frames per second of the file (default: the control rate)"),
    ] = None,
) -> None:
    """Render the controller on several bodies side by side, or one morphing body."""
    _headless_gl()  # before anything imports mujoco: it picks its GL backend at import
    from paramimic.render import render_family, render_morph
    from services.media import VIDEO_SUFFIXES, write_animation

    if out.suffix.lower() not in VIDEO_SUFFIXES:
        _fail(f"--out must end in one of {VIDEO_SUFFIXES}, got {out.name!r}")
    if seconds <= 0 or width < 16 or height < 16:
        _fail("--seconds must be positive and --width/--height at least 16")
    if fps is not None and not fps > 0:
        _fail("--fps must be positive")
    from paramimic.envs import env_for
    from paramimic.evaluation import deterministic
    from paramimic.training.method import method_for

    cfg, policy, state = _load_policy(run, max(seconds, 1.0))
    env = env_for(cfg)
    space = env.task_space
    dims = cfg.display_dims()
    bodies = _parse_shapes(shapes, space.names) if shapes else _default_bodies(space, dims)
    base = space.base(env.definition.param_names())
    tasks = []
    for shape in bodies:
        a = base.copy()
        for name, value in shape.items():
            a[space.names.index(name)] = value
        if not space.contains(a)[0]:
            _fail(f"--shapes: {shape} is outside the task space {space.ranges()}")
        tasks.append(a)
    act = deterministic(policy)
    if morph:
        if len(bodies) < 2:
            _fail("--morph needs at least two shapes to move between")
        frames = render_morph(act, env, tasks[0], bodies, seconds, width, height, seed)
    else:
        maker = lambda: env_for(cfg)  # noqa: E731
        perform = method_for(cfg).performer(state)  # [L21]: m_a = P_θ(a)
        frames = render_family(act, maker, tasks, seconds, width, height, seed, perform)
    stride = 1 if fps is None else max(1, round(1.0 / (env.dt * fps)))  # every stride-th frame
    path = write_animation(frames[::stride], out, fps=1.0 / (env.dt * stride))
    n, (h, w) = len(frames[::stride]), frames[0].shape[:2]
    console.print(f"wrote {path} ({n} frames, {w}x{h})")


@app.command("upgrade-checkpoint")
def upgrade_checkpoint(
    path: Annotated[Path, typer.Argument(help="a checkpoint file or run directory you trust")],
) -> None:
    """Rewrite a checkpoint of the pickled-numpy format (older paramimic) as plain data, in place.

    It unpickles the file once, which can run code: only for files you made yourself."""
    from paramimic.training import checkpoint

    try:
        console.print(f"upgraded {checkpoint.upgrade(path)}")
    except FileNotFoundError as e:
        _fail(str(e))


@app.command("export")
def export_cmd(
    run: Annotated[
        Path, typer.Argument(help="run directory, checkpoint file or shipped controller name")
    ],
    out: Annotated[Path, typer.Option(help="the policy file to write")],
    format: Annotated[str, typer.Option(help="onnx or torchscript")] = "onnx",
) -> None:
    """The run's deterministic policy, observation normalization folded in, as ONNX or
    TorchScript, with a JSON sidecar (OUT.json): observation layout, actions, task space."""
    from services.export import FORMATS, export

    if format not in FORMATS:
        _fail(f"--format {format!r}: one of {', '.join(FORMATS)}")
    cfg, policy, _ = _load_policy(run)
    path, meta = export(policy, cfg, out, format)
    console.print(f"wrote {path} and {meta}")


@app.command()
def play(
    run: Annotated[
        Path, typer.Argument(help="run directory, checkpoint file or shipped controller name")
    ],
    host: Annotated[str, typer.Option(help="address to serve on")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="port (0: any free port)")] = 8010,
) -> None:
    """The run's controller in real time in the browser: sliders change the body and the goal
    on the fly ([WL19] §5.2); [L21] runs perform the skill of the chosen task parameter."""
    _headless_gl()
    from services.launch.processes import free_port, port_is_free
    from services.play import serve

    if port == 0:
        port = free_port(host)
    elif not port_is_free(host, port):
        _fail(f"{host}:{port} is in use; pass --port (0 = any free port)")
    cfg, policy, state = _load_policy(run)
    token = secrets.token_urlsafe(16)
    console.print(
        f"play: http://{host}:{port}/?token={token}  ({cfg.name}, {cfg.character}; Ctrl-C to stop)",
        soft_wrap=True,
    )
    serve(cfg, policy, state, host, port, token)


controllers_app = typer.Typer(
    no_args_is_help=True, help="Trained controllers shipped with paramimic, taken by name."
)
app.add_typer(controllers_app, name="controllers")


@controllers_app.command("list")
def controllers_list() -> None:
    """The shipped controllers: name, config, character, gait or clip, env steps trained."""
    from rich.table import Table

    from paramimic.training import checkpoint
    from services.learner import controllers

    table = Table()
    table.add_column("name", no_wrap=True)  # the name is what `play`, `eval` and `render` take
    for column in ("config", "character", "motion", "env steps"):
        table.add_column(column)
    for name in controllers.names():
        state = checkpoint.read(controllers.find(name))
        env = state["config"]["env"]
        motion = env.get("gait") or env.get("clip") or "procedural gait"
        table.add_row(name, state["config"]["name"], state["config"]["character"], motion,
                      f"{state['progress']['env_steps']:,}")  # fmt: skip
    console.print(table)


@controllers_app.command("add")
def controllers_add(
    run: Annotated[Path, typer.Argument(help="run directory or checkpoint file")],
    name: Annotated[str, typer.Option(help="the controller's name")],
    folder: Annotated[
        Path | None, typer.Option(help="write here (default: the package's controllers)")
    ] = None,
) -> None:
    """Ship a run's controller: its config, policy and V̄ (no optimizer or sampler state) as a
    small weights-only file that play, render and eval take by name."""
    from paramimic.training import checkpoint
    from services.learner import controllers

    try:
        path = controllers.add(run, name, folder)
    except (ValueError, FileNotFoundError, checkpoint.CheckpointError) as e:
        _fail(str(e))
    console.print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)")


config_app = typer.Typer(no_args_is_help=True, help="Experiment configs and their recipes.")
app.add_typer(config_app, name="config")


@config_app.command("show")
def config_show(
    config: Annotated[Path, typer.Argument(help="experiment YAML")],
    sets: Annotated[
        list[str] | None,
        typer.Option("--set", help="KEY=VALUE (YAML value), e.g. --set recipe=wl19"),
    ] = None,
    departures: Annotated[
        bool, typer.Option("--departures", help="only the fields a recipe or the config sets")
    ] = False,
) -> None:
    """Every field of CONFIG with its value and where it comes from: the config, its recipe
    (with the paper's section or our study), or the library default (with its description)."""
    from rich.table import Table

    from paramimic.config import ExperimentConfig, field_descriptions, inline_measures, raw_config
    from paramimic.recipes import flatten, sources

    overrides = _parse_sets(sets)
    try:
        raw = raw_config(config, overrides)
        cfg = load_config(config, overrides)
    except ConfigError as e:
        _fail(str(e))
    fields = flatten(cfg.model_dump(mode="json", exclude={"env": {"clip_texts"}}))
    where = sources(inline_measures(raw), fields, field_descriptions(ExperimentConfig))
    table = Table("field", "value", "source", title=f"{config} (recipe: {cfg.recipe})")
    for key, value in fields.items():
        if departures and where[key].startswith("default"):
            continue
        table.add_row(key, json.dumps(value), where[key])
    console.print(table)


clip_app = typer.Typer(no_args_is_help=True, help="Motion clips: built-in ones and your own.")
app.add_typer(clip_app, name="clip")


@clip_app.command("info")
def clip_info(
    clip: Annotated[str, typer.Argument(help="a clip file (DeepMimic format) or a built-in name")],
    character: Annotated[str, typer.Option(help="the character the clip is for")] = "humanoid",
    as_json: Annotated[bool, typer.Option("--json", help="print JSON")] = False,
) -> None:
    """Frames, duration, loop mode, joints and root travel of a clip, read and checked the way
    `env.clip` reads it (errors name the problem), and every measure of the task-parameter
    library on the reference motion (the nominal a0 of a declared parameter, in SI units)."""
    from paramimic.characters import REGISTRY
    from paramimic.envs.skill_env import SkillEnv

    if character not in REGISTRY:
        _fail(f"--character {character!r}: one of {sorted(REGISTRY)}")
    try:
        c = REGISTRY[character].load_clip(clip)
        env = SkillEnv(character, {}, {"clip": clip})
    except (ValueError, KeyError) as e:
        _fail(str(e))
    travel = c.root_position[-1] - c.root_position[0]
    info = {
        "name": c.name,
        "frames": len(c.durations),
        "duration_s": round(c.duration, 4),
        "loop": c.loop,
        "spherical_joints": list(c.spherical_names),
        "revolute_joints": list(c.revolute_names),
        "root_travel_m": [round(float(x), 4) for x in travel],
        "root_height_m": [round(float(c.root_position[:, 2].min()), 4),
                          round(float(c.root_position[:, 2].max()), 4)],
        "measures": {k: round(v, 4) for k, v in env.reference_measures().items()},
    }  # fmt: skip
    if as_json:
        print(json.dumps(info))
        return
    measures = info.pop("measures")
    for key, value in info.items():
        console.print(f"{key:18s} {value}")
    console.print("measures on the reference motion (SI units: m, rad, rad/s, m/s, J):")
    for key, value in measures.items():
        console.print(f"  {key:40s} {value}")


@clip_app.command("import")
def clip_import(
    bvh: Annotated[Path, typer.Argument(help="a BVH motion capture file")],
    out: Annotated[Path, typer.Option(help="the humanoid clip to write (DeepMimic format)")],
    skeleton: Annotated[
        str, typer.Option(help="auto, cmu, mixamo, lafan1, or a YAML map (role: joint name)")
    ] = "auto",
    start: Annotated[float | None, typer.Option(help="first second kept")] = None,
    end: Annotated[float | None, typer.Option(help="last second kept")] = None,
    fps: Annotated[float, typer.Option(help="frames per second of the clip")] = 30.0,
    scale: Annotated[
        float | None, typer.Option(help="metres per file unit (default: from the legs)")
    ] = None,
    up: Annotated[str, typer.Option(help="the file's up axis: auto, +y, +z, ...")] = "auto",
    forward: Annotated[
        str, typer.Option(help="the way the skeleton faces at rest: auto, +z, -x, ...")
    ] = "auto",
    mirror: Annotated[bool, typer.Option(help="swap left and right")] = False,
    loop: Annotated[
        bool, typer.Option(help="find the best gait cycle in what is kept and close it into a loop")
    ] = False,
) -> None:
    """Retarget a BVH file onto the humanoid and write it as a clip that `env.clip` (a skill)
    or `env.gait` (with --loop) trains on; says which skeleton map it chose and why, the
    units, and how the feet meet the floor."""
    from paramimic.characters.bvh_import import import_bvh

    try:
        imported = import_bvh(
            bvh, skeleton, start, end, fps, scale, up, mirror, loop, forward=forward
        )
        text = imported.text("wrap" if loop else "none")
        imported.clip(out.stem, "wrap" if loop else "none")  # it reads back as env.clip does
    except (ValueError, KeyError) as e:
        _fail(str(e))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    report = imported.report
    console.print(f"skeleton map {report['skeleton']!r}: {report['why']}")
    console.print(f"up axis {report['up_axis']}, facing {report['forward_axis']} at rest; "
                  f"{report['metres_per_unit']:.4g} m per unit "
                  f"({report['units_guess']})")  # fmt: skip
    dropped = report["dropped"]
    console.print(f"{len(dropped)} joints of the file not used: {', '.join(dropped) or 'none'}")
    errors = ", ".join(f"{k} {m:.1f} deg (max {x:.1f})"
                       for k, (m, x) in report["hinge_error_deg"].items())  # fmt: skip
    console.print(f"1-DOF knees and elbows, the lower bone's angle off its hinge: {errors}")
    console.print(f"{report['frames']} frames, {report['seconds']:.2f} s at {fps:g} fps; "
                  f"lowest foot point {report['lowest_foot_min_m']:+.3f} m; feet on the "
                  f"ground in {100 * report['contact_share']:.0f} % of the frames")  # fmt: skip
    if report["cycle"] is not None:
        c = report["cycle"]
        console.print(f"gait cycle {c['start_s']:.2f}-{c['end_s']:.2f} s, closed (its ends "
                      f"differed by {c['residual_before_closing']:.3f})")  # fmt: skip
    console.print(f"wrote {out}")


@clip_app.command("export")
def clip_export(
    clip: Annotated[str, typer.Argument(help="a humanoid clip file or a built-in clip name")],
    bvh: Annotated[Path, typer.Option(help="the BVH file to write")],
) -> None:
    """Write a humanoid clip as BVH motion capture of the humanoid's own skeleton (metres, Y
    up), which `paramimic clip import` reads back."""
    from paramimic.characters.bvh_import import clip_frames, export_bvh

    try:
        frames = clip_frames(clip)
    except (ValueError, KeyError, OSError) as e:
        _fail(str(e))
    export_bvh(frames, bvh)
    console.print(f"wrote {bvh}: {len(frames)} frames of {clip}")


@clip_app.command("render")
def clip_render(
    clip: Annotated[str, typer.Argument(help="a clip file, a built-in name, or a BVH file")],
    out: Annotated[Path, typer.Option(help="clip.gif or clip.mp4")] = Path("clip.gif"),
    width: Annotated[int, typer.Option()] = 320,
    height: Annotated[int, typer.Option()] = 240,
    skeleton: Annotated[str, typer.Option(help="a BVH file's skeleton map")] = "auto",
    start: Annotated[float | None, typer.Option(help="a BVH file's first second")] = None,
    end: Annotated[float | None, typer.Option(help="a BVH file's last second")] = None,
) -> None:
    """Play a clip on the humanoid, kinematically (no training, no physics); a BVH file is
    imported as `clip import` does and its own skeleton drawn beside the humanoid in red."""
    _headless_gl()
    from paramimic.characters.bvh_import import clip_frames, import_bvh, render_clip
    from services.media import write_animation

    try:
        if clip.lower().endswith(".bvh"):
            imported = import_bvh(clip, skeleton, start, end)
            frames, source, bones = imported.frames, imported.source, imported.bones
        else:
            frames, source, bones = clip_frames(clip), None, ()
    except (ValueError, KeyError, OSError) as e:
        _fail(str(e))
    images = render_clip(frames, source, bones, width, height)
    fps = 1.0 / float(frames[0, 0]) if frames[0, 0] > 0 else 30.0
    write_animation(images, out, fps)
    console.print(f"wrote {out}: {len(images)} frames at {fps:g} fps")


PLACEHOLDERS = {"change-me", "changeme", "password", "secret", "redis", "token", "example"}
MIN_SECRET = 16
MIN_DISTINCT = 8  # 'aaaaaaaaaaaaaaaa' is 16 characters and no secret


SECRETS = ("REDIS_PASSWORD", "RAY_AUTH_TOKEN")


def secret_problems(environ: dict, need: tuple[str, ...] = SECRETS) -> list[str]:
    """What is wrong with a deployment's secrets (`need` required; PARAMIMIC_API_TOKEN
    optional): missing, a placeholder, shorter than 16 characters or of fewer than 8 distinct
    ones."""
    problems = []
    for name in (*need, "PARAMIMIC_API_TOKEN"):
        value = environ.get(name, "")
        if not value:
            if name in need:
                problems.append(f"{name} is not set")
        elif value.lower() in PLACEHOLDERS:
            problems.append(f"{name} is the placeholder {value!r}: set a random secret")
        elif len(value) < MIN_SECRET:
            problems.append(f"{name} is {len(value)} characters: use at least {MIN_SECRET}")
        elif len(set(value)) < MIN_DISTINCT:
            problems.append(f"{name} has {len(set(value))} distinct characters: set a random "
                            f"secret (at least {MIN_DISTINCT})")  # fmt: skip
    return problems


@app.command("health")
def health(
    run_dir: Annotated[Path, typer.Argument(help="the run directory")],
    max_age: Annotated[
        float, typer.Option(help="seconds the learner may go without refreshing its liveness file")
    ] = 600.0,
) -> None:
    """Exit 0 if a learner owns RUN_DIR and is moving (its liveness file is younger than
    --max-age), else 1 with the reason: the healthcheck of a deployment's learner."""
    from services.launch.liveness import problem

    reason = problem(run_dir, max_age)
    if reason is not None:
        print(reason)  # one plain line: a healthcheck's log
        raise typer.Exit(code=1)
    print(f"{run_dir}: alive")


@app.command("deploy-check")
def deploy_check(
    env_file: Annotated[
        Path | None,
        typer.Argument(help="a compose .env file (default: this process's environment)"),
    ] = None,
    need: Annotated[str, typer.Option(help="comma-separated secrets that must be set")] = ",".join(
        SECRETS
    ),
) -> None:
    """Refuse placeholder or short secrets before a cluster starts (the compose services run it
    first). Make one with: python -c "import secrets; print(secrets.token_hex(32))"."""
    import os

    from dotenv import dotenv_values

    environ = dict(os.environ) if env_file is None else dotenv_values(env_file)
    needed = tuple(n for n in need.split(",") if n)
    problems = secret_problems({k: v or "" for k, v in environ.items()}, needed)
    if problems:
        _fail("deploy-check: " + "; ".join(problems))
    console.print("deploy-check: secrets ok")


if __name__ == "__main__":
    app()
