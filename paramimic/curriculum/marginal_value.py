"""The marginal value function V̄(a) and its running mean μ ([WL19] §4.2, Alg. 1 l.24-26).

V̄ regresses the critic's value V(s) on the task parameters a of the states it was evaluated
at, which marginalizes the rest of the state (Eq. 8, uniform density over the visited states).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from paramimic.rl.networks import mlp, numpy_layers
from paramimic.rl.numpy_mlp import Layers
from paramimic.task_space import TaskSpace


class MarginalValue:
    def __init__(
        self,
        space: TaskSpace,
        hidden: tuple[int, ...] = (64, 64),
        lr: float = 1e-3,
        mu_lr: float = 1e-3,
        batch_size: int = 128,
        seed: int = 0,
    ) -> None:
        self.space = space
        self.lr, self.mu_lr, self.batch_size = lr, mu_lr, batch_size
        gen = torch.Generator().manual_seed(seed)
        with torch.random.fork_rng():
            torch.manual_seed(int(torch.randint(0, 2**31 - 1, (1,), generator=gen)))
            self.net: nn.Sequential = mlp([space.dim, *hidden, 1])
        self.opt = torch.optim.Adam(self.net.parameters(), lr=lr)
        self.mu: float | None = None  # set from the first batch, then updated as Alg. 1 l.26
        self.rng = np.random.default_rng(seed)
        self.fitted = False
        self.skipped = 0  # minibatches with a non-finite loss or value, never applied

    def _scaled(self, a: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(self.space.scaled(a), dtype=torch.float32)

    def layers(self) -> Layers:
        """The network's weights as numpy (W, b) pairs, for `adaptive.marginal_function`."""
        return numpy_layers(self.net)

    def predict(self, a: np.ndarray) -> np.ndarray:
        """V̄(a) for a batch [n, d] -> [n]."""
        with torch.no_grad():
            return self.net(self._scaled(np.atleast_2d(a))).squeeze(-1).numpy().astype(np.float64)

    def fit(self, tasks: np.ndarray, values: np.ndarray, steps: int) -> float:
        """`steps` minibatch updates on (a, v) pairs: Alg. 1 l.24-26. Returns the last loss."""
        tasks = np.asarray(tasks, dtype=np.float64)
        values = np.asarray(values, dtype=np.float64)
        if self.mu is None:
            # start μ and V̄'s output at the first batch's mean value, so that V̄ learns the
            # differences between tasks rather than spending its first updates on the offset
            self.mu = float(values.mean())
            with torch.no_grad():
                self.net[-1].bias.fill_(self.mu)
        loss_value = float("nan")
        for _ in range(steps):
            idx = self.rng.integers(0, len(values), size=min(self.batch_size, len(values)))
            v = torch.as_tensor(values[idx], dtype=torch.float32)
            pred = self.net(self._scaled(tasks[idx])).squeeze(-1)
            loss = 0.5 * (pred - v).pow(2).mean()  # l.25: θ ← θ − α (1/n) Σ (V̄(a) − v) ∇V̄
            if not torch.isfinite(loss) or not np.isfinite(values[idx]).all():
                self.skipped += 1  # a non-finite batch never reaches V̄ or μ
                continue
            self.opt.zero_grad()
            loss.backward()
            self.opt.step()
            self.mu -= self.mu_lr * float(self.mu - values[idx].mean())  # l.26
            loss_value = loss.item()
        self.fitted = True
        return loss_value

    def to_state(self) -> dict:
        return {
            "net": {k: v.detach().numpy().copy() for k, v in self.net.state_dict().items()},
            "opt": self.opt.state_dict(),
            "mu": self.mu,
            "rng": self.rng.bit_generator.state,
            "fitted": self.fitted,
        }

    def from_state(self, state: dict) -> None:
        self.net.load_state_dict({k: torch.as_tensor(v) for k, v in state["net"].items()})
        self.opt.load_state_dict(state["opt"])
        self.mu = state["mu"]
        self.rng.bit_generator.state = state["rng"]
        self.fitted = bool(state["fitted"])
