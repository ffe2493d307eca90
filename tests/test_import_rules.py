"""The dependency rules of DESIGN.md, checked on the source (every import, also those inside
functions) and on what a fresh interpreter loads."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# The library's layers, bottom up: a module imports only from its own layer or below.
LAYERS = [
    ("paramimic.messages", "paramimic.task_space", "paramimic.motion"),
    ("paramimic.characters",),
    ("paramimic.config",),
    ("paramimic.envs",),
    ("paramimic.rl", "paramimic.curriculum"),
    ("paramimic.evaluation", "paramimic.render"),
    ("paramimic.training",),
]
# Only modules that hold networks load torch.
TORCH_MODULES = {
    "paramimic.rl.networks",
    "paramimic.rl.ppo",
    "paramimic.curriculum.marginal_value",
    "paramimic.curriculum.parameterization_net",
    "paramimic.training.trainer",  # PPO, V̄ and P_θ on torch's threads
    "paramimic.training.checkpoint",  # tensors on disk
    "paramimic.training.tracking",  # torch's SummaryWriter writes TensorBoard's events
}
# services/<kind>/ import the library and these shared modules, not each other's packages;
# the launcher and the CLI compose them.
SHARED_SERVICES = ("services.keys", "services.store", "services.media", "services.asgi")
COMPOSERS = ("services.launch", "services.cli")


def _modules(package: str) -> dict[str, set[str]]:
    """module name -> the absolute names it imports (anywhere in the file)."""
    out = {}
    for path in sorted((ROOT / package).rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        name = ".".join(p for p in rel.parts if p != "__init__")
        imports = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                imports |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                imports |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
        out[name] = imports
    return out


def _layer(name: str) -> int | None:
    for i, prefixes in enumerate(LAYERS):
        if any(name == p or name.startswith(p + ".") for p in prefixes):
            return i
    return None


def test_library_imports_point_down_only():
    wrong = []
    for module, imports in _modules("paramimic").items():
        own = _layer(module)
        for target in imports:
            other = _layer(target)
            if own is not None and other is not None and other > own:
                wrong.append(f"{module} -> {target}")
    assert not wrong, "upward imports: " + ", ".join(sorted(wrong))


def test_the_curriculum_never_builds_an_env_and_torch_stays_with_the_networks():
    modules = _modules("paramimic")
    for module, imports in modules.items():
        if module.startswith("paramimic.curriculum"):
            assert not {i for i in imports if i.startswith(("paramimic.envs", "mujoco"))}, module
        if "torch" in {i.split(".")[0] for i in imports}:
            assert module in TORCH_MODULES, f"{module} imports torch but holds no network"


def test_the_library_knows_nothing_of_the_services():
    for module, imports in _modules("paramimic").items():
        roots = {i.split(".")[0] for i in imports}
        assert not roots & {"services", "ray", "redis", "fastapi", "uvicorn"}, module


def test_services_import_each_other_only_through_the_launcher():
    wrong = []
    for module, imports in _modules("services").items():
        if module.startswith(COMPOSERS) or module in SHARED_SERVICES:
            continue
        kind = ".".join(module.split(".")[:2])  # services.learner, services.api, ...
        for target in imports:
            if target.startswith("services.") and not target.startswith((kind, *SHARED_SERVICES)):
                wrong.append(f"{module} -> {target}")
    assert not wrong, "services importing each other: " + ", ".join(sorted(wrong))


@pytest.mark.parametrize(
    "module",
    [
        "paramimic.task_space",
        "paramimic.motion.fitness",
        "paramimic.curriculum.elite_set",
        "paramimic.curriculum.density",
        "paramimic.curriculum.mcmc",
        "paramimic.curriculum.skill",
        "paramimic.config",
    ],
)
def test_pure_modules_load_neither_torch_nor_mujoco(module):
    code = (
        f"import sys, {module}; bad = {{'torch', 'mujoco'}} & set(sys.modules); assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


@pytest.mark.parametrize(
    "module", ["paramimic.rl.rollout", "services.actors.rollout_actor", "services.sampler.actor"]
)
def test_rollout_actors_and_the_sampler_load_no_torch(module):
    """Actors act with numpy weights: torch would be most of their memory."""
    code = f"import sys, {module}; assert 'torch' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)
