"""Gaussian MLP policy, value network and running observation normalization."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from paramimic.rl.numpy_mlp import Layers, NumpyPolicy


class RunningMeanStd:
    """Mean and variance of a stream of vectors (Chan et al.'s parallel update)."""

    def __init__(self, dim: int) -> None:
        self.mean = np.zeros(dim)
        self.var = np.ones(dim)
        self.count = 0.0

    def update(self, x: np.ndarray) -> None:
        x = np.asarray(x, dtype=np.float64).reshape(-1, self.mean.shape[0])
        n = x.shape[0]
        if n == 0:
            return
        b_mean, b_var = x.mean(axis=0), x.var(axis=0)
        total = self.count + n
        delta = b_mean - self.mean
        self.mean = self.mean + delta * n / total
        m2 = self.var * self.count + b_var * n + delta**2 * self.count * n / total
        self.var = m2 / total
        self.count = total

    def state_dict(self) -> dict:
        return {"mean": self.mean.copy(), "var": self.var.copy(), "count": self.count}

    def load_state_dict(self, state: dict) -> None:
        self.mean = np.array(state["mean"], dtype=np.float64)
        self.var = np.array(state["var"], dtype=np.float64)
        self.count = float(state["count"])


def mlp(sizes: list[int], out_gain: float = 1.0) -> nn.Sequential:
    """ReLU hidden layers and a linear output ([WL19] §5), orthogonal init."""
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        lin = nn.Linear(sizes[i], sizes[i + 1])
        last = i == len(sizes) - 2
        nn.init.orthogonal_(lin.weight, gain=out_gain if last else np.sqrt(2))
        nn.init.zeros_(lin.bias)
        layers.append(lin)
        if not last:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class ActorCritic(nn.Module):
    """π(a|s) = N(μ(s), diag σ²) and V(s), both reading normalized observations.

    The normalizer's statistics are buffers, so one state_dict carries everything an actor
    needs to act.
    """

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden: tuple[int, ...],
        init_log_std: float,
        obs_clip: float = 10.0,
        obs_std_floor: float = 0.0,
        value_hidden: tuple[int, ...] | None = None,
    ) -> None:
        super().__init__()
        self.obs_dim, self.act_dim = obs_dim, act_dim
        self.register_buffer("obs_mean", torch.zeros(obs_dim))
        self.register_buffer("obs_std", torch.ones(obs_dim))
        self.obs_clip = obs_clip
        self.obs_std_floor = obs_std_floor
        self.pi = mlp([obs_dim, *hidden, act_dim], out_gain=0.01)
        self.log_std = nn.Parameter(torch.full((act_dim,), float(init_log_std)))
        self.v = mlp([obs_dim, *(hidden if value_hidden is None else value_hidden), 1], 1.0)

    def policy_parameters(self) -> list[nn.Parameter]:
        return [*self.pi.parameters(), self.log_std]

    def value_parameters(self) -> list[nn.Parameter]:
        return list(self.v.parameters())

    def set_normalizer(self, stats: RunningMeanStd) -> None:
        """Normalize by the experience's mean and std, the std at least `obs_std_floor`: an input
        that hardly varied (a part held on a stiff joint) must not turn a small change of the
        body into a large input (PPOConfig.obs_std_floor)."""
        std = np.maximum(np.sqrt(stats.var + 1e-8), self.obs_std_floor)
        self.obs_mean.copy_(torch.as_tensor(stats.mean, dtype=torch.float32))
        self.obs_std.copy_(torch.as_tensor(std, dtype=torch.float32))

    def normalize(self, obs: torch.Tensor) -> torch.Tensor:
        return ((obs - self.obs_mean) / self.obs_std).clamp(-self.obs_clip, self.obs_clip)

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(action mean [N, A], value [N]) for raw observations [N, obs_dim]."""
        x = self.normalize(obs)
        return self.pi(x), self.v(x).squeeze(-1)

    def log_prob(self, mean: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """log π(a|s) of a diagonal Gaussian, summed over action dims: [N]."""
        z = (actions - mean) / self.log_std.exp()
        return (-0.5 * z.pow(2) - self.log_std - 0.5 * np.log(2 * np.pi)).sum(-1)

    def entropy(self) -> torch.Tensor:
        return (self.log_std + 0.5 * np.log(2 * np.pi * np.e)).sum()

    @torch.no_grad()
    def act(self, obs: np.ndarray, noise: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """Actions, log-probs and values for a batch; `noise=None` acts deterministically."""
        obs_t = torch.from_numpy(np.asarray(obs, dtype=np.float32))
        mean, value = self(obs_t)
        if noise is None:
            actions = mean
        else:
            actions = mean + self.log_std.exp() * torch.from_numpy(noise.astype(np.float32))
        logp = self.log_prob(mean, actions)
        return actions.numpy(), logp.numpy(), value.numpy()

    def numpy_weights(self) -> dict[str, np.ndarray]:
        """Everything an actor needs to act, as float32 numpy arrays (no torch needed to read
        them): the networks, log σ, the normalizer and its clip."""
        state = {k: v.detach().numpy().astype(np.float32) for k, v in self.state_dict().items()}
        return state | {"obs_clip": np.float32(self.obs_clip)}

    def numpy_policy(self) -> NumpyPolicy:
        return NumpyPolicy(self.numpy_weights())

    @torch.no_grad()
    def value(self, obs: np.ndarray) -> np.ndarray:
        return self(torch.from_numpy(np.asarray(obs, dtype=np.float32)))[1].numpy()


def numpy_layers(seq: nn.Sequential) -> Layers:
    """The (W [in, out], b [out]) pairs of an mlp() as numpy arrays."""
    return [
        (m.weight.detach().numpy().T.copy(), m.bias.detach().numpy().copy())
        for m in seq
        if isinstance(m, nn.Linear)
    ]
