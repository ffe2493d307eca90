"""deploy/docker-compose.yml checked statically: the services, healthchecks everywhere, Redis with
AOF and a password from the environment, Ray's token auth on, only the API published."""

import subprocess
import sys
from pathlib import Path

import yaml

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
COMPOSE = yaml.safe_load((DEPLOY / "docker-compose.yml").read_text())
SERVICES = COMPOSE["services"]
RAY = ("ray-head", "ray-worker", "learner")


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "services.cli", *map(str, args)],
        capture_output=True, text=True, timeout=120, env={"PATH": "/usr/bin:/bin"},
        cwd=DEPLOY.parent,
    )  # fmt: skip


def _command(name: str) -> str:
    command = SERVICES[name]["command"]
    return " ".join(command) if isinstance(command, list) else command


def test_the_services():
    assert set(SERVICES) == {"redis", "ray-head", "ray-worker", "learner", "api"}
    assert "version" not in COMPOSE  # compose-spec: no version key


def test_every_service_has_a_healthcheck_and_waits_for_healthy_dependencies():
    for name, service in SERVICES.items():
        assert service["healthcheck"]["test"], name
        for dep, how in service.get("depends_on", {}).items():
            assert how == {"condition": "service_healthy"}, (name, dep)
    assert set(SERVICES["learner"]["depends_on"]) == {"redis", "ray-head"}
    assert set(SERVICES["ray-worker"]["depends_on"]) == {"ray-head"}


def test_redis_has_aof_a_password_from_the_environment_and_a_volume():
    redis = SERVICES["redis"]
    assert redis["image"] == "${REDIS_IMAGE:-redis:7}"
    assert redis["user"] == "redis"  # not root
    command = _command("redis")
    assert "--appendonly yes" in command and "exec redis-server /tmp/redis.conf" in command
    assert "requirepass" in command and "umask 077" in command  # in a 0600 file, not argv
    assert redis["environment"]["REDIS_PASSWORD"].startswith("${REDIS_PASSWORD:?")
    assert "redis-data:/data" in redis["volumes"] and "redis-data" in COMPOSE["volumes"]
    for name in ("learner", "api"):  # they reach it with the same password, from the env
        env = SERVICES[name]["environment"]
        assert env["REDIS_URL"] == "redis://redis:6379/0"
        assert env["REDIS_PASSWORD"] == "${REDIS_PASSWORD}"


def test_no_secret_is_ever_interpolated_into_a_command_line():
    for name in SERVICES:
        command = _command(name)
        for secret in ("REDIS_PASSWORD", "RAY_AUTH_TOKEN", "PARAMIMIC_API_TOKEN"):
            assert "${" + secret not in command.replace("$${", ""), (name, secret)
            assert f":${secret}@" not in command, (name, secret)


def test_placeholder_secrets_are_refused_before_anything_starts(tmp_path):
    """The services run `paramimic deploy-check`; Redis checks its own password in sh."""
    for name, need in (
        ("ray-head", "RAY_AUTH_TOKEN"),
        ("learner", None),
        ("api", "REDIS_PASSWORD"),
    ):
        command = _command(name)
        assert command.split("&&")[0].strip().startswith("sh -c paramimic deploy-check"), name
        if need:
            assert f"--need {need}" in command, name
    res = _cli("deploy-check", DEPLOY / ".env.example")
    assert res.returncode == 2
    assert "REDIS_PASSWORD is the placeholder 'change-me'" in res.stdout
    assert "RAY_AUTH_TOKEN is the placeholder" in res.stdout
    env = tmp_path / ".env"
    env.write_text("REDIS_PASSWORD=short\nRAY_AUTH_TOKEN=" + "a" * 32 + "\n")
    res = _cli("deploy-check", env)
    assert res.returncode == 2 and "REDIS_PASSWORD is 5 characters" in res.stdout
    env.write_text("REDIS_PASSWORD=" + "b" * 24 + "\nRAY_AUTH_TOKEN=" + "a" * 32 + "\n")
    res = _cli("deploy-check", env)  # long, and no secret
    assert res.returncode == 2 and "REDIS_PASSWORD has 1 distinct characters" in res.stdout
    env.write_text("REDIS_PASSWORD=Zq3vR8kLmW2xT5yB9nC4\nRAY_AUTH_TOKEN=a1b2c3d4e5f6a7b8c9d0e1f2\n")
    assert _cli("deploy-check", env).returncode == 0
    # the Redis container's own check, run by a real sh
    script = SERVICES["redis"]["command"][2].replace("$$", "$")
    for bad in ("change-me", "short"):
        res = subprocess.run(["sh", "-c", script], env={"REDIS_PASSWORD": bad, "PATH": "/bin"},
                             capture_output=True, text=True, timeout=10)  # fmt: skip
        assert res.returncode == 78 and "refusing" in res.stderr, bad


def test_healthchecks_test_the_service_and_the_learner_gets_time_to_checkpoint():
    for name, service in SERVICES.items():
        test = " ".join(service["healthcheck"]["test"])
        assert "pgrep -f" not in test, name  # it would match the healthcheck's own shell
    assert "redis-cli ping" in " ".join(SERVICES["redis"]["healthcheck"]["test"])
    assert "/health" in " ".join(SERVICES["api"]["healthcheck"]["test"])
    assert "ray health-check" in " ".join(SERVICES["ray-head"]["healthcheck"]["test"])
    learner = " ".join(SERVICES["learner"]["healthcheck"]["test"])
    assert "paramimic health /runs/$$RUN_NAME" in learner
    grace = SERVICES["learner"]["stop_grace_period"]
    assert grace.endswith("s") and int(grace[:-1]) >= 60


def test_only_the_api_is_published_and_on_loopback_by_default():
    published = {name for name, s in SERVICES.items() if s.get("ports")}
    assert published == {"api"}
    assert SERVICES["api"]["ports"] == ["${API_BIND:-127.0.0.1}:${API_PORT:-8000}:8000"]
    assert "--include-dashboard=$${RAY_DASHBOARD:-false}" in _command("ray-head")


def test_ray_token_auth_is_on_for_every_ray_process():
    for name in RAY:
        env = SERVICES[name]["environment"]
        assert env["RAY_AUTH_MODE"] == "token", name
        assert env["RAY_AUTH_TOKEN"].startswith("${RAY_AUTH_TOKEN:?"), name


def test_workers_join_the_head_and_the_learner_resumes_after_a_failure():
    assert "ray start --head" in _command("ray-head") and "--block" in _command("ray-head")
    assert "ray start --address=ray-head:6379" in _command("ray-worker")
    learner = _command("learner")
    assert "paramimic train" in learner and "--resume-if-exists" in learner
    assert "--ray-address ray-head:6379" in learner
    assert SERVICES["learner"]["restart"] == "on-failure"
    assert "runs:/runs" in SERVICES["learner"]["volumes"]


def test_the_env_example_names_every_variable_the_compose_file_requires():
    example = (DEPLOY / ".env.example").read_text()
    for var in ("REDIS_PASSWORD", "RAY_AUTH_TOKEN", "REDIS_IMAGE", "BASE_IMAGE", "TORCH_INDEX"):
        assert f"\n{var}=" in example, var
