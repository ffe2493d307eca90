"""The parameterization MLP P_θ of [L21] §5.2: a ↦ {(d_t, τ_t) | t = 0..T} (Eq. 11), a
regression on the elite episodes' traces minimizing Σ_t ‖d_t − d*_t‖² + (τ_t − τ*_t)² (Eq. 12)."""

from __future__ import annotations

import numpy as np
import torch

from paramimic.rl.networks import mlp, numpy_layers
from paramimic.task_space import TaskSpace


class ParameterizationNet:
    def __init__(
        self,
        space: TaskSpace,
        trace_shape: tuple[int, int],  # (T + 1, D + 1): per step, displacement d_t and τ_t
        hidden: tuple[int, ...] = (256, 256),
        lr: float = 1e-3,
        batch_size: int = 64,
        seed: int = 0,
    ) -> None:
        self.space, self.trace_shape, self.batch_size = space, tuple(trace_shape), batch_size
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            self.net = mlp([space.dim, *hidden, int(np.prod(trace_shape))])
        self.opt = torch.optim.Adam(self.net.parameters(), lr=lr)
        self.rng = np.random.default_rng(seed)
        self.version = 0  # bumped by every fit, so that actors know which P_θ they hold
        self.loss: float | None = None
        self.skipped = 0  # minibatches with a non-finite loss, never applied

    def predict(self, a: np.ndarray) -> np.ndarray:
        """P_θ(a) for a batch [n, d] -> traces [n, T + 1, D + 1]."""
        x = torch.as_tensor(self.space.scaled(a), dtype=torch.float32)
        with torch.no_grad():
            return self.net(x).numpy().reshape(-1, *self.trace_shape).astype(np.float64)

    def fit(self, params: np.ndarray, traces: np.ndarray, steps: int) -> float:
        """`steps` minibatch updates of Eq. 12 on elite (a, trace) pairs; returns the mean loss
        per trace of the last one."""
        x_all = torch.as_tensor(self.space.scaled(params), dtype=torch.float32)
        y_all = torch.tensor(np.asarray(traces, np.float32).reshape(len(params), -1))
        for _ in range(steps):
            idx = self.rng.integers(0, len(params), size=min(self.batch_size, len(params)))
            loss = (self.net(x_all[idx]) - y_all[idx]).pow(2).sum(dim=1).mean()  # Eq. 12
            if not torch.isfinite(loss):
                self.skipped += 1  # a non-finite elite trace never reaches P_θ
                continue
            self.opt.zero_grad()
            loss.backward()
            self.opt.step()
            self.loss = loss.item()
        self.version += 1
        return float("nan") if self.loss is None else float(self.loss)

    @property
    def mse(self) -> float | None:
        """The last fit's loss per trace entry (the bootstrap's threshold is on this)."""
        return None if self.loss is None else self.loss / int(np.prod(self.trace_shape))

    def layers(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(W, b) per layer as numpy, for `numpy_forward` where torch is not wanted."""
        return numpy_layers(self.net)

    def to_state(self) -> dict:
        return {
            "net": {k: v.detach().numpy().copy() for k, v in self.net.state_dict().items()},
            "opt": self.opt.state_dict(),
            "rng": self.rng.bit_generator.state,
            "version": self.version,
            "loss": self.loss,
        }

    def from_state(self, state: dict) -> None:
        self.net.load_state_dict({k: torch.as_tensor(v) for k, v in state["net"].items()})
        self.opt.load_state_dict(state["opt"])
        self.rng.bit_generator.state = state["rng"]
        self.version, self.loss = int(state["version"]), state["loss"]
