"""MLPs as plain numpy layers: what the sampler and the rollout workers run without torch.

`Layers` are the (W [in, out], b [out]) pairs exported from a torch `mlp()`; they travel between
processes as lists and come back as float32 arrays through `float32_layers`. `NumpyPolicy` is the
actor-critic of `paramimic.rl.networks` rebuilt from its numpy weights: a rollout worker acts
without importing torch (which would be most of its memory).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

Layers = list[tuple[np.ndarray, np.ndarray]]


def float32_layers(layers: Iterable) -> Layers:
    """(W, b) pairs of any array-likes (lists from JSON or Ray) as float32 arrays."""
    return [(np.asarray(w, np.float32), np.asarray(b, np.float32)) for w, b in layers]


def numpy_forward(layers: Layers, x: np.ndarray) -> np.ndarray:
    """mlp() forward in numpy with ReLU between layers: x [n, in] -> [n, out]."""
    last = len(layers) - 1
    for i, (w, b) in enumerate(layers):
        x = x @ w + b
        if i < last:
            np.maximum(x, 0.0, out=x)  # ReLU
    return x


def layers_from_state(state: Mapping[str, np.ndarray], prefix: str) -> Layers:
    """The (W [in, out], b [out]) pairs of a torch `mlp()` named `prefix` in a state dict
    (keys `prefix.<i>.weight` [out, in] and `prefix.<i>.bias`), in layer order."""
    indices = sorted(
        {int(k.split(".")[1]) for k in state if k.startswith(prefix + ".") and k.endswith("weight")}
    )
    return [
        (
            np.ascontiguousarray(np.asarray(state[f"{prefix}.{i}.weight"], np.float32).T),
            np.asarray(state[f"{prefix}.{i}.bias"], np.float32).copy(),
        )
        for i in indices
    ]


class NumpyPolicy:
    """The Gaussian policy and value of an ActorCritic from its numpy weights
    (`ActorCritic.numpy_weights`): the same function without torch's per-op overhead, which
    dominates for the small batches a rollout worker steps (M envs)."""

    def __init__(self, weights: Mapping[str, np.ndarray]) -> None:
        self.obs_mean = np.asarray(weights["obs_mean"], np.float32)
        self.obs_std = np.asarray(weights["obs_std"], np.float32)
        self.obs_clip = np.float32(weights.get("obs_clip", 10.0))
        self.pi = layers_from_state(weights, "pi")
        self.v = layers_from_state(weights, "v")
        self.log_std = np.asarray(weights["log_std"], np.float32)
        self.std = np.exp(self.log_std)
        self.act_dim = len(self.log_std)
        self._logp_const = np.float32(-self.log_std.sum() - 0.5 * np.log(2 * np.pi) * self.act_dim)

    def _normalize(self, obs: np.ndarray) -> np.ndarray:
        x = (np.asarray(obs, dtype=np.float32) - self.obs_mean) / self.obs_std
        return np.clip(x, -self.obs_clip, self.obs_clip, out=x)

    def act(self, obs: np.ndarray, noise: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """Actions, log-probs and values for a batch; `noise=None` acts deterministically."""
        x = self._normalize(obs)
        mean = numpy_forward(self.pi, x)
        value = numpy_forward(self.v, x)[:, 0]
        if noise is None:
            return mean, np.full(len(x), self._logp_const, np.float32), value
        noise = noise.astype(np.float32)
        actions = mean + self.std * noise
        logp = -0.5 * np.square(noise).sum(axis=-1) + self._logp_const  # z = noise
        return actions, logp.astype(np.float32), value

    def value(self, obs: np.ndarray) -> np.ndarray:
        return numpy_forward(self.v, self._normalize(obs))[:, 0]
