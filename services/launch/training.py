"""`paramimic train`: start what a run needs, train, and stop everything that was started.

Laptop default: an embedded Redis (data in the run directory), a local Ray, the sampler actor,
the rollout actors, the learner (this process) and the API child process on 127.0.0.1:8000.
`--redis-url` and `--ray-address` join existing ones instead; `--serial` runs the learner and one
rollout worker in this process with an in-process curriculum (no Ray, Redis or API).
"""

from __future__ import annotations

import fcntl
import os
import re
import signal
import threading
import time
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import yaml
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from paramimic.config import ExperimentConfig, resume_conflicts
from paramimic.training import checkpoint
from paramimic.training.trainer import SerialBackend, Trainer, TrainingDiverged, WriteRefused
from services.launch import reaper
from services.launch.liveness import LOCK_FILE, beat

RUN_ID_FILE = "run_id"


class LaunchError(RuntimeError):
    """Something the user can fix (a busy port, an existing run); nothing was started."""


@dataclass
class LaunchOptions:
    resume: bool = False
    serial: bool = False
    ray_address: str | None = None
    node_ip: str | None = None
    redis_url: str | None = None
    api: bool = True
    api_host: str = "127.0.0.1"
    api_port: int = 8000
    api_token: str | None = None


def run_id_for(run_dir: Path, cfg: ExperimentConfig, resume: bool) -> str:
    """A run's id: made once, kept in the run directory, reused by --resume."""
    path = run_dir / RUN_ID_FILE
    if resume and path.exists():
        return path.read_text().strip()
    run_id = f"{cfg.name}-{time.strftime('%Y%m%d-%H%M%S')}-{os.urandom(2).hex()}"
    path.write_text(run_id + "\n")
    return run_id


class StopFlag:
    """Set by the first Ctrl-C or SIGTERM: finish the iteration, checkpoint, stop. A second one
    interrupts at once (what was started is still stopped on the way out)."""

    def __init__(self, console: Console) -> None:
        self.set = False
        self.console = console

    def __call__(self, signum, frame) -> None:
        if self.set:
            raise KeyboardInterrupt
        self.console.print("[yellow]stopping after this iteration (again to interrupt)...[/]")
        self.set = True


def check_redis(url: str) -> None:
    """Fail before anything starts if `url` is malformed, unreachable or refuses the password."""
    import redis

    try:
        client = redis.Redis.from_url(url, socket_connect_timeout=3, socket_timeout=3)
        client.ping()
        client.close()
    except (ValueError, redis.exceptions.RedisError) as e:
        raise LaunchError(f"cannot use Redis at {masked(url)}: {e}") from e


def masked(url: str) -> str:
    """A Redis URL without its password, for messages."""
    return re.sub(r"(://[^:/@]*:)[^@]*@", r"\1***@", url)


def run_training(cfg: ExperimentConfig, opts: LaunchOptions, console: Console) -> int:
    """Train; returns the process exit code (0 done or stopped, 3 all rollout actors lost,
    4 the updates diverged, 5 fragments keep failing or the sampler failed)."""
    run_dir = cfg.resolved_run_dir()
    if not opts.resume and (checkpoint.checkpoint_dir(run_dir) / checkpoint.LATEST).exists():
        raise LaunchError(f"{run_dir} already holds a run; pass --resume or another --run-dir")
    state = None
    if opts.resume:
        try:
            state = checkpoint.load(run_dir)
        except (FileNotFoundError, checkpoint.CheckpointError) as e:
            raise LaunchError(str(e)) from e
        conflicts = resume_conflicts(state["config"], cfg)
        if conflicts:
            raise LaunchError(
                f"--resume: the config differs from {run_dir}'s checkpoint where a run cannot "
                f"change: " + "; ".join(conflicts)
            )
    api_port = opts.api_port
    if not opts.serial and opts.api:
        from services.launch.processes import free_port, port_is_free

        if api_port == 0:
            api_port = free_port(opts.api_host)
        elif not port_is_free(opts.api_host, api_port):
            raise LaunchError(
                f"{opts.api_host}:{api_port} is in use; pass --api-port (0 = any free) or --no-api"
            )
    if not opts.serial and opts.redis_url is not None:
        check_redis(opts.redis_url)
    run_dir.mkdir(parents=True, exist_ok=True)
    lock = lock_run_dir(run_dir)  # held until this process exits, however it exits
    stop = StopFlag(console)
    handlers = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    run = Run(cfg, run_dir, state, stop, console)
    try:
        with ExitStack() as services:
            if opts.serial:
                return _train_serial(run)
            return _train_distributed(run, opts, api_port, services)
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)
        lock.close()
        console.print(f"checkpoint: {checkpoint.checkpoint_dir(run_dir) / checkpoint.LATEST}")


