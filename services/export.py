"""`paramimic export`: a run's deterministic policy as one ONNX or TorchScript file with the
observation normalization folded in, and a JSON sidecar saying what goes in and comes out."""

from __future__ import annotations

import json
from pathlib import Path

import torch
from torch import nn

from paramimic.config import ExperimentConfig
from paramimic.rl.networks import ActorCritic

FORMATS = ("onnx", "torchscript")


class DeterministicPolicy(nn.Module):
    """obs [N, obs_dim] -> the policy's mean action [N, act_dim]: normalize (the run's running
    mean and std, clipped), then the policy MLP. No value net, no noise."""

    def __init__(self, policy: ActorCritic) -> None:
        super().__init__()
        self.register_buffer("obs_mean", policy.obs_mean.detach().clone())
        self.register_buffer("obs_std", policy.obs_std.detach().clone())
        self.obs_clip = float(policy.obs_clip)
        self.pi = policy.pi

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        x = ((obs - self.obs_mean) / self.obs_std).clamp(-self.obs_clip, self.obs_clip)
        return self.pi(x)


def sidecar(cfg: ExperimentConfig, policy: ActorCritic, fmt: str) -> dict:
    """What a user of the exported file needs: the observation layout, the actions (joint
    targets in [-1, 1], one per joint, at the control rate) and the task space."""
    from paramimic.characters import registration
    from paramimic.envs import env_for

    env = env_for(cfg)
    layout = env.observation_layout() if hasattr(env, "observation_layout") else None
    info = registration(cfg.character).info()
    return {
        "format": fmt,
        "input": {"name": "obs", "shape": ["batch", policy.obs_dim], "dtype": "float32"},
        "output": {"name": "action", "shape": ["batch", policy.act_dim], "dtype": "float32"},
        "observation_layout": None if layout is None else [
            {"name": n, "size": k} for n, k in layout
        ],
        "actions": {"joints": info["joints"], "low": -1.0, "high": 1.0,
                    "meaning": "PD target offsets, scaled to each joint's range"},
        "control_hz": cfg.env.control_hz,
        "character": cfg.character,
        "clip": cfg.env.clip,
        "task_space": {name: list(r) for name, r in cfg.task.items()},
        "config": cfg.model_dump(mode="json"),
    }  # fmt: skip


def export(policy: ActorCritic, cfg: ExperimentConfig, out: Path, fmt: str) -> tuple[Path, Path]:
    """Write the policy to `out` (ONNX opset 18 with a dynamic batch, or TorchScript) and the
    sidecar to `out` + '.json'; returns both paths."""
    if fmt not in FORMATS:
        raise ValueError(f"format {fmt!r}: one of {', '.join(FORMATS)}")
    module = DeterministicPolicy(policy).eval()
    example = torch.zeros(2, policy.obs_dim)
    out.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "torchscript":  # deprecated by torch in favour of torch.export, still loadable
        torch.jit.trace(module, example).save(str(out))
    else:  # needs the `export` extra (onnx, onnxscript)
        torch.onnx.export(
            module, (example,), str(out), input_names=["obs"], output_names=["action"],
            dynamic_shapes={"obs": {0: torch.export.Dim("batch")}}, opset_version=18,
            dynamo=True, external_data=False,
        )  # fmt: skip
    meta = out.with_name(out.name + ".json")
    meta.write_text(json.dumps(sidecar(cfg, policy, fmt), indent=1))
    return out, meta
