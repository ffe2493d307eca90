"""`docker-compose up` for real: the images are built (on a local Debian base made with
debootstrap, Redis from Debian's package; torch from pip's local wheel folder), the cluster
comes up with two Ray workers, a run progresses with actors on both workers, one worker is
stopped and training goes on, then everything is taken down.

Needs root and apt (it installs docker.io, docker-compose and debootstrap and starts dockerd
with --iptables=false if no engine runs, and stops what it started); skipped elsewhere.
Select it alone with `pytest -m compose`.
"""

from __future__ import annotations

import glob
import json
import os
import secrets
import shutil
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from services.launch.processes import free_port

DOCKER_TOOLS = ("dockerd", "docker-compose", "debootstrap")
pytestmark = [
    pytest.mark.compose,
    pytest.mark.skipif(
        os.geteuid() != 0 or not all(map(shutil.which, DOCKER_TOOLS)),
        reason="the compose test starts Docker as root with docker.io, docker-compose and "
        "debootstrap (`make test` installs them as root)",
    ),
]
ROOT = Path(__file__).resolve().parents[2]
COMPOSE_FILE = ROOT / "deploy" / "docker-compose.yml"
BASE = "local/debian:bookworm"
REDIS = "local/redis:compose-test"
IMAGE = "paramimic:compose-test"


def _run(*cmd: str, timeout: float = 900, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=timeout, **kw)


def _ok(*cmd: str) -> bool:
    return subprocess.run(cmd, capture_output=True).returncode == 0


@pytest.fixture(scope="module")
def engine(tmp_path_factory):
    """A running Docker engine with the local base image; what was started is stopped."""
    daemon = None
    if not _ok("docker", "info"):
        log = (tmp_path_factory.mktemp("dockerd") / "dockerd.log").open("w")
        daemon = subprocess.Popen(["dockerd", "--iptables=false"], stdout=log, stderr=log)
        deadline = time.monotonic() + 60
        while not _ok("docker", "info"):
            assert daemon.poll() is None and time.monotonic() < deadline, "dockerd did not start"
            time.sleep(1)
    _remove_stale_projects()
    try:
        if not _ok("docker", "image", "inspect", BASE):
            rootfs = tmp_path_factory.mktemp("rootfs")
            _run("debootstrap", "--variant=minbase", "bookworm", str(rootfs), timeout=900)
            tar = subprocess.Popen(["tar", "-C", str(rootfs), "-c", "."], stdout=subprocess.PIPE)
            _run("docker", "import", "-", BASE, stdin=tar.stdout)
            tar.wait()
            shutil.rmtree(rootfs, ignore_errors=True)
        yield
    finally:
        if daemon is not None:
            daemon.terminate()
            daemon.wait(timeout=60)


def _remove_stale_projects() -> None:
    """Containers and volumes of an earlier run of this test that was killed before its
    `down`: a restarted engine would bring them back (restart: unless-stopped)."""
    names = _run("docker", "ps", "-a", "--format", "{{.Names}}").stdout.split()
    for project in {n.split("_")[0] for n in names if n.startswith("pmtest")}:
        pid = project.removeprefix("pmtest")
        if pid.isdigit() and not os.path.exists(f"/proc/{pid}"):
            _run("docker", "rm", "-f", *[n for n in names if n.startswith(project + "_")])
            volumes = _run("docker", "volume", "ls", "-q").stdout.split()
            stale = [v for v in volumes if v.startswith(project + "_")]
            if stale:
                _run("docker", "volume", "rm", *stale)


def _local_build_inputs() -> None:
    """torch's CPU wheel from pip's find-links folder, and this machine's extra CA certificates
    (its TLS proxy), into the build context folders the Dockerfile reads."""
    links = os.environ.get("PIP_FIND_LINKS") or subprocess.run(
        [sys.executable, "-m", "pip", "config", "get", "global.find-links"],
        capture_output=True, text=True,
    ).stdout.strip()  # fmt: skip
    wheels = glob.glob(os.path.join(links, "torch-2.13.0*.whl"))
    assert wheels, f"no torch 2.13.0 wheel in pip's find-links folder {links!r}"
    for w in wheels:
        target = ROOT / "deploy" / "wheels" / Path(w).name
        if not target.exists():
            shutil.copy(w, target)
    for crt in glob.glob("/usr/local/share/ca-certificates/*.crt"):
        shutil.copy(crt, ROOT / "deploy" / "certs")