def lock_run_dir(run_dir: Path):
    """An exclusive flock on the run directory: one learner per run dir. The kernel drops it
    when the process dies, even by SIGKILL. Returns the open lock file (close to release)."""
    f = (run_dir / LOCK_FILE).open("a+")
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        f.seek(0)
        holder = f.read().strip() or "unknown"
        f.close()
        raise LaunchError(
            f"{run_dir} is in use by another learner (pid {holder}); stop it first"
        ) from None
    f.seek(0)
    f.truncate()
    f.write(f"{os.getpid()}\n")
    f.flush()
    return f


@dataclass
class Run:
    """What one training run carries from the launcher into its loop."""

    cfg: ExperimentConfig
    run_dir: Path
    state: dict | None  # the checkpoint it resumes from
    stop: StopFlag
    console: Console


def write_run_config(run: Run) -> None:
    """config.yaml in the run directory: written once the run is this learner's (its lock and,
    in Redis, its lease), so a learner refused the run writes nothing."""
    (run.run_dir / "config.yaml").write_text(
        yaml.safe_dump(run.cfg.model_dump(mode="json"), sort_keys=False)
    )


def _train_serial(run: Run) -> int:
    cfg, run_dir, state, stop, console = run.cfg, run.run_dir, run.state, run.stop, run.console
    write_run_config(run)
    trainer = Trainer(cfg, run_dir)
    if state is not None:
        trainer.load_state_dict(state)
        _say_resumed(trainer, console)
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    try:
        with _progress_bar(console, cfg.train.total_steps, trainer.progress.env_steps) as show:
            trainer.train(
                backend, cfg.train.total_steps, on_metrics=show, should_stop=lambda: stop.set
            )
    except TrainingDiverged as e:
        console.print(f"[bold red]stopped:[/] {e}; checkpoint saved")
        return 4
    return 0


def _train_distributed(run: Run, opts: LaunchOptions, api_port: int, services: ExitStack) -> int:
    return DistributedRun(run, opts, api_port, services).train()


def _stops() -> dict[type[Exception], tuple[int, str, str]]:
    """What ends a distributed run early: its exit code and what to say (Trainer.train writes
    a checkpoint on the way out in every case)."""
    from services.learner.ray_backend import (
        AllActorsLost,
        ClusterFailing,
        FragmentsFailing,
        SamplerFailed,
    )
    from services.store import LeaseLost

    fix = "checkpoint saved, fix and --resume"
    return {
        AllActorsLost: (3, "stopped", "checkpoint saved, resume with --resume"),
        TrainingDiverged: (4, "stopped", "checkpoint saved"),
        FragmentsFailing: (5, "stopped (rollouts keep failing)", fix),
        SamplerFailed: (5, "stopped (sampler failed)", fix),
        ClusterFailing: (5, "stopped (Ray refused the weights)", fix),
        WriteRefused: (
            6,
            "stopped (lease lost)",
            "nothing written after it; another learner may own the run",
        ),
        LeaseLost: (
            6,
            "stopped (lease lost)",
            "nothing written after it; another learner may own the run",
        ),
    }


