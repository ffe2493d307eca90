"""deploy/docker-compose.yml checked statically: the services, healthchecks everywhere, Redis with
AOF and a password from the environment, Ray's token auth on, only the API published."""

from pathlib import Path

import yaml

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
COMPOSE = yaml.safe_load((DEPLOY / "docker-compose.yml").read_text())
SERVICES = COMPOSE["services"]
RAY = ("ray-head", "ray-worker", "learner")


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
    command = _command("redis")
    assert "--appendonly yes" in command and '--requirepass "$$REDIS_PASSWORD"' in command
    assert redis["environment"]["REDIS_PASSWORD"].startswith("${REDIS_PASSWORD:?")
    assert "redis-data:/data" in redis["volumes"] and "redis-data" in COMPOSE["volumes"]
    for name in ("learner", "api"):  # they reach it with the same password
        assert "redis://:$$REDIS_PASSWORD@redis:6379/0" in _command(name)


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