def _containers(project: str, service: str) -> list[str]:
    out = _run("docker", "ps", "--filter", f"label=com.docker.compose.project={project}",
               "--filter", f"label=com.docker.compose.service={service}",
               "--format", "{{.Names}}").stdout  # fmt: skip
    return sorted(out.split())


def _health(project: str) -> dict[str, str]:
    out = _run("docker", "ps", "-a", "--filter", f"label=com.docker.compose.project={project}",
               "--format", "{{.Names}}\t{{.Status}}").stdout  # fmt: skip
    return dict(line.split("\t", 1) for line in out.strip().splitlines())


def test_compose_cluster_trains_across_workers_and_survives_losing_one(engine, wait_until):
    _local_build_inputs()
    _run("docker", "build", "--network", "host", "--build-arg", f"BASE_IMAGE={BASE}",
         "-f", str(ROOT / "tests" / "deploy" / "redis.Dockerfile"), "-t", REDIS,
         str(ROOT / "tests" / "deploy"))  # fmt: skip
    project = f"pmtest{os.getpid()}"
    port = free_port("127.0.0.1")
    env = {
        **os.environ,
        "BASE_IMAGE": BASE,
        "TORCH_INDEX": "",  # torch from deploy/wheels only
        "REDIS_IMAGE": REDIS,
        "PARAMIMIC_IMAGE": IMAGE,
        "REDIS_PASSWORD": secrets.token_hex(16),
        "RAY_AUTH_TOKEN": secrets.token_hex(32),
        "RAY_WORKER_CPUS": "1",
        "API_PORT": str(port),
        "PARAMIMIC_TRAIN_ARGS": "--total-steps 100000000",
    }
    compose = ["docker-compose", "-f", str(COMPOSE_FILE), "-p", project]
    _run(*compose, "build", env=env, timeout=1200)
    try:
        _run(*compose, "up", "-d", "--scale", "ray-worker=2", env=env, timeout=600)

        def healthy() -> bool:
            h = _health(project)
            return len(h) == 6 and all("(healthy)" in s for s in h.values())

        wait_until(healthy, 300, "every service healthy")
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10.0) as api:

            def progress() -> dict:
                runs = api.get("/runs").json()
                return api.get(f"/runs/{runs[0]['run_id']}/progress").json() if runs else {}

            def events() -> list[str]:
                run = api.get("/runs").json()[0]["run_id"]
                return [e["type"] for e in api.get(f"/runs/{run}/events").json()]

            p = wait_until(lambda: (q := progress()).get("iteration", 0) >= 2 and q, 300, "a run")
            assert (p["actors"], p["nodes"]) == (2, 2), p  # actors on both workers
            victim = _containers(project, "ray-worker")[-1]
            _run("docker", "stop", victim)
            wait_until(lambda: "node_lost" in events(), 180, "the node_lost event")
            it = progress()["iteration"]
            p = wait_until(
                lambda: (q := progress())["iteration"] >= it + 2 and q, 300, "training on"
            )
            assert (p["actors"], p["nodes"], p["status"]) == (1, 1, "running"), p
        # Redis kept its data with AOF, behind the password
        redis = _containers(project, "redis")[0]
        assert "appendonlydir" in _run("docker", "exec", redis, "ls", "/data").stdout
        assert "NOAUTH" in _run("docker", "exec", redis, "redis-cli", "ping").stdout
    finally:
        logs = subprocess.run([*compose, "logs", "--tail", "30"], env=env, capture_output=True,
                              text=True).stdout  # fmt: skip
        subprocess.run([*compose, "down", "-v"], env=env, capture_output=True, timeout=300)
        print(json.dumps({"project": project}), logs[-4000:])