class DistributedRun:
    """One run on Ray with Redis and the API, as steps: each `start_*` starts one thing and
    registers its stop on `services` (an ExitStack, unwound in reverse on the way out); `train`
    runs the loop and maps how it ended to an exit code."""

    def __init__(self, run: Run, opts: LaunchOptions, api_port: int, services: ExitStack):
        self.run, self.opts, self.api_port, self.services = run, opts, api_port, services
        self.console, self.stop = run.console, run.stop
        self.redis_url = opts.redis_url
        self.embedded_redis = None
        self.redis_lock = threading.Lock()
        self.api = None
        self.api_url: str | None = None

    def start_watchdog(self) -> None:
        """Ends what we start if we are killed; stopped last on the way out."""
        watchdog = reaper.start()
        self.services.callback(lambda: (watchdog.terminate(), watchdog.wait(10)))

    def start_redis(self) -> None:
        """An embedded Redis with its data in the run directory, unless --redis-url names one."""
        from services.launch.redis_server import EmbeddedRedis

        if self.redis_url is not None:
            return
        server = self.embedded_redis = EmbeddedRedis(self.run.run_dir / "redis")
        self.redis_url = server.start()
        self.services.callback(server.stop)
        self.console.print(f"Redis: embedded, {masked(self.redis_url)}, AOF in {server.data_dir}")
        # watched every second, not between iterations: an iteration waits on Redis, and a
        # Redis down for longer than 2/3 of the run's lease would cost the learner its lease
        done = threading.Event()

        def keep() -> None:
            while not done.wait(1.0):
                self.keep_redis_alive()

        keeper = threading.Thread(target=keep, name="redis-keeper", daemon=True)
        keeper.start()
        self.services.callback(lambda: (done.set(), keeper.join(10)))

    def connect_ray(self) -> None:
        import ray

        from services.learner.cluster import connect

        if connect(self.opts.ray_address, self.opts.node_ip):
            self.services.callback(ray.shutdown)
            self.console.print(
                "Ray: a private local cluster started for this run (token auth); "
                "--ray-address or RAY_ADDRESS joins another"
            )
        else:
            self.console.print(f"Ray: joined {ray.get_runtime_context().gcs_address}")
        # ray.init puts sys.exit on SIGTERM in the driver: a `kill` or `docker stop` then left
        # in the middle of an iteration and the process aborted on its way out; it stops as
        # Ctrl-C does
        signal.signal(signal.SIGTERM, self.stop)

    def own_run(self) -> None:
        """The run's lease: one learner per run id, also across machines sharing the Redis."""
        from services.learner.reporter import RunOwned, RunReporter

        self.run_id = run_id_for(self.run.run_dir, self.run.cfg, self.opts.resume)
        self.reporter = RunReporter(self.redis_url, self.run_id)
        try:
            self.reporter.acquire()
        except RunOwned as e:
            raise LaunchError(str(e)) from e
        self.services.callback(self.reporter.release)

    def start_stack(self) -> None:
        """The sampler and the rollout actors, and the learner talking to them."""
        from services.launch.stack import ray_stack

        cfg, run_dir, state = self.run.cfg, self.run.run_dir, self.run.state
        stack = self.services.enter_context(
            ray_stack(cfg, run_dir, self.redis_url, self.run_id, owner=self.reporter.owner)
        )
        self.trainer, self.backend = stack.trainer, stack.backend
        self.backend.should_stop = lambda: self.stop.set  # SIGTERM honoured while it waits
        if state is not None:
            self.trainer.load_state_dict(state)  # the sampler takes the checkpoint's curriculum
            _say_resumed(self.trainer, self.console)
        self.console.print(
            f"Ray: {self.backend.num_actors} rollout actors x {cfg.actors.num_envs} envs, "
            f"{self.backend.steps} steps per fragment, {cfg.actors.mode} mode"
        )

    def start_api(self) -> None:
        from services.launch.api_process import ApiProcess

        opts = self.opts
        if opts.api:
            log = self.run.run_dir / "api.log"
            self.api = ApiProcess(self.redis_url, opts.api_host, self.api_port, opts.api_token, log)
            self.api_url = self.api.start()
            self.services.callback(self.api.stop)
            self.console.print(
                f"API: {self.api_url}  (dashboard at /, docs at /docs; run id {self.run_id})"
            )
        self.reporter.start(self.run.cfg, self.run.run_dir, self.run.cfg.train.total_steps,
                            self.api_url)  # fmt: skip

    # --- what the loop calls ------------------------------------------------------------------

    def before_iteration(self) -> None:
        """Apply the API's requests: k now; a pause holds here until resumed or stopped."""
        reporter, stop = self.reporter, self.stop
        paused, k = reporter.take_control()
        announced = False
        while True:
            if k is not None:
                self.trainer.curriculum.set_k(k)
            if not paused or stop.set:
                break
            if not announced:
                reporter.set_status("paused", "training paused")
                self.console.print("[yellow]paused (POST /runs/{run}/resume to go on)[/]")
                announced = True
            time.sleep(0.5)  # the pause's poll of the control hash
            self.supervise(self.trainer.progress.iteration)  # a paused run stays live
            paused, k = reporter.take_control()
        if announced and not stop.set:
            reporter.set_status("running", "training resumed")

    checkpointed: int | None = None  # the iteration of the last checkpoint written

    def on_checkpoint(self, path: Path | None, iteration: int, error: str | None = None) -> None:
        if path is not None:
            self.checkpointed = iteration
        if error is not None:
            self.reporter.event("checkpoint_failed", error, {"iteration": iteration})
            self.console.print(f"[yellow]{error}[/]")
            return
        self.reporter.event(
            "checkpoint", f"checkpoint at iteration {iteration}", {"path": str(path)}
        )

    def on_metrics(self, m: dict) -> None:
        self.reporter.progress(m, self.trainer.episode_ids)
        for kind, message, data in self.backend.take_events():  # nodes lost and joined
            self.reporter.event(kind, message, {**data, "iteration": m["iteration"]})
            self.console.print(f"[yellow]{message}[/]")
        self.supervise(m["iteration"])

    def keep_api_alive(self, iteration: int) -> None:
        """The API died: start it again (on the same port); a restart that fails is reported
        and tried again at the next check, the run goes on."""
        if self.api is None or self.api.alive():
            return
        try:
            self.api.start()
        except Exception as e:
            self.console.print(f"[yellow]the API process had exited and did not restart: {e}[/]")
            return
        message = f"the API process had exited; restarted on {self.api.url}"
        self.reporter.event("api_restarted", message, {"iteration": iteration})
        self.console.print(f"[yellow]{message}[/]")

    def keep_redis_alive(self) -> None:
        """The embedded Redis died: start it again on its port and its AOF (the sampler and
        the reporter reconnect; what it had flushed is kept)."""
        server = self.embedded_redis
        with self.redis_lock:  # the keeper thread and the loop's `supervise`
            if server is None or server.process is None or server.process.poll() is None:
                return
            try:
                server.start()
            except RuntimeError as e:
                self.console.print(f"[yellow]the embedded Redis exited and did not restart: {e}[/]")
                return
        self.console.print("[yellow]the embedded Redis had exited; restarted on its port[/]")

    def supervise(self, iteration: int) -> None:
        """What the loop refreshes and keeps up between iterations and while paused: the
        liveness file, the embedded Redis, the API."""
        beat(self.run.run_dir)
        self.keep_redis_alive()
        self.keep_api_alive(iteration)

    # --- the run --------------------------------------------------------------------------------

    def train(self) -> int:
        """Start everything, train; the exit code: 0 finished or stopped, else `_stops()`'."""
        for step in (self.start_watchdog, self.start_redis, self.connect_ray, self.own_run,
                     lambda: write_run_config(self.run), self.start_stack,
                     self.start_api):  # fmt: skip
            step()
        cfg, trainer, stop, stops = self.run.cfg, self.trainer, self.stop, _stops()
        beat(self.run.run_dir)
        total, done = cfg.train.total_steps, trainer.progress.env_steps
        status, code = "failed", 1
        try:
            with _progress_bar(self.console, total, done) as show:
                trainer.train(
                    self.backend,
                    cfg.train.total_steps,
                    on_metrics=lambda m: (self.on_metrics(m), show(m)),
                    should_stop=lambda: stop.set,
                    before_iteration=self.before_iteration,
                    on_checkpoint=self.on_checkpoint,
                    may_write=self.reporter.holds,
                )
            status, code = ("stopped" if stop.set else "finished"), 0
        except tuple(stops) as e:
            code, what, then = stops[type(e)]
            if (
                then.startswith("checkpoint saved")
                and self.checkpointed != trainer.progress.iteration
            ):
                then = (f"no final checkpoint (the last is iteration {self.checkpointed}); "
                        "--resume continues from it")  # fmt: skip
            self.console.print(f"[bold red]{what}:[/] {e}; {then}")
        finally:
            if code == 1 and stop.set:  # interrupted by a second Ctrl-C
                status = "stopped"
            self.record_end(status)
        return code

    def record_end(self, status: str) -> None:
        try:
            self.reporter.set_status(status, f"training {status} at iteration "
                                             f"{self.trainer.progress.iteration}")  # fmt: skip
        except Exception as e:  # Redis gone: the run's end is still in the checkpoint
            self.console.print(f"[yellow]could not record the run's end in Redis: {e}[/]")


