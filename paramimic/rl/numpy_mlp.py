"""An MLP as plain numpy layers: what the sampler and the rollout workers run without torch.

`Layers` are the (W [in, out], b [out]) pairs exported from a torch `mlp()`; they travel between
processes as lists and come back as float32 arrays through `float32_layers`.
"""

from __future__ import annotations

from collections.abc import Iterable

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
