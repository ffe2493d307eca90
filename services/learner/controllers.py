"""Shipped controllers: a trained run's policy as a small weights-only file, taken by name.

DeepMimic ships its trained policies beside its clips; paramimic ships the humanoid's the same
way. A controller file is a checkpoint cut down to what `paramimic play`, `render` and `eval`
read — the run's config, the policy (with its observation normalization), the marginal value
V̄ and, for an [L21] skill, its curriculum (P_θ and the elites that deal m_a) — without the
optimizer, the sampler's buffers or the learner's history. It is plain data, read with
`torch.load(weights_only=True)` like every checkpoint (`paramimic/training/checkpoint.py`), so a
planted file cannot run code. Shipped files live in `paramimic/data/controllers/NAME.pt` and
install with the package; `paramimic controllers add RUN --name NAME` writes one.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import torch

from paramimic.training import checkpoint
from paramimic.training.checkpoint import shipped as find
from paramimic.training.checkpoint import shipped_dir as directory
from paramimic.training.checkpoint import shipped_names as names

KEEP = ("config", "obs_dim", "act_dim", "marginal", "progress")

__all__ = ["add", "controller_state", "directory", "find", "names"]


def controller_state(state: dict) -> dict:
    """A checkpoint's state reduced to what playing, rendering and evaluating a policy need."""
    out = {k: state[k] for k in KEEP if k in state}
    # the normalizer's statistics too: a family warm started from the controller (`init_from`)
    # tells constant inputs from varying ones by them
    out["learner"] = {k: state["learner"][k] for k in ("policy", "normalizer")}
    if state["config"].get("env", {}).get("clip") is not None and "curriculum" in state:
        out["curriculum"] = state["curriculum"]
    return out


def add(run: Path, name: str, folder: Path | None = None) -> Path:
    """Write the latest checkpoint of `run` (or a checkpoint file) as controller `name`."""
    if not name.replace("_", "").replace("-", "").isalnum():
        raise ValueError(f"controller name {name!r}: letters, digits, '_' and '-' only")
    state = controller_state(checkpoint.load(run))
    folder = folder or directory()
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}{checkpoint.SUFFIX}"
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=checkpoint.SUFFIX)
    with os.fdopen(fd, "wb") as f:
        torch.save(checkpoint.encode(state), f)
    os.chmod(tmp, 0o644)  # mkstemp's 0600 would keep a shipped file from other users
    os.replace(tmp, path)
    checkpoint.read(path)  # it loads back as plain data
    return path