def _say_resumed(trainer: Trainer, console: Console) -> None:
    console.print(
        f"resumed at iteration {trainer.progress.iteration}, {trainer.progress.env_steps} env steps"
    )


class _progress_bar:
    """A rich progress bar; the context value updates it from one iteration's metrics."""

    def __init__(self, console: Console, total: int, completed: int) -> None:
        self.bar = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            TextColumn("{task.completed:,.0f}/{task.total:,.0f} steps"),
            TextColumn("{task.fields[info]}"),
            TimeElapsedColumn(),
            console=console,
        )
        self.task = self.bar.add_task("training", total=total, completed=completed, info="")

    def __enter__(self):
        self.bar.__enter__()
        return self.show

    def __exit__(self, *exc) -> None:
        self.bar.__exit__(*exc)

    def show(self, m: dict) -> None:
        info = (
            f"it {m['iteration']}  {m['steps_per_second']:,.0f} steps/s  "
            f"return {m.get('mean_return', float('nan')):.2f}  "
            f"fall {m.get('fall_percent', float('nan')):.0f}%"
        )
        if "range_width" in m:
            info += f"  range {100 * m['range_width']:.0f}%"
        if m.get("actor_restarts"):
            info += f"  restarts {m['actor_restarts']}"
        self.bar.update(self.task, completed=m["env_steps"], info=info)
