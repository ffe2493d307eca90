"""`paramimic train` as a user runs it: embedded Redis, local Ray, the sampler, the actors, the
learner and the API from one command; pause/resume/k over the API; `paramimic status`; and
nothing left running after it exits, normally or by Ctrl-C."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
import time

import httpx
import psutil
import pytest
import redis
import yaml
from conftest import compose_learner_health, holds, wait_until

from services.keys import RunKeys
from services.launch.redis_server import EmbeddedRedis

TOKEN = "launch-test-token"
TINY = {
    "name": "tiny",
    "character": "hopper",
    "task": {"leg_length": [0.8, 1.2], "torso_length": [0.9, 1.1], "target_velocity": [1, 1]},
    "env": {"max_episode_seconds": 1.0},
    "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 2},
    "curriculum": {"p_mcmc": 1, "n_mcmc": 100},
    "actors": {"num_actors": 2, "num_envs": 4},
    "train": {"total_steps": 10**9, "checkpoint_every": 2},
}


class Launch:
    """`paramimic train` in a subprocess; its output and every descendant process it had."""

    def __init__(self, tmp_path, *args, extra_env: dict | None = None, **train):
        cfg = tmp_path / "tiny.yaml"
        cfg.write_text(yaml.safe_dump({**TINY, "train": {**TINY["train"], **train}}))
        self.run_dir = tmp_path / "run"
        env = os.environ | {"PARAMIMIC_API_TOKEN": TOKEN, "COLUMNS": "200", "RAY_ADDRESS": ""}
        env |= extra_env or {}
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "services.cli",
                "train",
                cfg,
                "--run-dir",
                self.run_dir,
                "--api-port",
                "0",
                *args,
            ],  # fmt: skip
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
        )
        self.lines: list[str] = []
        self.descendants: dict[psutil.Process, str] = {}  # process -> name when seen
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.watcher = threading.Thread(target=self._watch, daemon=True)
        self.reader.start()
        self.watcher.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line)

    def _watch(self) -> None:
        me = psutil.Process(self.proc.pid)
        while self.proc.poll() is None:
            try:
                for p in me.children(recursive=True):
                    # the latest name: a child seen between fork and exec is still "python"
                    with contextlib.suppress(psutil.NoSuchProcess):
                        self.descendants[p] = p.name()
            except psutil.NoSuchProcess:
                continue
            time.sleep(0.1)

    def output(self) -> str:
        return "".join(self.lines)

    def api_url(self, timeout=180.0) -> str:
        def printed():
            assert self.proc.poll() is None, self.output()
            return re.search(r"API: (http://127\.0\.0\.1:\d+)", self.output())

        return wait_until(printed, timeout, "the API URL in the output", 0.1).group(1)

    def wait(self, timeout=300.0) -> int:
        """The exit code, once the output is read to its end and the watcher has stopped."""
        code = self.proc.wait(timeout)
        self.reader.join(30)
        self.watcher.join(30)
        return code

    def leftovers(self, timeout=30.0) -> list[str]:
        """Descendants still alive `timeout` s after the exit (Ray reaps its own)."""
        with contextlib.suppress(AssertionError):
            wait_until(lambda: not any(_alive(p) for p in self.descendants), timeout, "", 0.5)
        return [self.descendants[p] for p in self.descendants if _alive(p)]


def _alive(p: psutil.Process) -> bool:
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def _assert_locked_down(launch: Launch) -> None:
    """The embedded Redis wants its per-launch password, the local Ray its token, and
    neither secret is on any command line of what the launcher started."""
    conf = (launch.run_dir / "redis" / "redis.conf").read_text()
    password = re.search(r'requirepass "(.+)"', conf).group(1)
    port = int(re.search(r"^port (\d+)", conf, re.M).group(1))
    assert len(password) >= 24
    assert (launch.run_dir / "redis").stat().st_mode & 0o077 == 0
    stranger = redis.Redis(host="127.0.0.1", port=port, socket_connect_timeout=3)
    with pytest.raises(redis.exceptions.RedisError, match="(?i)auth"):
        stranger.ping()
    assert redis.Redis(host="127.0.0.1", port=port, password=password).ping()
    gcs_process = wait_until(lambda: _gcs_process(launch), 60, "the GCS process")
    gcs_env = gcs_process.environ()  # what the launcher gave Ray (after its own start)
    token = gcs_env["RAY_AUTH_TOKEN"]
    assert gcs_env["RAY_AUTH_MODE"] == "token" and len(token) >= 32
    # -ww: full command lines whatever the terminal width (CI sets 80 columns, which cut a
    # secret at the end of a long line out of sight, and gcs_server's own path with it)
    args = subprocess.run(["ps", "-eww", "-o", "args"], capture_output=True, text=True).stdout
    assert "gcs_server" in args and "redis-server" in args
    assert password not in args and token not in args
    # a Ray client without the token is refused by the run's GCS
    gcs = _gcs_address(gcs_process)
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_AUTH")}
    code = f"import ray; ray.init(address={gcs!r}); print('CONNECTED')"
    res = subprocess.run(
        [sys.executable, "-c", code],
        env=env | {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": "not-the-token"},
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert res.returncode != 0 and "CONNECTED" not in res.stdout


def _gcs_process(launch: Launch) -> psutil.Process | None:
    for p in list(launch.descendants):
        with contextlib.suppress(psutil.NoSuchProcess):
            if p.name() == "gcs_server":
                return p
    return None


def _gcs_address(gcs: psutil.Process) -> str:
    """The GCS address its raylet was given, checked to be one this GCS listens on."""
    raylet = next(p for p in gcs.parent().children() if p.name() == "raylet")
    address = next(a.split("=", 1)[1] for a in raylet.cmdline() if a.startswith("--gcs-address="))
    listening = {c.laddr.port for c in gcs.net_connections("tcp") if c.status == "LISTEN"}
    assert int(address.rsplit(":", 1)[1]) in listening, (address, listening)
    return address


def _stored_run(run_dir):
    """The run as the embedded Redis persisted it (its AOF), read by a new server."""
    with EmbeddedRedis(run_dir / "redis") as server:
        client = redis.Redis.from_url(server.url, decode_responses=True)
        run_id = (run_dir / "run_id").read_text().strip()
        keys = RunKeys(run_id)
        meta, n_history = client.hgetall(keys.meta), client.zcard(keys.history)
        client.close()
    return meta, n_history


def test_one_command_run_with_api_control_stopped_by_sigterm(tmp_path):
    launch = Launch(tmp_path)
    try:
        url = launch.api_url()
        c = httpx.Client(base_url=url, timeout=10.0)
        auth = {"Authorization": f"Bearer {TOKEN}"}
        [summary] = c.get("/runs").json()
        run = summary["run_id"]
        assert summary["status"] == "running" and summary["name"] == "tiny"
        progress = wait_until(
            lambda: (p := c.get(f"/runs/{run}/progress").json())["iteration"] >= 3 and p,
            180, "3 iterations",
        )  # fmt: skip
        assert progress["env_steps"] >= 3 * 256 and progress["steps_per_second"] > 0
        history = c.get(f"/runs/{run}/history").json()["items"]
        assert [h["iteration"] for h in history][:3] == [1, 2, 3]
        cur = c.get(f"/runs/{run}/curriculum").json()
        assert cur["mode"] == "adaptive" and cur["episodes"] > 0 and cur["refills"] >= 1
        grid = c.get(f"/runs/{run}/curriculum/marginal-value").json()
        assert grid["available"] and len(grid["values"]) == 21
        sources = {b["source"] for b in c.get(f"/runs/{run}/curriculum/samples").json()}
        assert sources == {"actor0", "actor1"}  # the rollout actors ask the sampler
        kinds = {e["type"] for e in c.get(f"/runs/{run}/events").json()}
        assert {"run_started", "sampler_started", "checkpoint"} <= kinds
        _assert_locked_down(launch)

        # pause: the learner holds before its next iteration
        assert c.post(f"/runs/{run}/pause", headers=auth).status_code == 202
        wait_until(
            lambda: c.get(f"/runs/{run}/progress").json()["status"] == "paused", 180, "paused"
        )
        held = c.get(f"/runs/{run}/progress").json()["iteration"]
        holds(lambda: c.get(f"/runs/{run}/progress").json()["iteration"] == held, 2.0, "pause")
        # a paused learner is alive to its healthcheck (the compose file's own command): it
        # owns the run and keeps moving
        health = compose_learner_health(launch.run_dir, max_age=30)
        assert health.returncode == 0, health.stdout + health.stderr
        # k is applied while paused; resume goes on
        assert c.put(f"/runs/{run}/curriculum/k", json={"k": 0}, headers=auth).status_code == 202
        wait_until(
            lambda: c.get(f"/runs/{run}/curriculum").json()["mode"] == "uniform", 180, "k = 0"
        )
        assert c.post(f"/runs/{run}/resume", headers=auth).status_code == 202
        wait_until(
            lambda: c.get(f"/runs/{run}/progress").json()["iteration"] > held, 180,
            "training to go on",
        )  # fmt: skip
        kinds = [e["type"] for e in c.get(f"/runs/{run}/events?limit=1000").json()]
        for kind in ("run_paused", "k_changed", "run_running"):
            assert kind in kinds

        status = subprocess.run(
            [sys.executable, "-m", "services.cli", "status", "--api", url],
            capture_output=True, text=True, timeout=60, env=os.environ | {"COLUMNS": "200"},
        )  # fmt: skip
        assert status.returncode == 0, status.stdout + status.stderr
        assert run in status.stdout and "curriculum.mode" in status.stdout
        assert "uniform" in status.stdout

        # SIGTERM (what `kill`, `docker stop` and systemd send) stops as Ctrl-C does: the
        # iteration finishes and is checkpointed (ray.init had put sys.exit in its place)
        launch.proc.send_signal(signal.SIGTERM)
        assert launch.wait() == 0, launch.output()
        assert "stopping after this iteration" in launch.output()
    finally:
        if launch.proc.poll() is None:
            launch.proc.kill()
    assert (launch.run_dir / "checkpoints" / "latest.pt").is_file()
    names = set(launch.descendants.values())
    assert {"redis-server", "raylet", "gcs_server"} <= names, names  # what was started
    assert launch.leftovers() == []
    try:
        httpx.get(f"{url}/health", timeout=2.0)
        raise AssertionError("the API still answers")
    except httpx.ConnectError:
        pass
    meta, n_history = _stored_run(launch.run_dir)
    assert meta["status"] == "stopped" and n_history >= 4


def test_a_run_that_ends_stops_everything_it_started_and_resumes(tmp_path):
    launch = Launch(tmp_path, total_steps=768)
    assert launch.wait() == 0, launch.output()
    assert "API: http://127.0.0.1:" in launch.output()
    assert "redis-server" in launch.descendants.values()
    assert launch.leftovers() == []
    meta, n_history = _stored_run(launch.run_dir)
    assert meta["status"] == "finished" and n_history == 3
    run_id = (launch.run_dir / "run_id").read_text()
    # --resume: the same run id, its Redis state reloaded from the AOF, one more iteration
    again = Launch(tmp_path, "--resume", "--total-steps", "1024", total_steps=768)
    assert again.wait() == 0, again.output()
    assert "resumed at iteration 3" in again.output()
    assert (launch.run_dir / "run_id").read_text() == run_id
    assert again.leftovers() == []
    meta, n_history = _stored_run(launch.run_dir)
    assert meta["status"] == "finished" and n_history == 4


def test_a_busy_api_port_fails_before_anything_starts(tmp_path):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        cfg = tmp_path / "tiny.yaml"
        cfg.write_text(yaml.safe_dump(TINY))
        res = subprocess.run(
            [sys.executable, "-m", "services.cli", "train", cfg, "--run-dir", tmp_path / "run",
             "--api-port", str(port)],  # fmt: skip
            capture_output=True, text=True, timeout=120, env=os.environ | {"COLUMNS": "200"},
        )  # fmt: skip
    assert res.returncode == 2
    assert f"127.0.0.1:{port} is in use" in res.stdout
    assert not (tmp_path / "run").exists()


def test_an_external_redis_with_a_password_is_used_and_left_running(tmp_path):
    with EmbeddedRedis(tmp_path / "external", password="pa55word") as server:
        launch = Launch(tmp_path, "--redis-url", server.url, "--no-api", total_steps=512)
        assert launch.wait() == 0, launch.output()
        assert "Redis: embedded" not in launch.output()
        assert not (launch.run_dir / "redis").exists()  # no server of its own
        client = redis.Redis.from_url(server.url, decode_responses=True)
        run_id = (launch.run_dir / "run_id").read_text().strip()
        assert client.hget(RunKeys(run_id).meta, "status") == "finished"  # still up, has the run
        assert client.zcard(RunKeys(run_id).history) == 2
        with pytest.raises(redis.AuthenticationError):
            redis.Redis(port=server.port).get("x")  # the password is required
        assert launch.leftovers() == []
        # a wrong password fails at once, before anything starts, without echoing it
        wrong = server.url.replace("pa55word", "wrong")
        res = subprocess.run(
            [sys.executable, "-m", "services.cli", "train", tmp_path / "tiny.yaml",
             "--run-dir", tmp_path / "other", "--redis-url", wrong, "--api-port", "0"],  # fmt: skip
            capture_output=True, text=True, timeout=60, env=os.environ | {"COLUMNS": "200"},
        )  # fmt: skip
        assert res.returncode == 2 and "cannot use Redis at redis://:***@" in res.stdout
        assert "wrong" not in res.stdout and not (tmp_path / "other").exists()


def test_a_run_has_one_owner_and_a_killed_launcher_takes_its_children(
    tmp_path, api_url, redis_server
):
    """A second learner on the run dir is refused; SIGKILL of the launcher takes
    the embedded Redis and the API with it (PDEATHSIG), so --resume starts cleanly; a learner
    that stops renewing its lease shows as `stale`."""
    launch = Launch(tmp_path)
    try:
        url = launch.api_url()
        wait_until(lambda: (launch.run_dir / "checkpoints" / "latest.pt").exists(), 180, "ckpt")
        second = Launch(tmp_path, "--resume")
        assert second.wait(120) == 2, second.output()
        assert "in use by another learner" in second.output()
        children = {
            p: name
            for p, name in list(launch.descendants.items())
            if name == "redis-server" or "services.cli api" in " ".join(_cmdline(p))
        }
        assert "redis-server" in children.values() and len(children) == 2, children
        launch.proc.kill()
        launch.proc.wait(30)
        wait_until(lambda: not any(_alive(p) for p in children), 15, "Redis and API to exit")
        # and everything else it started, Ray's agents included (the reaper sees to them)
        left = lambda: [n for p, n in launch.descendants.items() if _alive(p)]  # noqa: E731
        wait_until(lambda: not left(), 45, "every process the launcher started to exit")
        with pytest.raises(httpx.ConnectError):
            httpx.get(f"{url}/health", timeout=2.0)
    finally:
        if launch.proc.poll() is None:
            launch.proc.kill()
    again = Launch(tmp_path, "--resume", "--no-api", "--total-steps", "1024")
    assert again.wait() == 0, again.output()
    assert "resumed at iteration" in again.output()
    assert again.leftovers() == []

    # the lease: a learner killed with SIGKILL stops renewing it and its run turns stale
    code = (
        "import os, sys, signal; from paramimic.config import ExperimentConfig;"
        "from services.learner.reporter import RunReporter;"
        "r = RunReporter(sys.argv[1], 'lease-run'); r.acquire(lease_seconds=2);"
        "r.start(ExperimentConfig.model_validate({'character': 'hopper'}), __import__('pathlib')"
        ".Path('.'), 10, None); print('owned', flush=True); os.kill(os.getpid(), signal.SIGKILL)"
    )
    res = subprocess.run(
        [sys.executable, "-c", code, redis_server.url], capture_output=True, text=True
    )
    assert "owned" in res.stdout, res.stderr
    wait_until(
        lambda: httpx.get(f"{api_url}/runs/lease-run/progress").json()["status"] == "stale",
        30, "the killed learner's run to show as stale",
    )  # fmt: skip


def test_a_laptop_runs_redis_killed_is_restarted_by_the_launcher_and_training_goes_on(tmp_path):
    """SIGKILL of the embedded Redis: the launcher (not a test or a benchmark) starts it again
    on its port and AOF within seconds, the learner keeps its lease, and training goes on."""
    launch = Launch(tmp_path, "--no-api")
    log = launch.run_dir / "metrics.jsonl"
    rows = lambda: len(log.read_text().splitlines()) if log.exists() else 0  # noqa: E731
    try:
        wait_until(lambda: rows() >= 3, 180, "3 iterations")
        [server] = [p for p, name in launch.descendants.items()
                    if name == "redis-server" and _alive(p)]  # fmt: skip
        server.kill()
        wait_until(lambda: "restarted on its port" in launch.output(), 30, "the restart")
        done = rows()
        wait_until(lambda: rows() >= done + 3, 120, "3 more iterations")
        assert launch.proc.poll() is None, launch.output()
        assert "lease lost" not in launch.output()
        restarted = [p for p, name in launch.descendants.items()
                     if name == "redis-server" and _alive(p)]  # fmt: skip
        assert len(restarted) == 1 and restarted[0].pid != server.pid
        launch.proc.send_signal(signal.SIGINT)
        assert launch.wait(120) == 0, launch.output()
    finally:
        if launch.proc.poll() is None:
            launch.proc.kill()
    assert launch.leftovers() == []


def test_a_second_learner_of_the_same_run_id_is_refused_by_the_redis_lease(tmp_path, redis_server):
    """Two run directories (two machines' disks, so no shared file lock) of one run id on one
    Redis: the second learner is refused by the lease before it writes anything, and the
    first trains on."""
    import shutil

    here = {"REDIS_URL": redis_server.url}
    (tmp_path / "a").mkdir()
    first = Launch(tmp_path / "a", "--no-api", extra_env=here)
    try:
        ckpt = first.run_dir / "checkpoints" / "latest.pt"
        wait_until(lambda: ckpt.exists() or first.proc.poll() is not None, 180, "a checkpoint")
        assert first.proc.poll() is None, first.output()
        run_id = (first.run_dir / "run_id").read_text().strip()
        client = redis.Redis.from_url(redis_server.url, decode_responses=True)
        keys = RunKeys(run_id)
        owner = client.get(keys.lease)
        assert owner
        (tmp_path / "b").mkdir()
        copy = tmp_path / "b" / "run"
        shutil.copytree(first.run_dir, copy, ignore=shutil.ignore_patterns(".lock", "heartbeat"))
        before = client.hgetall(keys.meta)
        files = {p: p.read_bytes() for p in copy.rglob("*") if p.is_file()}
        second = Launch(tmp_path / "b", "--resume", "--no-api", extra_env=here)
        assert second.wait(120) == 2, second.output()
        assert f"run {run_id} is being trained by another learner" in second.output()
        assert client.get(keys.lease) == owner  # still the first's
        meta = client.hgetall(keys.meta)
        assert meta.get("status") == before.get("status") == "running"
        # nothing written into its run directory: no row, no checkpoint
        assert {p: p.read_bytes() for p in files} == files
        assert not list((copy / "checkpoints").glob("ckpt_*.pt")) or set(
            (copy / "checkpoints").glob("ckpt_*.pt")
        ) <= set(files)
        it = int(client.hget(keys.progress, "iteration"))
        wait_until(lambda: int(client.hget(keys.progress, "iteration")) > it, 120,
                   "the first learner to train on")  # fmt: skip
    finally:
        first.proc.kill()
        first.proc.wait(30)


def _cmdline(p: psutil.Process) -> list[str]:
    try:
        return p.cmdline()
    except psutil.NoSuchProcess:
        return []
